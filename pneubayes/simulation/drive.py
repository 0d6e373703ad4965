"""The drive signals of a simulation on a recording's sample grid (:class:`Inputs`), and
the arrays as the compiled kernel's one signature takes them."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np


@dataclass(frozen=True)
class Inputs:
    """Drive signals on the sample grid (the recording's time base).

    Parameters
    ----------
    time_s : (N,) strictly increasing sample times, s
    command_V : (N,) valve command, V, held between samples (zero-order hold)
    position_m : (N,) piston position, m, linear between samples
    supply_pressure_Pa : (N,) measured absolute supply, Pa, linear between samples
    command_before_start : float or None
        The command held before the first sample (a triggered recording's pre-trigger
        command, in the command's unit), which a delayed or lagging valve still sees
        after the recording starts; None: the first sample's command, held since long
        before the start.
    exhaust_command : (N,) or None
        A separately commanded exhaust valve's command (in its own unit, held between
        samples; the recording's ``exhaust_command`` column); None when the exhaust is a
        port of the one valve.
    reading_Pa : (N,) or None
        The recorded pressure reading, Pa; read only for what a window inherits from
        before its start: a lagged reading's warm-up (effect ``sensor_lag``: from the
        reading 5 settling times before the window's start), the reading's relaxations
        and plays, a volume play's walls. None: unknown (they start at rest at the
        window's own initial pressure).
    """

    time_s: np.ndarray
    command_V: np.ndarray
    position_m: np.ndarray
    supply_pressure_Pa: np.ndarray
    command_before_start: float | None = None
    exhaust_command: np.ndarray | None = None
    reading_Pa: np.ndarray | None = None

    def __post_init__(self):
        before = self.command_before_start
        if before is not None and not (isinstance(before, (int, float))
                                       and not isinstance(before, bool)
                                       and np.isfinite(before)):
            raise ValueError(f"Inputs.command_before_start must be a finite number or None, "
                             f"got {before!r}")
        names = ("time_s", "command_V", "position_m", "supply_pressure_Pa")
        if self.exhaust_command is not None:
            names += ("exhaust_command",)
        if self.reading_Pa is not None:
            names += ("reading_Pa",)
        arrs = {k: np.ascontiguousarray(getattr(self, k), dtype=np.float64) for k in names}
        n = arrs["time_s"].shape
        for k, a in arrs.items():
            if a.ndim != 1 or a.shape != n:
                raise ValueError(f"Inputs.{k} has shape {a.shape}; all inputs must be 1-D of "
                                 f"the same length as time_s {n}")
            if k != "reading_Pa" and not np.all(np.isfinite(a)):  # (a gap: NaN)
                raise ValueError(f"Inputs.{k} contains NaN or infinite values")
            object.__setattr__(self, k, a)
        if n[0] < 2:
            raise ValueError("Inputs: need at least 2 samples")
        if np.any(np.diff(arrs["time_s"]) <= 0):
            raise ValueError("Inputs.time_s must be strictly increasing")

    @property
    def n_samples(self) -> int:
        return self.time_s.shape[0]

    @classmethod
    def constant(cls, time_s, command_V, position_m: float, supply_pressure_Pa: float):
        """Inputs with a fixed position and a constant supply."""
        t = np.asarray(time_s, dtype=np.float64)
        return cls(t, np.broadcast_to(np.asarray(command_V, np.float64), t.shape).copy(),
                   np.full(t.shape, float(position_m)), np.full(t.shape, float(supply_pressure_Pa)))

    @classmethod
    def from_recording(cls, recording) -> "Inputs":
        """Inputs of a :class:`pneubayes.io.Recording` (nominal supply/fixed position if absent)."""
        return cls(recording.time_s, recording.command_V, recording.position_or_fixed(),
                   recording.supply_or_nominal(), recording.command_before_start,
                   recording.exhaust_command(), recording.pressure_Pa)

    def with_command(self, command_V) -> "Inputs":
        """The same inputs with another (e.g. delayed or filtered) valve command."""
        return Inputs(self.time_s, command_V, self.position_m, self.supply_pressure_Pa,
                      self.command_before_start, self.exhaust_command, self.reading_Pa)

    def kernel_arrays(self):
        """``(t, u, ue, x, ps, pm, offset)``: the drive arrays the compiled kernel reads
        (``ue`` the exhaust command, zeros without one; ``pm`` the recorded reading, NaN
        without one), with a declared pre-trigger command as one extra sample held from
        10 s before the start (``offset`` 1: window starts shift by one), else the
        arrays as they are (writeable copies of read-only ones, as a recording's are:
        :func:`kernel_ready_arrays`). Built on the first call and kept: the inputs are not
        to be modified after construction."""
        return self._kernel_ready

    @cached_property
    def _kernel_ready(self):
        t, u, x, ps = self.time_s, self.command_V, self.position_m, self.supply_pressure_Pa
        ue = self.exhaust_command if self.exhaust_command is not None else np.zeros_like(t)
        pm = self.reading_Pa if self.reading_Pa is not None else np.full(t.shape, np.nan)
        if self.command_before_start is None:
            return (*kernel_ready_arrays(t, u, ue, x, ps, pm), 0)
        return (np.concatenate(([t[0] - 10.0], t)),
                np.concatenate(([float(self.command_before_start)], u)),
                np.concatenate((ue[:1], ue)),
                np.concatenate((x[:1], x)), np.concatenate((ps[:1], ps)),
                np.concatenate(([np.nan], pm)), 1)



def kernel_ready_arrays(*arrays):
    """The arrays as the compiled kernel's one signature wants them: C-contiguous and
    writeable. numba compiles a separate copy of the kernel for every combination of
    read-only flags (a recording's arrays are read-only), tens of seconds each. (An
    array that already is one is passed as it is: ``np.require`` costs about 1 us a
    call even then.)"""
    return [a if a.flags.c_contiguous and a.flags.writeable
            else np.require(a, requirements=("C", "W")) for a in arrays]
