"""Run the virtual bench: plant effects, simulate the truth finely, measure, write.

The truth is the thin-port model plus the planted effects (the same effect objects a
model fits), with rig-specific true values (:func:`truth_parameters`), simulated on a
fine grid with tight tolerances (:meth:`SolverConfig.reference`) and passed through the
:class:`SensorChain`. Recordings follow ``recording-format.md``; the truth goes to
``truth.json`` (a model card of the true model plus a ``bench`` section).

With ``BenchConfig.forms`` (realistic forms of effects, :mod:`pneubayes.bench.forms`)
the truth is simulated instead by the independent high-fidelity plant
(:func:`pneubayes.bench.plant.simulate_plant`), with the catalogue ``effects`` planted
beside the forms (each catalogue effect once: as an effect or as a form). The supply
column then records the supply at the valve inlet (a RegulatorDroop shows there). The
card's model is the catalogue part (effects and base; with an AcousticTube its
``dead_volume_m3`` includes the tube's volume, as the format defines it, unless
overridden, when the override is the total); ``bench.planted_forms`` records the forms
and ``bench.planted_effects`` names the catalogue effects of both; out-of-catalogue
forms (no catalogue effect) are listed in ``bench.out_of_catalogue_forms``.
"""

from __future__ import annotations

import errno
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

import pneubayes
from pneubayes.atomic import write_json_atomic
from pneubayes.bench.forms import (
    AcousticTube,
    CapillarySensorPort,
    InletJetAtSensor,
    LaggingPositionSensor,
    PlantForm,
    SaturatingSensor,
    SensorBow,
    SensorHysteresis,
    SensorThermalShock,
    SensorZeroDrift,
    SkewedPressureChannel,
    SolenoidGroundShift,
    catalogue_names_of,
    check_forms,
)
from pneubayes.bench.plant import PlantConfig, simulate_plant
from pneubayes.bench.protocols import piston_motion, step_commands
from pneubayes.bench.sensors import SensorChain
from pneubayes.effects import CATALOGUE, Effect, effects_from_names  # noqa: F401 (re-exported)
from pneubayes.effects.path import SLOT_INDEX
from pneubayes.io.recording import Recording, RecordingMetadata, write_recording
from pneubayes.model import Model
from pneubayes.physics.calibration import reading_zero_Pa, sensor_reading_Pa
from pneubayes.physics.cylinder import cylinder_preset
from pneubayes.physics.gas import GasConstants
from pneubayes.physics.valve import valve_preset
from pneubayes.rig import Rig
from pneubayes.simulation import Inputs, SolverConfig, simulate

ATMOSPHERE_PA = 101_325.0
#: About 5.5 bar absolute (NOTES.md): a 450 kPa working range, as Table III implies.
SUPPLY_PA = ATMOSPHERE_PA + 450_000.0
TEMPERATURE_K = 293.15

#: Rig-specific truth: dead volume (valve port, fittings and end cap; the tube of the
#: tube_delay effect comes on top) and the scale of the leak relative to the AIRPEL's
#: (paper: AIRPEL anti-stiction cylinders leak, SMC and PRN hardly).
CYLINDER_TRUTH: dict[str, dict[str, float]] = {
    "AIR37": {"dead_volume_m3": 1.5e-7, "leak_scale": 1.0},
    "AIR200": {"dead_volume_m3": 1.5e-7, "leak_scale": 1.0},
    "SMC": {"dead_volume_m3": 2.0e-6, "leak_scale": 0.05},
    "PRN": {"dead_volume_m3": 5.0e-7, "leak_scale": 0.05},
}

PROTOCOLS = ("fixed", "moving")


def truth_parameters(model: Model, cylinder: str, valve: str, rig: Rig,
                     overrides: Mapping[str, float] | None = None) -> dict[str, float]:
    """Realistic true parameter values for a rig: Table II valve, rig dead volume,
    each effect's bench defaults (the leak scaled per cylinder), then ``overrides``.

    A planted tube adds its volume to the dead volume (the format's dead volume
    includes the tube), unless ``dead_volume_m3`` is overridden."""
    values = dict(valve_preset(valve).parameters())
    rig_truth = CYLINDER_TRUTH.get(cylinder, {"dead_volume_m3": 5e-7, "leak_scale": 1.0})
    values["dead_volume_m3"] = rig_truth["dead_volume_m3"]
    for e in model.effects:
        d = e.bench_defaults()
        if e.name == "cylinder_leak":
            d = {k: v * rig_truth["leak_scale"] for k, v in d.items()}
        values.update(d)
    for k, v in (overrides or {}).items():
        if k not in model.parameter_names:
            raise ValueError(f"--set {k}: not a parameter of the bench model "
                             f"{list(model.parameter_names)}")
        values[k] = float(v)
    if model.has("tube_delay") and "dead_volume_m3" not in (overrides or {}):
        values["dead_volume_m3"] += float(
            model.effect("tube_delay").tube_volume_m3(values, rig))
    model.check_bounds(model.vector(values))
    return values


@dataclass(frozen=True)
class BenchConfig:
    """One bench session: rig, planted effects, protocol and sensors.

    ``ranges_V`` and ``positions`` (fractions of the stroke) define the fixed-volume
    recordings (one per pair); ``count`` the number of moving-volume recordings.
    ``forms`` (realistic effect forms) switch the truth to the high-fidelity plant,
    integrated with ``plant_solver``. ``supply_Pa`` is the regulated supply (absolute).
    """

    cylinder: str
    valve: str
    effects: tuple[Effect, ...] = ()
    protocol: str = "fixed"
    duration_s: float = 20.0
    seed: int = 0
    overrides: Mapping[str, float] = field(default_factory=dict)
    ranges_V: tuple[float, ...] = (5.0, 3.0, 0.5)
    positions: tuple[float, ...] = (0.1, 0.5, 0.9)
    count: int = 2
    moving_range_V: float = 5.0
    fine_rate_Hz: float = 10_000.0
    sensor: SensorChain = field(default_factory=SensorChain)
    solver: SolverConfig = field(default_factory=SolverConfig.reference)
    forms: tuple[PlantForm, ...] = ()
    plant_solver: PlantConfig = field(default_factory=PlantConfig.reference)
    supply_Pa: float = SUPPLY_PA

    def __post_init__(self):
        object.__setattr__(self, "forms", check_forms(self.forms,
                                                      [e.name for e in self.effects]))
        if not isinstance(self.plant_solver, PlantConfig):
            raise TypeError(f"plant_solver must be a PlantConfig, got "
                            f"{type(self.plant_solver).__name__}")
        if self.protocol not in PROTOCOLS:
            raise ValueError(f"protocol must be one of {PROTOCOLS}, got {self.protocol!r}")
        if not self.duration_s > 0:
            raise ValueError(f"duration_s must be > 0, got {self.duration_s}")
        if not self.supply_Pa > ATMOSPHERE_PA:
            raise ValueError(f"supply_Pa must be above the atmosphere ({ATMOSPHERE_PA:g} Pa, "
                             f"absolute), got {self.supply_Pa!r}")
        ratio = self.fine_rate_Hz / self.sensor.sample_rate_Hz
        if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
            raise ValueError("fine_rate_Hz must be an integer multiple of the sample rate")
        for f in self.positions:
            if not 0.0 <= f <= 1.0:
                raise ValueError(f"positions are fractions of the stroke in [0, 1], got {f}")

    @property
    def model(self) -> Model:
        return Model(self.effects)


@dataclass(frozen=True)
class BenchResult:
    """Paths written and the truth."""

    recordings: tuple[Path, ...]
    truth_path: Path
    truth: dict


def _plans(cfg: BenchConfig, stroke: float) -> list[dict]:
    if cfg.protocol == "fixed":
        return [{"name": f"fixed_u{r:g}_x{100 * f:.0f}".replace(".", "p"), "range_V": r,
                 "position_m": f * stroke}
                for f in cfg.positions for r in cfg.ranges_V]
    return [{"name": f"moving_{i:02d}", "range_V": cfg.moving_range_V, "position_m": None}
            for i in range(cfg.count)]


def accepted_rules(pressure_Pa) -> tuple[str, ...]:
    """Plausibility rules a bench recording of ``pressure_Pa`` (absolute, Pa) accepts:
    ``pressure-low`` where its 1st percentile is below half an atmosphere (a sealed
    chamber the piston draws to a vacuum is real; the bench's pressures are absolute
    by construction, never a gauge reading), else none."""
    low = np.percentile(np.asarray(pressure_Pa, dtype=np.float64), 1) < 0.5 * ATMOSPHERE_PA
    return ("pressure-low",) if low else ()


#: The catalogue effects that act on the reading alone (the chamber's physics sees p).
_SENSOR_EFFECTS = ("sensor_calibration", "sensor_drift", "sensor_nonlinearity")


def _sensor_read(model: Model, truth: Mapping[str, float], rig: Rig):
    """``read(time_s, pressure_Pa)``: what the sensor of ``model`` at ``truth`` records,
    through the zero, gain and curvature its effects lower
    (:func:`~pneubayes.physics.calibration.sensor_reading_Pa`)."""
    sl = model.lower(model.as_matrix(truth), rig)[0]
    zero = [sl[SLOT_INDEX[k]] for k in ("reading_offset_Pa", "reading_drift_Pa_per_s",
                                        "reading_warm_up_Pa",
                                        "reading_warm_up_time_constant_s")]
    gain = 1.0 + sl[SLOT_INDEX["reading_gain_error"]]
    curvature = sl[SLOT_INDEX["reading_curvature_Pa"]]
    return lambda t, p: sensor_reading_Pa(np.asarray(p, dtype=np.float64), ATMOSPHERE_PA,
                                          reading_zero_Pa(t, *zero), gain, curvature)


def run_bench(cfg: BenchConfig, out_dir, overwrite: bool = False,
              progress: Callable[[str], None] | None = None) -> BenchResult:
    """Generate the recordings of ``cfg`` into ``out_dir`` and write ``truth.json``."""
    out = Path(out_dir)
    truth_path = out / "truth.json"
    if truth_path.exists() and not overwrite:  # before any work, so nothing is half-done
        raise FileExistsError(errno.EEXIST, "refusing to overwrite (pass overwrite=True)",
                              str(truth_path))
    out.mkdir(parents=True, exist_ok=True)
    cyl = cylinder_preset(cfg.cylinder)
    model = cfg.model
    rig = Rig(cyl.bore_m, ATMOSPHERE_PA, cfg.supply_Pa, GasConstants(temperature_K=TEMPERATURE_K),
              stroke_m=cyl.stroke_m)
    truth = truth_parameters(model, cfg.cylinder, cfg.valve, rig, cfg.overrides)
    truth, plant_truth = _form_truth(cfg, truth)
    fs_out = cfg.sensor.sample_rate_Hz
    step = int(round(cfg.fine_rate_Hz / fs_out))
    n_out = int(round(cfg.duration_s * fs_out)) + 1
    t_out = np.arange(n_out) / fs_out
    t_fine = np.arange((n_out - 1) * step + 1) / cfg.fine_rate_Hz
    plans = _plans(cfg, cyl.stroke_m)
    # the sensor's effects (calibration, drift, curvature) are simulated neutral and the
    # true pressure read through their lowered slots, as the simulator reads it
    sensor = [model.effect(n) for n in _SENSOR_EFFECTS if model.has(n)]
    sensor_neutral = {k: v for e in sensor for k, v in e.neutral_values().items()}
    read = _sensor_read(model, truth, rig) if sensor else None
    seeds = np.random.SeedSequence(cfg.seed).spawn(len(plans))
    written, entries = [], []
    for plan, ss in zip(plans, seeds):
        if progress:
            progress(f"bench: {plan['name']} ({cfg.duration_s:g} s)")
        rng = np.random.default_rng(ss)
        u_out = np.round(step_commands(t_out, rng, plan["range_V"], clock_s=1.0 / fs_out), 4)
        u_fine = np.repeat(u_out, step)[: t_fine.size]
        if plan["position_m"] is None:
            x_fine = piston_motion(t_fine, rng, cyl.stroke_m)
        else:
            x_fine = np.full(t_fine.size, plan["position_m"])
        supply_fine = np.full(t_fine.size, cfg.supply_Pa)
        for e in model.effects:
            supply_fine = e.perturb_inputs(t_fine, supply_fine, rig, rng)
        inputs = Inputs(t_fine, u_fine, x_fine, supply_fine)
        # the chamber starts at rest at atmospheric pressure; a miscalibrated sensor
        # (sensor_calibration) reads it, as everything else, through its calibration
        if cfg.forms:
            traj = simulate_plant(plant_truth, cfg.forms, inputs, rig, ATMOSPHERE_PA,
                                  cfg.plant_solver, effects=model.effects)
            p_true, supply_fine = traj.pressure_Pa, traj.supply_at_valve_Pa
            for form in cfg.forms:  # a sensor port facing the inlet's jet
                if isinstance(form, InletJetAtSensor):
                    p_true = form.read(traj.inlet_flow_kg_per_s, p_true)
        else:
            p_true = simulate(model, {**truth, **sensor_neutral}, inputs, rig,
                              ATMOSPHERE_PA, cfg.solver).pressure_Pa[0]
        for form in cfg.forms:  # a sensor behind a capillary reads its cavity
            if isinstance(form, CapillarySensorPort):
                p_true = form.read(t_fine, p_true)
        for form in cfg.forms:  # a bowed sensor reads the pressure off its line
            if isinstance(form, SensorBow):
                p_true = form.read(p_true, ATMOSPHERE_PA)
        for form in cfg.forms:  # a warming sensor's zero drifts over the recording
            if isinstance(form, SensorZeroDrift):
                p_true = form.read(t_fine, p_true)
        for form in cfg.forms:  # a sensor whose diaphragm warms with the gas overshoots
            if isinstance(form, SensorThermalShock):
                p_true = form.read(t_fine, p_true)
        for form in cfg.forms:  # a sensor with play in its diaphragm's linkage
            if isinstance(form, SensorHysteresis):
                p_true = form.read(p_true)
        for form in cfg.forms:  # a sensor grounded through the solenoid driver's return
            if isinstance(form, SolenoidGroundShift):
                p_true = form.read(t_fine, u_fine, p_true)
        for form in cfg.forms:  # a sensor whose output saturates at its full scale
            if isinstance(form, SaturatingSensor):
                p_true = form.read(p_true, ATMOSPHERE_PA)
        for form in cfg.forms:  # a pressure channel logged late against the others
            if isinstance(form, SkewedPressureChannel):
                p_true = form.read(t_fine, p_true)
        if read is not None:
            p_true = read(t_fine, p_true)
        s = cfg.sensor
        p_meas = s.measure(t_fine, p_true, t_out, s.pressure_noise_Pa, rng,
                           s.pressure_quantum_Pa)
        sup_meas = s.measure(t_fine, supply_fine, t_out, s.supply_noise_Pa, rng,
                             s.pressure_quantum_Pa)
        meta = RecordingMetadata(
            cylinder=cfg.cylinder, valve=cfg.valve, bore_m=cyl.bore_m, stroke_m=cyl.stroke_m,
            atmospheric_pressure_Pa=ATMOSPHERE_PA, supply_pressure_Pa=cfg.supply_Pa,
            temperature_K=TEMPERATURE_K, position_m=plan["position_m"],
            extra={"source": "pneubayes virtual bench", "protocol": cfg.protocol,
                   "command_range_V": plan["range_V"]},
            accept_unusual=accepted_rules(p_meas))
        pos = None
        if plan["position_m"] is None:
            for form in cfg.forms:  # a lagging length sensor reads behind the piston
                if isinstance(form, LaggingPositionSensor):
                    x_fine = form.read(t_fine, x_fine)
            pos = np.clip(s.measure(t_fine, x_fine, t_out, s.position_noise_m, rng), 0.0,
                          cyl.stroke_m)
        # Logged at the ADC/DAC resolution: 0.1 Pa, 0.1 um, 0.1 mV.
        rec = Recording(metadata=meta, time_s=t_out, command_V=np.round(u_out, 4),
                        pressure_Pa=np.round(p_meas, 1), supply_pressure_Pa=np.round(sup_meas, 1),
                        position_m=None if pos is None else np.round(pos, 7))
        stem = out / plan["name"]
        write_recording(rec, stem, overwrite=overwrite)
        written.append(out / f"{plan['name']}.csv")
        entries.append({"file": f"{plan['name']}.csv", "range_V": plan["range_V"],
                        "position_m": plan["position_m"]})
    # an out-of-catalogue form (catalogue_name None) plants no catalogue effect: a
    # discovery run should name none for it
    planted = set(model.effect_names) | set(catalogue_names_of(cfg.forms))
    forms_extra = {"plant_solver": cfg.plant_solver.to_dict(),
                   "plant_dead_volume_m3": plant_truth["dead_volume_m3"]} if cfg.forms else {}
    card = model.to_card(truth, extra={"bench": {
        "cylinder": cfg.cylinder, "valve": cfg.valve, "protocol": cfg.protocol,
        "planted_effects": [n for n in CATALOGUE if n in planted],
        "planted_forms": [f.to_dict() for f in cfg.forms],
        "out_of_catalogue_forms": [type(f).__name__ for f in cfg.forms
                                   if f.catalogue_name is None], **forms_extra,
        "duration_s": cfg.duration_s,
        "seed": cfg.seed, "overrides": dict(cfg.overrides),
        "fine_rate_Hz": cfg.fine_rate_Hz, "sensor": cfg.sensor.to_dict(),
        "solver": cfg.solver.to_dict(), "initial_pressure_Pa": ATMOSPHERE_PA,
        "rig": {"bore_m": cyl.bore_m, "stroke_m": cyl.stroke_m,
                "atmospheric_pressure_Pa": ATMOSPHERE_PA, "supply_pressure_Pa": cfg.supply_Pa,
                "temperature_K": TEMPERATURE_K},
        "recordings": entries, "pneubayes_version": pneubayes.__version__}})
    write_json_atomic(truth_path, card)
    return BenchResult(tuple(written), truth_path, card)


def _form_truth(cfg: BenchConfig, truth: dict[str, float]):
    """``(card values, plant values)``: the plant's chamber excludes an AcousticTube's
    volume, which its cells hold; the card's dead volume includes it (the format's)."""
    card, plant = dict(truth), dict(truth)
    tube = next((f for f in cfg.forms if isinstance(f, AcousticTube)), None)
    if tube is None:
        return card, plant
    if "dead_volume_m3" in cfg.overrides:
        plant["dead_volume_m3"] = truth["dead_volume_m3"] - tube.volume_m3
        if not plant["dead_volume_m3"] > 0:
            raise ValueError(f"--set dead_volume_m3={truth['dead_volume_m3']:g} is the total "
                             f"dead volume, tube included; it must exceed the AcousticTube's "
                             f"volume {tube.volume_m3:g} m^3")
    else:
        card["dead_volume_m3"] = truth["dead_volume_m3"] + tube.volume_m3
    cfg.model.check_bounds(cfg.model.vector(card))
    return card, plant


def identification_sets(cylinder: str, valve: str, seed: int, duration_s: float, out_dir,
                        held_count: int = 1, overwrite: bool = False,
                        effects: Sequence[str] = ("cylinder_leak",)):
    """The identification design used by experiments and benchmarks.

    Training: fixed-volume recordings at 50 % and 90 % of the stroke with command ranges
    +-5 and +-0.5 V (4 recordings); held out: ``held_count`` moving-piston recordings
    (seed + 1000). Returns ``(train, held)`` :class:`BenchResult` objects.
    """
    out = Path(out_dir)
    eff = effects_from_names(effects)
    train = run_bench(BenchConfig(cylinder, valve, eff, protocol="fixed",
                                  duration_s=duration_s, seed=seed, positions=(0.5, 0.9),
                                  ranges_V=(5.0, 0.5)), out / "train", overwrite=overwrite)
    held = run_bench(BenchConfig(cylinder, valve, eff, protocol="moving",
                                 duration_s=duration_s, seed=seed + 1000, count=held_count),
                     out / "held", overwrite=overwrite)
    return train, held
