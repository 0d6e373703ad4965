"""Import the GTDynamics jumping-robot system-identification trials.

Source: ``borglab/GTDynamics`` at commit ``2dd29bf3``,
``examples/example_jumping_robot/system-id-data/`` (BSD-2-Clause, Georgia Tech), as laid
out in ``realdata/gtdynamics-jumping-robot/trials/<trial>/``. Per trial and muscle
(knee_right, hip_right, hip_left, knee_left) one format-2 recording:

- ``time_s``: the raw file's time (s; the valves' recorded open time is the origin);
- ``pressure_psi_gauge``: the raw (unfiltered) muscle channel, psi gauge, made absolute
  by the reader with the stated atmosphere;
- ``supply_pressure_psi_gauge``: the raw source-tank channel (the tank drains during the
  fill; it is measured, so the rig card's supply is ``measured``);
- ``command_V``: the muscle's valve, 1 between its recorded open and close times, else
  0 (binary; the rig card declares it), with ``command_before_start`` 0; a time of
  ``inf`` in ``t_valve.csv`` is a valve that does not open (or close) within the record
  (null in the sidecar's ``valve_open_s`` / ``valve_close_s``); muscles may open and
  close at different times;
- ``cam_travel_m`` (an extra column the model does not read; where the trial folder
  has its video's ``angle_pre_rad.csv`` and ``vid_time_s.txt``): the cam's travel (m)
  from the video's joint angles, the cam's constant radius 0.045 m (``robot_config``:
  ``rad0``, ``slope`` 0) times the cam angle's change since frame 0, which grows as
  the knees flex (their cam angle is 180 deg less the joint angle) and the hips extend
  (90 deg plus it). The authors' pre-processed angles (250 fps, frame 0 at the
  pressure record's origin) are smoothed by a centred Savitzky-Golay filter (7 frames,
  quadratic; their frame-to-frame noise is 2-5 mrad, 0.1-0.2 mm of travel) and
  interpolated linearly onto the pressure's times. It is not the muscle's contraction
  as measured: the tendon in series (8200 N/m) stretches under the muscle's force, and
  the muscle's volume as the authors' cubic of this travel predicted the held-out fills
  worse than a fixed volume (docs/history.md, 2026-12-03);
- rows up to ``end_s`` only: the muscles are vented at about 0.33-0.40 s by something
  the recorded command does not contain (the data's README).

The atmosphere is not recorded: 101325 Pa, as the data authors' own model uses. The
temperature is the authors' configured 296.15 K. Marker pixels and poses are not
converted.
"""

from __future__ import annotations

import csv
import hashlib
import json
import math
from pathlib import Path

import numpy as np

from pneubayes.atomic import write_json_atomic
from pneubayes.io.recording_format import FORMAT_2

JOINTS = ("knee_right", "hip_right", "hip_left", "knee_left")
SOURCE = {"repository": "https://github.com/borglab/GTDynamics",
          "commit": "2dd29bf31606357bbd9dd67f0caf224a8573be93",
          "path": "examples/example_jumping_robot/system-id-data/",
          "licence": "BSD-2-Clause (Copyright (c) 2020 Georgia Tech Research Corporation)"}
ATMOSPHERE_PA = 101325.0
TEMPERATURE_K = 296.15   # robot_config*.yaml 'T'
TUBE_LENGTH_M = 74 * 0.0254      # robot_config 'l_tube_valve_musc' (in)
TUBE_DIAMETER_M = 0.1575 * 0.0254  # robot_config 'd_tube_valve_musc' (in)
VALVE_TIME_CONSTANT_S = 1e-3     # robot_config 'time_constant_valve'
CAM_RADIUS_M = 0.045             # robot_config 'rad0' (knee and hip), 'slope' 0
#: d(cam angle)/d(joint angle) per joint (robot_config 'theta_range': the knee's cam
#: angle runs 0-180 deg as its joint angle runs 180-0, the hip's as it runs -90-90)
CAM_SIGN = {"knee_right": -1.0, "hip_right": 1.0, "hip_left": 1.0, "knee_left": -1.0}
#: Savitzky-Golay smoothing of the video angles: frames (odd) and polynomial order
ANGLE_SMOOTHING = (7, 2)
RIG_CARD_NAME = "gtdynamics-muscle.rig.json"


def rig_card() -> dict:
    """The muscles' rig card: what the data authors documented, priors for the rest."""
    tube_volume = math.pi / 4 * TUBE_DIAMETER_M ** 2 * TUBE_LENGTH_M
    return {
        "format": "pneubayes-rig/1",
        "name": "GTDynamics jumping-robot McKibben muscle",
        "atmospheric_pressure_Pa": ATMOSPHERE_PA,
        "temperature_K": TEMPERATURE_K,
        "command": {"unit": "binary"},
        "chamber": {"kind": "fixed",
                    "volume_m3": {"prior": "log-uniform", "bounds": [1e-5, 5e-4]}},
        "valve": {"kind": "switching",
                  "open_area_m2": {"prior": "log-uniform", "bounds": [1e-7, 1e-4]},
                  "exhaust_area_m2": 0.0, "opening_delay_s": 0.0,
                  "opening_time_constant_s": VALVE_TIME_CONSTANT_S},
        "supply": {"kind": "measured"},
        "tube": {"length_m": TUBE_LENGTH_M, "inner_diameter_m": TUBE_DIAMETER_M},
        "notes": (
            "Valve: on/off, brand undocumented; time constant 1 ms and no opening delay "
            "as the authors' robot_config.yaml states. Chamber: the muscle volume at "
            f"rest is 4.24e-5 m^3 plus the tube's {tube_volume:.3g} m^3 in the authors' "
            "model and grows with contraction during the jump; the recordings carry "
            "the cam's travel from the video (cam_travel_m), but the authors' volume "
            "cubic of it predicted worse than a fixed volume, so the volume is a fixed "
            "unknown here (its change is misfit). "
            "Supply: the source tank's measured pressure. Atmosphere not recorded "
            "(101325 Pa assumed, as the authors' model)."),
    }


def _read_matrix(path: Path, ncols: int) -> np.ndarray:
    from pneubayes.limits import check_input_file

    check_input_file(path)
    rows = []
    with path.open(newline="") as fh:
        for i, row in enumerate(csv.reader(fh), start=1):
            if not row or row[0].lstrip().startswith("#"):
                continue
            try:
                vals = [float(c) for c in row if c.strip()]
            except ValueError:
                raise ValueError(f"{path} row {i}: not numbers: {row!r}") from None
            if len(vals) != ncols:
                raise ValueError(f"{path} row {i}: expected {ncols} values, got {len(vals)}")
            rows.append(vals)
    if not rows:
        raise ValueError(f"{path}: no data rows")
    return np.array(rows)


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def cam_travel_m(time_s, video_time_s, angles_rad, joint: str) -> np.ndarray:
    """A muscle's cam travel (m) at ``time_s`` (s, the pressure record's times) from its
    joint's video angles ``angles_rad`` (rad) at ``video_time_s`` (s, frame 0 at 0): the
    cam radius times the cam angle's change since frame 0, the angles smoothed by
    :data:`ANGLE_SMOOTHING` first, linear between frames and held beyond the last."""
    from scipy.signal import savgol_filter

    frames, order = ANGLE_SMOOTHING
    a = np.asarray(angles_rad, dtype=np.float64)
    smooth = savgol_filter(a, frames, order) if a.size >= frames else a
    travel = CAM_RADIUS_M * CAM_SIGN[joint] * (smooth - smooth[0])
    return np.interp(time_s, video_time_s, travel)


def import_trial(trial_dir, out_dir, end_s: float = 0.33) -> list[Path]:
    """Write the four muscles' recordings of one trial under ``out_dir/<trial>/``;
    returns the written CSV paths. The rig card is written by :func:`import_gtdynamics`."""
    trial = Path(trial_dir)
    raw_path, valve_path = trial / "pressure_raw_psi.csv", trial / "t_valve.csv"
    for p in (raw_path, valve_path):
        if not p.is_file():
            raise ValueError(f"{trial}: not a GTDynamics trial folder (no {p.name})")
    raw = _read_matrix(raw_path, 6)
    valve = _read_matrix(valve_path, 4)
    # the video (optional: without it the recordings carry no cam travel)
    angle_path, video_path = trial / "angle_pre_rad.csv", trial / "vid_time_s.txt"
    video = angle_path.is_file() or video_path.is_file()
    if video:
        for p in (angle_path, video_path):
            if not p.is_file():
                raise ValueError(f"{trial}: {p.name} is missing beside the video's other "
                                 "file (the cam travel needs both)")
        angles = _read_matrix(angle_path, 4)
        video_t = _read_matrix(video_path, 1)[:, 0]
        if video_t.size != angles.shape[0]:
            raise ValueError(f"{video_path}: {video_t.size} frame times for "
                             f"{angles.shape[0]} rows of {angle_path.name}")
        video_t = video_t - video_t[0]
        if not np.all(np.diff(video_t) > 0):
            raise ValueError(f"{video_path}: frame times must increase")
    if valve.shape[0] != 2:
        raise ValueError(f"{valve_path}: expected 2 rows (open, close times), got "
                         f"{valve.shape[0]}")
    for j, joint in enumerate(JOINTS):
        t_open, t_close = float(valve[0, j]), float(valve[1, j])
        if np.isnan(t_open) or np.isnan(t_close) or t_open == -np.inf:
            raise ValueError(f"{valve_path}: {joint}'s open and close times must be numbers "
                             f"or inf (never), got {t_open!r}, {t_close!r}")
        if t_close < t_open:
            raise ValueError(f"{valve_path}: {joint} closes at {t_close!r} s, before it "
                             f"opens at {t_open!r} s")
    keep = raw[:, 0] <= end_s
    if keep.sum() < 20:
        raise ValueError(f"{raw_path}: fewer than 20 samples before end_s = {end_s} s")
    raw = raw[keep]
    t = raw[:, 0]
    out = Path(out_dir) / trial.name
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for j, joint in enumerate(JOINTS):
        t_open, t_close = valve[0, j], valve[1, j]
        # held command: the sample at t is open when the valve was open at t
        cmd = ((t >= t_open) & (t < t_close)).astype(float)
        stem = out / joint
        head = "time_s,command_V,pressure_psi_gauge,supply_pressure_psi_gauge"
        rows = [f"{a!r},{c:g},{p!r},{s!r}"
                for a, c, p, s in zip(t.tolist(), cmd, raw[:, 1 + 1 + j].tolist(),
                                      raw[:, 1].tolist())]
        if video:
            head += ",cam_travel_m"
            travel = cam_travel_m(t, video_t, angles[:, j], joint)
            rows = [f"{row},{x:.6e}" for row, x in zip(rows, travel.tolist())]
        lines = [head] + rows
        sidecar = {
            "format": FORMAT_2, "rig": f"../{RIG_CARD_NAME}",
            "cylinder": f"GTDynamics {joint} muscle", "valve": f"{joint} on/off valve",
            "atmospheric_pressure_Pa": ATMOSPHERE_PA, "temperature_K": TEMPERATURE_K,
            "supply_pressure_psi_gauge": float(raw[0, 1]),
            "command_before_start": 0.0,
            "import": {
                **SOURCE, "trial": trial.name, "channel": joint,
                "files": {f.name: _sha256(f) for f in (raw_path, valve_path)
                          + ((angle_path, video_path) if video else ())},
                # (inf in t_valve, a valve not opened or not closed within the
                # record, is written null: write_json_atomic's json_safe)
                "valve_open_s": t_open, "valve_close_s": t_close,
                "rows": f"t <= {end_s} s of {int(keep.size)} (venting after it is not "
                        "in the recorded command)",
                "conversion": "raw psi gauge columns kept in psi gauge (format 2); the "
                              "reader adds the stated atmosphere; nominal supply = the "
                              "source's first reading" + (
                                  "; cam_travel_m = the cam's travel "
                                  f"({CAM_RADIUS_M} m x the cam angle's change from frame "
                                  f"0, angles Savitzky-Golay {ANGLE_SMOOTHING})"
                                  if video else ""),
            },
        }
        tmp = stem.with_suffix(".csv.tmp")
        tmp.write_text("\n".join(lines) + "\n")
        tmp.replace(stem.with_suffix(".csv"))
        write_json_atomic(stem.with_suffix(".json"), sidecar)
        written.append(stem.with_suffix(".csv"))
    return written


def import_gtdynamics(trial_dirs, out_dir, end_s: float = 0.33) -> list[Path]:
    """Import trial folders into ``out_dir`` (one sub-folder per trial) and write the
    shared rig card ``out_dir/gtdynamics-muscle.rig.json``; returns the CSV paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for d in trial_dirs:
        written += import_trial(d, out, end_s)
    write_json_atomic(out / RIG_CARD_NAME, rig_card())
    (out / "import.json").write_text(json.dumps(
        {"importer": "gtdynamics", **SOURCE, "trials": [Path(d).name for d in trial_dirs],
         "end_s": end_s}, indent=2) + "\n")
    return written
