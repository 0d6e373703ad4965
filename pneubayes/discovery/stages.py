"""The discovery loop's later stages: pairs of effects, and the named effects' other forms.

When no single effect passes verification in a round, the loop tries two more
things before it stops (:class:`~pneubayes.discovery.loop.Discovery`, step 7):

* **pairs** (``pair_members``): the round's trials with the largest training gains,
  fitted jointly two at a time from their members' fitted values; two effects can each
  fail alone and pass together;
* **other forms** (``max_form_swaps``): each named effect refitted in the other forms
  it proposes beside the rest of the model (a tube chosen as a wave tube alone can be a
  lumped line beside heat transfer).

:class:`LaterStages` is a mixin of :class:`~pneubayes.discovery.loop.Discovery`: it uses
the loop's ``settings``, ``_fit``, ``_better``, ``_controls`` and ``log``.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from pneubayes.discovery.candidates import effect_candidates, first_free
from pneubayes.discovery.rounds import gain_shortfall, min_gain_Pa, pairs_to_try
from pneubayes.discovery.verification import StepFit
from pneubayes.effects import make_effect
from pneubayes.errors import SimulationError
from pneubayes.model import Model


def form_label(model: Model, group: str) -> str:
    """The form of a model's effect (``"-"`` for an effect with one form; an acoustic
    line's with its cells, ``"line/8"``; a sensor lag on every channel
    ``"first_order/all"``)."""
    opts = model.effect(group).options()
    return (str(opts.get("form", "-")) + (f"/{opts['segments']}" if "segments" in opts else "")
            + (f"/{opts['channels']}" if "channels" in opts else ""))


class LaterStages:
    """The pair and form stages (a mixin of the discovery loop)."""

    def _pairs(self, tried: dict, current: StepFit, ctx):
        """The pair stage (``pair_members``): the round's trials with the largest
        training gains fitted jointly in pairs, each from the current fit with its
        members' fitted values and with their trials' starts (the lower training RMSE
        kept); a pair passes as a single trial does (against the
        current fit and its control, closing ``last_resort_min_gap_closed`` of the gap,
        above the gain floor) and must beat each member's own trial too. Appends to the
        ledger; returns (current, passing pairs) with each pair's effects as a tuple."""
        s = self.settings
        sindy, train, train_ws, held_ws, data_key, noise, ledger = ctx
        pairs = pairs_to_try({g: forms[0][1].train_rmse_Pa for g, forms in tried.items()
                              if forms},
                             current.train_rmse_Pa,
                             min_gain_Pa(noise, current.train_rmse_Pa - noise, s),
                             s.pair_members)
        if not pairs:
            return current, []
        self.log("discover: no single effect passed; fitting pairs of the round's "
                 "largest training gains: " + ", ".join(f"{a} + {b}" for a, b in pairs))
        ledger.append({"step": len(ledger), "action": "pairs",
                       "groups": [f"{a} + {b}" for a, b in pairs]})
        fitted = []
        for a, b in pairs:
            chosen = self._pair_forms(a, b, tried, sindy, train[0].rig())
            if chosen is None:
                self.log(f"discover: pair {a} + {b}: no fitted form of each can be "
                         "simulated beside the other's; not fitted")
                continue
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
                    fits.append((self._fit(model, start, train_ws, held_ws, data_key),
                                 start))
                except (FloatingPointError, SimulationError) as exc:
                    self.log(f"discover: pair {a} + {b} from {len(fits) + 1} of "
                             f"{len(starts)} start(s) failed ({type(exc).__name__})")
            if not fits:
                continue
            fit, start = min(fits, key=lambda fx: fx[0].train_rmse_Pa)
            if len(fits) > 1:
                self.log(f"discover: pair {a} + {b}: training RMSE "
                         + ", ".join(f"{f.train_rmse_Pa:.0f}" for f, _ in fits)
                         + " Pa from the members' fitted values and their own starts")
            fitted.append((a, b, model, start, fit))
        controls, current = self._controls([(f"pair {f[0]} + {f[1]}", f[4]) for f in fitted],
                                           current, ctx)
        passing = []
        gap_Pa = current.heldout_rmse_Pa - noise
        for (a, b, model, start, fit), control in zip(fitted, controls):
            ok, gain, pval, diff = self._better(fit, current)
            basin = bool(ok and control is not None and control is not current
                         and not self._better(fit, control)[0])
            # each member must carry a gain the other's own trial does not have
            needed = {g: bool(self._better(fit, tried[other][0][1])[0])
                      for g, other in ((a, b), (b, a))}
            drop_Pa = current.heldout_rmse_Pa - fit.heldout_rmse_Pa
            least = min_gain_Pa(noise, gap_Pa, s)
            closed, short, under = gain_shortfall(drop_Pa, gap_Pa,
                                                  s.last_resort_min_gap_closed, least)
            ok = ok and not basin and all(needed.values()) and not short and not under
            names = [n for g in (a, b) for n in model.effect(g).parameter_names()]
            ledger.append({
                "step": len(ledger), "action": "pair", "effects": [a, b], "passed": ok,
                "effect_options": {g: model.effect(g).options() for g in (a, b)},
                "start": {k: start[k] for k in names},
                "fitted": {k: fit.params[k] for k in names}, "gap_closed": closed,
                "train_rmse_Pa": fit.train_rmse_Pa,
                "heldout_rmse_before_Pa": current.heldout_rmse_Pa,
                "heldout_rmse_after_Pa": fit.heldout_rmse_Pa,
                "score_gain": gain, "score_p_value": pval,
                "control_heldout_rmse_Pa": None if control is None else
                control.heldout_rmse_Pa,
                "not_better_than_control": basin, "members_needed": needed,
                "windows_improved": int(np.sum(diff > 0)), "windows": int(diff.size),
                "wall_time_s": fit.wall_time_s})
            why = ([] if not basin else ["its gain is its basin's"]) + [
                f"not better than {g2} alone" for g, g2 in ((b, a), (a, b))
                if not needed[g]] + (
                [f"it closes {100 * (closed or 0.0):.0f} % of the gap"] if short else []) + (
                [f"it gains {drop_Pa:.1f} Pa, under {least:.1f} Pa"] if under else [])
            self.log(f"discover: {'passes' if ok else 'reject'} pair {a} + {b}: held-out "
                     f"RMSE {current.heldout_rmse_Pa:.0f} -> {fit.heldout_rmse_Pa:.0f} Pa, "
                     f"better in {int(np.sum(diff > 0))}/{diff.size} windows "
                     f"(p = {pval:.2g}), log predictive gain {gain:.1f}"
                     + ("" if ok or not why else "; " + "; ".join(why)))
            if ok:
                passing.append((fit.heldout_rmse_Pa, (a, b), fit, gain, pval))
        return current, passing

    def _other_forms(self, current: StepFit, ctx) -> StepFit | None:
        """The form stage (``max_form_swaps``): each named effect refitted in the other
        forms it proposes beside the rest of the model (a tube named beside heat transfer
        as a transport delay is an acoustic line there; alone it was a wave tube), started
        at the current fit; a form passes as a trial does against the current fit (its
        control is the current fit itself: the same parameters elsewhere). Appends to the
        ledger; returns the passing refit with the lowest held-out RMSE, or None."""
        s = self.settings
        sindy, train, train_ws, held_ws, data_key, noise, ledger = ctx
        rig = train[0].rig()
        options = []
        for g in current.model.effect_names:
            rest = current.model.without(g)
            effect = make_effect(g, **current.model.effect_options(g))
            term = {k: current.params[k] for k in effect.discovery_fallback
                    if k in current.params}
            here = SimpleNamespace(model=rest, params={k: current.params[k]
                                                       for k in rest.parameter_names})
            for m, start in effect_candidates(here, g, {"best_term_start": term or None},
                                              rig, s.tube_line_segments,
                                              s.tube_line_cutoff_Hz, s.tube_line_form):
                if form_label(m, g) == form_label(current.model, g):
                    continue
                # the rest of the model where it was fitted; the new form's own values
                start = {**start, **{k: current.params[k] for k in rest.parameter_names}}
                options.append((g, m, start))
        if not options:
            return None
        self.log("discover: nothing passed; refitting the named effects in their other "
                 "forms: " + ", ".join(f"{g} {form_label(m, g)}" for g, m, _ in options))
        ledger.append({"step": len(ledger), "action": "other forms",
                       "groups": [f"{g} {form_label(m, g)}" for g, m, _ in options]})
        gap_Pa = current.heldout_rmse_Pa - noise
        least = min_gain_Pa(noise, gap_Pa, s)
        passing = []
        for g, m, start in options:
            try:
                fit = self._fit(m, start, train_ws, held_ws, data_key, first_free(m, g))
            except (FloatingPointError, SimulationError) as exc:
                self.log(f"discover: {g} {form_label(m, g)} failed ({type(exc).__name__})")
                continue
            ok, gain, pval, diff = self._better(fit, current)
            drop_Pa = current.heldout_rmse_Pa - fit.heldout_rmse_Pa
            ok = ok and drop_Pa >= least
            names = m.effect(g).parameter_names()
            ledger.append({
                "step": len(ledger), "action": "form", "effect": g, "passed": ok,
                "from": form_label(current.model, g), "to": form_label(m, g),
                "effect_options": m.effect(g).options(),
                "fitted": {k: fit.params[k] for k in names},
                "train_rmse_Pa": fit.train_rmse_Pa,
                "heldout_rmse_before_Pa": current.heldout_rmse_Pa,
                "heldout_rmse_after_Pa": fit.heldout_rmse_Pa,
                "score_gain": gain, "score_p_value": pval,
                "windows_improved": int(np.sum(diff > 0)), "windows": int(diff.size),
                "wall_time_s": fit.wall_time_s})
            self.log(f"discover: {'passes' if ok else 'reject'} {g} as {form_label(m, g)} "
                     f"(was {form_label(current.model, g)}): training RMSE "
                     f"{current.train_rmse_Pa:.0f} -> {fit.train_rmse_Pa:.0f} Pa, held-out "
                     f"{current.heldout_rmse_Pa:.0f} -> {fit.heldout_rmse_Pa:.0f} Pa, better "
                     f"in {int(np.sum(diff > 0))}/{diff.size} windows (p = {pval:.2g})")
            if ok:
                passing.append((fit.heldout_rmse_Pa, g, m, fit))
        if not passing:
            return None
        _, g, m, fit = min(passing, key=lambda t: t[0])
        self.log(f"discover: SWAP {g} to {form_label(m, g)} (the largest held-out improvement)")
        ledger.append({"step": len(ledger), "action": "swap form", "effect": g,
                       "to": form_label(m, g),
                       "heldout_rmse_before_Pa": current.heldout_rmse_Pa,
                       "heldout_rmse_after_Pa": fit.heldout_rmse_Pa})
        return fit

    def _pair_forms(self, a: str, b: str, tried: dict, sindy, rig):
        """The fitted forms of ``a`` and ``b`` to pair, ``((model, fit, start), (...))``:
        of the combinations in which each form is one its effect proposes beside the
        other's (a transmission-line tube has no temperature state beside it), the one
        with the lowest summed training RMSE; None if there is none."""
        s = self.settings

        def proposed(g, beside):
            forms = effect_candidates(beside, g, sindy.evidence_[g], rig,
                                      s.tube_line_segments, s.tube_line_cutoff_Hz,
                                      s.tube_line_form)
            return {m.effect(g).options().get("form") for m, _ in forms}

        combos = sorted(((x, y) for x in tried[a] for y in tried[b]),
                        key=lambda xy: xy[0][1].train_rmse_Pa + xy[1][1].train_rmse_Pa)
        for x, y in combos:
            if (y[0].effect(b).options().get("form") in proposed(b, x[1])
                    and x[0].effect(a).options().get("form") in proposed(a, y[1])):
                return x, y
        return None
