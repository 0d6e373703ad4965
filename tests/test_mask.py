"""The mask of invalid stretches (a recording's ``valid`` column)."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from conftest import chamber_recording

from pneubayes.discovery.one_step import one_step_data
from pneubayes.errors import RecordingError
from pneubayes.inference.windows import WindowSet
from pneubayes.io import read_recording, write_recording


def _masked(rec, invalid):
    v = np.ones(rec.n_samples)
    v[invalid] = 0
    return replace(rec, extra_columns={"valid": v})


def test_windows_touching_an_invalid_sample_are_left_out():
    rec = chamber_recording(duration_s=2.0)  # 1 kHz: 0.2-s windows of 201 samples
    full = WindowSet([rec], 0.2, 0.2)
    assert full.n_windows == 10
    masked = WindowSet([_masked(rec, slice(450, 460))], 0.2, 0.2)
    # samples 450-459 lie in the window starting at 400 only
    assert list(masked.blocks[0].starts) == [s for s in full.blocks[0].starts if s != 400]
    # a window ending exactly on an invalid sample is out too (its last sample)
    edge = WindowSet([_masked(rec, [600])], 0.2, 0.2)
    assert 400 not in edge.blocks[0].starts and 600 not in edge.blocks[0].starts
    with pytest.raises(ValueError, match="no window lies within"):
        WindowSet([_masked(rec, slice(None))], 0.2, 0.2)


def test_one_step_rows_touching_an_invalid_sample_are_left_out():
    rec = _masked(chamber_recording(duration_s=0.1), [17])
    rows = one_step_data(rec, 5).valid_rows()
    # row r spans samples 5 r .. 5 r + 5: sample 17 is in row 3 only
    assert rows.size == 20 and list(np.nonzero(~rows)[0]) == [3]
    edge = one_step_data(_masked(chamber_recording(duration_s=0.1), [15]), 5).valid_rows()
    assert list(np.nonzero(~edge)[0]) == [2, 3]  # a block boundary sample: both rows


def test_the_valid_column_round_trips_and_is_checked(tmp_path):
    rec = _masked(chamber_recording(duration_s=0.2), slice(50, 60))
    write_recording(rec, tmp_path / "r")
    back = read_recording(tmp_path / "r.csv")
    np.testing.assert_array_equal(back.valid_mask(), rec.valid_mask())
    text = (tmp_path / "r.csv").read_text().splitlines()
    header = text[0].split(",")
    j = header.index("valid")
    row = text[5].split(",")
    row[j] = "2"
    text[5] = ",".join(row)
    (tmp_path / "r.csv").write_text("\n".join(text) + "\n")
    with pytest.raises(RecordingError, match=r"row 6 column 'valid'.*1 \(valid\) or 0"):
        read_recording(tmp_path / "r.csv")
    json.loads((tmp_path / "r.json").read_text())  # the sidecar untouched by the check


def test_a_masked_glitch_does_not_reach_the_residuals():
    """A wild stretch (a sensor glitch) masked out leaves the scored windows those of the
    clean recording: the mask removes data, it never edits it."""
    from pneubayes.model import Model
    from pneubayes.physics.valve import valve_preset
    from pneubayes.simulation import SolverConfig

    rec = chamber_recording(duration_s=1.0)
    p = rec.pressure_Pa.copy()
    p[520:530] += 3e5
    glitched = replace(rec, pressure_Pa=p)
    clean_ws = WindowSet([rec], 0.1, 0.1)
    masked_ws = WindowSet([_masked(glitched, slice(520, 530))], 0.1, 0.1)
    keep = [k for k, s in enumerate(clean_ws.blocks[0].starts)
            if s in set(masked_ws.blocks[0].starts)]
    assert len(keep) == clean_ws.n_windows - 1
    model = Model()
    params = {**valve_preset("valve1").parameters(), "dead_volume_m3": 2e-6}
    a = clean_ws.residuals(model, params, SolverConfig.standard())[:, keep]
    b = masked_ws.residuals(model, params, SolverConfig.standard())
    np.testing.assert_array_equal(a, b)
