"""Sliding-window least squares of eqs. (15)–(17): θ = argmin Σ (y - θ1 g1 - θ2 g2)².

Over the last N samples (the window) the estimate is the solution of the 2×2 normal
equations (eq. 17)

    [S11 S12] [θ1]   [S1y]          S_ij = Σ g_i g_j,  S_iy = Σ g_i y,  Syy = Σ y²
    [S12 S22] [θ2] = [S2y]

O(1) per tick: the six window sums are `SlidingSums` (sliding sums with an exact refresh
every N ticks, so no drift and no O(N) spike). ``run`` is the batch path with the same
arithmetic in the same order, so it is bit-equal to ``step``.

Ill-conditioned windows. When the rig is at rest (v ≈ 0) g2 ≈ 0 and g1 is the filtered sign
of noise; when g1 and g2 are nearly collinear (a single pure sine, say) the split between θ1
and θ2 is arbitrary. A window is *valid* when it is full, each regressor's mean square
exceeds ``min_mean_square`` and the normalised determinant 1 - ρ² = det / (S11 S22)
exceeds ``min_rcond``; otherwise θ is NaN and ``ok`` is False, and the detector holds
its decision (never an alarm on an invalid window).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fdi_daemon.core.sliding_sums import SlidingSums

__all__ = ["WindowLS", "WindowSolution", "solve_sums", "products", "N_SUMS", "MIN_RCOND"]

#: sums kept per window: S11, S12, S22, S1y, S2y, Syy
N_SUMS = 6
#: default floor of 1 - ρ² = det / (S11 S22) for a valid window
MIN_RCOND = 1e-6

_NAN = math.nan


@dataclass(frozen=True)
class WindowSolution:
    """Vectorised solution of the normal equations for a sequence of windows."""

    theta1: np.ndarray
    theta2: np.ndarray
    ok: np.ndarray  # bool
    sse: np.ndarray  # Σ e² of the window fit (NaN where not ok)
    det: np.ndarray  # S11 S22 - S12²


class WindowLS:
    """Sliding-window least squares for two regressors (eqs. 15–17)."""

    __slots__ = ("window_samples", "min_rcond", "min_mean_square", "_sums", "_min_s11",
                 "_min_s22", "ok", "sse", "theta1", "theta2")

    def __init__(self, window_samples: int, min_rcond: float = MIN_RCOND,
                 min_mean_square: tuple[float, float] = (0.0, 0.0)) -> None:
        if isinstance(window_samples, bool) or not isinstance(window_samples, (int, np.integer)) \
                or window_samples < 3:
            raise ValueError(f"window_samples must be a whole number >= 3, got {window_samples!r}")
        if not 0.0 <= float(min_rcond) < 1.0:
            raise ValueError("min_rcond must lie in [0, 1)")
        ms1, ms2 = (float(v) for v in min_mean_square)
        if not (ms1 >= 0 and ms2 >= 0 and math.isfinite(ms1) and math.isfinite(ms2)):
            raise ValueError("min_mean_square must be two finite numbers >= 0")
        self.window_samples = int(window_samples)
        self.min_rcond = float(min_rcond)
        self.min_mean_square = (ms1, ms2)
        self._min_s11 = ms1 * self.window_samples
        self._min_s22 = ms2 * self.window_samples
        self._sums = SlidingSums(self.window_samples, N_SUMS)
        self.reset()

    def reset(self) -> None:
        """Empty window."""
        self._sums.reset()
        self.ok = False
        self.sse = _NAN
        self.theta1 = _NAN
        self.theta2 = _NAN

    @property
    def count(self) -> int:
        """Samples in the window (≤ window_samples)."""
        return self._sums.count

    @property
    def sums(self) -> tuple[float, ...]:
        """Current (S11, S12, S22, S1y, S2y, Syy)."""
        return tuple(self._sums.sliding)

    def get_state(self) -> dict:
        """A copy of the state (see `SlidingSums.get_state`)."""
        return self._sums.get_state()

    def set_state(self, state: dict) -> None:
        self._sums.set_state(state)
        self._solve()

    def push(self, g1: float, g2: float, y: float) -> None:
        """Add one sample to the window (and drop the oldest); O(1)."""
        self._sums.push((g1 * g1, g1 * g2, g2 * g2, g1 * y, g2 * y, y * y))

    def step(self, g1: float, g2: float, y: float) -> tuple[float, float]:
        """Push one sample and return θ = (θ1, θ2) of the current window (NaN if invalid)."""
        self._sums.push((g1 * g1, g1 * g2, g2 * g2, g1 * y, g2 * y, y * y))
        return self._solve()

    def _solve(self) -> tuple[float, float]:
        s11, s12, s22, s1y, s2y, syy = self._sums.sliding
        det = s11 * s22 - s12 * s12
        if (self._sums.count == self.window_samples and s11 > self._min_s11
                and s22 > self._min_s22 and det > self.min_rcond * (s11 * s22)):
            t1 = (s22 * s1y - s12 * s2y) / det
            t2 = (s11 * s2y - s12 * s1y) / det
            sse = syy - t1 * s1y - t2 * s2y
            self.ok = True
            self.sse = sse if sse > 0.0 else 0.0
        else:
            t1 = t2 = _NAN
            self.ok = False
            self.sse = _NAN
        self.theta1 = t1
        self.theta2 = t2
        return t1, t2

    def run_sums(self, g1: np.ndarray, g2: np.ndarray, y: np.ndarray) -> tuple[np.ndarray,
                                                                            np.ndarray]:
        """Push arrays; returns (sums after every sample, shape (n, 6); samples in the window).

        Bit-equal to calling ``push`` per sample and reading ``sums``.
        """
        g1 = np.asarray(g1, dtype=float)
        g2 = np.asarray(g2, dtype=float)
        y = np.asarray(y, dtype=float)
        n = g1.size
        if not (g1.shape == g2.shape == y.shape == (n,)):
            raise ValueError("g1, g2 and y must be 1-D arrays of equal length")
        sums, counts = self._sums.run(products(g1, g2, y))
        self._solve()
        return sums, counts

    def run(self, g1: np.ndarray, g2: np.ndarray, y: np.ndarray) -> tuple[np.ndarray,
                                                                       np.ndarray]:
        """Batch ``step``: θ1 and θ2 after every sample (NaN where the window is invalid)."""
        sums, counts = self.run_sums(g1, g2, y)
        sol = solve_sums(sums, counts, self.window_samples, self.min_rcond,
                         self.min_mean_square)
        return sol.theta1, sol.theta2


def products(g1: np.ndarray, g2: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The (n, 6) rows g1², g1 g2, g2², g1 y, g2 y, y² that the window sums add up."""
    out = np.empty((g1.size, N_SUMS))
    np.multiply(g1, g1, out=out[:, 0])
    np.multiply(g1, g2, out=out[:, 1])
    np.multiply(g2, g2, out=out[:, 2])
    np.multiply(g1, y, out=out[:, 3])
    np.multiply(g2, y, out=out[:, 4])
    np.multiply(y, y, out=out[:, 5])
    return out


def solve_sums(sums: np.ndarray, counts: np.ndarray, window_samples: int,
               min_rcond: float, min_mean_square: tuple[float, float]) -> WindowSolution:
    """Eq. (17) for every row of ``sums`` (same arithmetic as ``WindowLS.step``)."""
    s11, s12, s22, s1y, s2y, syy = (sums[:, i] for i in range(N_SUMS))
    det = s11 * s22 - s12 * s12
    ok = ((np.asarray(counts) == window_samples)
          & (s11 > min_mean_square[0] * window_samples)
          & (s22 > min_mean_square[1] * window_samples)
          & (det > min_rcond * (s11 * s22)))
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (s22 * s1y - s12 * s2y) / det
        t2 = (s11 * s2y - s12 * s1y) / det
        sse = syy - t1 * s1y - t2 * s2y
    sse = np.where(sse > 0.0, sse, 0.0)
    t1 = np.where(ok, t1, np.nan)
    t2 = np.where(ok, t2, np.nan)
    sse = np.where(ok, sse, np.nan)
    return WindowSolution(theta1=t1, theta2=t2, ok=ok, sse=sse, det=det)
