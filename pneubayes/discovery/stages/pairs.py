"""Stage: the round's strongest trials fitted jointly, two at a time."""

from __future__ import annotations

import numpy as np

from pneubayes.discovery.candidates import effect_candidates
from pneubayes.discovery.rounds import gain_shortfall, min_gain_Pa, pairs_to_try
from pneubayes.discovery.stages.base import Stage
from pneubayes.discovery.state import RoundState
from pneubayes.errors import FIT_FAILURES


class Pairs(Stage):
    """When nothing passed and the held-out error is far above the noise floor, fit the
    round's trials with the largest training gains in pairs, each jointly from its
    members' fitted values and from their trials' starts (the lower training RMSE
    kept; ledger action ``pair``). Two effects can each fail alone (one fixes a regime
    and leaves the other's misfit to drift) and pass together. A pair passes as a
    single trial does (against the current fit and its control, closing
    ``min_gap_closed`` of the gap, above the gain floor) and must beat each member's own
    trial; the best adds both effects.

    Parameters
    ----------
    members : int
        The round's trials with the largest training gains paired (at least 2).
    min_gap_closed : float
        Share of the held-out RMSE's gap above the noise floor a pair must close.
    """

    name = "pairs"

    def __init__(self, members: int = 3, min_gap_closed: float = 0.25):
        if members < 2:
            raise ValueError(f"Pairs: members must be >= 2 (a pair), got {members}")
        self.members = members
        self.min_gap_closed = min_gap_closed

    def options(self):
        return {"members": self.members, "min_gap_closed": self.min_gap_closed}

    def run(self, state: RoundState, runner) -> None:
        if state.passing or not state.far():
            return
        s, noise = runner.settings, runner.data.noise_Pa
        tried, current = state.tried, state.current
        pairs = pairs_to_try({g: forms[0][1].train_rmse_Pa for g, forms in tried.items()
                              if forms},
                             current.train_rmse_Pa,
                             min_gain_Pa(noise, current.train_rmse_Pa - noise, s),
                             self.members)
        if not pairs:
            return
        runner.log("discover: no single effect passed; fitting pairs of the round's "
                   "largest training gains: " + ", ".join(f"{a} + {b}" for a, b in pairs))
        runner.ledger.record("pairs", groups=[f"{a} + {b}" for a, b in pairs])
        fitted = [f for f in (self._fit_pair(a, b, state, runner) for a, b in pairs)
                  if f is not None]
        controls = runner.controls([(f"pair {f[0]} + {f[1]}", f[4]) for f in fitted], state)
        state.passing = [p for p in (self._verdict(f, control, state, runner)
                                     for f, control in zip(fitted, controls))
                         if p is not None]

    def _fit_pair(self, a: str, b: str, state: RoundState, runner):
        """The pair fitted from two starts, the members' fitted values and their trials'
        own starts: ``(a, b, model, start, fit)`` of the lower training RMSE, or None."""
        current = state.current
        chosen = self.forms(a, b, state.tried, state.search, runner)
        if chosen is None:
            runner.log(f"discover: pair {a} + {b}: no fitted form of each can be "
                       "simulated beside the other's; not fitted")
            return None
        (ma, fa, sa), (mb, fb, sb) = chosen
        model = current.model.with_effect(ma.effect(a)).with_effect(mb.effect(b))
        # two starts: the members' fitted values (each fitted alone, it may have run
        # to a bound standing in for the other) and their trials' own starts
        starts = []
        for values_a, values_b in ((fa.params, fb.params), (sa, sb)):
            start = {k: current.params[k] for k in current.model.parameter_names}
            for m, values, g in ((ma, values_a, a), (mb, values_b, b)):
                start.update({k: values[k] for k in m.effect(g).parameter_names()})
            if start not in starts:
                starts.append(start)
        fits = []
        for start in starts:
            try:
                fits.append((runner.fit(model, start), start))
            except FIT_FAILURES as exc:
                runner.log(f"discover: pair {a} + {b} from {len(fits) + 1} of "
                           f"{len(starts)} start(s) failed ({type(exc).__name__})")
        if not fits:
            return None
        fit, start = min(fits, key=lambda fx: fx[0].train_rmse_Pa)
        if len(fits) > 1:
            runner.log(f"discover: pair {a} + {b}: training RMSE "
                       + ", ".join(f"{f.train_rmse_Pa:.0f}" for f, _ in fits)
                       + " Pa from the members' fitted values and their own starts")
        return a, b, model, start, fit

    def _verdict(self, fitted, control, state: RoundState, runner):
        """Verify one fitted pair; record it. Returns the passing tuple or None."""
        s, noise = runner.settings, runner.data.noise_Pa
        a, b, model, start, fit = fitted
        current, tried = state.current, state.tried
        gap_Pa = current.heldout_rmse_Pa - noise
        ok, gain, pval, diff = runner.better(fit, current)
        basin = bool(ok and control is not None and control is not current
                     and not runner.better(fit, control)[0])
        # each member must carry a gain the other's own trial does not have
        needed = {g: bool(runner.better(fit, tried[other][0][1])[0])
                  for g, other in ((a, b), (b, a))}
        drop_Pa = current.heldout_rmse_Pa - fit.heldout_rmse_Pa
        least = min_gain_Pa(noise, gap_Pa, s)
        closed, short, under = gain_shortfall(drop_Pa, gap_Pa, self.min_gap_closed, least)
        ok = ok and not basin and all(needed.values()) and not short and not under
        names = [n for g in (a, b) for n in model.effect(g).parameter_names()]
        runner.ledger.record(
            "pair", effects=[a, b], passed=ok,
            effect_options={g: model.effect(g).options() for g in (a, b)},
            start={k: start[k] for k in names},
            fitted={k: fit.params[k] for k in names}, gap_closed=closed,
            train_rmse_Pa=fit.train_rmse_Pa,
            heldout_rmse_before_Pa=current.heldout_rmse_Pa,
            heldout_rmse_after_Pa=fit.heldout_rmse_Pa,
            score_gain=gain, score_p_value=pval,
            control_heldout_rmse_Pa=None if control is None else control.heldout_rmse_Pa,
            not_better_than_control=basin, members_needed=needed,
            windows_improved=int(np.sum(diff > 0)), windows=int(diff.size),
            wall_time_s=fit.wall_time_s)
        why = ([] if not basin else ["its gain is its basin's"]) + [
            f"not better than {g2} alone" for g, g2 in ((b, a), (a, b))
            if not needed[g]] + (
            [f"it closes {100 * (closed or 0.0):.0f} % of the gap"] if short else []) + (
            [f"it gains {drop_Pa:.1f} Pa, under {least:.1f} Pa"] if under else [])
        runner.log(f"discover: {'passes' if ok else 'reject'} pair {a} + {b}: held-out "
                   f"RMSE {current.heldout_rmse_Pa:.0f} -> {fit.heldout_rmse_Pa:.0f} Pa, "
                   f"better in {int(np.sum(diff > 0))}/{diff.size} windows "
                   f"(p = {pval:.2g}), log predictive gain {gain:.1f}"
                   + ("" if ok or not why else "; " + "; ".join(why)))
        return (fit.heldout_rmse_Pa, (a, b), fit, gain, pval) if ok else None

    @staticmethod
    def forms(a: str, b: str, tried: dict, search, runner):
        """The fitted forms of ``a`` and ``b`` to pair, ``((model, fit, start), (...))``:
        of the combinations in which each form is one its effect proposes beside the
        other's (a transmission-line tube has no temperature state beside it), the one
        with the lowest summed training RMSE; None if there is none."""
        s, rig = runner.settings, runner.data.rig()

        def proposed(g, beside):
            forms = effect_candidates(beside, g, search.evidence_[g], rig, s.forms)
            return {m.effect(g).options().get("form") for m, _ in forms}

        combos = sorted(((x, y) for x in tried[a] for y in tried[b]),
                        key=lambda xy: xy[0][1].train_rmse_Pa + xy[1][1].train_rmse_Pa)
        for x, y in combos:
            if (y[0].effect(b).options().get("form") in proposed(b, x[1])
                    and x[0].effect(a).options().get("form") in proposed(a, y[1])):
                return x, y
        return None
