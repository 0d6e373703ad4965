"""Physics core against hand-computed values (paper section III, appendix, Tables I, II, IV)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pneubayes.physics.chamber import net_mass_flow, pressure_rate
from pneubayes.physics.cylinder import CYLINDERS, chamber_volume, cylinder_preset
from pneubayes.physics.gas import GasConstants
from pneubayes.physics.orifice import flow_function, flow_partials, mass_flow
from pneubayes.physics.valve import (
    VALVES,
    gompertz_area,
    gompertz_partials,
    gompertz_scalar,
    valve_preset,
)

GAS = GasConstants()
P_ATM, P_SUP = 101325.0, 551325.0


def _consts(gas=GAS):
    return gas.alpha_s_per_m, gas.beta_s_per_m, gas.theta, gas.heat_capacity_ratio


# ---------------------------------------------------------------- gas constants
def test_gas_constants_defaults_are_table_iv():
    assert GAS.discharge_coefficient == 0.72
    assert GAS.compressibility == 0.99
    assert GAS.molar_mass_kg_per_mol == 0.029
    assert GAS.gas_constant_J_per_mol_K == 8.31
    assert GAS.heat_capacity_ratio == 1.4
    assert GAS.temperature_K == 293.15


def test_gas_constants_against_appendix_by_hand():
    C, Z, M, R, k, T = 0.72, 0.99, 0.029, 8.31, 1.4, 293.15
    alpha = C * math.sqrt(2 * M / (Z * R * T) * k / (k - 1))
    beta = C * math.sqrt(k * M / (Z * R * T) * (2 / (k + 1)) ** ((k + 1) / (k - 1)))
    theta = ((k + 1) / 2) ** (k / (k - 1))
    rs = R / M
    assert GAS.alpha_s_per_m == pytest.approx(alpha, rel=1e-14)
    assert GAS.beta_s_per_m == pytest.approx(beta, rel=1e-14)
    assert GAS.theta == pytest.approx(theta, rel=1e-14)
    assert GAS.specific_gas_constant_J_per_kg_K == pytest.approx(rs, rel=1e-14)
    # Numbers worked out independently (to 4-5 digits) as a check of the check.
    assert theta == pytest.approx(1.893, abs=5e-4)
    assert rs == pytest.approx(286.55, abs=0.01)
    assert alpha == pytest.approx(6.6057e-3, rel=1e-4)
    assert beta == pytest.approx(1.7096e-3, rel=1e-4)
    assert GAS.speed_of_sound_m_per_s == pytest.approx(math.sqrt(k * rs * T), rel=1e-14)


def test_gas_constants_follow_temperature():
    hot = GasConstants(temperature_K=350.0)
    assert hot.alpha_s_per_m == pytest.approx(GAS.alpha_s_per_m * math.sqrt(293.15 / 350.0),
                                              rel=1e-13)
    assert hot.beta_s_per_m == pytest.approx(GAS.beta_s_per_m * math.sqrt(293.15 / 350.0),
                                             rel=1e-13)
    assert hot.theta == GAS.theta


def test_subsonic_and_choked_coefficients_meet_at_theta():
    # At r = 1/theta: alpha sqrt(r^(2/k) - r^((k+1)/k)) must equal beta (eq. 3 continuity).
    k = GAS.heat_capacity_ratio
    r = 1.0 / GAS.theta
    assert GAS.alpha_s_per_m * math.sqrt(r ** (2 / k) - r ** ((k + 1) / k)) == pytest.approx(
        GAS.beta_s_per_m, rel=1e-13)


@pytest.mark.parametrize("bad", [dict(temperature_K=0.0), dict(heat_capacity_ratio=1.0),
                                 dict(molar_mass_kg_per_mol=float("nan"))])
def test_gas_constants_reject_unphysical(bad):
    with pytest.raises(ValueError):
        GasConstants(**bad)


# ---------------------------------------------------------------- orifice
def test_orifice_continuity_at_critical_ratio(hand):
    theta = GAS.theta
    pd = 2.0e5
    prev = None
    for gap in (1e-2, 1e-4, 1e-6, 1e-9):
        pu_hi, pu_lo = pd * theta * (1 + gap), pd * theta * (1 - gap)
        above = float(flow_function(pu_hi, pd, GAS))   # choked branch
        below = float(flow_function(pu_lo, pd, GAS))   # subsonic branch
        rel = abs(above - below) / above
        # no jump: the difference is only the O(gap) change of p_u itself ...
        assert rel < 2.01 * gap
        if prev is not None:
            assert rel < prev
        prev = rel
        # ... and the subsonic value just below theta equals the choked law there to O(gap^2)
        assert below / (GAS.beta_s_per_m * pu_lo) == pytest.approx(1.0, abs=2 * gap ** 2 + 1e-13)
        assert below == pytest.approx(hand.z(pu_lo, pd), rel=1e-12)
    exact = GAS.beta_s_per_m * pd * theta
    assert float(flow_function(pd * theta * (1 - 1e-9), pd, GAS)) == pytest.approx(exact, rel=2e-9)


@pytest.mark.parametrize("pu,pd", [(5.5e5, 1.0e5), (3.0e5, 2.9e5), (2.0e5, 1.5e5),
                                   (1.01325e5, 1.01e5), (8e5, 1e5), (4e5, 2.2e5)])
def test_orifice_antisymmetry_and_sign(pu, pd):
    f = float(flow_function(pu, pd, GAS))
    b = float(flow_function(pd, pu, GAS))
    assert f > 0 and b < 0
    assert b == -f


@pytest.mark.parametrize("p", [1e3, 101325.0, 3e5, 551325.0, 1e7])
def test_orifice_zero_at_equal_pressure(p):
    assert float(flow_function(p, p, GAS)) == 0.0


@pytest.mark.parametrize("ratio", [1.9, 2.0, 3.0, 5.44, 10.0, 100.0])
def test_orifice_choked_branch_is_beta_pu(ratio):
    pd = 101325.0
    pu = ratio * pd
    assert float(flow_function(pu, pd, GAS)) == pytest.approx(GAS.beta_s_per_m * pu, rel=1e-14)
    # independent of the downstream pressure once choked
    assert float(flow_function(pu, pd * 0.5, GAS)) == pytest.approx(GAS.beta_s_per_m * pu,
                                                                    rel=1e-14)


def test_orifice_subsonic_branch_matches_eq3(hand):
    rng = np.random.default_rng(3)
    pu = rng.uniform(1.0e5, 6.0e5, 200)
    ratio = rng.uniform(1.0 + 1e-6, GAS.theta * (1 - 1e-9), 200)
    pd = pu / ratio
    got = flow_function(pu, pd, GAS)
    want = np.array([hand.z(a, b) for a, b in zip(pu, pd)])
    np.testing.assert_allclose(got, want, rtol=1e-12)
    # explicit formula once more, without the helper
    k = 1.4
    r = pd / pu
    np.testing.assert_allclose(
        got, GAS.alpha_s_per_m * pu * np.sqrt(r ** (2 / k) - r ** ((k + 1) / k)), rtol=1e-12)
    # reverse direction is minus the swapped evaluation
    np.testing.assert_allclose(flow_function(pd, pu, GAS), -want, rtol=1e-12)


def test_orifice_vectorised_over_a_grid_matches_scalar_formula(hand):
    p = np.linspace(0.5e5, 7e5, 41)
    pu, pd = np.meshgrid(p, p, indexing="ij")
    got = flow_function(pu, pd, GAS)
    want = np.vectorize(hand.flow)(pu, pd)
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=0)


def test_mass_flow_is_area_times_flow_function():
    assert float(mass_flow(3e-7, 5e5, 1e5, GAS)) == pytest.approx(
        3e-7 * GAS.beta_s_per_m * 5e5, rel=1e-14)


@pytest.mark.parametrize("bad", [(0.0, 1e5), (1e5, -1.0), (float("nan"), 1e5)])
def test_flow_function_rejects_nonpositive_pressure(bad):
    with pytest.raises(ValueError):
        flow_function(*bad, GAS)


@pytest.mark.parametrize("pu,pd", [(3.0e5, 2.0e5), (2.0e5, 3.0e5), (1.5e5, 1.0e5),
                                   (1.0e5, 1.5e5), (5.5e5, 4.0e5), (4.0e5, 5.5e5),
                                   (5.5e5, 1.0e5), (1.0e5, 5.5e5), (1.1e5, 1.0e5)])
def test_flow_partials_match_central_differences(pu, pd):
    a, b, th, k = _consts()
    f, du, dd = flow_partials(pu, pd, a, b, th, k, 0.0)
    assert f == pytest.approx(float(flow_function(pu, pd, GAS)), rel=1e-14)
    h = 1e-3  # Pa; the function is smooth on this scale away from pu == pd and theta
    fd_u = (flow_partials(pu + h, pd, a, b, th, k, 0.0)[0]
            - flow_partials(pu - h, pd, a, b, th, k, 0.0)[0]) / (2 * h)
    fd_d = (flow_partials(pu, pd + h, a, b, th, k, 0.0)[0]
            - flow_partials(pu, pd - h, a, b, th, k, 0.0)[0]) / (2 * h)
    scale = abs(f) / max(pu, pd)
    assert du == pytest.approx(fd_u, rel=1e-6, abs=1e-9 * scale)
    assert dd == pytest.approx(fd_d, rel=1e-6, abs=1e-9 * scale)


def test_flow_partials_analytic_on_choked_branch():
    a, b, th, k = _consts()
    _, du, dd = flow_partials(5.5e5, 1.0e5, a, b, th, k, 0.0)
    assert du == b and dd == 0.0
    _, du, dd = flow_partials(1.0e5, 5.5e5, a, b, th, k, 0.0)
    assert du == 0.0 and dd == -b


# ---------------------------------------------------------------- Gompertz, Table II
TABLE_II = {
    "valve1": ((2.9274e-08, 5.501e-07, 3.539, 1.564, 0.12),
               (2.6076e-08, 6.079e-07, 3.149, -1.365, -0.1)),
    "valve2": ((2.627e-08, 8.731e-07, 4.029, 0.929, -0.1505),
               (2.964e-08, 8.659e-07, 3.942, -0.9816, 0.1584)),
}


@pytest.mark.parametrize("name", sorted(TABLE_II))
def test_table_ii_presets(name, hand):
    preset = valve_preset(name)
    inlet, exhaust = TABLE_II[name]
    g_in, g_ex = preset.inlet, preset.exhaust
    assert (g_in.offset_m2, g_in.a_m2, g_in.b, g_in.c_per_V, g_in.d_V) == inlet
    assert (g_ex.offset_m2, g_ex.a_m2, g_ex.b, g_ex.c_per_V, g_ex.d_V) == exhaust
    u = np.linspace(-5, 5, 101)
    for gm, row in ((g_in, inlet), (g_ex, exhaust)):
        want = np.array([hand.gompertz(v, *row) for v in u])
        np.testing.assert_allclose(gm.area(u), want, rtol=1e-14)
        np.testing.assert_allclose(gompertz_area(u, *row), want, rtol=1e-14)
        for v in (-5.0, -0.3, 0.0, 0.7, 5.0):
            assert gompertz_scalar(v, *row) == pytest.approx(hand.gompertz(v, *row), rel=1e-14)
    params = preset.parameters()
    assert params["inlet_a_m2"] == inlet[1] and params["exhaust_c_per_V"] == exhaust[3]
    assert len(params) == 10


def test_gompertz_hand_values_valve1():
    # eq. 11 worked out on paper: offset + a exp(-b exp(-c (u + d)))
    v = valve_preset("valve1")
    assert float(v.inlet.area(0.0)) == pytest.approx(
        2.9274e-08 + 5.501e-07 * math.exp(-3.539 * math.exp(-1.564 * 0.12)), rel=1e-14)
    assert float(v.exhaust.area(0.0)) == pytest.approx(
        2.6076e-08 + 6.079e-07 * math.exp(-3.149 * math.exp(-1.365 * 0.1)), rel=1e-14)
    # at +5 V the inlet is near fully open (offset + a), the exhaust at its offset
    assert float(v.inlet.area(5.0)) == pytest.approx(2.9274e-08 + 5.501e-07, rel=2e-3)
    assert float(v.exhaust.area(5.0)) == pytest.approx(2.6076e-08, rel=1e-6)


@pytest.mark.parametrize("name", sorted(VALVES))
def test_gompertz_partials_are_central_differences_of_the_map(name):
    """The least squares' Jacobian (eq. 11 differentiated by hand) against central
    differences with a step of 1e-6 of each parameter's size."""
    u = np.linspace(-5, 5, 41)
    for g in (valve_preset(name).inlet, valve_preset(name).exhaust):
        theta = np.array([g.offset_m2, g.a_m2, g.b, g.c_per_V, g.d_V])
        got = gompertz_partials(u, *theta)
        assert got.shape == (41, 5)
        for j in range(5):
            h = 1e-6 * max(abs(theta[j]), 1e-3 if j >= 2 else 1e-9)
            up, dn = theta.copy(), theta.copy()
            up[j] += h
            dn[j] -= h
            fd = (gompertz_area(u, *up) - gompertz_area(u, *dn)) / (2 * h)
            np.testing.assert_allclose(got[:, j], fd, rtol=1e-6,
                                       atol=1e-9 * np.max(np.abs(fd)) + 1e-20)


@pytest.mark.parametrize("name", sorted(VALVES))
def test_gompertz_monotone_in_command(name):
    u = np.linspace(-5, 5, 2001)
    v = valve_preset(name)
    a_in, a_ex = v.inlet.area(u), v.exhaust.area(u)
    assert np.all(np.diff(a_in) >= 0) and np.all(np.diff(a_ex) <= 0)
    # strictly so where neither map has underflowed to its offset
    mid = (u > -1.5) & (u < 1.5)
    assert np.all(np.diff(a_in[mid]) > 0) and np.all(np.diff(a_ex[mid]) < 0)
    assert a_in[-1] > 10 * a_in[0] and a_ex[0] > 10 * a_ex[-1]


def test_unknown_valve_and_cylinder():
    with pytest.raises(KeyError):
        valve_preset("valve3")
    with pytest.raises(KeyError):
        cylinder_preset("AIR38")


# ---------------------------------------------------------------- cylinders, Table I
@pytest.mark.parametrize("name,volume", [("AIR37", 2.3856e-06), ("AIR200", 1.2723e-05),
                                         ("SMC", 2.0106e-05), ("PRN", 3.50e-06)])
def test_table_i_volumes(name, volume):
    c = cylinder_preset(name)
    got = c.swept_volume_m3
    # 4 significant digits as printed in Table I
    assert float(f"{got:.4e}") == pytest.approx(volume, rel=1e-12)
    if name != "PRN":
        assert got == pytest.approx(math.pi / 4 * c.bore_m ** 2 * c.stroke_m, rel=1e-14)


def test_table_i_geometry():
    assert (CYLINDERS["AIR37"].bore_m, CYLINDERS["AIR37"].stroke_m) == (0.009, 0.0375)
    assert (CYLINDERS["AIR200"].bore_m, CYLINDERS["AIR200"].stroke_m) == (0.009, 0.200)
    assert (CYLINDERS["SMC"].bore_m, CYLINDERS["SMC"].stroke_m) == (0.032, 0.025)


def test_chamber_volume_map():
    x = np.array([0.0, 0.01, 0.0375])
    np.testing.assert_allclose(chamber_volume(x, 2e-7, 0.009),
                               2e-7 + math.pi / 4 * 0.009 ** 2 * x, rtol=1e-14)


# ---------------------------------------------------------------- chamber, eqs. 4, 5, 9
def test_chamber_pressure_rate_and_net_flow_by_hand(hand):
    g = hand.gas()
    p, a_in, a_ex, a_l = 2.5e5, 4e-7, 1e-7, 3e-8
    mdot = net_mass_flow(p, a_in, a_ex, P_SUP, P_ATM, GAS, leak_area_m2=a_l)
    want = a_in * hand.flow(P_SUP, p) - (a_ex + a_l) * hand.flow(p, P_ATM)
    assert float(mdot) == pytest.approx(want, rel=1e-12)
    vol, vdot = 3e-6, -2e-6
    rate = pressure_rate(p, vol, vdot, mdot, GAS)
    assert float(rate) == pytest.approx(1.4 / vol * (g.rs * g.T * want - p * vdot), rel=1e-12)


def test_the_tabulated_friction_law_matches_churchills_formula():
    from pneubayes.physics.tube import (
        CHURCHILL_TABLE_RE,
        churchill_fre,
        churchill_fre_table,
    )

    # laminar (64), the transition, the turbulent branch and beyond the table's end
    re = np.exp(np.linspace(math.log(500.0), math.log(3.0 * CHURCHILL_TABLE_RE[1]), 20001))
    exact = np.array([churchill_fre(r) for r in re])
    table = np.array([churchill_fre_table(r) for r in re])
    assert np.max(np.abs(table / exact - 1.0)) < 1e-8
    assert churchill_fre_table(999.0) == 64.0 and churchill_fre(999.0) == 64.0
    # Poiseuille's 64 joins the turbulent branch continuously at the table's start
    assert churchill_fre_table(1000.0) == pytest.approx(64.0, rel=1e-12)
    assert churchill_fre_table(3e4) > 100.0  # turbulent: f Re grows with Re


def test_the_tabulated_friction_slope_matches_the_formulas():
    from pneubayes.physics.tube import churchill_fre_and_slope_table, churchill_fre_slope

    def slope(r):
        return churchill_fre_and_slope_table(r)[1]

    re = np.exp(np.linspace(math.log(500.0), math.log(3e8), 20001))
    exact = np.array([churchill_fre_slope(r) for r in re])
    table = np.array([slope(r) for r in re])
    assert np.max(np.abs(table - exact)) < 1e-5
    assert slope(999.0) == 0.0  # laminar: f Re = 64
    assert 0.7 < slope(1e6) < 0.9  # turbulent: about Re^0.75


def test_the_unsteady_frictions_turbulent_cutoff_is_vardy_and_browns():
    """0 in laminar flow; from Re 4000 ``Re^k / 12.86`` with ``k = log10(15.29 /
    Re^0.0567)`` (Vardy and Brown 2003: about 525 at Re 1e4); continuous and rising
    across the fade-in."""
    from pneubayes.physics.tube import vardy_brown_cutoff

    assert vardy_brown_cutoff(500.0) == 0.0 and vardy_brown_cutoff(2000.0) == 0.0
    for re in (4000.0, 1e4, 1e5):
        k = math.log10(15.29 / re ** 0.0567)
        assert vardy_brown_cutoff(re) == pytest.approx(re ** k / 12.86, rel=1e-12)
    assert vardy_brown_cutoff(1e4) == pytest.approx(525.0, rel=0.01)
    re = np.linspace(1990.0, 1e5, 20001)
    b = np.array([vardy_brown_cutoff(r) for r in re])
    assert np.all(np.diff(b) >= 0.0) and np.max(np.abs(np.diff(b))) < 1.0
