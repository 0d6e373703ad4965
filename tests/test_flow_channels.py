"""Measured port flows in the likelihood (:mod:`pneubayes.inference.flow_channels`), on
the shipped RespiraWorks card driven by run 5's commands: a venturi column written from
the model's own inlet flow, ``dp = 0.4 + 2e7 q^2`` (its units), and a planted plant."""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from pneubayes.inference.flow_channels import FlowChannel, flow_rows, port_flows
from pneubayes.inference.refine import TrajectoryRefiner
from pneubayes.inference.windows import WindowSet
from pneubayes.io import read_recording
from pneubayes.model import Model
from pneubayes.rigcard import load_rig_card
from pneubayes.simulation import Inputs, SolverConfig, simulate

DATA = Path(__file__).resolve().parents[1] / "data" / "real" / "respiraworks"
N = 800  # 8 s at 100 Hz


@pytest.fixture(scope="module")
def plant():
    card = load_rig_card(DATA / "respiraworks-oxy.rig.json")
    rec = read_recording(DATA / "OXY" / "covent_pc_5.csv", rig_card=card).slice(0, N)
    model = Model(rig_card=card)
    truth = model.base_start_values()
    p = simulate(model, truth, Inputs.from_recording(rec), rec.rig(),
                 float(rec.pressure_Pa[0]), SolverConfig.standard()).pressure_Pa[0]
    rec = replace(rec, pressure_Pa=p)
    q_in, q_ex = port_flows(model, model.vector(truth)[None], rec)
    extra = dict(rec.extra_columns, dp_inhale=0.4 + 2e7 * q_in[0] ** 2,
                 dp_exhale=0.1 + 5e6 * q_ex[0] ** 2)
    return {"model": model, "truth": truth, "rec": replace(rec, extra_columns=extra)}


def _rows(plant, **change):
    m = plant["model"]
    th = m.vector({**plant["truth"], **{k: v * plant["truth"][k] for k, v in change.items()}})
    return flow_rows(m, th[None], plant["rec"], [FlowChannel("dp_inhale", "inlet", 100.0)])[0]


def test_the_rows_vanish_at_the_truth_and_see_the_maps_shape_not_its_scale(plant):
    q_in, _ = port_flows(plant["model"], plant["model"].vector(plant["truth"])[None],
                         plant["rec"])
    assert q_in.max() > 1e-4  # the inhale valve opens in these 8 s
    span = 100.0 * np.ptp(plant["rec"].extra_columns["dp_inhale"])
    assert np.sqrt(np.mean(_rows(plant) ** 2)) < 1e-9 * span
    # an uncalibrated sensor's gain absorbs the area's scale ...
    assert np.sqrt(np.mean(_rows(plant, inlet_a_m2=0.8) ** 2)) < 1e-9 * span
    # ... but not the map's shape (the command at which it opens)
    assert np.sqrt(np.mean(_rows(plant, inlet_d_V=1.3) ** 2)) > 1e-2 * span


def test_a_refit_with_the_flow_rows_finds_the_maps_shape(plant):
    model, rec = plant["model"], plant["rec"]
    chans = [FlowChannel("dp_inhale", "inlet", 100.0)]
    start = {**plant["truth"], "inlet_d_V": 1.3 * plant["truth"]["inlet_d_V"]}
    fit = TrajectoryRefiner(
        model, SolverConfig.standard(), free=("inlet_d_V",), max_nfev=40,
        extra_residuals=lambda th: flow_rows(model, th, rec, chans)).fit(
        WindowSet([rec], 2.0, 2.0), start)
    assert fit.params_["inlet_d_V"] == pytest.approx(plant["truth"]["inlet_d_V"], rel=1e-3)
    assert fit.covariance_.shape == (1, 1) and np.isfinite(fit.covariance_[0, 0])


def test_bad_channels_are_named(plant):
    with pytest.raises(ValueError, match="port"):
        FlowChannel("dp_inhale", "outlet", 1.0)
    with pytest.raises(ValueError, match="law"):
        FlowChannel("dp_inhale", "inlet", 1.0, law="cubic")
    with pytest.raises(ValueError, match="weight_Pa_per_unit"):
        FlowChannel("dp_inhale", "inlet", 0.0)
    with pytest.raises(ValueError, match="no column 'flow'"):
        flow_rows(plant["model"], plant["model"].vector(plant["truth"])[None], plant["rec"],
                  [FlowChannel("flow", "inlet", 1.0)])
    delayed = Model(["tube_delay"], rig_card=plant["model"].rig_card)
    th = delayed.vector({**plant["truth"], "tube_delay_s": 0.01})
    with pytest.raises(ValueError, match="command_delay_s"):
        port_flows(delayed, th[None], plant["rec"])
    with pytest.raises(TypeError, match="extra_residuals"):
        TrajectoryRefiner(plant["model"], SolverConfig.standard(), extra_residuals=3)
