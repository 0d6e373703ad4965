"""Where a posterior's chain is kept: an emcee backend that resumes only its own posterior.

A chain file (HDF5, emcee's ``HDFBackend``, group ``pneubayes``) carries two attributes
besides emcee's own: ``pneubayes_fingerprint`` (:func:`posterior_fingerprint`, written
when the chain starts) and ``pneubayes_burn`` (where production started; re-adaptation
moves it). A stored chain is resumed only if its fingerprint equals the run's; a chain
of another posterior is an error and the file is left untouched.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np

from pneubayes.inference.likelihood import N_NOISE_SUMMARY
from pneubayes.inference.windows import WindowSet
from pneubayes.model import Model
from pneubayes.simulation import rig_constants

#: Version of what a stored chain holds (parameters, noise-summary blobs); part of the
#: posterior fingerprint, so a chain written by an incompatible version is not resumed.
CHAIN_FORMAT = "pneubayes-chain/2"
GROUP = "pneubayes"


def posterior_fingerprint(model: Model, data: WindowSet) -> str:
    """A digest of what defines the posterior a chain samples: the model (effects,
    options, parameter names and prior bounds), the data (every block's inputs, rig --
    its declared pressure filter included --, windows and measured pressures) and the
    chain format. Two runs with equal digests sample the same posterior, so one may
    resume the other's chain."""
    h = hashlib.sha256()
    lo, hi = model.bounds
    filters = [None if b.rig.pressure_filter is None else b.rig.pressure_filter.to_dict()
               for b in data.blocks]
    if any(f is not None for f in filters):  # (digests without a filter stay as they were)
        h.update(json.dumps({"pressure_filters": filters}, sort_keys=True).encode())
    h.update(json.dumps({"format": CHAIN_FORMAT, "noise_summary": N_NOISE_SUMMARY,
                         "effects": list(model.effect_names),
                         "options": {e.name: e.options() for e in model.effects},
                         "parameters": list(model.parameter_names),
                         "lower": lo.tolist(), "upper": hi.tolist(),
                         "horizon_s": data.horizon_s, "stride_s": data.stride_s,
                         "length": data.length}, sort_keys=True, default=str).encode())
    for b in data.blocks:
        for a in (b.inputs.time_s, b.inputs.command_V, b.inputs.position_m,
                  b.inputs.supply_pressure_Pa, rig_constants(b.rig), b.starts, b.measured,
                  b.warmup_starts, b.warmup_p0):
            h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()[:24]


def open_chain(path, model: Model, data: WindowSet, n_walkers: int, ndim: int):
    """``(backend, resumed)``: the emcee backend of a run, and whether it holds a chain
    of this posterior to continue.

    ``path`` None keeps the chain in memory. Otherwise an HDF5 file there with steps
    is resumed if its fingerprint and shape (walkers x dimensions) match; if they do
    not, ``ValueError`` naming the file (the file is not touched). A new or empty file
    is reset and stamped with the fingerprint.
    """
    import emcee

    if path is None:
        backend = emcee.backends.Backend()
        backend.reset(n_walkers, ndim)
        return backend, False
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    backend = emcee.backends.HDFBackend(str(path), name=GROUP)
    key = posterior_fingerprint(model, data)
    if path.exists():
        try:
            steps = backend.iteration
        except OSError as exc:  # not HDF5, or truncated: never reset over it
            raise ValueError(f"{path}: the chain file cannot be read ({exc}); it is left "
                             "untouched. Remove it to start the chain again, or give another "
                             "output folder") from None
        except (KeyError, AttributeError):  # a file without a chain yet
            steps = 0
        if steps > 0:
            stored = stored_attr(backend, "pneubayes_fingerprint")
            if stored != key or backend.shape != (n_walkers, ndim):
                raise ValueError(
                    f"{path}: this chain samples another posterior (its model, data, "
                    "walkers or pneubayes chain format differ: fingerprint "
                    f"{stored!r}, this run {key!r}); it is left untouched. Remove it, or "
                    "give another output folder")
            return backend, True
    backend.reset(n_walkers, ndim)
    with backend.open("a") as f:
        f[backend.name].attrs["pneubayes_fingerprint"] = key
    return backend, False


def set_aside_other_chain(path, model: Model, data: WindowSet) -> Path | None:
    """Move a chain of another posterior at ``path`` to ``<stem>.<its fingerprint>.h5``
    beside it, so a run that owns ``path`` (the discovery loop's run folder, whose
    final model changes when the loop's answer changes) can start its own chain there
    without losing the old one. Returns where the old chain went, or None when ``path``
    holds no chain or a chain of this posterior. An unreadable file is left alone (the
    sampler then reports it)."""
    import emcee

    path = Path(path)
    if not path.exists():
        return None
    try:
        backend = emcee.backends.HDFBackend(str(path), name=GROUP, read_only=True)
        steps = backend.iteration
    except (OSError, KeyError, AttributeError):
        return None
    stored = stored_attr(backend, "pneubayes_fingerprint")
    if steps == 0 or stored == posterior_fingerprint(model, data):
        return None
    target = path.with_name(f"{path.stem}.{stored or 'unstamped'}{path.suffix}")
    path.replace(target)
    return target


def read_chain(path):
    """A stored chain, read only: the emcee backend of ``path`` (``get_chain``,
    ``get_log_prob``; the chain is in the sampler's coordinates)."""
    import emcee

    return emcee.backends.HDFBackend(str(path), name=GROUP, read_only=True)


def stored_attr(backend, name: str):
    """A string attribute of the chain's group, or None."""
    try:
        with backend.open() as f:
            value = f[backend.name].attrs.get(name)
    except (OSError, KeyError):
        return None
    return value.decode() if isinstance(value, bytes) else (
        None if value is None else str(value))


def stored_burn(backend, default: int) -> int:
    """Where production started (re-adaptations move it), as stored with the chain."""
    try:
        with backend.open() as f:
            return int(f[backend.name].attrs.get("pneubayes_burn", default))
    except (AttributeError, OSError, KeyError):
        return int(getattr(backend, "pneubayes_burn", default))


def store_burn(backend, burn: int) -> None:
    """Record where production starts."""
    try:
        with backend.open("a") as f:
            f[backend.name].attrs["pneubayes_burn"] = int(burn)
    except AttributeError:  # the in-memory backend
        backend.pneubayes_burn = int(burn)
