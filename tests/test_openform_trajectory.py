"""The open-form search on prediction windows: a closure term's first-order effect on
the predicted pressure, against the simulator's own difference."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import BORE, P_ATM, P_SUP, STROKE, moving_position, random_steps

from pneubayes.discovery.one_step import one_step_data
from pneubayes.discovery.openform import OpenFormSearch
from pneubayes.discovery.openform.signals import path_signals
from pneubayes.discovery.openform.trajectory import WindowResponse
from pneubayes.effects.closure import Closure
from pneubayes.effects.closure_terms import Term
from pneubayes.inference.windows import WindowSet
from pneubayes.io.recording import Recording, RecordingMetadata
from pneubayes.model import Model
from pneubayes.physics.valve import valve_preset
from pneubayes.simulation import Inputs, SolverConfig, simulate

SOLVER = SolverConfig.reference()


def _recording(seed: int, terms=None, values=None, noise_Pa=0.0, n=6001):
    """A 6-s valve1 recording on a moving piston (1 kHz), simulated with the plain
    model, or with a closure of ``terms`` at ``values``."""
    md = RecordingMetadata("AIR37", "valve1", BORE, STROKE, P_ATM, P_SUP, 293.15)
    rng = np.random.default_rng(seed)
    dt = 1e-3
    t = np.arange(n) * dt
    u = random_steps(rng, n, dt, hold_s=(0.1, 0.6))
    blank = Recording(md, t, u, np.full(n, P_ATM), position_m=moving_position(t))
    model = Model() if terms is None else Model().with_effect(Closure(terms=terms))
    params = {**valve_preset("valve1").parameters(), "dead_volume_m3": 4e-6, **(values or {})}
    p = simulate(model, params, Inputs.from_recording(blank), blank.rig(), P_ATM,
                 SOLVER).pressure_Pa[0]
    return Recording(md, t, u, p + rng.normal(0.0, noise_Pa, n) if noise_Pa else p,
                     position_m=blank.position_m, source=f"r{seed}.csv")


def _windows(rec):
    ws = WindowSet([rec], 2.0, 2.0)
    b = ws.blocks[0]
    return ws, b


def test_the_window_response_is_the_simulators_first_order_difference():
    """A small constant extra flow and a small inlet-flow term, simulated, move each
    window's prediction by what the linear response says, to within 1 % of it."""
    params = {**valve_preset("valve1").parameters(), "dead_volume_m3": 4e-6}
    rec = _recording(0)
    ws, b = _windows(rec)
    sig = path_signals(Model(), params, rec, one_step_data(rec, 5))
    response = WindowResponse(sig, b.starts, ws.length, b.rig, every=10)
    for term, c in (("one", 2e-7), ("inlet_flow", 2e-3), ("pressure_ratio", 1e-7)):
        model = Model().with_effect(Closure(terms=term))
        theta = np.stack([model.vector({**params, "closure_coefficient_0": v})
                          for v in (0.0, c)])
        sim = ws.simulate(model, theta, SOLVER)  # (2, W, L)
        moved = response.sample((sim[1] - sim[0])[:, 1:])
        linear = c * response(Term.parse(term).evaluate(sig))
        assert np.abs(linear).max() > 20.0  # Pa: an effect well above the solver's error
        err = np.sqrt(np.mean((moved - linear) ** 2)) / np.sqrt(np.mean(linear ** 2))
        assert err < 0.01, (term, err)
    # rows window by window, the kept samples every 10th; a (M, K) input maps column-wise
    assert response.n_rows == b.starts.size * ((ws.length - 1) // 10)
    two = response(np.column_stack([np.ones(sig["interval_s"].size)] * 2))
    np.testing.assert_array_equal(two[:, 0], two[:, 1])
    with pytest.raises(ValueError, match="every"):
        WindowResponse(sig, b.starts, ws.length, b.rig, every=0)
    with pytest.raises(ValueError, match="run past"):
        WindowResponse(sig, b.starts + 10**6, ws.length, b.rig, every=10)
    with pytest.raises(ValueError, match="window values"):
        response.sample(np.zeros((1, 3)))


@pytest.mark.slow
def test_the_window_search_finds_a_small_leak_alone_with_its_coefficient():
    """A leak of 4e-7 kg/s per atmosphere of gauge pressure under 300 Pa of noise
    (invisible in one interval, it accumulates over a window): the search on the
    windows' residual keeps it alone, as c (p / P_atm - 1) (a pressure ratio with the
    constant, or the pressure hinge at the atmosphere), c within 10 %."""
    planted = -4e-7
    recs = [_recording(seed, "pressure_ratio; one",
                       {"closure_coefficient_0": planted, "closure_coefficient_1": -planted},
                       noise_Pa=300.0, n=8001) for seed in (1, 2, 3)]
    params = {**valve_preset("valve1").parameters(), "dead_volume_m3": 4e-6}
    signals, targets, maps = [], [], []
    for rec in recs:
        ws, b = _windows(rec)
        sig = path_signals(Model(), params, rec, one_step_data(rec, 5))
        r = WindowResponse(sig, b.starts, ws.length, b.rig, every=50)
        missing = -ws.residuals(Model(), Model().vector(params)[None], SOLVER)[0]
        signals.append(sig)
        maps.append(r)
        targets.append(r.sample(missing))
    search = OpenFormSearch(chunk_rows=maps[0].rows_per_window, seed=0, n_models=20)
    search.fit(signals, targets, row_maps=maps)
    assert len(search.terms_) == 1, search.terms_
    (t,) = search.terms_
    assert str(t.term) in ("pressure_ratio", "pressure_hinge")
    assert t.coefficient == pytest.approx(planted, rel=0.1)
    if str(t.term) == "pressure_hinge":
        assert t.threshold_a == pytest.approx(1.0, abs=0.1)
    with pytest.raises(ValueError, match="row maps"):
        search.fit(signals, targets, row_maps=maps[:1])
    with pytest.raises(ValueError, match="rows"):
        search.fit(signals, [t[:-1] for t in targets], row_maps=maps)
