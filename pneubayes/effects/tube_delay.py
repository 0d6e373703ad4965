"""Connecting tube between valve and chamber (paper IV-E; Richer & Hurmuzlu 2000).

In both forms the parameter ``tube_delay_s`` = L / c, the one-way acoustic transit
time, sets the tube length L.

``form="transport"`` (the paper's): for a given inner diameter D (2 mm in the paper),

- the delay: the flow the valve passes at t - L/c reaches the chamber at t; we apply it
  to the command (the valve's opening), which keeps the chamber's pressure feedback
  instantaneous, so the model stays stable however small the chamber;
- the attenuation of Richer & Hurmuzlu, ``phi = exp(-R_t Rs T L / (2 p c))`` with the
  laminar tube resistance ``R_t = 32 mu / D^2``, evaluated at the chamber pressure p;
- the tube's own volume ``pi D^2 / 4 L`` (:meth:`TubeDelay.tube_volume_m3`) is part of
  ``dead_volume_m3`` (the recording format's dead volume includes the tube) and is not
  added again: models with and without the tube share one volume map. The bench adds
  it to the true dead volume when it plants a tube.

``form="line"``: the tube as a lumped acoustic line of ``segments`` cells, with its
inner diameter ``tube_diameter_m`` a second parameter. Each cell (volume A L / n) has a
pressure obeying eq. 5 at the supply temperature, and each junction towards the next
cell (the last: the chamber) a mass flow q with inertia and smooth-pipe friction,
``dq/dt = A / l (p_i - p_{i+1}) - f Re mu q / (2 rho D^2)``
(:mod:`pneubayes.physics.tube`), on a staggered grid: the link l is L / n between cell
centres and L / (2 n) from the last cell's centre to the chamber (the centred lumping;
:mod:`pneubayes.simulation.line`). The valve's port flows enter the first cell and see
its pressure, not the chamber's; waves travel and reflect (a pure delay cannot lag and
ring as an outside tube does). Its volume, in ``dead_volume_m3``, leaves the chamber's.

``form="wave"``: the tube as a transmission line (TLM; :mod:`pneubayes.simulation.wave`),
with the line's two parameters: ``segments`` (default 8) lossless elements whose waves
cross each in its share of the transit time and reflect at the ends, the same friction
lumped at the junctions; no cells, so the cost does not grow with the length. The
junctions update on a grid (``grid_s``, default 0.1 ms, or an element's transit if
shorter; coarser is faster and smears more: ``benchmarks/tube_forms.py``). Its output
moves continuously with the transit time. Not beside heat transfer; its volume leaves
the chamber's. ``unsteady_friction=True`` adds ``tube_unsteady_friction`` (0-3, 0 the
quasi-steady tube), the weight of Zielke's frequency-dependent wall shear (Trikha's
three exponentials, Vardy and Brown's turbulent cut-off): a line's ring after a sharp
switch damps faster (:func:`pneubayes.simulation.wave.unsteady_shear`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from pneubayes.effects.base import Effect, Parameter
from pneubayes.effects.discovery import CandidateContext, TrialTerm
from pneubayes.effects.path import LINE_MAX_SEGMENTS, WAVE_MAX_SEGMENTS
from pneubayes.rig import Rig

_FORMS = ("transport", "line", "wave")
_TUBE_FORMS = ("line", "wave")  # the forms with a bore and the tube's volume as states


class TubeDelay(Effect):
    """The valve-chamber tube: transport delay with attenuation, or an acoustic line."""

    name = "tube_delay"
    #: The forms (``form`` option) this effect has; the first is the default.
    forms = _FORMS
    option_variants = ({"form": "wave", "unsteady_friction": True},)
    acts_on = ("command_delay_s", "flow_attenuation_Pa", "line_length_m", "line_diameter_m",
               "line_segments", "line_viscosity_Pa_s", "wave_length_m", "wave_diameter_m",
               "wave_viscosity_Pa_s", "wave_segments", "wave_grid_s",
               "wave_unsteady_friction")

    def __init__(self, tube_diameter_m: float = 0.002, air_viscosity_Pa_s: float = 1.81e-5,
                 form: str = "transport", segments: int = 0, grid_s: float = 1e-4,
                 unsteady_friction: bool = False):
        self.tube_diameter_m = tube_diameter_m
        self.unsteady_friction = unsteady_friction
        self.air_viscosity_Pa_s = air_viscosity_Pa_s
        self.form = form
        self.grid_s = grid_s
        # 0: the form's own count, the line's 3 cells or the wave tube's 8 elements
        self.segments = segments if segments != 0 else (8 if form == "wave" else 3)

    def _check(self):
        super()._check()
        if not (self.tube_diameter_m > 0 and self.air_viscosity_Pa_s > 0):
            raise ValueError("tube_delay: tube_diameter_m and air_viscosity_Pa_s must be > 0")
        most = WAVE_MAX_SEGMENTS if self.form == "wave" else LINE_MAX_SEGMENTS
        if (isinstance(self.segments, bool) or not isinstance(self.segments, int)
                or not 1 <= self.segments <= most):
            raise ValueError(f"tube_delay: segments must be an integer in 1..{most}, "
                             f"got {self.segments!r}")
        if isinstance(self.grid_s, bool) or not isinstance(self.grid_s, (int, float)) \
                or not 1e-5 <= self.grid_s <= 1e-2:
            raise ValueError(f"tube_delay: grid_s must be a number in [1e-5, 1e-2] s, got "
                             f"{self.grid_s!r}")
        if not isinstance(self.unsteady_friction, bool):
            raise ValueError(f"tube_delay: unsteady_friction must be true or false, got "
                             f"{self.unsteady_friction!r}")
        if self.unsteady_friction and self.form != "wave":
            raise ValueError(f"tube_delay: unsteady_friction is an option of the 'wave' "
                             f"form, not of {self.form!r}")

    def options(self):
        opts = {"tube_diameter_m": self.tube_diameter_m,
                "air_viscosity_Pa_s": self.air_viscosity_Pa_s, "form": self.form}
        if self.form in _TUBE_FORMS:
            opts["segments"] = self.segments
        if self.form == "wave":
            opts["grid_s"] = self.grid_s
        if self.unsteady_friction:
            opts["unsteady_friction"] = True
        return opts

    def parameters(self):
        self._check()
        delay = Parameter("tube_delay_s", "s", 0.0, 0.03, "uniform",
                          "transport delay L/c of the valve-chamber tube", neutral=0.0)
        if self.form == "transport":
            return (delay,)
        if self.form == "wave":
            delay = Parameter("tube_delay_s", "s", 0.0, 0.03, "uniform",
                              "acoustic transit time L/c of the valve-chamber tube",
                              neutral=0.0)
        # any diameter is neutral at zero length
        bore = Parameter("tube_diameter_m", "m", 5e-4, 1e-2, "log-uniform",
                         "inner diameter of the valve-chamber tube",
                         neutral=self.tube_diameter_m)
        if not self.unsteady_friction:
            return (delay, bore)
        return (delay, bore, Parameter(
            "tube_unsteady_friction", "-", 0.0, 3.0, "uniform",
            "share of Zielke's unsteady wall shear in the transmission-line tube",
            neutral=0.0))

    def lower(self, values: Mapping[str, np.ndarray], rig: Rig):
        self._check()
        delay = np.asarray(values["tube_delay_s"], dtype=np.float64)
        c = rig.gas.speed_of_sound_m_per_s
        length = c * delay
        if self.form == "wave":
            dia = np.asarray(values["tube_diameter_m"], dtype=np.float64)
            return {"wave_length_m": length, "wave_diameter_m": dia,
                    "wave_viscosity_Pa_s": np.full(delay.shape, self.air_viscosity_Pa_s),
                    "wave_segments": np.full(delay.shape, float(self.segments)),
                    "wave_grid_s": np.full(delay.shape, float(self.grid_s)),
                    "wave_unsteady_friction": np.asarray(
                        values["tube_unsteady_friction"], dtype=np.float64)
                    if self.unsteady_friction else np.zeros(delay.shape)}
        if self.form == "line":
            dia = np.asarray(values["tube_diameter_m"], dtype=np.float64)
            return {"line_length_m": length, "line_diameter_m": dia,
                    "line_segments": np.full(delay.shape, float(self.segments)),
                    "line_viscosity_Pa_s": np.full(delay.shape, self.air_viscosity_Pa_s)}
        d = self.tube_diameter_m
        rs_t = rig.gas.specific_gas_constant_J_per_kg_K * rig.gas.temperature_K
        r_t = 32.0 * self.air_viscosity_Pa_s / d**2
        return {
            "command_delay_s": delay,
            # phi = exp(-R_t Rs T L / (2 p c)) = exp(-value / p)
            "flow_attenuation_Pa": r_t * rs_t * length / (2.0 * c),
        }

    def tube_volume_m3(self, values: Mapping[str, np.ndarray], rig: Rig):
        """Volume pi D^2/4 c tau of the tube the parameter ``values`` describe, m^3."""
        d = (values["tube_diameter_m"] if self.form in _TUBE_FORMS else self.tube_diameter_m)
        return (math.pi / 4.0 * np.asarray(d, dtype=np.float64) ** 2
                * rig.gas.speed_of_sound_m_per_s
                * np.asarray(values["tube_delay_s"], dtype=np.float64))

    # ------------------------------------------------------------------ discovery
    library_strengths = (0.001, 0.002, 0.004, 0.007, 0.012, 0.02)
    discovery_fallback = {"tube_delay_s": 0.003}

    def library_terms(self, strengths):
        """The port flows delayed by each trial delay (s), with the tube's friction."""
        return tuple(TrialTerm(f"delay {v * 1e3:g} ms", {"tube_delay_s": v},
                               values={"tube_delay_s": v}) for v in strengths)

    @staticmethod
    def line_cells(transit_s: float, cutoff_Hz: float, most: int) -> int:
        """Cells of an acoustic line of transit time ``transit_s``: the fewest whose
        lumped cut-off n / (pi T) reaches ``cutoff_Hz``, at least 3 (or ``most`` if
        lower) and at most ``most``."""
        need = math.ceil(math.pi * transit_s * cutoff_Hz - 1e-9)
        return int(min(most, max(3, need)))

    @staticmethod
    def wave_grid_s(transit_s: float, segments: int, most_s: float, per_element: int) -> float:
        """The grid (s) of a transmission line of ``segments`` elements started at the
        transit time ``transit_s``: an element's transit over ``per_element``, between
        0.1 ms and ``most_s`` (0.1 ms when ``most_s`` is). Fixed for the fit: a grid
        that moved with the transit time made the fit's objective rough."""
        fine = 1e-4
        return float(min(max(most_s, fine), max(fine, transit_s / (segments * per_element))))

    def candidate_forms(self, ctx: CandidateContext):
        """This form (the paper's transport delay) and an acoustic line (outside tubes
        are lines, which lag and ring; none where the model has no room for the line's
        states, the transmission line also beside a compliant chamber), both at the best
        term's delay. The line's cells follow its length
        (:meth:`line_cells`: ``ctx.line_cutoff_Hz``, at most ``ctx.line_segments``); with
        ``ctx.line_form`` "wave" it is the transmission-line tube (8 elements) instead,
        except beside heat transfer (the wave tube has no temperature state; the line does).
        The line's volume comes out of the fitted dead volume: where the effect's bore
        would make it more than half of that, the line starts narrower, at half (the
        transit time is what the residual shows; the bore is a guess either way, and a
        long tube into a small chamber holds most of the dead volume)."""
        start = self.candidate_start(ctx.term_start)
        out = [(self, start)]
        if self.form in _TUBE_FORMS or ctx.line_segments == 0:
            return out
        # (the transmission line carries no temperature state: not beside heat transfer;
        # it carries a compliant chamber, not a tank or a second compartment)
        heated = ctx.slot("heat_coupling") > 0
        wave = ctx.line_form == "wave" and not heated \
            and ctx.slot("tank_volume_m3") == 0 and ctx.slot("lung_volume_m3") == 0
        if not (ctx.second_state_free or wave):
            return out
        # (the delay's bounds do not depend on the cells)
        probe = TubeDelay(**{**self.options(), "form": "line", "segments": 1})
        delay = ctx.inside(probe, "tube_delay_s", start["tube_delay_s"])
        if wave:  # the transmission line: no cells, on a grid fixed by its start
            line = TubeDelay(**{**self.options(), "form": "wave", "segments": 8,
                                "grid_s": self.wave_grid_s(delay, 8, *ctx.wave_grid),
                                "unsteady_friction": ctx.wave_unsteady})
        else:
            cells = self.line_cells(delay, ctx.line_cutoff_Hz, ctx.line_segments)
            line = TubeDelay(**{**self.options(), "form": "line", "segments": cells})
        dia = line.neutral_values()["tube_diameter_m"]
        vol = float(line.tube_volume_m3({"tube_delay_s": delay, "tube_diameter_m": dia},
                                        ctx.rig))
        start = {"tube_delay_s": delay}
        if vol > 0.5 * ctx.dead_volume_m3:
            start["tube_diameter_m"] = ctx.inside(line, "tube_diameter_m", dia * math.sqrt(
                0.5 * ctx.dead_volume_m3 / vol))
        out.append((line, start))
        return out

    def form_after_fit(self, params, ctx: CandidateContext):
        """An acoustic line whose fitted transit time needs more cells than it has
        (:meth:`line_cells`; its start delay came from a transport-delay term, which
        sees a line's transit short) is fitted again with them, from its fit."""
        if self.form != "line" or ctx.line_segments == 0:
            return None
        cells = self.line_cells(params["tube_delay_s"], ctx.line_cutoff_Hz, ctx.line_segments)
        if cells <= self.segments:
            return None
        more = TubeDelay(**{**self.options(), "segments": cells})
        return more, {k: params[k] for k in more.parameter_names()}

    def refine_first(self):
        """An acoustic line's step costs tens of times a plain one, and a refinement's
        Jacobian one simulation per free parameter: the line's two parameters and the
        dead volume it shares are fitted first (four simulations per Jacobian instead of
        a dozen), then everything from there (the discovery loop screens the form on
        that first stage). The wave tube is refined in full from its start, unscreened:
        with only its own parameters free and the valve maps held where the current fit
        had put them (they had absorbed the tube), its first stage failed the screen on
        Table III's AIR37/valve1 rig (a 1-m x 2-mm tube) and a second-order sensor lag
        stood in for the tube (2.8-3.0 x the noise floor over seeds 0-2); refined in
        full the wave was named there on seeds 0 and 2 (seed 1 not run)."""
        return ("tube_delay_s", "tube_diameter_m", "dead_volume_m3") \
            if self.form == "line" else None

    def volume_taken_m3(self, values, rig):
        """An acoustic or wave line's volume leaves the chamber's (the dead volume
        includes it); the transport form takes none."""
        return self.tube_volume_m3(values, rig) if self.form in _TUBE_FORMS else None

    def bench_defaults(self):
        # A 1 m tube: 2.9 ms at 343 m/s, 3.1e-6 m^3 of 2 mm tube.
        if self.form in _TUBE_FORMS:  # a 34-cm tube of 2.5 mm bore, 1.7e-6 m^3
            return {"tube_delay_s": 0.001, "tube_diameter_m": 0.0025}
        return {"tube_delay_s": 0.003}
