"""The effect catalogue: each physical effect is one small object behind one interface.

Names are exactly the catalogue's: ``cylinder_leak``, ``tube_delay``, ``valve_deadzone``,
``supply_fluctuation``, ``supply_restriction`` (a restriction upstream of the valve's
inlet), ``critical_ratio`` (ports that choke at their own pressure ratio, ISO 6358's
``b``), ``heat_transfer``, ``spool_lag``, ``sensor_lag``,
``sensor_calibration``, ``sensor_drift``, ``sensor_nonlinearity``, ``valve_stiction``,
``closure`` (an open-form extra mass flow), ``reading_closure`` (open-form relaxations
of the reading), ``reading_play`` (open-form plays, backlash, of the reading),
``reading_command`` (open-form lags of the command's magnitude in the reading),
``reading_flow`` (open-form terms of the ports' mass flows in the reading),
``reading_hinge`` (open-form knees of the reading, read last),
``volume_closure`` (open-form hinges of the chamber's volume in its pressure),
``volume_play`` (open-form friction-held walls: plays and stops of the chamber's
volume), ``loaded_wall`` (an open-form wall with inertia: the chamber's volume as a
mass on a spring), ``port_restriction`` (an open-form restriction in series at the
chamber's port), ``command_clock`` (an open-form valve driver on its own clock) and
``valve_dead_time`` (a valve's dead time that depends on the supply pressure), the last
twelve, and ``supply_restriction``, never searched for by the discovery library.
"""

from __future__ import annotations

import inspect
import math
import numbers

from pneubayes.effects.base import Component, Effect, Eq10Fit, Parameter
from pneubayes.effects.closure import Closure
from pneubayes.effects.command_clock import CommandClock
from pneubayes.effects.critical_ratio import CriticalRatio
from pneubayes.effects.cylinder_leak import CylinderLeak
from pneubayes.effects.heat_transfer import HeatTransfer
from pneubayes.effects.loaded_wall import LoadedWall
from pneubayes.effects.port_restriction import PortRestriction
from pneubayes.effects.reading_closure import ReadingClosure
from pneubayes.effects.reading_command import ReadingCommand
from pneubayes.effects.reading_flow import ReadingFlow
from pneubayes.effects.reading_hinge import ReadingHinge
from pneubayes.effects.reading_play import ReadingPlay
from pneubayes.effects.sensor_calibration import SensorCalibration
from pneubayes.effects.sensor_drift import SensorDrift
from pneubayes.effects.sensor_lag import SensorLag
from pneubayes.effects.sensor_nonlinearity import SensorNonlinearity
from pneubayes.effects.spool_lag import SpoolLag
from pneubayes.effects.supply_fluctuation import SupplyFluctuation
from pneubayes.effects.supply_restriction import SupplyRestriction
from pneubayes.effects.thin_port import ThinPort
from pneubayes.effects.tube_delay import TubeDelay
from pneubayes.effects.valve_dead_time import ValveDeadTime
from pneubayes.effects.valve_deadzone import ValveDeadzone
from pneubayes.effects.valve_stiction import ValveStiction
from pneubayes.effects.volume_closure import VolumeClosure
from pneubayes.effects.volume_play import VolumePlay

CATALOGUE: dict[str, type[Effect]] = {
    cls.name: cls
    for cls in (CylinderLeak, TubeDelay, ValveDeadzone, SupplyFluctuation, HeatTransfer,
                SpoolLag, SensorLag, SensorCalibration, SensorDrift,
                SensorNonlinearity, ValveStiction, Closure, ReadingClosure, ReadingPlay,
                ReadingCommand, ReadingFlow, ReadingHinge, VolumeClosure, VolumePlay, LoadedWall,
                PortRestriction, CommandClock, ValveDeadTime, SupplyRestriction,
                CriticalRatio)
}


def make_effect(name: str, **options) -> Effect:
    """Build a catalogue effect by name, e.g. ``make_effect("cylinder_leak", form="laminar")``.

    Parameters
    ----------
    name : str
        A key of :data:`CATALOGUE`.
    **options
        Constructor arguments of the effect (e.g. ``form``), each of its default's kind.

    Returns
    -------
    Effect

    Raises
    ------
    ValueError
        An unknown name or option, or an option of the wrong kind.
    """
    try:
        cls = CATALOGUE[name]
    except KeyError:
        raise ValueError(f"unknown effect {name!r}; the catalogue has {sorted(CATALOGUE)}") \
            from None
    _check_options(cls, options)
    try:
        return cls(**options)
    except TypeError as exc:
        raise ValueError(f"effect {name!r}: bad options {options!r} ({exc})") from None


def effects_from_names(names, leak_form: str = "orifice") -> tuple[Effect, ...]:
    """Effect objects for catalogue names, e.g.
    ``Model(effects_from_names(["cylinder_leak", "tube_delay"]))``.

    Parameters
    ----------
    names : iterable of str
        Keys of :data:`CATALOGUE`, each effect in its default form.
    leak_form : str
        The form of ``cylinder_leak`` (default ``"orifice"``).

    Returns
    -------
    tuple of Effect
    """
    return tuple(make_effect(n, form=leak_form) if n == "cylinder_leak" else make_effect(n)
                 for n in names)


def catalogue_parameter_names() -> frozenset[str]:
    """Every parameter name of every catalogue effect, in every form (and the option
    sets an effect lists in its ``option_variants``)."""
    names = set()
    for cls in CATALOGUE.values():
        for options in ([{"form": f} for f in cls.forms] or [{}]) + list(cls.option_variants):
            names.update(cls(**options).parameter_names())
    return frozenset(names)


def _check_options(cls: type[Effect], options: dict) -> None:
    """Every option is a constructor argument, of the kind of its default (a string, an
    integer or a finite real number); raises ValueError naming the option."""
    params = inspect.signature(cls.__init__).parameters
    known = [k for k in params if k != "self"]
    for key, value in options.items():
        if key not in known:
            raise ValueError(f"effect {cls.name!r}: unknown option {key!r}; its options are "
                             f"{known}")
        default = params[key].default
        if isinstance(default, str):
            ok, kind = isinstance(value, str), "a string"
        elif isinstance(default, int) and not isinstance(default, bool):
            ok, kind = isinstance(value, int) and not isinstance(value, bool), "an integer"
        elif isinstance(default, float):
            ok = (isinstance(value, numbers.Real) and not isinstance(value, bool)
                  and math.isfinite(value))
            kind = "a finite number"
        else:
            continue
        if not ok:
            raise ValueError(f"effect {cls.name!r}: option {key!r} must be {kind}, got "
                             f"{value!r}")


__all__ = ["CATALOGUE", "Closure", "CommandClock", "Component", "CylinderLeak", "Effect",
           "Eq10Fit",
           "HeatTransfer", "Parameter", "ReadingClosure", "ReadingCommand", "ReadingFlow",
           "ReadingHinge", "ReadingPlay",
           "SensorCalibration",
           "SensorDrift", "SensorLag",
           "SensorNonlinearity", "SpoolLag",
           "SupplyFluctuation", "SupplyRestriction", "CriticalRatio", "ThinPort", "TubeDelay",
           "ValveDeadzone", "ValveStiction",
           "VolumeClosure", "VolumePlay", "LoadedWall", "PortRestriction",
           "catalogue_parameter_names",
           "make_effect"]
