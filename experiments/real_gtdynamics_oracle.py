"""Real recordings: how close to the noise can the GTDynamics fills come at all?

    python experiments/real_gtdynamics_oracle.py --out results/real_gtdynamics_oracle

The discovery loop stops at about 6.4 x the noise floor on the held-out trials
(``real_gtdynamics.py``). This script bounds what the model class it ends with (the
rig card's fixed-volume muscle, the wave tube) can reach, with point fits (multiple
shooting on the same 44-ms windows, the same split):

- ``shared``: one parameter set fitted on the training trials (the loop's model);
- ``per_muscle``: the muscle's volume, the tube's bore and its delay fitted per muscle
  on that muscle's training recordings (each muscle is its own chamber and tube; a
  held-out trial's muscle is one of them);
- ``oracle``: the delay and the volume fitted on each held-out recording itself, the
  rest shared: no prediction can do better with this model class, so it is a floor,
  not a result;

each with the RMSE left after dropping the 2 % largest residuals (the raw psi channels
have isolated spikes of tens of kPa that no model predicts). Deterministic (no random
draws). Writes OUT/real_gtdynamics_oracle.json.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from real_gtdynamics import DATA, HORIZON_S, load

from pneubayes.atomic import write_json_atomic
from pneubayes.effects import TubeDelay
from pneubayes.inference.pipeline import FitSettings
from pneubayes.inference.predictive import noise_floor_Pa
from pneubayes.inference.refine import TrajectoryRefiner
from pneubayes.inference.windows import WindowSet
from pneubayes.model import Model
from pneubayes.provenance import provenance
from pneubayes.rigcard import load_rig_card

MUSCLES = ("hip_left", "hip_right", "knee_left", "knee_right")
#: Share of the largest absolute residuals dropped for the spike-free RMSE.
SPIKE_SHARE = 0.02


def _model(card, fixed: dict | None = None) -> Model:
    """The card's muscle beside the wave tube; ``fixed`` parameters pinned (bounds
    1e-9 wide around the value)."""
    bounds = {k: (v * (1 - 1e-9), v * (1 + 1e-9)) for k, v in (fixed or {}).items()}
    return Model([TubeDelay(form="wave")], rig_card=card, bounds=bounds)


def _fit(model, recs, start, nfev):
    ref = TrajectoryRefiner(model, FitSettings().refine_solver, horizon_s=HORIZON_S,
                            max_nfev=nfev).fit(WindowSet(recs, HORIZON_S, HORIZON_S), start)
    return ref.params_


def _residuals(model, params, recs) -> np.ndarray:
    return WindowSet(recs, HORIZON_S, HORIZON_S).residuals(
        model, params, FitSettings().refine_solver).reshape(-1)


def _summary(res: np.ndarray, noise: float) -> dict:
    a = np.sort(np.abs(res))
    kept = a[:int(round((1 - SPIKE_SHARE) * a.size))]
    rmse = float(np.sqrt(np.mean(res ** 2)))
    return {"rmse_Pa": rmse, "over_noise": rmse / noise,
            "rmse_without_spikes_Pa": float(np.sqrt(np.mean(kept ** 2))),
            "samples": int(res.size)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True)
    ap.add_argument("--data", default=str(DATA))
    args = ap.parse_args(argv)
    data = Path(args.data)
    card = load_rig_card(data / "gtdynamics-muscle.rig.json")
    train, held = load(data)
    noise = noise_floor_Pa(train + held)
    model = _model(card)
    start = {**model.neutral_values(), **model.base_start_values(), "tube_delay_s": 0.015}
    start = {k: v for k, v in start.items() if k in model.parameter_names}
    shared = _fit(model, train, start, 150)
    rows = {"shared": _summary(_residuals(model, shared, held), noise)}
    per_muscle, oracle = [], []
    free = ("dead_volume_m3", "tube_diameter_m", "tube_delay_s")
    fitted = {}
    for m in MUSCLES:
        sub = _model(card, {k: v for k, v in shared.items() if k not in free})
        own = _fit(sub, [r for r in train if m in str(r.source)], shared, 100)
        fitted[m] = {k: own[k] for k in free}
        per_muscle.append(_residuals(sub, own, [r for r in held if m in str(r.source)]))
    rows["per_muscle"] = _summary(np.concatenate(per_muscle), noise)
    rows["per_muscle"]["parameters"] = fitted
    for rec in held:
        sub = _model(card, {k: v for k, v in shared.items()
                            if k not in ("dead_volume_m3", "tube_delay_s")})
        own = _fit(sub, [rec], shared, 60)
        oracle.append(_residuals(sub, own, [rec]))
    rows["oracle"] = _summary(np.concatenate(oracle), noise)
    result = {"noise_floor_Pa": noise, "horizon_s": HORIZON_S, "shared_parameters": shared,
              "held_out_recordings": [str(r.source) for r in held], "fits": rows,
              "spike_share": SPIKE_SHARE, "provenance": provenance()}
    write_json_atomic(Path(args.out) / "real_gtdynamics_oracle.json", result)
    for k, v in rows.items():
        print(f"{k:11s} held-out {v['rmse_Pa']:7.0f} Pa ({v['over_noise']:.2f} x the "
              f"{noise:.0f}-Pa noise), without the {100 * SPIKE_SHARE:g} % largest "
              f"{v['rmse_without_spikes_Pa']:7.0f} Pa")
    return 0


if __name__ == "__main__":
    sys.exit(main())
