"""The open-form search at the reading: relaxations of the reading in the prediction
windows' residual.

A reading closure (:class:`~pneubayes.effects.reading_closure.ReadingClosure`) adds
``g (p - p_bar)`` to a window's reading, ``p_bar`` the first-order low-pass of the
pressure with time constant ``tau``, warm at the window's start from the recorded
reading. Its effect on a window's prediction, to first order in ``g``, is that term
along the predicted pressure plus the chamber's start moved by ``p_bar(start) - r0``
along the start sensitivity (:meth:`ReadingWindows.column`, as the simulator reads a
window). :class:`ReadingSearch` regresses the windows' residual (measured
minus predicted) on those columns over a grid of time constants, greedily: the best
column, its time constant refined, then the best on what is left. A term is kept when
it explains at least ``min_explained_fraction`` of the residual's uncentred sum of
squares and its gain is ``min_t`` standard errors from zero, the errors clustered by
window (a window's residual is one correlated trace, not independent samples). Two
kept terms then have their time constants refined together (the gains solved for at
each): within a window two relaxations are far from orthogonal, and the greedy first
pick may be their compromise.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize, minimize_scalar

from pneubayes.discovery.openform.clustered import last_column_fit, stacked_residual
from pneubayes.effects.reading_closure import READING_MAX_TERMS, TIME_CONSTANT_BOUNDS_S
from pneubayes.simulation.reading_closure import history_low_pass, relaxed_reading
from pneubayes.simulation.reading_command import command_lag
from pneubayes.simulation.reading_play import history_play, play_rows


@dataclass(frozen=True)
class ReadingTerm:
    """A kept relaxation: ``gain`` (-), ``time_constant_s`` (s), the share of the
    residual's uncentred sum of squares it explains on its own (``explained``) and its
    gain over its window-clustered standard error (``t``)."""

    gain: float
    time_constant_s: float
    explained: float
    t: float

    def __str__(self) -> str:
        return f"{self.gain:+.4g} (p - p_bar), tau = {self.time_constant_s:.4g} s"


@dataclass(frozen=True)
class ReadingWindows:
    """One recording's prediction windows as the search reads them.

    Attributes
    ----------
    time_s, predicted_Pa : (W, L) arrays
        The windows' sample times (s) and the current model's predicted pressure (Pa).
    residual_Pa : (W, L - 1) array
        Measured minus predicted, samples 1..L-1 of each window (Pa).
    sensitivity : (W, L) array or None
        The prediction's start sensitivity dp/dp0 (-); None: 1 throughout.
    history : tuple or None
        ``(time_s, reading_Pa, starts)``: the whole recording's times and reading and
        the windows' first samples, from which each relaxation starts warm (as the
        simulator starts it, :mod:`pneubayes.simulation.reading_closure`); None: at rest.
    command : tuple or None
        ``(time_s, command, before, starts)``: the whole recording's times, command and
        the command held before it, and the windows' first samples, for the lags of the
        command (:meth:`command_column`); None: none searched.
    """

    time_s: np.ndarray
    predicted_Pa: np.ndarray
    residual_Pa: np.ndarray
    sensitivity: np.ndarray | None = None
    history: tuple | None = None
    command: tuple | None = None

    def command_column(self, tau_s: float) -> np.ndarray:
        """d(reading)/dc at c = 0 for a lag of the command's magnitude with time constant
        ``tau_s`` (:mod:`pneubayes.simulation.reading_command`): ``l`` at the window's
        samples less the chamber's start moved by ``l(start)`` along the start
        sensitivity; as :meth:`column` (zeros without the ``command``)."""
        if self.command is None:
            return np.zeros(self.residual_Pa.size)
        t_all, command, before, starts = self.command
        lag = command_lag(t_all, command, float(tau_s), before)
        at = lag[np.asarray(starts)[:, None] + np.arange(np.shape(self.time_s)[1])]
        sens = 1.0 if self.sensitivity is None else np.asarray(self.sensitivity)
        return (at - sens * at[:, :1])[:, 1:].reshape(-1)

    def column(self, tau_s: float) -> np.ndarray:
        """d(reading)/dg at g = 0 for a relaxation of time constant ``tau_s``: ``p - p_bar``
        plus the chamber's start moved by ``p_bar(start) - r0`` along the start
        sensitivity; samples 1..L-1 of every window, flattened (Pa)."""
        p = np.asarray(self.predicted_Pa, dtype=np.float64)
        r0 = p[:, 0]
        bar0 = r0
        if self.history is not None:
            t_all, reading, starts = self.history
            warm = history_low_pass(t_all, reading, np.full((1, 1), float(tau_s)), starts)[0, 0]
            bar0 = np.where(np.isfinite(warm), warm, r0)
        col = relaxed_reading(self.time_s, p[None], np.ones((1, 1)),
                              np.full((1, 1), float(tau_s)), bar0[None, None])[0] - p
        sens = 1.0 if self.sensitivity is None else np.asarray(self.sensitivity)
        col = col + sens * (bar0 - r0)[:, None]
        return col[:, 1:].reshape(-1)


    def play_column(self, width_Pa: float) -> np.ndarray:
        """d(reading)/dh at h = 0 for a play of half-width ``width_Pa``
        (:mod:`pneubayes.simulation.reading_play`): ``p - y`` plus the chamber's start
        moved by ``y(start) - r0`` along the start sensitivity; as :meth:`column`."""
        p = np.asarray(self.predicted_Pa, dtype=np.float64)
        r0 = p[:, 0]
        y0 = r0
        if self.history is not None:
            _, reading, starts = self.history
            warm = history_play(reading, np.full((1, 1), float(width_Pa)), starts)[0, 0]
            y0 = np.where(np.isfinite(warm), warm, r0)
        y, _ = play_rows(p, np.zeros_like(p), float(width_Pa), y0)
        sens = 1.0 if self.sensitivity is None else np.asarray(self.sensitivity)
        col = p - y + sens * (y0 - r0)[:, None]
        return col[:, 1:].reshape(-1)


    def hinge_column(self, threshold_Pa: float, below: bool = False) -> np.ndarray:
        """d(reading)/dc at c = 0 for a knee of the reading at ``threshold_Pa`` (Pa
        absolute; :mod:`pneubayes.simulation.reading_hinge`): ``max(0, p - theta)`` less
        the chamber's start moved by ``max(0, r0 - theta)`` along the start sensitivity
        (with ``below``, a knee below: ``min``); as :meth:`column`."""
        p = np.asarray(self.predicted_Pa, dtype=np.float64)
        sens = 1.0 if self.sensitivity is None else np.asarray(self.sensitivity)
        side = np.minimum if below else np.maximum
        col = side(p - threshold_Pa, 0.0) - sens * side(p[:, :1] - threshold_Pa, 0.0)
        return col[:, 1:].reshape(-1)


def reading_windows(window_set, model, params, solver) -> list[ReadingWindows]:
    """The windows of ``window_set`` (a :class:`~pneubayes.inference.windows.WindowSet`)
    as ``model`` at ``params`` (one set) predicts them by ``solver``, one
    :class:`ReadingWindows` per recording, each with the recording's reading as its
    history."""
    ws = window_set
    resid, sens = ws.residuals_and_sensitivity(model, model.vector(params)[None], solver)
    out, n0 = [], 0
    for b in ws.blocks:
        w = b.starts.size
        r = -resid[0, n0:n0 + w]  # measured minus predicted
        t_all = np.asarray(b.inputs.time_s, dtype=np.float64)
        reading = b.inputs.reading_Pa
        out.append(ReadingWindows(
            t_all[b.starts[:, None] + np.arange(ws.length)],
            np.concatenate([b.measured[:, :1], b.measured[:, 1:] - r], axis=1), r,
            sens[0, n0:n0 + w],
            None if reading is None else (t_all, np.asarray(reading, np.float64), b.starts),
            (t_all, np.asarray(b.inputs.command_V, np.float64),
             b.inputs.command_before_start, b.starts)))
        n0 += w
    return out


def relaxation_columns(blocks: Sequence[ReadingWindows], tau_s: float) -> np.ndarray:
    """:meth:`ReadingWindows.column` of each block, in block order (Pa; 0 where a
    prediction failed)."""
    x = np.concatenate([b.column(tau_s) for b in blocks])
    return np.where(np.isfinite(x), x, 0.0)


def command_columns(blocks: Sequence[ReadingWindows], tau_s: float) -> np.ndarray:
    """:meth:`ReadingWindows.command_column` of each block, in block order (Pa per command
    unit; 0 where a prediction failed)."""
    x = np.concatenate([b.command_column(tau_s) for b in blocks])
    return np.where(np.isfinite(x), x, 0.0)


def hinge_columns(blocks: Sequence[ReadingWindows], threshold_Pa: float,
                  below: bool = False) -> np.ndarray:
    """:meth:`ReadingWindows.hinge_column` of each block, in block order (Pa; 0 where a
    prediction failed)."""
    x = np.concatenate([b.hinge_column(threshold_Pa, below) for b in blocks])
    return np.where(np.isfinite(x), x, 0.0)


def play_columns(blocks: Sequence[ReadingWindows], width_Pa: float) -> np.ndarray:
    """:meth:`ReadingWindows.play_column` of each block, in block order (Pa; 0 where a
    prediction failed)."""
    x = np.concatenate([b.play_column(width_Pa) for b in blocks])
    return np.where(np.isfinite(x), x, 0.0)


class ReadingSearch:
    """Greedy search of reading relaxations in the windows' residual (scikit-learn
    contract: settings in the constructor, :meth:`fit` sets the ``_`` attributes).

    Parameters
    ----------
    time_constants_s : sequence of float
        The grid searched (s, within the reading closure's bounds); the best is refined
        between its neighbours.
    max_terms : int
        Most terms kept (1..2, the reading closure's room).
    min_explained_fraction : float
        A kept term's least share of the residual's uncentred sum of squares.
    min_t : float
        A kept term's least gain over its window-clustered standard error.

    Attributes
    ----------
    terms_ : list of ReadingTerm
        Kept terms, in the order found.
    explained_fraction_ : float
        Share of the residual's uncentred sum of squares the kept terms explain together.
    best_ : ReadingTerm or None
        The best single column's fit, kept or not (what the search saw).
    """

    def __init__(self, time_constants_s: Sequence[float] = tuple(np.geomspace(3e-3, 10.0, 30)),
                 max_terms: int = READING_MAX_TERMS, min_explained_fraction: float = 0.02,
                 min_t: float = 4.0):
        self.time_constants_s = time_constants_s
        self.max_terms = max_terms
        self.min_explained_fraction = min_explained_fraction
        self.min_t = min_t

    def get_params(self) -> dict:
        """The constructor's settings (scikit-learn's contract)."""
        return {"time_constants_s": self.time_constants_s, "max_terms": self.max_terms,
                "min_explained_fraction": self.min_explained_fraction, "min_t": self.min_t}

    #: The most terms the component holds.
    max_terms_allowed = READING_MAX_TERMS
    #: The component's time constants' bounds, s (what the grid must lie within).
    time_constant_bounds_s = TIME_CONSTANT_BOUNDS_S

    def _checked_grid(self) -> np.ndarray:
        """The searched grid, checked."""
        taus = np.asarray(self.time_constants_s, dtype=np.float64)
        lo, hi = self.time_constant_bounds_s
        if taus.ndim != 1 or taus.size < 3 or np.any(np.diff(taus) <= 0) \
                or taus[0] < lo or taus[-1] > hi:
            raise ValueError(f"time_constants_s must be at least 3 increasing values within "
                             f"[{lo}, {hi}] s, got {self.time_constants_s!r}")
        return taus

    def _validate(self, blocks):
        taus = self._checked_grid()
        self._check_blocks(blocks)
        return taus

    def _check_blocks(self, blocks) -> None:
        """Raise ValueError unless the settings besides the grid and ``blocks`` (a list
        of :class:`ReadingWindows`, shapes consistent) are valid."""
        most = self.max_terms_allowed
        if not (isinstance(self.max_terms, int) and 1 <= self.max_terms <= most):
            raise ValueError(f"max_terms must be an integer in 1..{most}, got "
                             f"{self.max_terms!r}")
        if not 0.0 < self.min_explained_fraction < 1.0 or not self.min_t > 0.0:
            raise ValueError("min_explained_fraction must be in (0, 1) and min_t > 0, got "
                             f"{self.min_explained_fraction!r}, {self.min_t!r}")
        if isinstance(blocks, ReadingWindows) or not len(blocks) \
                or not all(isinstance(b, ReadingWindows) for b in blocks):
            raise ValueError("fit takes a list of ReadingWindows, one per recording (at "
                             "least one)")
        for i, b in enumerate(blocks):
            t, p, y = (np.asarray(a) for a in (b.time_s, b.predicted_Pa, b.residual_Pa))
            if t.ndim != 2 or p.shape != t.shape or y.shape != (t.shape[0], t.shape[1] - 1) \
                    or (b.sensitivity is not None and np.shape(b.sensitivity) != t.shape):
                raise ValueError(f"block {i}: times {t.shape}, predicted {p.shape}, residual "
                                 f"{y.shape} and sensitivity {np.shape(b.sensitivity)} must be "
                                 "(W, L), (W, L), (W, L - 1) and (W, L) or None")

    def fit(self, blocks: Sequence[ReadingWindows]) -> "ReadingSearch":
        """Search the windows' residual, one :class:`ReadingWindows` per recording."""
        taus = self._validate(blocks)
        blocks = list(blocks)
        y, windows = stacked_residual([b.residual_Pa for b in blocks])
        ok = np.isfinite(y)
        total = float(y[ok] @ y[ok])
        self.terms_, self.best_, self.explained_fraction_ = [], None, 0.0
        if total <= 0.0:
            return self
        kept_cols: list[np.ndarray] = []
        for _ in range(self.max_terms):
            basis = np.stack(kept_cols, axis=1) if kept_cols else None

            def score(log_tau, basis=basis):  # the sum of squares it adds beside the kept
                x = self._columns(blocks, float(np.exp(log_tau)))
                x = np.where(ok, x, 0.0)
                own = float(x @ x)
                if basis is not None:
                    x = x - basis @ np.linalg.lstsq(basis, x, rcond=None)[0]
                xx = float(x @ x)
                # (a column within rounding of the kept ones adds nothing)
                return 0.0 if xx <= 1e-9 * own else float(x @ np.where(ok, y, 0.0)) ** 2 / xx
            logs = np.log(taus)
            gains = np.array([score(v) for v in logs])
            j = int(np.argmax(gains))
            lo, hi = logs[max(j - 1, 0)], logs[min(j + 1, logs.size - 1)]
            best = minimize_scalar(lambda v: -score(v), bounds=(lo, hi), method="bounded",
                                   options={"xatol": 1e-3})
            log_tau = best.x if -best.fun > gains[j] else logs[j]
            tau = float(np.exp(log_tau))
            col = np.where(ok, self._columns(blocks, tau), 0.0)
            term = self._term(kept_cols + [col], y, ok, windows, tau, total)
            if self.best_ is None:
                self.best_ = term
            if term.explained < self.min_explained_fraction or abs(term.t) < self.min_t:
                break
            kept_cols.append(col)
            self.terms_.append(term)
        if len(kept_cols) > 1:  # the time constants refined together (a greedy first
            kept_cols = self._joint(blocks, y, ok, windows, total, taus)  # pick may be the
        if kept_cols:  # two's compromise)
            x = np.stack(kept_cols, axis=1)
            g = np.linalg.lstsq(x, np.where(ok, y, 0.0), rcond=None)[0]
            e = np.where(ok, y, 0.0) - x @ g
            self.explained_fraction_ = 1.0 - float(e @ e) / total
            self.terms_ = [self._new_term(float(gk), self._value_of(k), k.explained, k.t)
                           for gk, k in zip(g, self.terms_)]
        return self

    def _joint(self, blocks, y, ok, windows, total, taus) -> list[np.ndarray]:
        """The kept terms' time constants refined together (the gains solved for at
        each), ``terms_`` updated; returns their columns."""
        yy = np.where(ok, y, 0.0)
        lo, hi = np.log(taus[0]), np.log(taus[-1])

        def columns(logs):
            return [np.where(ok, self._columns(blocks, float(np.exp(np.clip(v, lo, hi)))),
                             0.0) for v in logs]

        def sse(logs):
            x = np.stack(columns(logs), axis=1)
            e = yy - x @ np.linalg.lstsq(x, yy, rcond=None)[0]
            return float(e @ e) / total
        start = np.log([self._value_of(k) for k in self.terms_])
        best = minimize(sse, start, method="Nelder-Mead",
                        options={"xatol": 1e-3, "fatol": 1e-9, "maxiter": 200})
        logs = np.clip(best.x, lo, hi) if best.fun < sse(start) else start
        cols = columns(logs)
        self.terms_ = [self._term([c for j, c in enumerate(cols) if j != k] + [cols[k]], y, ok,
                                  windows, float(np.exp(logs[k])), total)
                       for k in range(len(cols))]
        return cols

    def _term(self, cols, y, ok, windows, value, total):
        """The last of ``cols`` fitted beside the others: its gain, its own share of the
        sum of squares (beside them) and its window-clustered t."""
        gain, explained, t = last_column_fit(cols, y, ok, windows, total)
        return self._new_term(gain, value, explained, t)

    # the kind of term searched: a subclass searches another (PlaySearch)
    @staticmethod
    def _columns(blocks, value):
        return relaxation_columns(blocks, value)

    @staticmethod
    def _new_term(gain, value, explained, t):
        return ReadingTerm(gain, value, explained, t)

    @staticmethod
    def _value_of(term):
        return term.time_constant_s
