"""Out-of-catalogue forms between the valve and its surroundings: what sits on a port
or a line (a silencer, a check valve, a meter-out throttle, a supply hose, a
quick-exhaust valve)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from pneubayes.bench.forms.base import (
    PlantForm,
    _non_negative,
    _positive,
    _smoothstep,
)


@dataclass(frozen=True)
class ExhaustSilencer(PlantForm):
    """A porous (sintered) silencer on the valve's exhaust port, with its own volume.

    The valve's exhaust port discharges into the silencer body (pressure ``p_m``, volume
    ``V_m = volume_m3``) instead of the atmosphere; the body vents through the porous
    element with a Forchheimer law (Darcy's viscous drop plus an inertial drop)::

        p_m - P_atm = R_l m_out + R_t m_out |m_out|
        dp_m/dt = kappa Rs T_s / V_m (m_ex - m_out),   m_ex = a_ex f(p, p_m)

    with ``R_l = laminar_fraction dp_ref / m_ref`` and ``R_t = (1 - laminar_fraction)
    dp_ref / m_ref^2`` for the back-pressure ``dp_ref = back_pressure_Pa`` the element
    makes at a steady ``m_ref = 1 g/s``. The chamber's exhaust then sees a back-pressure
    that grows with its own flow (a clogged silencer slows the exhaust most when it is
    fastest) and the gas in the body blows back for a moment when the valve switches.
    The leaks still vent to the atmosphere. ``back_pressure_Pa = 0`` is no silencer (the
    state is omitted). ``p_m`` starts at the atmosphere.
    """

    catalogue_name: ClassVar[str | None] = None
    back_pressure_Pa: float
    laminar_fraction: float = 0.5
    volume_m3: float = 2e-6

    #: The reference flow at which ``back_pressure_Pa`` is stated, kg/s (1 g/s).
    REFERENCE_FLOW_KG_PER_S: ClassVar[float] = 1e-3

    def __post_init__(self):
        _non_negative(self, "back_pressure_Pa")
        _positive(self, "volume_m3")
        f = self.laminar_fraction
        if isinstance(f, bool) or not isinstance(f, (int, float)) or not 0.0 <= f <= 1.0:
            raise ValueError(f"ExhaustSilencer.laminar_fraction must be a number in [0, 1], "
                             f"got {f!r}")

    @property
    def resistances(self) -> tuple[float, float]:
        """``(R_l Pa/(kg/s), R_t Pa/(kg/s)^2)`` of the Forchheimer law."""
        m = self.REFERENCE_FLOW_KG_PER_S
        return (self.laminar_fraction * self.back_pressure_Pa / m,
                (1.0 - self.laminar_fraction) * self.back_pressure_Pa / (m * m))


@dataclass(frozen=True)
class MeterOutThrottle(PlantForm):
    """A one-way flow control (a meter-out speed controller) at the cylinder's port.

    Between the valve and the chamber sits a fitting of volume ``volume_m3`` (pressure
    p_f, which the valve's ports see). From the fitting into the chamber the gas passes
    a needle of area ``needle_area_m2`` and, in parallel, a check valve of area
    ``check_area_m2`` that opens with the forward drop ``p_f - p``::

        mdot_fc = (A_n + A_c S((p_f - p - dp_c) / dp_c + 1/2)) f(p_f, p),

    S the C1 smoothstep, ``dp_c = crack_pressure_Pa``, f the thin-port flow of eqs. 1-3
    (signed; below a 1-kPa drop linear in the drop, as laminar flow is, which keeps the
    two restrictions in series well posed). A fill passes the open check; a vent leaves
    through the needle alone, so the exhaust is throttled and the fitting's pressure lags
    the chamber's. Eq. 5 holds in the fitting at the supply temperature.
    ``needle_area_m2 = 0`` is no throttle (the state is omitted); it cannot be planted
    beside an AcousticTube.
    """

    catalogue_name: ClassVar[str | None] = None
    needle_area_m2: float
    check_area_m2: float = 1e-6
    crack_pressure_Pa: float = 10e3
    volume_m3: float = 5e-7

    def __post_init__(self):
        _non_negative(self, "needle_area_m2")
        _positive(self, "check_area_m2", "crack_pressure_Pa", "volume_m3")

    def check_opening(self, forward_drop_Pa: float) -> float:
        """The check valve's fraction open at a drop ``p_f - p`` (Pa)."""
        c = self.crack_pressure_Pa
        return _smoothstep((forward_drop_Pa - c) / c + 0.5)


@dataclass(frozen=True)
class SupplyHose(PlantForm):
    """A supply line that starves the valve: a hose of volume ``volume_m3`` fed from the
    regulator through a restriction (a fitting, a quick coupling, the regulator's own
    port) of sonic area ``restriction_area_m2``.

    The valve's inlet sees the hose's pressure p_h, not the regulator's p_r::

        dp_h/dt = kappa Rs T / V_h (A_r f(p_r, p_h) - mdot_in),

    f the thin-port flow of eqs. 1-3. A fill draws the hose down and it recovers
    through the restriction; the supply sensor sits at the regulator (the recording's
    supply column is p_r), so the drop is not measured. ``restriction_area_m2 = 0`` is no
    hose (the state is omitted).
    """

    catalogue_name: ClassVar[str | None] = None
    restriction_area_m2: float
    volume_m3: float = 5e-5

    def __post_init__(self):
        _non_negative(self, "restriction_area_m2")
        _positive(self, "volume_m3")


@dataclass(frozen=True)
class ExhaustCheckValve(PlantForm):
    """A check valve in the exhaust line (a non-return on a shared exhaust manifold, a
    quick-exhaust valve's lip): the exhaust port discharges against its cracking
    pressure, so the chamber vents only down to it::

        mdot_ex = a_ex f(p, P_atm + p_c)  for p > P_atm + p_c, else 0,

    f the orifice law of eqs. 1-3 and ``p_c = crack_pressure_Pa`` (gauge). Nothing
    enters through the exhaust. ``crack_pressure_Pa = 0`` is the plain exhaust.
    """

    catalogue_name: ClassVar[str | None] = None
    crack_pressure_Pa: float

    def __post_init__(self):
        _non_negative(self, "crack_pressure_Pa")


@dataclass(frozen=True)
class QuickExhaustValve(PlantForm):
    """A quick-exhaust valve (QEV) at the chamber's port, fed by the valve through a
    line of volume ``line_volume_m3``. Its diaphragm passes air from the line into the
    chamber; when the chamber is above the line it seals the line and opens its own
    exhaust straight to the atmosphere::

        w = smoothstep((p - p_l) / switch_band_Pa),
        m_chamber = a_p (1 - w) f(p_l, p) - a_q w f(p, P_atm),
        dp_l/dt = kappa Rs T_s / V_l (m_in(p_l) - m_ex(p_l) - a_p (1 - w) f(p_l, p)),

    p_l the line's pressure (the valve's ports see it), ``a_q = exhaust_area_m2``,
    ``a_p = passage_area_m2``, f eqs. 1-3 (signed; through the passage linear in the
    drop below 1 kPa, laminar). ``exhaust_area_m2 = 0`` is no QEV (the port as without
    it).
    """

    catalogue_name: ClassVar[str | None] = None
    exhaust_area_m2: float
    passage_area_m2: float = 1.5e-6
    switch_band_Pa: float = 1e4
    line_volume_m3: float = 5e-7

    def __post_init__(self):
        _non_negative(self, "exhaust_area_m2")
        _positive(self, "passage_area_m2", "switch_band_Pa", "line_volume_m3")
