"""Per-unit quantities: one model for a rig of several actuators of one kind, each unit's
own chamber, tube or delay refitted on its own recordings.

A robot's or a hand's muscles share their valve type, supply and effects, but each has
its own volume, its own length of tube and its own valve's timing. A model fitted on
all of them shares those too, and each unit's recordings carry what the average misses.
:class:`UnitRefit` keeps the shared fit (the start) and refits the named quantities per
unit on that unit's recordings (:class:`~pneubayes.inference.refine.TrajectoryRefiner`
on the same windows), so a new recording of a known unit is predicted with its own
values. A unit is named by its recordings' metadata (``cylinder`` and ``valve``: one
chamber of one cylinder behind one valve, the recording format's own identity) or by a
caller's function. :meth:`UnitRefit.write_units` writes each unit's values as a run
folder of its own: a model card of its point estimate, which
:func:`~pneubayes.inference.fit_folder.read_fit` and ``Model.from_card`` read (no
posterior: ``pneubayes predict``, which draws from one, does not take it).
"""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import numpy as np

from pneubayes.inference.refine import TrajectoryRefiner
from pneubayes.inference.windows import WindowSet
from pneubayes.model import Model
from pneubayes.simulation.config import SolverConfig


def unit_name(recording) -> str:
    """A recording's unit: its metadata's ``cylinder / valve``."""
    return f"{recording.metadata.cylinder} / {recording.metadata.valve}"


class UnitRefit:
    """Refit named quantities of a shared fit per unit (scikit-learn estimator contract).

    Parameters
    ----------
    model : Model
    solver : SolverConfig
        Solver for the window predictions.
    names : sequence of str
        The unit quantities (model parameter names, e.g. ``dead_volume_m3``,
        ``tube_delay_s``); every other parameter stays at the shared fit's value.
    horizon_s, stride_s : float
        The prediction windows the refit and the scores use, s.
    unit : callable or None
        ``unit(recording) -> str``; None: :func:`unit_name`.
    max_nfev : int
        Each unit's budget of residual evaluations.

    Attributes
    ----------
    shared_ : dict
        The start (after ``fit``, as every attribute below).
    units_ : dict
        Unit name -> full parameter dict.
    sd_ : dict
        Unit name -> the Laplace SDs of ``names`` (natural units; NaN where the
        recordings do not inform one).
    rmse_Pa_, recordings_ : dict
        Unit name -> its training windows' RMSE (Pa); how many recordings it has.
    """

    def __init__(self, model: Model, solver: SolverConfig, names: Sequence[str],
                 horizon_s: float, stride_s: float, unit: Callable | None = None,
                 max_nfev: int = 60):
        self.model = model
        self.solver = solver
        self.names = names
        self.horizon_s = horizon_s
        self.stride_s = stride_s
        self.unit = unit
        self.max_nfev = max_nfev

    def _unit_of(self, recording) -> str:
        return (self.unit or unit_name)(recording)

    def fit(self, recordings, start: dict) -> "UnitRefit":
        """Refit ``names`` per unit of ``recordings`` from ``start`` (a full parameter
        dict: the shared fit)."""
        names = list(self.names)
        unknown = [n for n in names if n not in self.model.parameter_names]
        if not names:
            raise ValueError("names: none given (the unit quantities to refit)")
        if unknown:
            raise ValueError(f"names: {unknown} are not parameters of {self.model}")
        missing = [n for n in self.model.parameter_names if n not in start]
        if missing:
            raise ValueError(f"start: no value for {missing}")
        groups: dict[str, list] = {}
        for rec in recordings:
            groups.setdefault(self._unit_of(rec), []).append(rec)
        if not groups:
            raise ValueError("recordings: none given")
        self.shared_ = dict(start)
        self.units_, self.sd_, self.rmse_Pa_, self.recordings_ = {}, {}, {}, {}
        for name, recs in groups.items():
            ref = TrajectoryRefiner(self.model, self.solver, self.horizon_s, self.stride_s,
                                    free=names, max_nfev=self.max_nfev).fit(recs, start)
            cov = ref.covariance_
            sd = np.sqrt(np.clip(np.diag(cov), 0.0, None)) if cov is not None \
                else np.full(len(names), np.nan)
            self.units_[name] = dict(ref.params_)
            self.sd_[name] = {n: float(s) for n, s in zip(names, sd)}
            self.rmse_Pa_[name] = float(ref.rmse_Pa_)
            self.recordings_[name] = len(recs)
        return self

    def params_for(self, recording) -> dict:
        """The parameters that predict ``recording``: its unit's."""
        name = self._unit_of(recording)
        if name not in self.units_:
            raise ValueError(f"{recording.source}: unit {name!r} was not fitted (units: "
                             f"{sorted(self.units_)})")
        return self.units_[name]

    def residuals(self, recordings) -> np.ndarray:
        """Window prediction minus measurement of each recording with its unit's
        parameters, the window starts dropped, concatenated (Pa)."""
        out = [WindowSet([rec], self.horizon_s, self.stride_s).residuals(
            self.model, self.params_for(rec), self.solver).reshape(-1)
            for rec in recordings]
        return np.concatenate(out) if out else np.empty(0)

    def write_units(self, folder, extra: Mapping | None = None) -> dict[str, Path]:
        """Write each unit's parameters as a run folder ``folder/<unit>/model.json`` (the
        unit's name with every run of characters other than letters, digits, ``.``,
        ``_`` and ``-`` as ``_``), ``extra`` laid over each card (e.g. the shared fit's
        ``Fit.card_extra()``: how its recordings were prepared) and the card's ``unit``
        entry saying which unit, which quantities were refitted, their SDs and the
        unit's training RMSE. Returns unit name -> folder."""
        folders: dict[str, Path] = {}
        for name in self.units_:
            slug = re.sub(r"[^A-Za-z0-9._-]+", "_", name).strip("_") or "unit"
            path = Path(folder) / slug
            if path in folders.values():
                raise ValueError(f"units {name!r} and "
                                 f"{next(n for n, p in folders.items() if p == path)!r} "
                                 f"write the same folder {path}; name the units apart "
                                 "(UnitRefit's unit=)")
            folders[name] = path
        for name, path in folders.items():
            path.mkdir(parents=True, exist_ok=True)
            self.model.save_card(self.units_[name], path / "model.json", extra={
                **(dict(extra) if extra else {}),
                "unit": {"name": name, "quantities": list(self.names), "sd": self.sd_[name],
                         "train_rmse_Pa": self.rmse_Pa_[name],
                         "train_recordings": self.recordings_[name]}})
        return folders
