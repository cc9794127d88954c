"""Sums of the last N rows of a stream of k-vectors, O(1) per tick, exact every N ticks.

The stream is cut into blocks of N rows. Within the current block a fresh accumulator C
adds the rows pushed so far (additions only); the ring keeps, for every position i in
the block, the accumulator value C_prev[i] of the previous block and its total S_prev.
The window of the last N rows is the tail of the previous block plus the head of this one:

    Σ window = (S_prev - C_prev[i]) + C[i]  =  S_prev + (C[i] - C_prev[i])

and at the end of each block it is C itself (exact: additions only). So the sums never
drift by more than one block of rounding, nothing accumulates without bound, and every
tick costs the same (no O(N) recomputation spike).

``run`` is the batch path: a compiled loop (numba) doing the same additions in the same
order, so it is bit-equal to ``push``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numba import njit

__all__ = ["SlidingSums"]


class SlidingSums:
    """Window sums of ``width``-vectors over the last ``window_samples`` pushes."""

    __slots__ = ("window_samples", "width", "_zero", "_ring", "_ring_arr", "_pos", "_count",
                 "_prev_total", "_fresh", "sliding")

    def __init__(self, window_samples: int, width: int) -> None:
        if isinstance(window_samples, bool) or not isinstance(window_samples, (int, np.integer)) \
                or window_samples < 1:
            raise ValueError(f"window_samples must be a whole number >= 1, got {window_samples!r}")
        if isinstance(width, bool) or not isinstance(width, (int, np.integer)) or width < 1:
            raise ValueError(f"width must be a whole number >= 1, got {width!r}")
        self.window_samples = int(window_samples)
        self.width = int(width)
        self._zero = (0.0,) * self.width
        self.reset()

    def reset(self) -> None:
        """Empty window."""
        # C_prev[i], then C[i] once reached; a list of tuples for push, an array for run
        # (whichever was used last holds it, the other is None)
        self._ring = [self._zero] * self.window_samples
        self._ring_arr = None
        self._pos = 0  # position in the current block
        self._count = 0
        self._prev_total = [0.0] * self.width  # S_prev
        self._fresh = [0.0] * self.width  # C of the current block so far
        self.sliding = [0.0] * self.width  # the current window sums (read, never write)

    @property
    def count(self) -> int:
        """Rows in the window (≤ window_samples)."""
        return self._count

    def get_state(self) -> dict:
        """A copy of the state."""
        return {"ring": self._ring_array().copy(),
                "pos": self._pos, "count": self._count,
                "prev_total": np.array(self._prev_total), "fresh": np.array(self._fresh),
                "sliding": np.array(self.sliding)}

    def set_state(self, state: dict) -> None:
        ring = np.asarray(state["ring"], dtype=float).reshape(-1, self.width)
        if ring.shape[0] != self.window_samples:
            raise ValueError("ring length does not match window_samples")
        self._ring = None
        self._ring_arr = ring.copy()
        self._pos = int(state["pos"])
        self._count = int(state["count"])
        self._prev_total = [float(v) for v in state["prev_total"]]
        self._fresh = [float(v) for v in state["fresh"]]
        self.sliding = [float(v) for v in state["sliding"]]

    def _ring_array(self) -> np.ndarray:
        if self._ring_arr is None:
            self._ring_arr = np.array(self._ring, dtype=float).reshape(-1, self.width)
            self._ring = None
        return self._ring_arr

    def push(self, new: Sequence[float]) -> list[float]:
        """Add one row (``width`` floats); returns the window sums (do not modify them)."""
        if self._ring is None:
            self._ring = [tuple(row) for row in self._ring_arr.tolist()]
            self._ring_arr = None
        pos = self._pos
        c = [a + b for a, b in zip(self._fresh, new)]
        before = self._ring[pos]
        self._ring[pos] = tuple(c)
        if self._count < self.window_samples:
            self._count += 1
        if pos + 1 == self.window_samples:  # end of the block: exact
            self.sliding = c
            self._prev_total = c
            self._fresh = [0.0] * self.width
            self._pos = 0
        else:
            self.sliding = [p + (x - y) for p, x, y in zip(self._prev_total, c, before)]
            self._fresh = c
            self._pos = pos + 1
        return self.sliding

    def run(self, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Push an (n, width) array; returns (window sums after every row, rows in the window).

        Bit-equal to calling ``push`` per row (the compiled loop does the same additions).
        """
        new = np.ascontiguousarray(rows, dtype=float)
        if new.ndim != 2 or new.shape[1] != self.width:
            raise ValueError(f"rows must have shape (n, {self.width})")
        n = new.shape[0]
        N, W = self.window_samples, self.width
        counts = np.minimum(self._count + np.arange(1, n + 1), N)
        if n == 0:
            return np.empty((0, W)), counts
        ring = self._ring_array()
        out = np.empty((n, W))
        prev_total = np.array(self._prev_total)
        fresh = np.array(self._fresh)
        sliding = np.array(self.sliding)
        self._pos = int(_run_kernel(new, ring, self._pos, prev_total, fresh, sliding, out))
        self._count = int(counts[-1])
        self._prev_total = prev_total.tolist()
        self._fresh = fresh.tolist()
        self.sliding = sliding.tolist()
        return out, counts


@njit(cache=True, nogil=True)
def _run_kernel(new, ring, pos, prev_total, fresh, sliding, out):  # pragma: no cover - jit
    """`SlidingSums.push` for every row of ``new`` (state arrays updated in place)."""
    n, width = new.shape
    N = ring.shape[0]
    for k in range(n):
        for w in range(width):
            fresh[w] = fresh[w] + new[k, w]
        if pos + 1 == N:
            for w in range(width):
                ring[pos, w] = fresh[w]
                sliding[w] = fresh[w]
                prev_total[w] = fresh[w]
                fresh[w] = 0.0
            pos = 0
        else:
            for w in range(width):
                before = ring[pos, w]
                ring[pos, w] = fresh[w]
                sliding[w] = prev_total[w] + (fresh[w] - before)
            pos += 1
        for w in range(width):
            out[k, w] = sliding[w]
    return pos
