"""A closure's terms: their shape (``"a*b"``, :class:`Term`), their formula in SI
units, and how the evaluated terms of a closure combine into the chamber's mass flow.

A term is ``c F_a F_b`` of the features of :mod:`pneubayes.effects.closure_features`.
A term that reads a port's flow modulates that port (a change of its effective area,
which cannot reverse the port: :data:`PORT_FACTOR_LIMITS`); any other adds its flow.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pneubayes.effects.closure_features import (
    FEATURE_BY_NAME,
    PORT_FEATURES,
    evaluate_feature,
    feature,
)
from pneubayes.effects.path import CLOSURE_MAX_TERMS


def reads_ports(terms) -> bool:
    """Whether any of ``terms`` (:class:`Term`) reads a feature of the valve's ports
    (:data:`PORT_FEATURES`)."""
    return any(name in PORT_FEATURES for t in terms for name in (t.a, t.b))


#: The port flows a closure term can modulate, and the bounds of the port's factor ``s``:
#: a term that reads a port's flow (its first such feature) adds ``c q F_other`` to that
#: port's ``q s``, and ``s`` is clipped so the port's flow does not reverse (the inlet's
#: and the net flow ``q (1 + s)``: ``s >= -1``; the exhaust's outflow ``-q (1 - s)``:
#: ``s <= 1``). A term is then a change of the port's effective area, which cannot turn
#: negative: a cut-off found below the supply stays shut above it instead of blowing the
#: chamber up through a reversed inlet.
PORT_FACTOR_LIMITS: dict[str, tuple[float, float]] = {
    "inlet_flow": (-1.0, np.inf), "exhaust_flow": (-np.inf, 1.0),
    "net_flow": (-1.0, np.inf)}


def combine_terms(terms) -> np.ndarray:
    """A closure's mass flow into the chamber (kg/s) from its evaluated terms.

    ``terms``: ``(c, name_a, F_a, name_b, F_b)`` per term, with ``c`` its coefficient and
    the names either feature names or arrays of feature codes (one per row, broadcasting
    against the values). A term that reads no port flow adds ``c F_a F_b``; the terms of
    a port flow add ``q clip(s)`` (:data:`PORT_FACTOR_LIMITS`)."""
    codes = {name: FEATURE_BY_NAME[name].code for name in PORT_FACTOR_LIMITS}
    free = 0.0
    factor = dict.fromkeys(codes, 0.0)
    flow = dict.fromkeys(codes, 0.0)
    for c, name_a, fa, name_b, fb in terms:
        code_a, code_b = _codes(name_a), _codes(name_b)
        a_port = np.isin(code_a, list(codes.values()))
        b_port = ~a_port & np.isin(code_b, list(codes.values()))
        for name, code in codes.items():  # a term belongs to its first port flow
            on_a, on_b = code_a == code, b_port & (code_b == code)
            factor[name] = factor[name] + np.where(on_a, c * fb, np.where(on_b, c * fa, 0.0))
            flow[name] = np.where(on_a, fa, np.where(on_b, fb, flow[name]))
        free = free + np.where(a_port | b_port, 0.0, c * (fa * fb))
    total = free
    for name, (lo, hi) in PORT_FACTOR_LIMITS.items():
        total = total + flow[name] * np.clip(factor[name], lo, hi)
    return np.asarray(total, dtype=np.float64)


def modulated_port(term: "Term") -> str | None:
    """The port flow feature ``term`` modulates (its first of
    :data:`PORT_FACTOR_LIMITS`), or None for a term that reads no port's flow."""
    for name in (term.a, term.b):
        if name in PORT_FACTOR_LIMITS:
            return name
    return None


def _codes(name) -> np.ndarray:
    """Feature codes of a feature name or of an array of codes."""
    if isinstance(name, str):
        return np.asarray(FEATURE_BY_NAME[name].code)
    return np.asarray(name)


@dataclass(frozen=True)
class Term:
    """One closure term's shape: a base feature, or the product of two.

    Written ``"a"`` or ``"a*b"`` (feature names), e.g. ``"inlet_flow*pressure_hinge"``;
    a closure's terms are joined by ``"; "``. Its value is ``c * F_a * F_b``."""

    a: str
    b: str = "one"

    def __post_init__(self):
        feature(self.a)
        feature(self.b)

    @classmethod
    def parse(cls, text: str) -> "Term":
        parts = [p.strip() for p in str(text).split("*")]
        if len(parts) > 2 or not all(parts):
            raise ValueError(f"closure term {text!r}: write one feature or two joined by "
                             "'*' (e.g. 'inlet_flow*pressure_hinge')")
        return cls(*parts)

    def __str__(self) -> str:
        return self.a if self.b == "one" else f"{self.a}*{self.b}"

    @property
    def unit(self) -> str:
        """The unit of the term's coefficient, kg/s over the features' units."""
        units = [feature(n).unit for n in (self.a, self.b) if feature(n).unit != "1"]
        units = [u for u in units if u != "-"]
        return "kg/s" if not units else "kg/s / (" + " ".join(units) + ")"

    def hinges(self) -> tuple[str, ...]:
        """Which of ``"a"``, ``"b"`` are hinge features (each has a threshold)."""
        return tuple(k for k, n in (("a", self.a), ("b", self.b)) if feature(n).hinge)

    def evaluate(self, signals: dict, threshold_a: float = 0.0,
                 threshold_b: float = 0.0) -> np.ndarray:
        """``F_a * F_b`` on ``signals`` (the coefficient not applied)."""
        return (evaluate_feature(self.a, signals, threshold_a)
                * evaluate_feature(self.b, signals, threshold_b))


def parse_terms(text: str) -> tuple[Term, ...]:
    """A closure's terms from ``"a*b; c"``; ValueError for none or more than
    :data:`CLOSURE_MAX_TERMS`."""
    terms = tuple(Term.parse(t) for t in str(text).split(";") if t.strip())
    if not 1 <= len(terms) <= CLOSURE_MAX_TERMS:
        raise ValueError(f"a closure holds 1 to {CLOSURE_MAX_TERMS} terms, got "
                         f"{len(terms)} in {text!r}")
    return terms


#: Each feature as written in a term's formula (``{theta}``: the hinge's threshold).
SYMBOLS: dict[str, str] = {
    "one": "1", "pressure_ratio": "(p / P_atm)", "supply_ratio": "(p_s / P_atm)",
    "spool": "s", "inlet_area": "(a_in / 1 mm^2)", "exhaust_area": "(a_ex / 1 mm^2)",
    "inlet_flow": "m_in", "exhaust_flow": "m_ex", "volume": "(V / 1 cm^3)",
    "volume_rate": "(dV/dt / V)", "volume_speed": "(|dV/dt| / 1 cm^3/s)",
    "pressure_hinge": "max(0, p / P_atm - {theta})",
    "spool_hinge_up": "max(0, s - {theta})", "spool_hinge_down": "max(0, {theta} - s)",
    "net_flow": "(m_in - m_ex)", "pressure_hinge_down": "max(0, {theta} - p / P_atm)",
    "command_direction": "sgn(du)",
    "pressure_relaxation": "((p - p_bar[{theta}]) / P_atm)",
    "net_flow_lag": "(q_bar[{theta}] - (m_in - m_ex))",
    "volume_hinge_up": "max(0, V / 1 cm^3 - {theta})",
    "volume_hinge_down": "max(0, {theta} - V / 1 cm^3)",
    "inlet_drop": "(|p_s - p| / P_atm)", "inlet_drop_hinge": "max(0, {theta} - |p_s - p| / P_atm)",
    "inlet_flux": "(f(p_s, p) x 1 mm^2)", "exhaust_flux": "(f(p, P_atm) x 1 mm^2)",
    "spool_null_hinge": "max(0, {theta} - |s|)",
    "inlet_area_hinge": "max(0, a_in / 1 mm^2 - {theta})",
    "exhaust_area_hinge": "max(0, a_ex / 1 mm^2 - {theta})",
    "net_flux": "((f(p_s, p) - f(p, P_atm)) x 1 mm^2)",
    "command_lag": "(s_bar[{theta}] - s)",
    "command_lag_fall": "max(0, s_bar[{theta}] - s)",
    "command_lag_rise": "max(0, s - s_bar[{theta}])",
    "inlet_area_late_fall": "((a_in(u_hi[{theta}]) - a_in(u)) / 1 mm^2)",
    "exhaust_area_late_fall": "((a_ex(u_hi[{theta}]) - a_ex(u)) / 1 mm^2)",
    "inlet_area_late_rise": "((a_in(u_lo[{theta}]) - a_in(u)) / 1 mm^2)",
    "exhaust_area_late_rise": "((a_ex(u_lo[{theta}]) - a_ex(u)) / 1 mm^2)",
}


def term_formula(term: Term, k: int) -> str:
    """Term ``k`` of a closure as a formula of its parameters' names, e.g.
    ``"c_0 m_in max(0, p / P_atm - theta_0_b)"`` (kg/s into the chamber)."""
    parts = [f"c_{k}"]
    for side, name in (("a", term.a), ("b", term.b)):
        if name != "one":
            parts.append(SYMBOLS[name].format(theta=f"theta_{k}_{side}"))
    return " ".join(parts)
