"""A sequential test on the innovations of a linear regression y = φᵀθ + e.

A *reference* least-squares fit of y on φ runs over a sliding window of N samples that ends
``lag`` samples before the newest one (so that a change in the newest samples does not leak
into it at once); it is re-solved on the ticks where tick % ``every`` == ``phase``. The standardised innovation
z = (y - φᵀθ_ref)/σ_ref, with σ_ref² = SSE/(N - p) floored at ``min_sigma``², is averaged
over the last M samples:

    T = (1/M) Σ_M z²            (≈ 1 while the reference describes the data)

``step`` (one tick, floats) and ``run`` (arrays) use the same arithmetic in the same order and
give bit-equal statistics.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence

import numpy as np

from fdi_daemon.core.normal_equations import packed_products, packed_width, solve_packed
from fdi_daemon.core.sliding_sums import SlidingSums

__all__ = ["InnovationTest", "packed_row", "innovation"]


def packed_row(phi: Sequence[float], y: float) -> tuple[float, ...]:
    """One packed product row (order of `packed_products`)."""
    p = len(phi)
    if p == 4:  # the monitor's case, spelled out (it runs twice per tick)
        a, b, c, d = phi
        return (a * a, a * b, a * c, a * d, b * b, b * c, b * d, c * c, c * d, d * d,
                a * y, b * y, c * y, d * y, y * y)
    row = [phi[i] * phi[j] for i in range(p) for j in range(i, p)]
    row.extend(phi[i] * y for i in range(p))
    row.append(y * y)
    return tuple(row)


def innovation(y, phi, theta):
    """e = y - φᵀθ for floats (phi: sequence of floats) or arrays (phi: sequence of columns)."""
    acc = theta[0] * phi[0]
    for i in range(1, len(theta)):
        acc = acc + theta[i] * phi[i]
    return y - acc


class InnovationTest:
    """Lagged reference fit + windowed mean of squared standardised innovations."""

    __slots__ = ("p", "window_samples", "lag_samples", "test_samples", "every", "phase",
                 "min_sigma2",
                 "_dof", "_width", "_fifo", "_ref", "_test", "_tick", "theta", "sigma2", "ok",
                 "statistic")

    def __init__(self, p: int, window_samples: int, lag_samples: int, test_samples: int,
                 every: int = 1, min_sigma: float = 0.0, phase: int = 0) -> None:
        if window_samples <= p:
            raise ValueError("window_samples must exceed the number of regressors")
        self.p = int(p)
        self.window_samples = int(window_samples)
        self.lag_samples = int(lag_samples)
        self.test_samples = int(test_samples)
        self.every = int(every)
        self.phase = int(phase) % self.every
        self.min_sigma2 = float(min_sigma) ** 2
        self._dof = self.window_samples - self.p
        self._width = packed_width(self.p)
        self._ref = SlidingSums(self.window_samples, self._width)
        self._test = SlidingSums(self.test_samples, 1)
        self.reset()

    def reset(self) -> None:
        self._fifo: deque = deque()
        self._ref.reset()
        self._test.reset()
        self._tick = 0
        self.theta = [0.0] * self.p
        self.sigma2 = math.inf
        self.ok = False
        self.statistic = math.nan

    @property
    def reference_sums(self) -> list[float]:
        """The packed sums of the reference window (ending ``lag`` samples ago)."""
        return list(self._ref.sliding)

    @property
    def recent_rows(self) -> list[tuple[float, ...]]:
        """The packed rows not yet in the reference window (the last ``lag`` ticks)."""
        return list(self._fifo)

    def get_state(self) -> dict:
        return {"fifo": list(self._fifo), "ref": self._ref.get_state(),
                "test": self._test.get_state(), "tick": self._tick, "theta": list(self.theta),
                "sigma2": self.sigma2, "ok": self.ok, "statistic": self.statistic}

    def set_state(self, st: dict) -> None:
        self._fifo = deque(st["fifo"])
        self._ref.set_state(st["ref"])
        self._test.set_state(st["test"])
        self._tick = st["tick"]
        self.theta = list(st["theta"])
        self.sigma2 = st["sigma2"]
        self.ok = st["ok"]
        self.statistic = st["statistic"]

    # ------------------------------------------------------------------ per tick
    def step(self, phi: Sequence[float], y: float, row: tuple[float, ...] | None = None
             ) -> float:
        """One tick; returns the statistic T. ``row``: `packed_row(phi, y)` if already made."""
        if row is None:
            row = packed_row(phi, y)
        fifo = self._fifo
        fifo.append(row)
        if len(fifo) > self.lag_samples:
            sums = self._ref.push(fifo.popleft())
        else:
            sums = self._ref.sliding
        if self._tick % self.every == self.phase:
            if self._ref.count == self.window_samples:
                theta, sse, ok = solve_packed(sums, self.p)
                s2 = sse / self._dof
                self.theta = theta
                self.sigma2 = s2 if s2 > self.min_sigma2 else self.min_sigma2
                self.ok = bool(ok)
            else:
                self.ok = False
        self._tick += 1
        if self.ok:
            e = innovation(y, phi, self.theta)
            z2 = e * e / self.sigma2
        else:
            z2 = 0.0
        self.statistic = self._test.push((z2,))[0] / self.test_samples
        return self.statistic

    # ------------------------------------------------------------------ batch
    def run(self, phi: np.ndarray, y: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
        """Batch ``step``: statistic, reference ok and the reference θ (one array per
        regressor) after every row of phi (n, p)."""
        n = len(y)
        p, W = self.p, self._width
        ticks = self._tick + np.arange(n)
        rows = packed_products(phi, y)
        pending = np.array(list(self._fifo), dtype=float).reshape(-1, W)
        queue = np.concatenate([pending, rows])
        n_push = max(0, queue.shape[0] - self.lag_samples)
        start_sums = list(self._ref.sliding)
        start_count = self._ref.count
        pushed, counts = self._ref.run(queue[:n_push])
        self._fifo = deque(tuple(x) for x in queue[n_push:].tolist())
        offset = n - n_push  # the first `offset` ticks push nothing (the lag is filling)
        solve_at = np.flatnonzero(ticks % self.every == self.phase)
        if solve_at.size:
            j = solve_at - offset
            has = j >= 0
            if has.all():  # the usual case: every solve tick has pushed
                sel = pushed[j]
                full = counts[j] == self.window_samples
            else:
                sel = np.empty((solve_at.size, W))
                sel[~has] = start_sums
                sel[has] = pushed[j[has]]
                full = np.full(solve_at.size, start_count == self.window_samples)
                full[has] = counts[j[has]] == self.window_samples
            with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
                th, sse, sok = solve_packed(sel.T, p)
                s2 = sse / self._dof
            s2 = np.where(s2 > self.min_sigma2, s2, self.min_sigma2)
            sok = np.asarray(sok) & full
            # per tick: the latest solve (ok), and the latest solve on a full window (θ, σ²;
            # a solve on a window that is not full only clears ok, as in step)
            at = np.full(n, -1)
            at[solve_at] = np.arange(solve_at.size)
            at = np.maximum.accumulate(at)
            src = np.maximum.accumulate(np.where(full, np.arange(solve_at.size), -1))
            value_src = np.where(at >= 0, src[np.maximum(at, 0)], -1)
            have = value_src >= 0
            pick = np.maximum(value_src, 0)
            theta = [np.where(have, np.asarray(th[q])[pick], self.theta[q]) for q in range(p)]
            sigma2 = np.where(have, s2[pick], self.sigma2)
            ok = np.where(at >= 0, sok[np.maximum(at, 0)], self.ok)
            if have[-1]:
                self.theta = [float(theta[q][-1]) for q in range(p)]
                self.sigma2 = float(sigma2[-1])
            self.ok = bool(ok[-1])
        else:
            theta = [np.full(n, self.theta[q]) for q in range(p)]
            sigma2 = np.full(n, self.sigma2)
            ok = np.full(n, self.ok)
        with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
            e = innovation(y, [phi[:, i] for i in range(p)], theta)
            z2 = np.where(ok, e * e / sigma2, 0.0)
        stat = self._test.run(z2[:, None])[0][:, 0] / self.test_samples
        self._tick += n
        if n:
            self.statistic = float(stat[-1])
        return stat, ok, theta
