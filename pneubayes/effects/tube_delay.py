"""Connecting tube between valve and chamber (paper IV-E; Richer & Hurmuzlu 2000).

One parameter, the transport delay ``tube_delay_s`` = L / c, sets the tube length L for
a given inner diameter D (2 mm in the paper). From it follow:

- the delay: the flow the valve passes at t - L/c reaches the chamber at t; we apply it
  to the command (the valve's opening), which keeps the chamber's pressure feedback
  instantaneous, so the model stays stable however small the chamber;
- the attenuation of Richer & Hurmuzlu, ``phi = exp(-R_t Rs T L / (2 p c))`` with the
  laminar tube resistance ``R_t = 32 mu / D^2``, evaluated at the chamber pressure p;
- the tube's own volume ``pi D^2 / 4 L`` (:meth:`TubeDelay.tube_volume_m3`). The
  recording format defines the dead volume as the chamber volume at position 0 *tube
  included*, so the tube's volume is part of ``dead_volume_m3`` and not added again
  here: a model with and without this effect then share one volume map, and the tube
  volume is not confounded with the dead volume. The bench adds it to the true dead
  volume when it plants a tube.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from pneubayes.effects.base import Effect, Parameter
from pneubayes.rig import Rig


class TubeDelay(Effect):
    """Transport delay, friction attenuation and volume of the connecting tube."""

    name = "tube_delay"
    acts_on = ("command_delay_s", "flow_attenuation_Pa")

    def __init__(self, tube_diameter_m: float = 0.002, air_viscosity_Pa_s: float = 1.81e-5):
        self.tube_diameter_m = tube_diameter_m
        self.air_viscosity_Pa_s = air_viscosity_Pa_s

    def options(self):
        return {"tube_diameter_m": self.tube_diameter_m,
                "air_viscosity_Pa_s": self.air_viscosity_Pa_s}

    def parameters(self):
        return (Parameter("tube_delay_s", "s", 0.0, 0.03, "uniform",
                          "transport delay L/c of the valve-chamber tube", neutral=0.0),)

    def lower(self, values: Mapping[str, np.ndarray], rig: Rig):
        d = self.tube_diameter_m
        if not (d > 0 and self.air_viscosity_Pa_s > 0):
            raise ValueError("tube_delay: tube_diameter_m and air_viscosity_Pa_s must be > 0")
        delay = np.asarray(values["tube_delay_s"], dtype=np.float64)
        c = rig.gas.speed_of_sound_m_per_s
        length = c * delay
        rs_t = rig.gas.specific_gas_constant_J_per_kg_K * rig.gas.temperature_K
        r_t = 32.0 * self.air_viscosity_Pa_s / d**2
        return {
            "command_delay_s": delay,
            # phi = exp(-R_t Rs T L / (2 p c)) = exp(-value / p)
            "flow_attenuation_Pa": r_t * rs_t * length / (2.0 * c),
        }

    def tube_volume_m3(self, tube_delay_s, rig: Rig):
        """Volume of the tube whose delay is ``tube_delay_s``: pi D^2/4 c tau, m^3."""
        return (math.pi / 4.0 * self.tube_diameter_m**2 * rig.gas.speed_of_sound_m_per_s
                * np.asarray(tube_delay_s, dtype=np.float64))

    def bench_defaults(self):
        # A 1 m tube: 2.9 ms at 343 m/s, 3.1e-6 m^3 of 2 mm tube.
        return {"tube_delay_s": 0.003}
