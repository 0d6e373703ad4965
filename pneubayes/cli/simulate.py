"""``pneubayes simulate``: a model card's pressure for a recording's inputs."""

from __future__ import annotations

import numpy as np

from pneubayes.cli.common import (
    not_an_input,
    output_file,
    print_findings,
    recording_files,
)
from pneubayes.errors import PneubayesError

#: simulate --atol must be under this, Pa (an error of an atmosphere is no accuracy).
ATOL_MAX_PA = 1e5


def cmd_simulate(args) -> int:
    from pneubayes.atomic import write_text_atomic
    from pneubayes.io.recording import read_recording
    from pneubayes.model import Model
    from pneubayes.simulation import Inputs, SolverConfig, simulate

    if args.rtol >= 1.0:
        raise PneubayesError(f"--rtol {args.rtol:g}: a relative tolerance must be under 1 "
                             "(3e-5 by default; 1 or more asks for no accuracy at all)")
    if args.atol >= ATOL_MAX_PA:
        raise PneubayesError(f"--atol {args.atol:g}: an absolute tolerance must be under "
                             f"{ATOL_MAX_PA:g} Pa, an atmosphere (10 Pa by default)")
    out = output_file(args.out, ".csv", args.overwrite)
    not_an_input([out], [*recording_files([args.recording]), args.model])
    rec = read_recording(args.recording, args.accept, args.rig)
    model, params = Model.load_card(args.model)
    print_findings("simulate", [rec])
    if model.rig_card != rec.rig_card:
        raise PneubayesError(f"--model {args.model} and {rec.source} describe different "
                             "rigs (rig cards)")
    if args.max_step <= 1e-12:
        raise PneubayesError(f"--max-step {args.max_step:g}: must be above 1e-12 s, the "
                             "integrator's smallest step")
    solver = SolverConfig(rtol=args.rtol, atol_Pa=args.atol, atol_K=0.01,
                          max_step_s=args.max_step, min_step_s=1e-12, max_steps_per_s=2.5e7)
    traj = simulate(model, params, Inputs.from_recording(rec), rec.rig(),
                    float(rec.pressure_Pa[0]), solver)
    p = traj.pressure_Pa[0]
    if not np.all(np.isfinite(p)):
        raise PneubayesError(f"--model {args.model} on {rec.source}: the simulated pressure "
                             "is not finite; nothing written")
    write_text_atomic(out, "time_s,pressure_Pa\n" + "".join(
        f"{t:.9g},{v:.6f}\n" for t, v in zip(rec.time_s, p)))
    rmse = float(np.sqrt(np.mean((p - rec.pressure_Pa) ** 2)))
    lo, hi = np.percentile(rec.pressure_Pa, [1, 99])
    print(f"{out}: {p.size} samples; open-loop RMSE against the measured pressure "
          f"{rmse:.0f} Pa ({100 * rmse / max(hi - lo, 1e-9):.2f} % of the measured span)")
    return 0
