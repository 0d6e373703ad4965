"""A second-order lag parametrised by its group delay at DC and its damping, shared by
the second-order forms of ``sensor_lag`` and ``spool_lag``.

``x'' = w^2 (in - x) - 2 z w x'`` has group delay ``D = 2 z / w`` at DC: the lag a slow
signal sees, comparable with a first-order lag's time constant, and 0 for no lag (at
any damping). A large z is the first-order lag of time constant D.
"""

from __future__ import annotations

import numpy as np

from pneubayes.effects.base import Parameter


def delay_and_damping(prefix: str, what: str, max_delay_s: float
                      ) -> tuple[Parameter, Parameter]:
    """The parameters ``{prefix}_delay_s`` (uniform on 0 to ``max_delay_s``) and
    ``{prefix}_damping`` (uniform on 0.2-5) of the second-order lag of ``what``."""
    return (Parameter(f"{prefix}_delay_s", "s", 0.0, max_delay_s, "uniform",
                      f"group delay 2 z / w at DC of {what}", neutral=0.0),
            Parameter(f"{prefix}_damping", "-", 0.2, 5.0, "uniform",
                      f"damping ratio z of {what}",
                      neutral=1.0))  # any damping is neutral at zero delay


def natural_frequency(delay_s, damping) -> tuple[np.ndarray, np.ndarray]:
    """``(w rad/s, z)`` of group delays ``delay_s`` and dampings ``damping``: w = 2 z / D,
    and (0, 0), no lag, where D = 0."""
    delay = np.asarray(delay_s, dtype=np.float64)
    damping = np.asarray(damping, dtype=np.float64)
    on = delay > 0.0
    w = np.where(on, 2.0 * damping / np.where(on, delay, 1.0), 0.0)
    return w, np.where(on, damping, 0.0)
