"""The Tassa, Wu, Movellan & Todorov (2013) pressure model: formulas and exact simulation.

Ten parameters c0..c9, no gas physics, linear in the pressure (NOTES.md, "Peer models";
the form published with the group's MuJoCo-era code)::

    u' = u - c2,   sigma(w) = w / sqrt(w^2 + 1),   softabs(w) = sqrt(w^2 + eps^2)
    b  = (c1 + c0)/2 + (c1 - c0)/2 * sigma(c3 u' + c4 u'^3)      target at rest, MPa
    r0 = (c7 (softabs(u') + c8 u') + c9) / (1 + c6 x)             rate at rest, 1/s
    r  = r0 + c5 v / (1 + c6 x)                                   rate, 1/s
    a  = b r0 / r                                                 target, MPa
    dp/dt = r (a - p) = r0 b - r p                                MPa/s

Units and conventions (our recordings are SI: Pa absolute, V, m, s):

- ``p`` is the **absolute** pressure in MPa (``pressure_Pa / 1e6``), not gauge: the
  published target spans c0..c1 = 0.094..0.513 MPa on a rig with about 92 kPa of
  atmosphere and a 521-kPa supply (NOTES.md); in gauge an open exhaust would hold 94 kPa.
  The velocity term ``-c5 v p / (1 + c6 x)`` is eq. 5's compression ``-n p dV/dt / V``.
- ``u = command_V / 5 V``, in -1..+1 (+ opens the inlet). With c3 = 1.24 and c4 = 8.4
  the published sigma saturates near |u'| = 1, which fits a normalised command.
- ``x = position_m / stroke_m`` (0 = fully retracted = smallest chamber, as in
  :mod:`pneubayes.physics.cylinder`); ``v = dx/dt`` in strokes per second. Then
  ``1 + c6 x`` is the chamber volume over the dead volume, the same for any cylinder.
- Rescaling u, x or v only reparametrises c; only the *published* set (from another
  rig: a start, not a prediction) depends on these choices.
- softabs uses ``eps`` = :data:`SOFTABS_EPS` = 0.01 (1 % of full command, 50 mV); the
  published form does not give it. It rounds the corner of ``|u'|`` for least squares
  and adds ``c7 eps`` to the rate at ``u' = 0``, which c9 absorbs.

Within each sample interval the inputs are held: the command as recorded (zero-order
hold), the position at the midpoint, and the velocity as the mean ``(x[k+1] - x[k]) /
dt`` (the thin-port simulator's linear position). The model is then linear in p with
constant coefficients, and :func:`zoh_step` integrates it exactly:
``p[k+1] = a + (p[k] - a) exp(-r dt) = p[k] exp(-r dt) + r0 b dt phi1(-r dt)``, with
``phi1(z) = (exp(z) - 1)/z``, which never divides by r: exact and finite at ``r = 0``
and for ``r < 0`` (compression outruns the valve). Nothing is clipped: a window whose
rate stays very negative overflows to inf, and least squares rejects the step.

The estimator that fits c0..c9 is :class:`pneubayes.baselines.tassa.TassaModel`.
"""

from __future__ import annotations

import numbers
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from pneubayes.errors import ParameterError
from pneubayes.io.recording import Recording

PARAMETER_NAMES = tuple(f"c{i}" for i in range(10))
#: The published set (NOTES.md): c0..c9, for MPa absolute, normalised u and x, 1/s.
PUBLISHED_PARAMETERS = (0.09397, 0.51348, 0.03588, 1.23598, 8.40409, 0.48503, 6.04244,
                        1.02187, 0.17530, 0.12164)
#: Command that maps to u = 1, V (the recording format's +-5 V).
COMMAND_FULL_SCALE_V = 5.0
#: Smoothing of softabs(w) = sqrt(w^2 + eps^2), in units of the normalised command.
SOFTABS_EPS = 1e-2
_PA_PER_MPA = 1e6
_INF = np.inf
#: Bounds used in fitting. c3, c4 >= 0 keep the target b rising with the command, as the
#: published set has it. Without them, a bench fit chose c4 < 0: the same error, but a
#: target that falls back to exhaust beyond the commands it saw. c6 > -0.9 keeps the
#: volume ratio 1 + c6 x > 0 on the stroke. c7, c9 >= 0 and |c8| <= 1 keep r0 > 0.
LOWER_BOUNDS = (-_INF, -_INF, -_INF, 0.0, 0.0, -_INF, -0.9, 0.0, -1.0, 0.0)
UPPER_BOUNDS = (_INF, _INF, _INF, _INF, _INF, _INF, _INF, _INF, 1.0, _INF)


# ------------------------------------------------------------------ the model itself
def _as_params(params, name: str = "params") -> np.ndarray:
    """Parameters as ``(10,)`` or ``(B, 10)`` float64. A mapping must name c0..c9."""
    if isinstance(params, Mapping):
        missing = [n for n in PARAMETER_NAMES if n not in params]
        unknown = [k for k in params if k not in PARAMETER_NAMES]
        if missing or unknown:
            raise ParameterError(f"{name}: missing {missing}, unknown {unknown}; the Tassa "
                                 f"model has exactly {list(PARAMETER_NAMES)}")
        params = [params[n] for n in PARAMETER_NAMES]
    try:
        c = np.array(params, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ParameterError(f"{name} must be 10 numbers c0..c9: {exc}") from None
    if c.ndim not in (1, 2) or c.shape[-1] != len(PARAMETER_NAMES):
        raise ParameterError(f"{name} must have shape (10,) or (B, 10) (c0..c9 of Tassa "
                             f"et al. 2013), got shape {c.shape}")
    bad = np.argwhere(~np.isfinite(np.atleast_2d(c)))
    if bad.size:
        row, j = bad[0]
        raise ParameterError(f"{name}: c{j} of parameter set {row} is "
                             f"{float(np.atleast_2d(c)[row, j])!r}; parameters must be finite")
    return c


def _columns(c: np.ndarray, ndim: int) -> list:
    """c0..c9 shaped to broadcast against inputs of ``ndim`` dims (a leading batch axis)."""
    if c.ndim == 1:
        return [c[i] for i in range(c.shape[0])]
    return [c[:, i].reshape((-1,) + (1,) * ndim) for i in range(c.shape[1])]


def tassa_coefficients(command, position, velocity, params, softabs_eps: float = SOFTABS_EPS):
    """Target at rest b (MPa), rate at rest r0 (1/s) and rate r (1/s) of the model.

    Parameters
    ----------
    command, position, velocity : array_like
        Normalised command u (-1..1), position x (fraction of the stroke) and velocity
        v (strokes/s); broadcast together.
    params : array_like ``(10,)`` or ``(B, 10)``, or mapping
        c0..c9. A batch adds a leading axis to the results.
    softabs_eps : float
        Smoothing of softabs, normalised command units.

    Returns
    -------
    (b, r0, r) : ndarrays
    """
    c = _as_params(params)
    u, x, v = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64)
                                    for a in (command, position, velocity)))
    c0, c1, c2, c3, c4, c5, c6, c7, c8, c9 = _columns(c, u.ndim)
    up = u - c2
    w = c3 * up + c4 * up**3
    b = 0.5 * (c1 + c0) + 0.5 * (c1 - c0) * w / np.sqrt(w * w + 1.0)
    volume_ratio = 1.0 + c6 * x
    r0 = (c7 * (np.sqrt(up * up + softabs_eps**2) + c8 * up) + c9) / volume_ratio
    r = r0 + c5 * v / volume_ratio
    return b, r0, r


def tassa_rhs(pressure_MPa, command, position, velocity, params,
              softabs_eps: float = SOFTABS_EPS):
    """dp/dt = r (a - p) = r0 b - r p, MPa/s (absolute MPa; inputs as in
    :func:`tassa_coefficients`). Written as ``r0 b - r p``, which is defined at r = 0."""
    b, r0, r = tassa_coefficients(command, position, velocity, params, softabs_eps)
    return r0 * b - r * np.asarray(pressure_MPa, dtype=np.float64)


def _phi1(z):
    """(exp(z) - 1)/z, with its series near 0."""
    small = np.abs(z) < 1e-6
    zs = np.where(small, 1.0, z)
    return np.where(small, 1.0 + z / 2.0 + z * z / 6.0, np.expm1(zs) / zs)


def zoh_step(pressure, rate, forcing, dt_s):
    """Exact solution of ``dp/dt = forcing - rate p`` after ``dt_s`` with both held.

    ``p exp(-rate dt) + forcing dt phi1(-rate dt)``. This equals ``a + (p - a) exp(-r dt)``
    with ``a = forcing / rate``, and it is finite for rate <= 0 (no division by rate).
    Units: any pressure unit, rate 1/s, forcing pressure/s, dt s.
    """
    z = -np.asarray(rate, dtype=np.float64) * dt_s
    with np.errstate(over="ignore", invalid="ignore"):
        return pressure * np.exp(z) + forcing * dt_s * _phi1(z)


@dataclass(frozen=True)
class TassaInputs:
    """Held inputs of each sample interval ``k -> k+1``, in model units.

    Attributes
    ----------
    dt_s : (N-1,) interval lengths, s
    command : (N-1,) normalised command u[k] = command_V[k] / 5 V (zero-order hold)
    position : (N-1,) position at the interval's midpoint, fraction of the stroke
    velocity : (N-1,) mean velocity over the interval, strokes/s
    """

    dt_s: np.ndarray
    command: np.ndarray
    position: np.ndarray
    velocity: np.ndarray

    @classmethod
    def from_arrays(cls, time_s, command_V, position_m, stroke_m: float) -> TassaInputs:
        """From SI samples: time (s), command (V), piston position (m), stroke (m)."""
        t = _vector("time_s", time_s)
        if t.size < 2:
            raise ValueError(f"time_s needs at least 2 samples, got {t.size}")
        if np.any(np.diff(t) <= 0):
            k = int(np.argmax(np.diff(t) <= 0)) + 1
            raise ValueError(f"time_s must be strictly increasing; sample {k} is {float(t[k])!r} s "
                             f"after {float(t[k - 1])!r} s")
        u = _vector("command_V", command_V, t.size)
        x = _vector("position_m", position_m, t.size)
        if not (isinstance(stroke_m, numbers.Real) and np.isfinite(stroke_m) and stroke_m > 0):
            raise ValueError(f"stroke_m must be a finite number > 0 (m), got {stroke_m!r}")
        dt = np.diff(t)
        xn = x / float(stroke_m)
        return cls(dt, u[:-1] / COMMAND_FULL_SCALE_V, 0.5 * (xn[1:] + xn[:-1]),
                   np.diff(xn) / dt)

    @classmethod
    def from_recording(cls, recording: Recording) -> TassaInputs:
        """From a :class:`~pneubayes.io.Recording` (its fixed position if none measured)."""
        return cls.from_arrays(recording.time_s, recording.command_V,
                               recording.position_or_fixed(), recording.metadata.stroke_m)

    def step_coefficients(self, params, softabs_eps: float = SOFTABS_EPS):
        """Per-interval decay ``exp(-r dt)`` and forcing (MPa) of the exact step.

        Shapes ``(N-1,)``, or ``(B, N-1)`` for a batch of parameter sets.
        """
        b, r0, r = tassa_coefficients(self.command, self.position, self.velocity, params,
                                      softabs_eps)
        z = -r * self.dt_s
        with np.errstate(over="ignore", invalid="ignore"):
            return np.exp(z), r0 * b * self.dt_s * _phi1(z)


def _vector(name: str, values, n: int | None = None) -> np.ndarray:
    try:
        a = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be numbers: {exc}") from None
    if a.ndim != 1 or (n is not None and a.size != n):
        want = "1-D" if n is None else f"1-D with {n} samples (like time_s)"
        raise ValueError(f"{name} must be {want}, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        k = int(np.argmax(~np.isfinite(a)))
        raise ValueError(f"{name}[{k}] is {float(a[k])!r}; values must be finite")
    return a


def _simulate_MPa(c: np.ndarray, inputs: TassaInputs, starts: np.ndarray, length: int,
                  p0_MPa: np.ndarray, softabs_eps: float) -> np.ndarray:
    """Windows ``(B, W, L)`` in MPa for a batch ``c (B, 10)``; no validation."""
    decay, forcing = inputs.step_coefficients(c, softabs_eps)
    idx = starts[:, None] + np.arange(length - 1)[None, :]
    d = np.ascontiguousarray(np.moveaxis(decay[:, idx], -1, 0))     # (L-1, B, W)
    f = np.ascontiguousarray(np.moveaxis(forcing[:, idx], -1, 0))
    out = np.empty((length, c.shape[0], starts.size))
    p = out[0] = np.broadcast_to(p0_MPa, out.shape[1:])
    with np.errstate(over="ignore", invalid="ignore"):
        for k in range(length - 1):
            p = d[k] * p + f[k]
            out[k + 1] = p
    return np.moveaxis(out, 0, -1)


def simulate_windows(params, time_s, command_V, position_m, starts, length: int, p0_Pa, *,
                     stroke_m: float, softabs_eps: float = SOFTABS_EPS) -> np.ndarray:
    """Open-loop predictions of the Tassa model over windows, Pa absolute.

    Window w starts at sample ``starts[w]`` from ``p0_Pa[w]``. Column 0 is that start,
    and column j is the prediction at sample ``starts[w] + j``: the conventions of
    :func:`pneubayes.evaluation.predict_windows`. Each sample interval is integrated
    exactly with held inputs (:func:`zoh_step`).

    Parameters
    ----------
    params : array_like ``(10,)`` or ``(B, 10)``, or mapping
        c0..c9 (module docstring for units).
    time_s, command_V, position_m : (N,) array_like
        Sample times (s), valve command (V, +-5) and piston position (m, 0 retracted).
    starts : (W,) int array_like
        First sample of each window, ``0 <= start <= N - length``.
    length : int
        Samples per window, including the start (>= 2).
    p0_Pa : (W,) array_like
        Absolute pressure at each window start, Pa (usually the measured one).
    stroke_m : float
        Cylinder stroke, m (normalises the position).
    softabs_eps : float
        Smoothing of softabs (:data:`SOFTABS_EPS`).

    Returns
    -------
    ndarray ``(W, length)``, or ``(B, W, length)`` for a batch of parameter sets.
    """
    c = _as_params(params)
    inputs = TassaInputs.from_arrays(time_s, command_V, position_m, stroke_m)
    n = inputs.dt_s.size + 1
    if isinstance(length, bool) or not isinstance(length, numbers.Integral) or length < 2:
        raise ValueError(f"length must be an integer >= 2 (samples per window including "
                         f"the start), got {length!r}")
    if length > n:
        raise ValueError(f"length {length} is longer than the {n} samples of time_s")
    s = np.asarray(starts)
    if s.ndim != 1 or (s.size and s.dtype.kind not in "iu"):
        raise ValueError(f"starts must be a 1-D array of sample indices, got "
                         f"shape {s.shape} dtype {s.dtype}")
    s = s.astype(np.int64)
    out = np.flatnonzero((s < 0) | (s > n - length))
    if out.size:
        raise ValueError(f"starts[{out[0]}] = {s[out[0]]} is outside 0..{n - length} (a "
                         f"window of {length} samples must end within the {n} samples)")
    p0 = _vector("p0_Pa", p0_Pa, s.size)
    if np.any(p0 <= 0):
        k = int(np.argmax(p0 <= 0))
        raise ValueError(f"p0_Pa[{k}] = {float(p0[k])!r}; start pressures are absolute and must "
                         f"be > 0 Pa")
    pred = _simulate_MPa(np.atleast_2d(c), inputs, s, int(length), p0 / _PA_PER_MPA,
                         softabs_eps) * _PA_PER_MPA
    return pred[0] if c.ndim == 1 else pred
