"""An effect is its own file plus one registry line (issue 66, item 3).

The toy effect below lives in this test file alone: a constant bleed out of the chamber
(a sampling line drawing a fixed mass flow), lowered onto signal-path slots that already
exist (the closure's constant term). One line registers it; the simulator, the
least-squares refinement and the discovery loop then find, name and fit it without any
edit to the package.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import BORE, P_ATM, P_SUP, STROKE, discovery_settings, random_steps

from pneubayes.effects import CATALOGUE
from pneubayes.effects.base import Effect, Parameter
from pneubayes.effects.closure_features import feature
from pneubayes.effects.discovery import TrialTerm
from pneubayes.io.recording import Recording, RecordingMetadata
from pneubayes.model import Model
from pneubayes.physics.valve import valve_preset
from pneubayes.simulation import Inputs, SolverConfig, simulate

BLEED = 1.5e-5  # kg/s, the planted truth
NOISE_PA = 200.0


class ConstantBleed(Effect):
    """A constant mass flow out of the chamber, ``bleed_kg_per_s`` (kg/s)."""

    name = "constant_bleed"
    acts_on = ("closure_terms", "closure_feature_a_0", "closure_feature_b_0",
               "closure_coefficient_0")
    library_strengths = (5e-6, 2e-5)

    def parameters(self):
        return (Parameter("bleed_kg_per_s", "kg/s", 0.0, 1e-4, "uniform",
                          "mass flow drawn out of the chamber", neutral=0.0),)

    def lower(self, values, rig):
        bleed = np.asarray(values["bleed_kg_per_s"], dtype=np.float64)
        one = float(feature("one").code)
        return {"closure_terms": np.where(bleed != 0.0, 1.0, 0.0),
                "closure_feature_a_0": one, "closure_feature_b_0": one,
                "closure_coefficient_0": -bleed}

    def bench_defaults(self):
        return {"bleed_kg_per_s": BLEED}

    def library_terms(self, strengths):
        return tuple(TrialTerm(f"bleed {b:g} kg/s", {"bleed_kg_per_s": b},
                               values={"bleed_kg_per_s": b}) for b in strengths)


@pytest.fixture
def registered(monkeypatch):
    """The one registry line (undone after the test)."""
    monkeypatch.setitem(CATALOGUE, ConstantBleed.name, ConstantBleed)


def _recordings(n: int = 5):
    """``n`` 8-s valve1 recordings (1 kHz, 200 Pa noise) of a chamber with the bleed."""
    truth_model = Model([ConstantBleed()])
    truth = {**valve_preset("valve1").parameters(), "dead_volume_m3": 2.4e-6,
             "bleed_kg_per_s": BLEED}
    md = RecordingMetadata("AIR37", "valve1", BORE, STROKE, P_ATM, P_SUP, 293.15,
                           position_m=0.015)
    recs = []
    for seed in range(n):
        rng = np.random.default_rng(seed)
        t = np.arange(8001) * 1e-3
        u = random_steps(rng, t.size, 1e-3, hold_s=(0.05, 0.3))
        blank = Recording(md, t, u, np.full(t.size, P_ATM))
        p = simulate(truth_model, truth, Inputs.from_recording(blank), blank.rig(), P_ATM,
                     SolverConfig.standard()).pressure_Pa[0]
        recs.append(Recording(md, t, u, p + rng.normal(0.0, NOISE_PA, t.size),
                              source=f"bleed_{seed}.csv"))
    return recs


def test_a_plug_in_effect_simulates_like_the_closure_it_lowers_onto(registered, rig):
    """The toy effect made by name is the same model as the closure's constant term."""
    from pneubayes.effects import make_effect

    t = np.arange(301) * 1e-3
    inputs = Inputs(t, np.where(t < 0.1, 4.0, -0.5), np.zeros_like(t), np.full_like(t, P_SUP))
    base = {**valve_preset("valve1").parameters(), "dead_volume_m3": 2.4e-6}
    toy = Model([make_effect("constant_bleed")])
    closure = Model([make_effect("closure", terms="one")])
    got = simulate(toy, {**base, "bleed_kg_per_s": BLEED}, inputs, rig, P_ATM,
                   SolverConfig.standard()).pressure_Pa[0]
    ref = simulate(closure, {**base, "closure_coefficient_0": -BLEED}, inputs, rig, P_ATM,
                   SolverConfig.standard()).pressure_Pa[0]
    plain = simulate(Model(), base, inputs, rig, P_ATM, SolverConfig.standard()).pressure_Pa[0]
    assert np.max(np.abs(got - plain)) > 1e3
    np.testing.assert_array_equal(got, ref)


@pytest.mark.slow
def test_discovery_names_and_fits_a_plug_in_effect(registered):
    """The plain loop (no fallback stages) searches the registered effect with the
    catalogue's, names it, and recovers its strength; the held-out error falls to about
    the noise."""
    from pneubayes.discovery.loop import Discovery
    settings = discovery_settings(posterior={"method": "none"},
                                  forms={"tube_line_segments": 0},
                                  data={"holdout_recordings": 2}, rounds={"max_effects": 1})
    result = Discovery(settings, None, log=None, stages=[]).fit(_recordings()).result_
    doc = result.to_dict()
    assert [e["name"] for e in doc["effects"]] == ["constant_bleed"], doc["ledger"]
    assert result.params["bleed_kg_per_s"] == pytest.approx(BLEED, rel=0.15)
    assert doc["rmse_final_Pa"] < 1.3 * doc["noise_floor_Pa"] < doc["rmse_base_Pa"]
