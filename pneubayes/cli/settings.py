"""The settings a fitting command runs with: the library's settings tree (FitSettings,
DiscoverySettings) from its defaults, the ``--settings`` file, the command's own options
and then every ``--set``, in that order (:mod:`pneubayes.settings_tree` applies each)."""

from __future__ import annotations

import dataclasses

from pneubayes.errors import PneubayesError
from pneubayes.settings_tree import SettingsError, override, read_table, table_of


def _settings_tree(default, path, assignments=()):
    """``default`` with the settings file ``path``'s table (None: none) and then the
    ``--set`` assignments applied (:mod:`pneubayes.settings_tree`); errors name the file
    or the assignment and the key."""
    tree = default
    if path is not None:
        try:
            tree = override(tree, read_table(path))
        except SettingsError as exc:
            text = str(exc)
            raise PneubayesError(text if text.startswith(str(path)) else
                                 f"--settings {path}: {text}") from None
    if assignments:
        try:
            tree = override(tree, table_of(assignments))
        except SettingsError as exc:
            raise PneubayesError(f"--set {exc}") from None
    return tree


def _fit_flags(args, prefix: str = "") -> list:
    """The settings tree's keys that fit's or discover's own options set (those given),
    as ``(key path, value)`` pairs under ``prefix`` (``"fit."`` for discover)."""
    from pneubayes.simulation import SolverConfig

    out = []

    def put(key, value):
        out.append((tuple(f"{prefix}{key}".split(".")), value))
    if getattr(args, "horizon", None) is not None:
        put("horizon_s", args.horizon)
        if getattr(args, "stride", None) is None:
            put("stride_s", args.horizon)
    if getattr(args, "stride", None) is not None:
        put("stride_s", args.stride)
    for opt, key in (("position_cutoff", "position_cutoff_Hz"),
                     ("supply_cutoff", "supply_cutoff_Hz")):
        v = getattr(args, opt, None)
        if v is not None:
            put(key, v or None)  # 0: raw
    if getattr(args, "walkers", None) is not None:
        put("sampler.n_walkers", args.walkers)
    if getattr(args, "max_steps", None) is not None:
        put("sampler.max_steps", args.max_steps)
    if args.seed is not None:
        put("sampler.seed", args.seed)
    if getattr(args, "jacobian_refresh", None) is not None:
        put("refine_jacobian_refresh", args.jacobian_refresh)
    if getattr(args, "pressure_filter", None) is not None:
        put("pressure_filter", args.pressure_filter)
    if getattr(args, "no_dense_output", False):
        put("sample_solver", SolverConfig.standard())
    return out


def _with_options(tree, pairs):
    """``tree`` with the options' values at their key paths, applied as a settings
    file's table is (:func:`pneubayes.settings_tree.override`; a settings object such as
    a PressureFilter as its table)."""
    return override(tree, table_of(
        (path, dataclasses.asdict(v) if dataclasses.is_dataclass(v) else v)
        for path, v in pairs))


def fit_settings(args):
    """fit's FitSettings: the defaults, the --settings file, then the options given."""
    from pneubayes.inference.pipeline import FitSettings

    return _with_options(_settings_tree(FitSettings(), args.settings), _fit_flags(args))


def discovery_settings(args):
    """discover's DiscoverySettings: the defaults, the --settings file, the options given,
    then every --set."""
    from pneubayes.discovery.settings import DiscoverySettings

    tree = _settings_tree(DiscoverySettings(), args.settings)
    pairs = _fit_flags(args, "fit.")
    if args.held_out:
        pairs.append((("data", "holdout_recordings"), len(args.held_out)))
    if args.posterior is not None:
        pairs.append((("posterior", "method"), args.posterior))
    if args.seed is not None:
        pairs.append((("seed",), args.seed))
    tree = _with_options(tree, pairs)
    tree = _settings_tree(tree, None, args.set)
    if args.held_out and tree.data.holdout_recordings != len(args.held_out):
        raise PneubayesError(f"--held-out: {len(args.held_out)} recordings, but "
                             f"data.holdout_recordings = {tree.data.holdout_recordings}")
    if not args.held_out and tree.data.holdout_recordings:
        raise SettingsError(f"data.holdout_recordings = {tree.data.holdout_recordings}: the "
                            "recordings held out whole are named with --held-out")
    return tree
