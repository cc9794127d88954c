"""A sequential test on the innovations of a linear regression y = φᵀθ + e.

A *reference* least-squares fit of y on φ runs over a sliding window of N samples that ends
``lag`` samples before the newest one (so that a change in the newest samples does not leak
into it at once); it is re-solved on the ticks where tick % ``every`` == ``phase``. Its
window sums are kept per refit: the rows the window reached since the last one are summed
in one go (`core.kernels.group_products`), so N is ``window_samples`` rounded to a whole
number of refits (`itest_groups`). The standardised innovation
z = (y - φᵀθ_ref)/σ_ref, with σ_ref² = SSE/(N - p) floored at ``min_sigma``², is averaged
over the last M samples:

    T = (1/M) Σ_M z²            (≈ 1 while the reference describes the data)

The state lives in a `core.compiled.Arena` (its own, or the monitor's) and every tick is the
compiled `core.kernels.itest_tick`: ``step`` (one tick) and ``run`` (arrays) are the same
kernel and give bit-equal statistics.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from fdi_daemon.core.compiled import Arena, jit
from fdi_daemon.core.kernels import (
    F64,
    I64,
    ITEST_INTS,
    itest_floats,
    itest_groups,
    itest_tick,
    sums_floats,
)
from fdi_daemon.core.normal_equations import packed_width

__all__ = ["InnovationTest", "packed_row"]


def packed_row(phi: Sequence[float], y: float) -> tuple[float, ...]:
    """One packed product row (order of `packed_products`; the kernel forms the same
    products, `core.kernels.group_products`)."""
    p = len(phi)
    row = [phi[i] * phi[j] for i in range(p) for j in range(i, p)]
    row.extend(phi[i] * y for i in range(p))
    row.append(y * y)
    return tuple(row)


class InnovationTest:
    """Lagged reference fit + windowed mean of squared standardised innovations."""

    __slots__ = (
        "p",
        "window_samples",
        "lag_samples",
        "test_samples",
        "every",
        "phase",
        "min_sigma2",
        "arena",
        "fo",
        "io",
        "_width",
    )

    def __init__(
        self,
        p: int,
        window_samples: int,
        lag_samples: int,
        test_samples: int,
        every: int = 1,
        min_sigma: float = 0.0,
        phase: int = 0,
        arena: Arena | None = None,
    ) -> None:
        if window_samples <= p:
            raise ValueError("window_samples must exceed the number of regressors")
        self.p = int(p)
        self.window_samples = int(window_samples)
        self.lag_samples = int(lag_samples)
        self.test_samples = int(test_samples)
        self.every = int(every)
        self.phase = int(phase) % self.every
        self.min_sigma2 = float(min_sigma) ** 2
        self._width = w = packed_width(self.p)
        p, n, lag, m = self.p, self.window_samples, self.lag_samples, self.test_samples
        self.arena = arena if arena is not None else Arena()
        groups = itest_groups(n, self.every)
        self.fo, self.io = fo, io = self.arena.alloc(
            itest_floats(p, n, lag, m, self.every), ITEST_INTS
        )
        ph = fo
        row = ph + p + 1
        fifo = row + w + 1
        ref = fifo + (lag + self.every) * (p + 1)
        tst = ref + sums_floats(groups, w + 1)
        th = tst + sums_floats(m, 1)
        scr = th + p
        sc = scr + 2 * p * p + p
        self.arena.i[io : io + ITEST_INTS] = (
            p,
            groups,
            lag,
            m,
            self.every,
            self.phase,
            w,
            0,
            0,
            0,
            0,
            0,
            0,
            0,
            0,
            ph,
            row,
            fifo,
            ref,
            tst,
            th,
            scr,
            sc,
            lag + self.every,
            groups * self.every,
        )
        self.reset()

    def _o(self, k: int) -> int:
        return int(self.arena.i[self.io + k])

    def reset(self) -> None:
        f, ii, io = self.arena.f, self.arena.i, self.io
        f[self.fo : self._o(22) + 6] = 0.0
        ii[io + 7 : io + 15] = 0
        ii[io + 7] = self.phase
        sc = self._o(22)
        f[sc : sc + 6] = (self.min_sigma2, math.inf, math.nan, 0.0, 0.0, 1.0 / self.test_samples)

    @property
    def theta(self) -> list[float]:
        th = self._o(20)
        theta: list[float] = self.arena.f[th : th + self.p].tolist()
        return theta

    @property
    def sigma2(self) -> float:
        return float(self.arena.f[self._o(22) + 1])

    @property
    def statistic(self) -> float:
        return float(self.arena.f[self._o(22) + 2])

    @property
    def ok(self) -> bool:
        return bool(self.arena.i[self.io + 8])

    # ------------------------------------------------------------------ per tick
    def step(self, phi: Sequence[float], y: float, row: tuple[float, ...] | None = None) -> float:
        """One tick; returns the statistic T (``row`` is accepted for compatibility and
        not needed: the kernel forms the packed row)."""
        ph = self._o(15)
        f = self.arena.f
        f[ph : ph + self.p] = phi
        f[ph + self.p] = y
        return float(itest_tick(f, self.arena.i, self.io))

    # ------------------------------------------------------------------ batch
    def run(
        self, phi: np.ndarray, y: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
        """Batch ``step``: statistic, reference ok and the reference θ (one array per
        regressor) after every row of phi (n, p)."""
        phi = np.ascontiguousarray(phi, dtype=float).reshape(-1, self.p)
        y = np.ascontiguousarray(y, dtype=float)
        n = y.size
        stat = np.empty(n)
        ok = np.empty(n, dtype=np.bool_)
        theta = np.empty((n, self.p))
        _itest_run(self.arena.f, self.arena.i, self.io, phi, y, stat, ok, theta)
        return stat, ok, [theta[:, q].copy() for q in range(self.p)]


@jit
def _itest_run(
    f: F64, ii: I64, io: int, phi: F64, y: F64, stat: F64, ok: npt.NDArray[np.bool_], theta: F64
) -> None:  # pragma: no cover - jit
    p = ii[io]
    ph = ii[io + 15]
    th = ii[io + 20]
    for k in range(y.shape[0]):
        for q in range(p):
            f[ph + q] = phi[k, q]
        f[ph + p] = y[k]
        stat[k] = itest_tick(f, ii, io)
        ok[k] = ii[io + 8] != 0
        for q in range(p):
            theta[k, q] = f[th + q]
