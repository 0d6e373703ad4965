"""A two-compartment chamber (rig card chamber kind ``two_compartment``): the measured
compartment feeds a compliant one through a laminar resistance. Limits, the reference
solver, step halving, window carrying and the pressure drop across the resistance."""

from __future__ import annotations

import copy

import numpy as np
import pytest
from rig_helpers import assert_converges_to

from pneubayes.model import Model
from pneubayes.physics.gas import GasConstants
from pneubayes.rig import Rig
from pneubayes.rigcard import RigCard
from pneubayes.simulation import Inputs, SolverConfig, simulate, simulate_windows
from pneubayes.simulation.reference import reference_simulate

P_ATM, P_SUP = 101325.0, 111325.0  # a ventilator's low-pressure supply
TIGHT = SolverConfig(rtol=1e-9, atol_Pa=1e-4, atol_K=1e-4, max_step_s=1e-3,
                     min_step_s=1e-14, max_steps_per_s=5e7)
GAS = GasConstants(temperature_K=296.0)
RIG = Rig(0.05, P_ATM, P_SUP, gas=GAS)
VC, VL, CL, R = 5e-4, 1e-3, 2e-7, 2e6  # m^3, m^3, m^3/Pa, Pa s/m^3 (QuickLung-like)

BASE = {
    "format": "pneubayes-rig/1", "name": "circuit and test lung",
    "atmospheric_pressure_Pa": P_ATM, "temperature_K": 296.0,
    "command": {"unit": "duty", "range": [0.0, 1.0]},
    "chamber": {"kind": "two_compartment", "volume_m3": VC, "lung_volume_m3": VL,
                "lung_compliance_m3_per_Pa": CL, "resistance_Pa_s_per_m3": R},
    "valve": {"kind": "switching", "open_area_m2": 2e-5, "exhaust_area_m2": 3e-5,
              "opening_delay_s": 0.0, "opening_time_constant_s": 0.0},
    "supply": {"kind": "constant", "pressure_Pa": P_SUP},
}


def card(**chamber) -> RigCard:
    d = copy.deepcopy(BASE)
    d["chamber"].update(chamber)
    return RigCard.from_dict(d, "card.json")


def inputs(t, u):
    return Inputs(t, u, np.zeros_like(t), np.full(t.shape, P_SUP))


def breath(dt=1e-3, n=2001):
    t = np.arange(n) * dt
    return t, ((t % 1.0) < 0.4).astype(float)


def run(c, inp, p0=P_ATM + 500.0, solver=TIGHT):
    return simulate(Model(rig_card=c), np.zeros((1, 0)), inp, RIG, p0, solver).pressure_Pa[0]


def test_the_card_reads_and_fits_its_unknowns():
    c = card(resistance_Pa_s_per_m3={"prior": "log-uniform", "bounds": [1e5, 1e8]},
             lung_compliance_m3_per_Pa={"prior": "log-uniform", "bounds": [1e-8, 1e-5]})
    assert set(Model(rig_card=c).parameter_names) == {"resistance_Pa_s_per_m3",
                                                      "lung_compliance_m3_per_Pa"}


def test_a_vanishing_resistance_is_one_compliant_chamber():
    """R -> 0: p_L = p, and V_c dp + (V_L + n p C_L) dp = n Rs T m dt is the compliant
    chamber of volume V_c + V_L0 and compliance C_L."""
    one = copy.deepcopy(BASE)
    one["chamber"] = {"kind": "compliant", "volume_m3": VC + VL, "compliance_m3_per_Pa": CL}
    t, u = breath()
    a = run(card(resistance_Pa_s_per_m3=1.0), inputs(t, u))
    b = run(RigCard.from_dict(one), inputs(t, u))
    assert np.ptp(b) > 3e3
    np.testing.assert_allclose(a, b, atol=2.0)  # Pa, of a 4-kPa swing


def test_a_closed_valve_keeps_the_pressure_and_the_limits_hold():
    c = card()
    t = np.arange(3001) * 1e-3
    d = copy.deepcopy(BASE)
    d["valve"]["exhaust_area_m2"] = 0.0
    closed = RigCard.from_dict(d, "card.json")
    kept = simulate(Model(rig_card=closed), np.zeros((1, 0)), inputs(t, 0 * t), RIG, 1.05e5,
                    TIGHT).pressure_Pa[0]
    assert np.max(np.abs(kept - 1.05e5)) < 1e-6
    t = np.arange(15001) * 2e-3  # 30 s: the lung's time constant is seconds
    filled = run(c, inputs(t, np.ones_like(t)), P_ATM)
    vented = run(c, inputs(t, np.zeros_like(t)), P_SUP)
    assert abs(filled[-1] - P_SUP) < 1.0 and abs(vented[-1] - P_ATM) < 1.0


def test_the_measured_pressure_jumps_by_the_resistance_drop_when_the_inlet_shuts():
    """At a steady inflow q the measured pressure leads the lung's by R q; with a small
    measured compartment it falls by about that within milliseconds of the inlet shutting
    (the step a single compliant chamber cannot make)."""
    d = copy.deepcopy(BASE)
    d["valve"]["exhaust_area_m2"] = 0.0
    c = RigCard.from_dict(d, "card.json")
    c = RigCard.from_dict({**c.to_dict(), "chamber": {**c.to_dict()["chamber"],
                                                       "volume_m3": 2e-5}}, "card.json")
    t = np.arange(701) * 1e-3
    u = (t < 0.3).astype(float)
    p = run(c, inputs(t, u), P_ATM)
    single = copy.deepcopy(d)
    single["chamber"] = {"kind": "compliant", "volume_m3": 2e-5 + VL,
                         "compliance_m3_per_Pa": CL}
    q = run(RigCard.from_dict(single, "card.json"), inputs(t, u), P_ATM)
    i = 300
    drop_two = p[i] - p[i + 10]   # 10 ms after shutting
    drop_one = q[i] - q[i + 10]
    assert drop_two > 200.0 and abs(drop_one) < 1.0
    # the drop is R times the lung's inflow just before: q_L = C_eff dp_L/dt
    assert p[i + 200] < p[i]  # settles at the shared pressure below the peak


def _against_reference(c):
    """Two breaths of card ``c`` by scipy's Radau (rtol 1e-10) and by the kernel at the
    standard preset and 100 x tighter: ``(reference, standard, tight)`` pressures, Pa."""
    t, u = breath(2e-3, 751)
    inp = inputs(t, u)
    ref = reference_simulate(Model(rig_card=c), np.zeros(0), inp, RIG, P_ATM + 500.0,
                             method="Radau", rtol=1e-10, atol=1e-6)
    return (ref, run(c, inp, solver=SolverConfig.standard()),
            run(c, inp, solver=SolverConfig.standard().tightened(100)))


@pytest.mark.parametrize("c_kw", [{}, {"volume_m3": 3e-5}])
def test_the_two_compartment_kernel_matches_the_reference_solver_and_converges(c_kw):
    ref, std, tight = _against_reference(card(**c_kw))
    assert_converges_to(ref, std, tight, min_span=2e3, std_of_span=1e-3, shrink=0.5)


def test_contiguous_windows_carry_the_second_compartment():
    c = card()
    t, u = breath(1e-3, 1201)
    inp = inputs(t, u)
    m = Model(rig_card=c)
    whole = simulate(m, np.zeros((1, 0)), inp, RIG, P_ATM + 500.0, TIGHT).pressure_Pa[0]
    chained = simulate_windows(m, np.zeros((1, 0)), inp, RIG, np.array([0, 600]), 601,
                               np.array([P_ATM + 500.0, whole[600]]), TIGHT)[0]
    np.testing.assert_allclose(chained[1], whole[600:], atol=1e-2)
    alone = simulate_windows(m, np.zeros((1, 0)), inp, RIG, np.array([600]), 601,
                             np.array([whole[600]]), TIGHT)[0, 0]
    assert np.max(np.abs(alone - whole[600:])) > 10.0  # the lung starts at p0 alone


def test_a_two_compartment_chamber_refuses_a_second_hidden_state():
    m = Model(["heat_transfer"], rig_card=card())
    t = np.arange(11) * 1e-3
    params = {n: m.parameter(n).upper * 0.5 for n in m.parameter_names}
    with pytest.raises(ValueError, match="two-compartment"):
        simulate(m, params, inputs(t, 0 * t), RIG, P_ATM, TIGHT)


# ---------------------------------------------------------------- a tabulated V(p)
def _vp_card(pressures, volumes, dead=VC):
    d = copy.deepcopy(BASE)
    d["chamber"] = {"kind": "compliant_table", "dead_volume_m3": dead,
                    "pressure_Pa": pressures, "volume_change_m3": volumes}
    return RigCard.from_dict(d, "card.json")


def test_a_two_point_volume_table_is_the_compliant_chamber():
    """V(p) = V0 + C (p - P_atm) tabulated at two points, extended beyond them."""
    one = copy.deepcopy(BASE)
    one["chamber"] = {"kind": "compliant", "volume_m3": VC, "compliance_m3_per_Pa": CL}
    tab = _vp_card([P_ATM, P_ATM + 1e4], [0.0, CL * 1e4])
    t, u = breath()
    a = run(tab, inputs(t, u))
    b = run(RigCard.from_dict(one), inputs(t, u))
    assert np.ptp(b) > 3e3
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-6)


def test_a_stiffening_volume_table_matches_the_reference_solver_and_converges():
    ref, std, tight = _against_reference(_vp_card(
        [P_ATM, P_ATM + 2e3, P_ATM + 5e3, P_ATM + 1e4], [0.0, 6e-4, 9e-4, 1.0e-3]))
    # the compliance jumps where the pressure crosses a table point, which the error
    # estimate does not see: 0.4 % of the span at the standard preset (measured), and
    # the error falls with the tolerance (x100 tighter: 40 times smaller)
    assert_converges_to(ref, std, tight, min_span=3e3, std_of_span=5e-3, shrink=0.1)
    # stiffer above 2 kPa gauge: the same inflow raises the pressure faster there
    assert np.max(ref) - P_ATM > 2e3


@pytest.mark.parametrize("pressures, volumes, words", [
    ([P_ATM, P_ATM], [0.0, 1e-4], ["'pressure_Pa' [1]", "strictly increasing"]),
    ([P_ATM, P_ATM + 1e3], [1e-4, 0.0], ["'volume_change_m3' [1]", "non-decreasing"]),
    ([P_ATM, P_ATM + 1e3, P_ATM + 2e3], [0.0, 1e-4], ["one value per pressure point"]),
    ([-1.0, P_ATM], [0.0, 1e-4], ["'pressure_Pa' [0]", "absolute"]),
])
def test_a_bad_volume_table_names_the_key_and_the_point(pressures, volumes, words):
    from pneubayes.errors import RigCardError

    with pytest.raises(RigCardError) as err:
        _vp_card(pressures, volumes)
    for w in words:
        assert w in str(err.value), (w, str(err.value))


def test_the_rates_layer_and_the_kernel_read_the_volume_table_alike():
    """rates.tabulated_volume (discovery's regime labels, broadcast over slot rows) and
    the kernel's compliant_volume give the same volume and compliance."""
    from pneubayes.simulation.chamber import compliant_volume
    from pneubayes.simulation.rates import tabulated_volume

    c = _vp_card([P_ATM, P_ATM + 2e3, P_ATM + 5e3, P_ATM + 1e4], [0.0, 6e-4, 9e-4, 1e-3])
    sl = Model(rig_card=c).lower(np.zeros((1, 0)), RIG)[0]
    p = P_ATM + np.array([-1e3, 0.0, 1e3, 2e3, 3e3, 1e4, 2e4])
    dv, slope = tabulated_volume(sl, p)
    kern = np.array([compliant_volume(float(q), VC, sl, P_ATM) for q in p])
    np.testing.assert_allclose(VC + dv, kern[:, 0], rtol=1e-12)
    np.testing.assert_allclose(slope, kern[:, 1], rtol=1e-12)
    rows = np.stack([sl, sl], axis=1)[:, :, None]  # (slots, 2, 1) against (1, 7)
    dv2, _ = tabulated_volume(rows, p[None, :])
    np.testing.assert_allclose(dv2, np.stack([dv, dv]), rtol=1e-12)
