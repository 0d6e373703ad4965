"""What the discovery loop found, in memory: :class:`DiscoveryResult`.

:meth:`Discovery.fit <pneubayes.discovery.loop.Discovery.fit>` leaves one in
``result_``; :func:`pneubayes.discovery.discover` returns it. The run folder
(:mod:`pneubayes.discovery.report`) writes it; nothing reads it back from there.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import pneubayes
from pneubayes.discovery.settings import DiscoverySettings
from pneubayes.discovery.verification import StepFit
from pneubayes.effects.closure_terms import (
    modulated_port,
    term_formula,
)
from pneubayes.effects.reading_closure import gain_name, time_constant_name
from pneubayes.effects.reading_command import command_gain_name, command_time_constant_name
from pneubayes.effects.reading_flow import FLOW_FEATURE_UNITS, flow_gain_name
from pneubayes.effects.reading_hinge import hinge_gain_name, hinge_threshold_name
from pneubayes.effects.reading_play import play_gain_name, play_width_name
from pneubayes.effects.volume_closure import compliance_name, threshold_name
from pneubayes.effects.volume_play import compliance_name as wall_compliance_name
from pneubayes.effects.volume_play import half_width_name, held_compliance_name
from pneubayes.inference.fit import PosteriorDraws, at_bounds

FORMAT = "pneubayes-discovery/1"
#: The open-form components: their terms are listed apart from the named effects.
OPEN_FORM = ("closure", "reading_closure", "reading_play", "reading_command", "reading_flow",
             "reading_hinge",
             "volume_closure",
             "volume_play", "loaded_wall", "port_restriction", "command_clock")


@dataclass(frozen=True, eq=False)
class DiscoveryResult(PosteriorDraws):
    """The loop's answer and its record.

    Attributes
    ----------
    settings : the loop's settings
    base, final : the starting and the final model's fits (model, refined parameters,
        training and held-out RMSE in Pa, held-out scores)
    accepted : the effects added, in order: name, library evidence, held-out score gain
        and p-value, held-out RMSE before and after (Pa)
    ledger : every step of the loop (fits, searches, trials, additions, prunings)
    maps : each round's disagreement map (:mod:`pneubayes.discovery.disagreement`)
    searches : each round's library evidence (inclusion probabilities, best terms)
    params : the final model's estimate -- the posterior median when one was sampled,
        else the refined point; ``estimate`` says which
    posterior : arviz InferenceData of the final model's emcee chain (None without one)
    posterior_summary : per parameter median, 5 % and 95 % quantiles, R-hat, ESS
    posterior_info : method (emcee or laplace), converged (laplace: the log-posterior
        is concave at its mode and the importance check finds its draws reliable), steps
        (laplace: 0), the sampling solver and its log-density roughness (nats); laplace:
        the importance check (Pareto k, its threshold, ESS fraction; None unchecked) and
        the parameters whose prior bound the mode is on
    noise_floor_Pa : the recordings' white-noise floor (median), Pa
    range_Pa : the rig's working range (supply - atmosphere), Pa
    span_Pa : the measured pressures' 1-99 % span, Pa
    train, held : the prepared recordings (or their parts) fitted on and held out
    wall_time_s : the loop's wall time, s
    stages : the pipeline's stages in order, each ``{"stage": name, **its options}``
    """

    settings: DiscoverySettings
    base: StepFit
    final: StepFit
    accepted: tuple
    ledger: tuple
    maps: tuple
    searches: tuple
    params: dict
    estimate: str
    noise_floor_Pa: float
    range_Pa: float
    span_Pa: float
    posterior: object | None = None
    posterior_summary: dict | None = None
    posterior_info: dict | None = None
    train: tuple = field(default=(), repr=False)
    held: tuple = field(default=(), repr=False)
    wall_time_s: float | None = None
    stages: tuple = ()

    #: What :class:`~pneubayes.inference.fit.PosteriorDraws` calls the result in errors.
    method = "discovery"

    @property
    def model(self):
        """The final model."""
        return self.final.model

    @property
    def effect_names(self) -> list[str]:
        """The effects the loop added, in order (stand-ins included: :meth:`stand_ins`)."""
        return [a["name"] for a in self.accepted]

    def stand_ins(self) -> dict[str, list[dict]]:
        """The added catalogue effects the final fit keeps only by driving a parameter of
        their own to a bound (other than the value that switches the effect off or a
        parameter's physical :attr:`~pneubayes.effects.base.Parameter.limit`): each
        name -> its parameters there (:func:`~pneubayes.inference.fit.at_bounds`: the
        posterior's 90 % interval, or the refined point without one, within 1 % of the
        bounds' width, decades judged in log space). Such an effect improves the
        prediction but its form is strained: it stands in for something it cannot
        express, and the loop does not name it."""
        model = self.final.model
        post = self.posterior_summary
        out = {}
        for a in self.accepted:
            if a["name"] in OPEN_FORM:
                continue
            names = model.effect(a["name"]).parameter_names()
            summary = {n: (post[n] if post is not None and n in post else
                           {"q05": self.final.params[n], "q95": self.final.params[n]})
                       for n in names}
            hits = []
            for b in at_bounds(model, summary):
                param = model.parameter(b["parameter"])
                if param.neutral is not None and param.neutral == b["value"]:
                    continue  # (at the value that switches it off: not a strained form)
                if param.limit == b["bound"]:
                    continue  # (where its physics ends: that limit, not a strained form)
                hits.append(b)
            if hits:
                out[a["name"]] = hits
        return out

    def found_terms(self) -> list[dict]:
        """The final model's open-form closure terms (empty without one): each term's
        text, its formula in SI units, its coefficient and thresholds (the posterior's
        median and 90 % interval when one was sampled, else the estimate), and where it
        acts."""
        model = self.final.model
        if not model.has("closure"):
            return []
        out = []
        for k, term in enumerate(model.effect("closure").term_list()):
            values = self._values([f"closure_coefficient_{k}"]
                                  + [f"closure_threshold_{k}_{side}" for side in term.hinges()])
            port = modulated_port(term)
            acts = ("mass flow into the chamber (kg/s)" if port is None else
                    f"mass flow into the chamber (kg/s), as a change of the {port}'s "
                    "effective area (its port's factor clipped where the flow would "
                    "reverse)")
            out.append({"term": str(term), "acts_on": acts,
                        "formula": term_formula(term, k), "parameters": values})
        return out

    def _values(self, names) -> dict:
        """Each of ``names``' unit and its posterior median and 90 % interval when one
        was sampled, else the estimate."""
        model, post = self.final.model, self.posterior_summary
        out = {}
        for n in names:
            p = model.parameter(n)
            if post is not None and n in post:
                out[n] = {"unit": p.unit, **{q: post[n][q] for q in ("median", "q05", "q95")}}
            else:
                out[n] = {"unit": p.unit, "estimate": self.final.params[n]}
        return out

    def _component_terms(self, component: str, label: str, acts_on: str, formula,
                         names) -> list[dict]:
        """Each term ``k`` of the final model's ``component`` (empty without one): its
        label, ``formula(k)`` and the values of ``names(k)`` (:meth:`_values`)."""
        model = self.final.model
        if not model.has(component):
            return []
        return [{"term": f"{label} {k}", "acts_on": acts_on, "formula": formula(k),
                 "parameters": self._values(names(k))}
                for k in range(model.effect(component).terms)]

    def found_reading_terms(self) -> list[dict]:
        """The final model's open-form terms at the reading (effects ``reading_closure``,
        ``reading_play``, ``reading_command``, ``reading_flow`` and ``reading_hinge``;
        empty without them): each relaxation's, play's, command lag's, port flow term's or
        knee's formula, its gain and time constant, half-width or knee (the posterior's
        median and 90 % interval when one was sampled, else the estimate), and where it
        acts."""
        return self._component_terms(
            "reading_closure", "relaxation", "the pressure reading (Pa)",
            lambda k: (f"r = p + g_{k} (p - p_bar_{k}), tau_{k} dp_bar_{k}/dt = p - p_bar_{k} "
                       f"(g_{k} = {gain_name(k)}, tau_{k} = {time_constant_name(k)}, s)"),
            lambda k: (gain_name(k), time_constant_name(k))) + self._component_terms(
            "reading_play", "play", "the pressure reading (Pa)",
            lambda k: (f"r = p + h_{k} (p - y_{k}), y_{k} = min(p + w_{k}, max(p - w_{k}, "
                       f"y_{k} before)) (h_{k} = {play_gain_name(k)}, w_{k} = "
                       f"{play_width_name(k)}, Pa)"),
            lambda k: (play_gain_name(k), play_width_name(k))) + self._component_terms(
            "reading_command", "command lag", "the pressure reading (Pa)",
            lambda k: (f"r = p + c_{k} l_{k}, tau_{k} dl_{k}/dt = |u| - l_{k} (c_{k} = "
                       f"{command_gain_name(k)}, Pa per command unit; tau_{k} = "
                       f"{command_time_constant_name(k)}, s)"),
            lambda k: (command_gain_name(k), command_time_constant_name(k))
        ) + self._component_terms(
            "reading_flow", "port flow term", "the pressure reading (Pa)",
            lambda k: (f"r = p + c_{k} F_{k}, F_{k} = {self._flow_feature(k)} "
                       f"({FLOW_FEATURE_UNITS[self._flow_feature(k)]}; q_in = A_in f(p_s, p), "
                       f"q_ex = A_ex f(p, P_atm), eqs. 1-3) (c_{k} = {flow_gain_name(k)}, Pa "
                       f"per {FLOW_FEATURE_UNITS[self._flow_feature(k)]})"),
            lambda k: (flow_gain_name(k),)) + self._component_terms(
            "reading_hinge", "knee", "the pressure reading (Pa), read last",
            lambda k: (f"r = z + c_{k} {self._knee_side()}(0, z - theta_{k}), z the reading "
                       f"without the knees (c_{k} = {hinge_gain_name(k)}; theta_{k} = "
                       f"{hinge_threshold_name(k)}, Pa absolute)"),
            lambda k: (hinge_gain_name(k), hinge_threshold_name(k)))

    def _knee_side(self) -> str:
        """``max`` for the final model's knees above, ``min`` for knees below."""
        return "min" if self.final.model.effect("reading_hinge").below else "max"

    def _flow_feature(self, k: int) -> str:
        """The feature of the final model's reading flow term ``k``."""
        return self.final.model.effect("reading_flow").features[k]

    def found_volume_terms(self) -> list[dict]:
        """The final model's open-form terms on the chamber's volume (effects
        ``volume_closure``, ``volume_play`` and ``loaded_wall``; empty without them): each
        hinge's, friction-held wall's or loaded wall's formula, its parameters (as
        :meth:`found_reading_terms` gives them), and where it acts."""
        return self._component_terms(
            "volume_closure", "hinge", "the chamber's volume (m^3)",
            lambda k: (f"V(p) = V_0 + C_{k} max(0, p - theta_{k}) (C_{k} = "
                       f"{compliance_name(k)}, m^3/Pa; theta_{k} = {threshold_name(k)}, "
                       "Pa absolute)"),
            lambda k: (compliance_name(k), threshold_name(k))) + self._component_terms(
            "volume_play", "wall", "the chamber's volume (m^3)",
            lambda k: (f"V = V_0 + C_{k} (w_{k} - P_atm) + H_{k} (p - w_{k}), w_{k} = min(p + "
                       f"r_{k}, max(p - r_{k}, w_{k} before)) (C_{k} = "
                       f"{wall_compliance_name(k)}, H_{k} = {held_compliance_name(k)}, "
                       f"m^3/Pa; r_{k} = {half_width_name(k)}, Pa)"),
            lambda k: (wall_compliance_name(k), held_compliance_name(k), half_width_name(k))
        ) + self._component_terms(
            "loaded_wall", "loaded wall", "the chamber's volume (m^3)",
            lambda k: ("V = V_0 + C x, x'' + 2 z w x' + w^2 x = w^2 (p - P_atm) (C = "
                       "loaded_wall_compliance, m^3/Pa; w / 2 pi = loaded_wall_frequency, "
                       "Hz; z = loaded_wall_damping)"),
            lambda k: ("loaded_wall_compliance", "loaded_wall_frequency",
                       "loaded_wall_damping"))

    def found_command_terms(self) -> list[dict]:
        """The final model's open-form term on the command (effect ``command_clock``;
        empty without it): the driver's formula, its parameters (as
        :meth:`found_reading_terms` gives them) and where it acts."""
        model = self.final.model
        if not model.has("command_clock"):
            return []
        eff = model.effect("command_clock")
        formula = ("the valve takes u(t_k) at ticks t_k = (phi + k) T and holds it from "
                   "t_k + L" if eff.form == "hold" else
                   "the valve at +-U (the sign of u(t_k)) from t_k + L + a (1 - d_k) T for "
                   "d_k T - e, d_k = min(|u(t_k)| / U, 1), shut for the rest of the period, "
                   "t_k = (phi + k) T")
        return [{"term": f"driver clock ({eff.form})", "acts_on": "the valve's command (V)",
                 "formula": formula + " (T = command_clock_period, s; phi = "
                 "command_clock_phase; L = command_clock_latency, s"
                 + ("; U = command_clock_full_command, V; e = command_clock_pulse_trim, s; "
                    "a = command_clock_pulse_alignment)" if eff.form == "pwm" else ")"),
                 "parameters": self._values(eff.parameter_names())}]

    def found_port_terms(self) -> list[dict]:
        """The final model's open-form term at the chamber's port (effect
        ``port_restriction``; empty without it): its formula, its parameters (as
        :meth:`found_reading_terms` gives them) and where it acts."""
        model = self.final.model
        if not model.has("port_restriction"):
            return []
        eff = model.effect("port_restriction")
        return [{"term": "port restriction",
                 "acts_on": "the valve's ports, which see the pressure x between them and "
                            "the restriction (Pa)",
                 "formula": "a_in f(p_s, x) - a_ex f(x, P_atm) = A f(x, p), A = 1 / k_f "
                            "into the chamber (x > p), 1 / k_v out of it (k_f = "
                            "port_restriction_fill, k_v = port_restriction_vent, 1/m^2; 0: "
                            "that direction unrestricted); with a check valve (c = "
                            "port_restriction_crack, Pa, > 0) the wider direction passes "
                            "the narrower's area below a drop |x - p| of c, its own above "
                            "2 c",
                 "parameters": self._values(eff.parameter_names())}]

    def to_dict(self) -> dict:
        """The ``pneubayes-discovery/1`` document (JSON-ready but for numpy scalars)."""
        post = self.posterior_summary
        strained = self.stand_ins()
        effects, stand_ins = [], []
        for a in self.accepted:
            if a["name"] in OPEN_FORM:  # open-form terms: listed apart, as found_terms,
                continue  # found_reading_terms, found_volume_terms, found_port_terms, ...
            eff = self.final.model.effect(a["name"])
            params = {}
            for n in eff.parameter_names():
                if post is not None:
                    params[n] = {k: post[n][k] for k in ("median", "q05", "q95")}
                else:
                    params[n] = {"estimate": self.final.params[n]}
            ev = a["evidence"]
            entry = {"name": a["name"], "options": eff.options(), "parameters": params,
                     "evidence": {"inclusion_probability": ev["inclusion_probability"],
                                  "t_max": ev["t_max"], "best_term": ev["best_term"],
                                  "score_gain": a["score_gain"],
                                  "score_p_value": a["score_p_value"]},
                     "rmse_before_Pa": a["rmse_before_Pa"], "rmse_after_Pa": a["rmse_after_Pa"]}
            if a["name"] in strained:  # kept in the model, not named
                stand_ins.append({**entry, "at_bounds": strained[a["name"]]})
            else:
                effects.append(entry)
        doc = {"format": FORMAT, "effects": effects, "stand_ins": stand_ins,
               "found_terms": self.found_terms(),
               "found_reading_terms": self.found_reading_terms(),
               "found_volume_terms": self.found_volume_terms(),
               "found_command_terms": self.found_command_terms(),
               "found_port_terms": self.found_port_terms(),
               "rmse_base_Pa": self.base.heldout_rmse_Pa,
               "rmse_final_Pa": self.final.heldout_rmse_Pa,
               "noise_floor_Pa": self.noise_floor_Pa, "range_Pa": self.range_Pa,
               "span_Pa": self.span_Pa, "horizon_s": self.settings.fit.horizon_s,
               "model": "model.json", "ledger": list(self.ledger),
               "settings": self.settings.to_dict(), "stages": list(self.stages),
               "seed": self.settings.seed,
               "wall_time_s": self.wall_time_s,
               "pneubayes_version": pneubayes.__version__}
        if self.posterior_info is not None:
            doc["posterior"] = {**self.posterior_info, "summary": post}
        return doc
