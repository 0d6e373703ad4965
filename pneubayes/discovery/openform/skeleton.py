"""Found open-form terms as the source of effect plug-ins a user can name and edit.

:func:`effect_skeleton` writes a Python module defining an
:class:`~pneubayes.effects.Effect` that lowers onto the closure's slots with the found
terms fixed; :func:`volume_effect_skeleton` one that lowers onto the chamber's volume
table as the found volume closure does; :func:`reading_effect_skeleton` one that relaxes
the reading as the found reading closure does. Their parameters carry the user's names
(to be edited), the found component's bounds and priors, and the fitted values as bench
defaults. Registering one is one line in ``pneubayes.effects.CATALOGUE`` (or
``Model([FoundEffect()])`` directly).
"""

from __future__ import annotations

from pneubayes.effects.closure_terms import term_formula
from pneubayes.effects.reading_closure import gain_name, time_constant_name
from pneubayes.effects.reading_command import command_gain_name, command_time_constant_name
from pneubayes.effects.reading_flow import FLOW_FEATURE_UNITS, flow_gain_name
from pneubayes.effects.reading_hinge import hinge_gain_name, hinge_threshold_name
from pneubayes.effects.reading_play import play_gain_name, play_width_name
from pneubayes.effects.volume_closure import compliance_name, threshold_name
from pneubayes.effects.volume_play import compliance_name as wall_compliance_name
from pneubayes.effects.volume_play import half_width_name, held_compliance_name


def effect_skeleton(model, params: dict, class_name: str = "FoundEffect",
                    effect_name: str = "found_effect") -> str:
    """The module text of an effect plug-in for ``model``'s closure at ``params``.

    Parameters
    ----------
    model : Model
        A model with a ``closure`` component.
    params : dict
        Its fitted parameter values.
    class_name, effect_name : str
        The class's and the catalogue's name for the new effect (edit them).

    Returns
    -------
    str
        Python source; ``exec`` of it defines ``class_name``.
    """
    if not model.has("closure"):
        raise ValueError("effect_skeleton: the model has no closure (no found term)")
    closure = model.effect("closure")
    names, lines = {}, []
    for k, term in enumerate(closure.term_list()):
        lines.append(f"#   term {k}: {term_formula(term, k)}  (kg/s into the chamber)")
        names[f"term{k}_coefficient"] = f"closure_coefficient_{k}"
        for side in term.hinges():
            names[f"term{k}_threshold_{side}"] = f"closure_threshold_{k}_{side}"
    return _delegating_module(
        class_name, effect_name, "a mass flow into the chamber",
        "an open-form closure term (kg/s into the chamber)", lines,
        "from pneubayes.effects.closure import Closure",
        f"Closure(terms={closure.options()['terms']!r})", names, params)


def volume_effect_skeleton(model, params: dict, class_name: str = "FoundVolume",
                           effect_name: str = "found_volume") -> str:
    """The module text of an effect plug-in for ``model``'s volume closure at ``params``
    (its hinges of the chamber's volume in its pressure, under the user's names), or for
    its volume play (its friction-held walls); parameters and return as
    :func:`effect_skeleton`'s."""
    if model.has("volume_play"):
        return _wall_skeleton(model, params, class_name, effect_name)
    if model.has("loaded_wall"):
        lines = [f"#   V = V_0 + C x, x'' + 2 z w x' + w^2 x = w^2 (p - P_atm); C = "
                 f"{float(params['loaded_wall_compliance']):.6g} m^3/Pa, w / 2 pi = "
                 f"{float(params['loaded_wall_frequency']):.6g} Hz, z = "
                 f"{float(params['loaded_wall_damping']):.6g}"]
        names = {"wall_compliance_m3_per_Pa": "loaded_wall_compliance",
                 "wall_frequency_Hz": "loaded_wall_frequency",
                 "wall_damping_ratio": "loaded_wall_damping"}
        return _delegating_module(
            class_name, effect_name, "a chamber wall that carries a load",
            "an open-form loaded wall of the chamber's volume", lines,
            "from pneubayes.effects.loaded_wall import LoadedWall", "LoadedWall()", names,
            params)
    if not model.has("volume_closure"):
        raise ValueError("volume_effect_skeleton: the model has no volume closure (no found "
                         "hinge of the chamber's volume)")
    terms = model.effect("volume_closure").terms
    names, lines = {}, []
    for k in range(terms):
        c, th = compliance_name(k), threshold_name(k)
        lines.append(f"#   hinge {k}: V(p) = V_0 + C_{k} max(0, p - theta_{k}); C_{k} = "
                     f"{float(params[c]):.6g} m^3/Pa, theta_{k} = {float(params[th]):.6g} Pa")
        names[f"hinge{k}_compliance_m3_per_Pa"] = c
        names[f"hinge{k}_threshold_Pa"] = th
    return _delegating_module(
        class_name, effect_name, "a chamber volume that grows with its pressure",
        "open-form hinges of the chamber's volume", lines,
        "from pneubayes.effects.volume_closure import VolumeClosure",
        f"VolumeClosure(terms={terms})", names, params)


def port_effect_skeleton(model, params: dict, class_name: str = "FoundPort",
                         effect_name: str = "found_port") -> str:
    """The module text of an effect plug-in for ``model``'s port restriction at
    ``params`` (a restriction in series at the chamber's port, under the user's names);
    parameters and return as :func:`effect_skeleton`'s."""
    if not model.has("port_restriction"):
        raise ValueError("port_effect_skeleton: the model has no port restriction")

    def area(k):
        return "none" if k <= 0.0 else f"{1.0 / k:.6g} m^2"

    kf, kv = float(params["port_restriction_fill"]), float(params["port_restriction_vent"])
    crack = float(params.get("port_restriction_crack", 0.0))
    lines = [f"#   a_in f(p_s, x) - a_ex f(x, P_atm) = A f(x, p); A = {area(kf)} into the "
             f"chamber, {area(kv)} out of it"]
    if crack > 0.0:
        lines.append(f"#   a check valve in the wider direction cracks at a drop of "
                     f"{crack:.6g} Pa (the narrower's area below it, its own above 2 x)")
    names = {"fill_inverse_area_per_m2": "port_restriction_fill",
             "vent_inverse_area_per_m2": "port_restriction_vent",
             "crack_Pa": "port_restriction_crack"}
    return _delegating_module(
        class_name, effect_name, "a restriction in series at the chamber's port",
        "an open-form restriction at the chamber's port", lines,
        "from pneubayes.effects.port_restriction import PortRestriction", "PortRestriction()",
        names, params)


def _wall_skeleton(model, params: dict, class_name: str, effect_name: str) -> str:
    """:func:`volume_effect_skeleton` for a volume play."""
    terms = model.effect("volume_play").terms
    names, lines = {}, []
    for k in range(terms):
        c, r, h = wall_compliance_name(k), half_width_name(k), held_compliance_name(k)
        lines.append(f"#   wall {k}: V = V_0 + C_{k} (w_{k} - P_atm) + H_{k} (p - w_{k}), w_{k} "
                     f"the play of p of half-width r_{k}; C_{k} = {float(params[c]):.6g} "
                     f"m^3/Pa, H_{k} = {float(params[h]):.6g} m^3/Pa, r_{k} = "
                     f"{float(params[r]):.6g} Pa")
        names[f"wall{k}_compliance_m3_per_Pa"] = c
        names[f"wall{k}_held_compliance_m3_per_Pa"] = h
        names[f"wall{k}_half_width_Pa"] = r
    return _delegating_module(
        class_name, effect_name, "a chamber wall whose give is held by friction",
        "open-form plays of the chamber's volume", lines,
        "from pneubayes.effects.volume_play import VolumePlay",
        f"VolumePlay(terms={terms})", names, params)


def _delegating_module(class_name, effect_name, what, found_as, lines, import_line,
                       component, names, params) -> str:
    """A plug-in module whose effect renames ``component``'s parameters (``names``: its
    own -> the component's) and lowers through it, its bench defaults the fitted
    ``params``."""
    mapping = "\n".join(f"        {mine!r}: {theirs!r}," for mine, theirs in names.items())
    defaults = "\n".join(f"        {mine!r}: {float(params[theirs])!r},"
                         for mine, theirs in names.items())
    return f'''"""{effect_name}: {what} found by pneubayes discover.

Found as {found_as}:
{chr(10).join(lines)}
Edit the names, the descriptions and the bounds to say what it is; ``lower`` keeps
writing the found component's slots. Register it with one line in
pneubayes.effects.CATALOGUE, or use it directly: ``Model([{class_name}()])``.
"""

from pneubayes.effects.base import Effect, Parameter
{import_line}

FOUND = {component}


class {class_name}(Effect):
    """Found: {what} (edit this description)."""

    name = {effect_name!r}
    acts_on = FOUND.acts_on
    beside_line = FOUND.beside_line
    #: This effect's parameter -> the found component's.
    NAMES = {{
{mapping}
    }}

    def parameters(self):
        found = {{p.name: p for p in FOUND.parameters()}}
        return tuple(Parameter(mine, found[theirs].unit, found[theirs].lower,
                               found[theirs].upper, found[theirs].prior,
                               f"found: {{theirs}} (edit)", neutral=found[theirs].neutral)
                     for mine, theirs in self.NAMES.items())

    def lower(self, values, rig):
        return FOUND.lower({{theirs: values[mine] for mine, theirs in self.NAMES.items()}},
                           rig)

    def bench_defaults(self):
        """The values discovery fitted."""
        return {{
{defaults}
        }}
'''


def _reading_skeleton(model, params: dict, component: str, missing: str, term, kind: dict,
                      class_name: str, effect_name: str) -> str:
    """The module text of an effect plug-in for ``model``'s found ``component`` at the
    reading at ``params`` (ValueError ``missing`` without one): ``term(k, params)`` gives
    term ``k``'s description line and its two ``(user's name, component's name)``
    pairs (a gain, then its second parameter); ``kind`` says what the terms are (its
    words, the component's class and module, the second parameter's list and the effect
    method and helper that read them)."""
    if not model.has(component):
        raise ValueError(missing)
    terms = model.effect(component).terms
    names, lines = [], []
    for k in range(terms):
        line, pairs = term(k, params)
        lines.append(line)
        names += [(mine, theirs, float(params[theirs])) for mine, theirs in pairs]
    mapping = "\n".join(f"        {mine!r}: {theirs!r}," for mine, theirs, _ in names)
    defaults = "\n".join(f"        {mine!r}: {value!r}," for mine, _, value in names)
    gains = [m for m, _, _ in names][0::2]
    seconds = [m for m, _, _ in names][1::2]
    cls, method, helper, second = (kind["class"], kind["method"], kind["helper"],
                                   kind["second"])
    return f'''"""{effect_name}: {kind["title"]}

Found as an open-form term at the reading (the chamber's pressure p is unchanged; its
reading r is):
{chr(10).join(lines)}
{kind["edit"]}
Register it with one line in pneubayes.effects.CATALOGUE, or use it directly:
``Model([{class_name}()])``.
"""

from pneubayes.effects.base import Effect, Parameter
from {kind["module"]} import {cls}


class {class_name}(Effect):
    """Found {kind["words"]} of the reading (edit this description)."""

    name = {effect_name!r}
    acts_on = ()  # (the simulator reads each window's pressure through it)
    relaxes_reading = True
    library_searched = False
    #: This effect's parameter -> the {component.replace("_", " ")}'s.
    NAMES = {{
{mapping}
    }}
    GAINS = {gains!r}
    {second} = {seconds!r}

    def parameters(self):
        found = {{p.name: p for p in {cls}(terms={terms}).parameters()}}
        return tuple(Parameter(mine, found[theirs].unit, found[theirs].lower,
                               found[theirs].upper, found[theirs].prior,
                               f"found: {{theirs}} (edit)", neutral=found[theirs].neutral,
                               limit=found[theirs].limit)
                     for mine, theirs in self.NAMES.items())

    def lower(self, values, rig):
        return {{}}  # (no slot of the kernel)

    def {method}(self, values):
        return {cls}.{helper}(values, self.GAINS, self.{second}{kind.get("helper_args", "")})

    def bench_defaults(self):
        """The values discovery fitted."""
        return {{
{defaults}
        }}
'''


def reading_effect_skeleton(model, params: dict, class_name: str = "FoundReading",
                            effect_name: str = "found_reading") -> str:
    """The module text of an effect plug-in for ``model``'s reading closure at
    ``params``: an effect that relaxes the reading
    (:meth:`~pneubayes.effects.Effect.reading_relaxations`) with the found number of
    relaxations, each a gain (-) and a time constant (s) under the user's names;
    parameters and return as :func:`effect_skeleton`'s."""
    def term(k, params):
        g, tau = gain_name(k), time_constant_name(k)
        return (f"#   relaxation {k}: r = p + g_{k} (p - p_bar_{k}), tau_{k} dp_bar_{k}/dt "
                f"= p - p_bar_{k}; g_{k} = {float(params[g]):.6g}, tau_{k} = "
                f"{float(params[tau]):.6g} s",
                [(f"relaxation{k}_gain", g), (f"relaxation{k}_time_constant_s", tau)])
    return _reading_skeleton(
        model, params, "reading_closure", "reading_effect_skeleton: the model has no "
        "reading closure (no found relaxation of the reading)", term, {
            "title": "relaxations of the pressure reading found by pneubayes discover.",
            "edit": "Edit the names, the descriptions and the bounds to say what it is (a "
                    "diaphragm's\ntemperature, a transducer's creep, a cavity before the "
                    "gauge).",
            "words": "relaxations", "class": "ReadingClosure",
            "module": "pneubayes.effects.reading_closure", "second": "TIME_CONSTANTS",
            "method": "reading_relaxations", "helper": "relaxations_named"},
        class_name, effect_name)


def play_effect_skeleton(model, params: dict, class_name: str = "FoundReadingPlay",
                         effect_name: str = "found_reading_play") -> str:
    """The module text of an effect plug-in for ``model``'s reading play at ``params``:
    an effect that adds plays to the reading
    (:meth:`~pneubayes.effects.Effect.reading_plays`) with the found number of plays,
    each a gain (-) and a half-width (Pa) under the user's names; parameters and return
    as :func:`effect_skeleton`'s."""
    def term(k, params):
        h, w = play_gain_name(k), play_width_name(k)
        return (f"#   play {k}: r = p + h_{k} (p - y_{k}), y_{k} = min(p + w_{k}, max(p - "
                f"w_{k}, y_{k} before)); h_{k} = {float(params[h]):.6g}, w_{k} = "
                f"{float(params[w]):.6g} Pa",
                [(f"play{k}_gain", h), (f"play{k}_half_width_Pa", w)])
    return _reading_skeleton(
        model, params, "reading_play", "play_effect_skeleton: the model has no reading play "
        "(no found play of the reading)", term, {
            "title": "plays (backlash) of the pressure reading found by pneubayes\ndiscover.",
            "edit": "Edit the names, the descriptions and the bounds to say what it is (play "
                    "in a gauge's\nlinkage, a diaphragm held by friction).",
            "words": "plays", "class": "ReadingPlay",
            "module": "pneubayes.effects.reading_play", "second": "WIDTHS",
            "method": "reading_plays", "helper": "plays_named"}, class_name, effect_name)


def command_effect_skeleton(model, params: dict, class_name: str = "FoundReadingCommand",
                            effect_name: str = "found_reading_command") -> str:
    """The module text of an effect plug-in for ``model``'s reading command lags at
    ``params``: an effect that adds lags of the command's magnitude to the reading
    (:meth:`~pneubayes.effects.Effect.reading_commands`) with the found number of lags,
    each a gain (Pa per command unit) and a time constant (s) under the user's names;
    parameters and return as :func:`effect_skeleton`'s."""
    def term(k, params):
        c, tau = command_gain_name(k), command_time_constant_name(k)
        return (f"#   lag {k}: r = p + c_{k} l_{k}, tau_{k} dl_{k}/dt = |u| - l_{k}; c_{k} "
                f"= {float(params[c]):.6g} Pa per command unit, tau_{k} = "
                f"{float(params[tau]):.6g} s",
                [(f"command{k}_gain_Pa", c), (f"command{k}_time_constant_s", tau)])
    return _reading_skeleton(
        model, params, "reading_command", "command_effect_skeleton: the model has no "
        "reading command lag (no found lag of the command in the reading)", term, {
            "title": "lags of the command's magnitude in the pressure reading found by\n"
                     "pneubayes discover.",
            "edit": "Edit the names, the descriptions and the bounds to say what it is (a "
                    "ground shared\nwith the solenoid's driver, the coil's field or heat "
                    "at the gauge).",
            "words": "command lags", "class": "ReadingCommand",
            "module": "pneubayes.effects.reading_command", "second": "TIME_CONSTANTS",
            "method": "reading_commands", "helper": "commands_named"},
        class_name, effect_name)


def hinge_effect_skeleton(model, params: dict, class_name: str = "FoundReadingHinge",
                          effect_name: str = "found_reading_hinge") -> str:
    """The module text of an effect plug-in for ``model``'s reading hinge at ``params``:
    an effect that reads the reading through knees last
    (:meth:`~pneubayes.effects.Effect.reading_hinges`) with the found number of knees,
    each a gain (-) and a threshold (Pa absolute) under the user's names; parameters and
    return as :func:`effect_skeleton`'s."""
    below = model.has("reading_hinge") and model.effect("reading_hinge").below

    def term(k, params):
        c, th = hinge_gain_name(k), hinge_threshold_name(k)
        return (f"#   knee {k}: r = z + c_{k} {'min' if below else 'max'}(0, z - theta_{k}); "
                f"c_{k} = {float(params[c]):.6g}, theta_{k} = {float(params[th]):.6g} Pa",
                [(f"knee{k}_gain", c), (f"knee{k}_threshold_Pa", th)])
    return _reading_skeleton(
        model, params, "reading_hinge", "hinge_effect_skeleton: the model has no reading "
        "hinge (no found knee of the reading)", term, {
            "title": "knees of the pressure reading (a static map read last) found by\n"
                     "pneubayes discover.",
            "edit": "Edit the names, the descriptions and the bounds to say what it is (a "
                    "transducer's\nrail, an ADC's full scale, a gauge spring's stop).",
            "words": "knees", "class": "ReadingHinge",
            "module": "pneubayes.effects.reading_hinge", "second": "THRESHOLDS",
            "method": "reading_hinges", "helper": "hinges_named",
            "helper_args": ", below=True" if below else ""}, class_name, effect_name)


_FLOW_TEMPLATE = '''"""{effect_name}: terms of the valve's port flows in the pressure reading
found by pneubayes discover.

Found as an open-form term at the reading (the chamber's pressure p is unchanged; its
reading r is):
{lines}
Edit the names, the descriptions and the bounds to say what it is (a fitting or hose
between the chamber and the sensor, a sensor port facing the inlet's jet).
Register it with one line in pneubayes.effects.CATALOGUE, or use it directly:
``Model([{class_name}()])``.
"""

from pneubayes.effects.base import Effect, Parameter
from pneubayes.effects.reading_flow import ReadingFlow


class {class_name}(Effect):
    """Found port-flow terms of the reading (edit this description)."""

    name = {effect_name!r}
    acts_on = ()  # (the simulator reads each window's pressure through it)
    relaxes_reading = True
    library_searched = False
    #: This effect's parameter -> the reading flow component's.
    NAMES = {{
{mapping}
    }}
    GAINS = {gains!r}
    FEATURES = {features!r}

    def parameters(self):
        found = {{p.name: p for p in ReadingFlow(features=self.FEATURES).parameters()}}
        return tuple(Parameter(mine, found[theirs].unit, found[theirs].lower,
                               found[theirs].upper, found[theirs].prior,
                               f"found: {{theirs}} (edit)", neutral=found[theirs].neutral)
                     for mine, theirs in self.NAMES.items())

    def lower(self, values, rig):
        return {{}}  # (no slot of the kernel)

    def reading_flows(self, values):
        return ReadingFlow.flows_named(values, self.GAINS, self.FEATURES)

    def bench_defaults(self):
        """The values discovery fitted."""
        return {{
{defaults}
        }}
'''


def flow_effect_skeleton(model, params: dict, class_name: str = "FoundReadingFlow",
                         effect_name: str = "found_reading_flow") -> str:
    """The module text of an effect plug-in for ``model``'s reading flow terms at
    ``params``: an effect that adds terms of the port flows to the reading
    (:meth:`~pneubayes.effects.Effect.reading_flows`) with the found features, each a
    gain (Pa per the feature's unit) under the user's names; parameters and return as
    :func:`effect_skeleton`'s."""
    if not model.has("reading_flow"):
        raise ValueError("flow_effect_skeleton: the model has no reading flow component (no "
                         "found term of the port flows in the reading)")
    features = model.effect("reading_flow").features
    names = [(f"{f}_gain", flow_gain_name(k), float(params[flow_gain_name(k)]))
             for k, f in enumerate(features)]
    lines = "\n".join(f"#   term {k}: r = p + c_{k} F_{k}, F_{k} = {f} "
                      f"({FLOW_FEATURE_UNITS[f]}); c_{k} = {v:.6g} Pa per "
                      f"{FLOW_FEATURE_UNITS[f]}"
                      for k, (f, (_, _, v)) in enumerate(zip(features, names)))
    return _FLOW_TEMPLATE.format(
        effect_name=effect_name, class_name=class_name, lines=lines,
        mapping="\n".join(f"        {m!r}: {t!r}," for m, t, _ in names),
        defaults="\n".join(f"        {m!r}: {v!r}," for m, _, v in names),
        gains=[m for m, _, _ in names], features=list(features))


__all__ = ["command_effect_skeleton", "effect_skeleton", "flow_effect_skeleton",
           "play_effect_skeleton", "reading_effect_skeleton", "volume_effect_skeleton"]
