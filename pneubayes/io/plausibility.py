"""Plausibility rules: values that are well-formed but physically impossible or unusual.

These rules catch a recording that satisfies the format and is still wrong (pressures in
bar, milliseconds written as seconds, degrees Celsius, a bore in millimetres) before it
costs a fit. A finding is an *error* when the value is clearly impossible (its message
says which unit was probably meant) and a *warning* when it is only unusual; warnings
never stop a command (``pneubayes check`` prints them, every run records them). An
unusual but real rig (a 100-Hz ventilator, a muscle at 600 kPa, a slow logger) accepts
rules by id in the recording's JSON (``"accept_unusual": ["sample-interval"]``) or for
one command (``--accept RULE[,RULE]``); an accepted finding is recorded as accepted.

The rules (:data:`RULES`), with their limits (module constants, SI):

========================  =============================================================
rule                      finding
========================  =============================================================
``atmosphere``            atmospheric pressure outside 50-110 kPa (error)
``temperature``           temperature outside 200-400 K (error)
``supply-pressure``       supply below 50 kPa or above 10 MPa absolute (error);
                          above 1.6 MPa (warning)
``working-range``         supply minus atmosphere below 10 kPa (warning)
``pressure-low``          a pressure column's 1st percentile below half the atmosphere
                          (error: another unit, or gauge)
``pressure-high``         a pressure column's 99th percentile above 10 MPa (error)
``pressure-above-supply`` chamber pressure above the supply by > 10 % of the working
                          range + 5 kPa (warning: a gauge supply?)
``pressure-span``         chamber pressure spans less than 10 kPa (warning)
``sample-interval``       median sample interval above 5 ms, below 200 Hz (warning)
``pressure-spikes``       isolated one-sample spikes of the chamber pressure (warning)
``time-unit``             samples >= 0.1 s apart and the pressure needs >= 2 s to cross
                          its span at its steepest (1 % of steps): milliseconds written
                          as seconds (error)
``time-gap``              one interval over 1000 x the median and over 1 s (error)
``bore``                  bore above 0.5 m (error), above 0.35 m or below 0.5 mm
                          (warning)
``stroke``                stroke above 5 m (error), above 2 m (warning)
``position``              the position column beyond 1.5 x stroke + 5 mm (error; not for
                          a rig card chamber that maps a coordinate: its own range)
========================  =============================================================
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import asdict, dataclass

import numpy as np

from pneubayes.io.spikes import SPIKE_NOISE_MULTIPLE, find_spikes
from pneubayes.io.units import LENGTH_UNITS, TEMPERATURE_UNITS, pressure_readings

#: Rule id -> what it checks (the module docstring has the limits).
RULES: dict[str, str] = {
    "atmosphere": "atmospheric pressure outside 50-110 kPa",
    "temperature": "temperature outside 200-400 K",
    "supply-pressure": "supply pressure below 50 kPa or above 1.6 MPa absolute",
    "working-range": "supply minus atmosphere below 10 kPa",
    "pressure-low": "pressure far below any atmosphere",
    "pressure-high": "pressure above 10 MPa",
    "pressure-above-supply": "chamber pressure well above the supply",
    "pressure-span": "chamber pressure spans less than 10 kPa",
    "sample-interval": "sample interval above 5 ms",
    "pressure-spikes": "isolated one-sample spikes in the chamber pressure",
    "time-unit": "time stamps that look like milliseconds",
    "time-gap": "one sample interval far longer than the others",
    "bore": "bore outside 0.5 mm - 0.35 m",
    "stroke": "stroke above 2 m",
    "position": "position column far beyond the stroke",
}

ATMOSPHERE_RANGE_Pa = (50e3, 110e3)
TEMPERATURE_RANGE_K = (200.0, 400.0)
SUPPLY_MIN_Pa = 50e3
SUPPLY_UNUSUAL_Pa = 1.6e6
SUPPLY_MAX_Pa = 10e6
WORKING_RANGE_MIN_Pa = 10e3
PRESSURE_MAX_Pa = 10e6
PRESSURE_SPAN_MIN_Pa = 10e3
SAMPLE_INTERVAL_MAX_s = 5e-3
TIME_UNIT_INTERVAL_s = 0.1
TIME_UNIT_RESPONSE_s = 2.0
TIME_GAP_RATIO = 1000.0
TIME_GAP_MIN_s = 1.0
BORE_RANGE_m = (0.5e-3, 0.35)
BORE_MAX_m = 0.5
STROKE_UNUSUAL_m = 2.0
STROKE_MAX_m = 5.0
#: Typical absolute pressures of a pneumatic chamber (for unit hints), Pa.
_CHAMBER_RANGE_Pa = (0.5 * 101325.0, 1.2e6)


@dataclass(frozen=True)
class Finding:
    """One plausibility finding.

    Parameters
    ----------
    rule : str
        The rule's id (a key of :data:`RULES`).
    severity : str
        ``"error"`` (clearly impossible) or ``"warning"`` (unusual).
    location : str
        The file and key or column.
    message : str
        What is wrong and, for a unit slip, which unit was probably meant.
    accepted : bool
        The user accepted this rule for this input (``accept_unusual`` or ``--accept``).
    """

    rule: str
    severity: str
    location: str
    message: str
    accepted: bool = False

    def text(self) -> str:
        """``message [rule]``, and ``(accepted)`` when the user accepted the rule."""
        tail = " (accepted)" if self.accepted else ""
        return f"{self.message} [{self.rule}]{tail}"

    def as_dict(self) -> dict:
        return asdict(self)


def check_accept(values, where: str) -> tuple[str, ...]:
    """Validate a list of rule ids to accept; ``where`` names the key or option.

    Raises ValueError naming ``where`` for a value that is not a list of known ids.
    """
    if isinstance(values, str) or not isinstance(values, Iterable):
        raise ValueError(f"{where}: must be a list of rule names, got {values!r}")
    out = []
    for v in values:
        if not isinstance(v, str) or v not in RULES:
            raise ValueError(f"{where}: unknown rule {v!r}; the rules are {sorted(RULES)}")
        out.append(v)
    return tuple(out)


def _finding(rule, severity, location, message, accept) -> Finding:
    return Finding(rule, severity, location, message, accepted=rule in accept)


def _probably(readings: list[str]) -> str:
    return f"; probably {' or '.join(readings)}" if readings else ""


def _length_readings(value_m: float, low_m: float, high_m: float) -> list[str]:
    return [f"{u} ({value_m:g} {u} = {value_m * f:g} m)" for u, f in LENGTH_UNITS.items()
            if u != "m" and low_m <= value_m * f <= high_m]


def _temperature_readings(value: float) -> list[str]:
    lo, hi = TEMPERATURE_RANGE_K
    out = []
    for unit, (scale, offset) in TEMPERATURE_UNITS.items():
        k = scale * value + offset
        if unit != "K" and lo <= k <= hi:
            out.append(f"degrees {unit} ({value:g} {unit} = {k:.2f} K)")
    return out


def rig_findings(values: Mapping[str, float], source: str,
                 accept: Iterable[str] = ()) -> list[Finding]:
    """Findings on a rig's scalar values, given by their SI names.

    ``values`` may hold ``atmospheric_pressure_Pa``, ``supply_pressure_Pa``,
    ``temperature_K``, ``bore_m`` and ``stroke_m`` (absent ones are not checked);
    ``source`` names the file, each location adds the key.
    """
    accept = set(accept)
    out: list[Finding] = []

    def at(key):
        return f"{source} key {key!r}"

    atm = values.get("atmospheric_pressure_Pa")
    if atm is not None and not ATMOSPHERE_RANGE_Pa[0] <= atm <= ATMOSPHERE_RANGE_Pa[1]:
        hint = [r for r in pressure_readings([atm], *ATMOSPHERE_RANGE_Pa) if "gauge" not in r]
        out.append(_finding("atmosphere", "error", at("atmospheric_pressure_Pa"),
                            f"{atm:g} Pa is not an atmosphere (50-110 kPa absolute)"
                            + _probably(hint), accept))
    sup = values.get("supply_pressure_Pa")
    if sup is not None:
        if sup < SUPPLY_MIN_Pa or sup > SUPPLY_MAX_Pa:
            hint = pressure_readings([sup], 1.5 * SUPPLY_MIN_Pa, SUPPLY_UNUSUAL_Pa)
            out.append(_finding("supply-pressure", "error", at("supply_pressure_Pa"),
                                f"{sup:g} Pa is no absolute supply pressure (50 kPa - "
                                f"10 MPa)" + _probably(hint), accept))
        elif sup > SUPPLY_UNUSUAL_Pa:
            out.append(_finding("supply-pressure", "warning", at("supply_pressure_Pa"),
                                f"{sup / 1e3:.0f} kPa absolute is above usual pneumatic "
                                "supplies (<= 1.6 MPa)", accept))
        if (atm is not None and ATMOSPHERE_RANGE_Pa[0] <= atm <= ATMOSPHERE_RANGE_Pa[1]
                and 0 < sup - atm < WORKING_RANGE_MIN_Pa):
            out.append(_finding("working-range", "warning", at("supply_pressure_Pa"),
                                f"the supply is only {sup - atm:.0f} Pa above the atmosphere "
                                "(a blower or a low-pressure rig?)", accept))
    temp = values.get("temperature_K")
    if temp is not None and not TEMPERATURE_RANGE_K[0] <= temp <= TEMPERATURE_RANGE_K[1]:
        out.append(_finding("temperature", "error", at("temperature_K"),
                            f"{temp:g} K is outside 200-400 K"
                            + _probably(_temperature_readings(temp)), accept))
    bore = values.get("bore_m")
    if bore is not None:
        if bore > BORE_MAX_m:
            out.append(_finding("bore", "error", at("bore_m"),
                                f"a bore of {bore:g} m is larger than any cylinder"
                                + _probably(_length_readings(bore, *BORE_RANGE_m)), accept))
        elif not BORE_RANGE_m[0] <= bore <= BORE_RANGE_m[1]:
            out.append(_finding("bore", "warning", at("bore_m"),
                                f"a bore of {bore * 1e3:g} mm is unusual (0.5-350 mm)", accept))
    stroke = values.get("stroke_m")
    if stroke is not None:
        if stroke > STROKE_MAX_m:
            out.append(_finding("stroke", "error", at("stroke_m"),
                                f"a stroke of {stroke:g} m is longer than any cylinder"
                                + _probably(_length_readings(stroke, 1e-3, STROKE_UNUSUAL_m)),
                                accept))
        elif stroke > STROKE_UNUSUAL_m:
            out.append(_finding("stroke", "warning", at("stroke_m"),
                                f"a stroke of {stroke:g} m is unusual (<= 2 m)", accept))
    return out


def _pressure_column_findings(p: np.ndarray, location: str, atm: float,
                              accept) -> list[Finding]:
    lo, hi = np.percentile(p, [1, 99])
    out = []
    if lo < 0.5 * atm:
        hint = pressure_readings([lo, hi], *_CHAMBER_RANGE_Pa, atmospheric_pressure_Pa=atm,
                                 min_span_Pa=0.0 if hi - lo < 1e-9 else 1e3, rest_Pa=atm)
        out.append(_finding("pressure-low", "error", location,
                            f"reads {lo:.4g}..{hi:.4g} (1st-99th "
                            f"percentile), far below the atmosphere ({atm:g} Pa): absolute "
                            f"pressures in Pa are expected" + _probably(hint), accept))
    if hi > PRESSURE_MAX_Pa:
        out.append(_finding("pressure-high", "error", location,
                            f"reaches {hi:.4g} Pa (99th percentile), above "
                            "any pneumatic supply (10 MPa): absolute pressures in Pa are "
                            "expected", accept))
    return out


def _spike_findings(p: np.ndarray, csv_name: str, accept) -> list[Finding]:
    """The rule ``pressure-spikes`` (:func:`pneubayes.io.spikes.find_spikes`)."""
    spikes = find_spikes(p)
    count = int(spikes.indices.size)
    if count == 0:
        return []
    rows = ", ".join(str(k + 2) for k in spikes.indices[:5]) + (", ..." if count > 5 else "")
    return [_finding("pressure-spikes", "warning", f"{csv_name} column 'pressure_Pa'",
                     f"{count} isolated sample(s) depart from both neighbours by "
                     f"{spikes.sizes_Pa.min():.3g}-{spikes.sizes_Pa.max():.3g} Pa, over "
                     f"{spikes.limit_Pa:.3g} Pa ({SPIKE_NOISE_MULTIPLE:g} x the "
                     f"sample-to-sample scatter, {spikes.scatter_Pa:.3g} Pa), and return "
                     f"(rows {rows}): sensor glitches? Every fit weighs them in its error "
                     "(0.2 % of the samples at 20 kPa add about 900 Pa to an RMSE); if they "
                     "are, replace each by its neighbours' mean (a fit's setting "
                     "despike_pressure = true; discover: --set fit.despike_pressure=true)",
                     accept)]


def _response_time_s(t: np.ndarray, p: np.ndarray) -> float:
    """Seconds the pressure needs to cross its 1-99 % span at its steepest 1 % of steps."""
    dt = np.diff(t)
    slope = np.abs(np.diff(p)) / dt
    steep = float(np.percentile(slope, 99))
    lo, hi = np.percentile(p, [1, 99])
    return math.inf if steep <= 0 else float(hi - lo) / steep


def _time_findings(t: np.ndarray, p: np.ndarray, csv_name: str, accept) -> list[Finding]:
    """The rules on ``time_s``: time-unit, time-gap and sample-interval (under
    :func:`recording_findings`' ``np.errstate``: huge times may overflow to inf)."""
    gaps = np.diff(t)
    dt = float(np.median(gaps))
    response = _response_time_s(t, p)
    out = []
    where = f"{csv_name} column 'time_s'"
    looks_ms = dt >= TIME_UNIT_INTERVAL_s and response >= TIME_UNIT_RESPONSE_s
    if looks_ms:
        out.append(_finding("time-unit", "error", where,
                            f"samples are {dt:g} s apart over {t[-1] - t[0]:g} s and the "
                            f"pressure needs about {response:.3g} s to cross its span at its "
                            "steepest; a pneumatic chamber responds in milliseconds: time_s "
                            "looks like milliseconds (divide by 1000, or name the column "
                            "time_ms in format 2)", accept))
    elif dt > SAMPLE_INTERVAL_MAX_s:
        out.append(_finding("sample-interval", "warning", where,
                            f"samples are {dt * 1e3:.3g} ms apart ({1 / dt:.3g} Hz); valve "
                            "transients last a few ms, so fast effects are unresolved",
                            accept))
    k = int(np.argmax(gaps))
    if not gaps[k] <= max(TIME_GAP_RATIO * dt, TIME_GAP_MIN_s):
        out.append(_finding("time-gap", "error", where,
                            f"time jumps from {t[k]:g} s to {t[k + 1]:g} s (row {k + 3}), "
                            f"{gaps[k] / dt:.3g} x the median interval: a typo, or recordings "
                            "joined? (split them into recordings)", accept))
    return out


def recording_findings(rec, csv_name: str, json_name: str,
                       accept: Iterable[str] = (), position_is_coordinate: bool = False
                       ) -> list[Finding]:
    """Every plausibility finding of a structurally valid
    :class:`~pneubayes.io.recording.Recording` (SI, absolute), errors and warnings.
    ``position_is_coordinate``: the ``position_m`` column is a rig card chamber's
    coordinate (a muscle's contraction), not a piston position, so the ``position`` rule
    (against the stroke) is not applied; the card checks the coordinate's range."""
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        return _recording_findings(rec, csv_name, json_name, set(accept),
                                   position_is_coordinate)


def _recording_findings(rec, csv_name: str, json_name: str, accept: set,
                        position_is_coordinate: bool = False) -> list[Finding]:
    md = rec.metadata
    out = rig_findings({k: getattr(md, k) for k in ("atmospheric_pressure_Pa",
                        "supply_pressure_Pa", "temperature_K", "bore_m", "stroke_m")},
                       json_name, accept)
    atm = md.atmospheric_pressure_Pa
    if not ATMOSPHERE_RANGE_Pa[0] <= atm <= ATMOSPHERE_RANGE_Pa[1]:
        atm = 101325.0  # the atmosphere itself is reported; judge the columns by a real one
    columns = [("pressure_Pa", rec.pressure_Pa)]
    if rec.supply_pressure_Pa is not None:
        columns.append(("supply_pressure_Pa", rec.supply_pressure_Pa))
    for name, p in columns:
        out += _pressure_column_findings(p, f"{csv_name} column {name!r}", atm, accept)
    impossible = any(f.severity == "error" and f.rule.startswith("pressure") for f in out)
    p = rec.pressure_Pa
    if not impossible and rec.n_samples >= 2:
        lo, hi = np.percentile(p, [1, 99])
        supply = (np.percentile(rec.supply_pressure_Pa, 99) if rec.supply_pressure_Pa
                  is not None else md.supply_pressure_Pa)
        margin = 0.1 * max(supply - atm, 0.0) + 5e3
        if hi > supply + margin:
            out.append(_finding("pressure-above-supply", "warning",
                                f"{csv_name} column 'pressure_Pa'",
                                f"the chamber reaches {hi:.6g} Pa, {hi - supply:.4g} Pa above "
                                f"the supply ({supply:.6g} Pa): is the supply gauge?", accept))
        if hi - lo < PRESSURE_SPAN_MIN_Pa:
            out.append(_finding("pressure-span", "warning", f"{csv_name} column 'pressure_Pa'",
                                f"the pressure spans only {hi - lo:.4g} Pa (1st-99th "
                                "percentile)", accept))
    if rec.n_samples >= 3:
        out += _time_findings(rec.time_s, p, csv_name, accept)
        if not impossible:
            out += _spike_findings(p, csv_name, accept)
    if rec.position_m is not None and not position_is_coordinate:
        limit = 1.5 * md.stroke_m + 5e-3
        far = float(np.max(np.abs(rec.position_m)))
        if far > limit:
            hint = _length_readings(far, 0.3 * md.stroke_m, limit)
            out.append(_finding("position", "error", f"{csv_name} column 'position_m'",
                                f"the position reaches {far:g} m on a stroke of "
                                f"{md.stroke_m:g} m" + _probably(hint), accept))
    return out


def recorded_findings(recordings) -> list[dict]:
    """The findings the recordings carry, as a run records them (one dict per finding,
    with the recording's source)."""
    return [{"recording": str(r.source), **f.as_dict()} for r in recordings
            for f in r.findings]
