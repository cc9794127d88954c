"""The status snapshot's θ history: the newest points (t, θ1, θ2) of every n-th tick.

A ring of rows in one array, so that a batch of ticks (`Monitor.run`) writes its points with
one slice assignment instead of a Python tuple per point (most of which the next chunk would
overwrite), and a single tick (`Monitor.step`) writes one row.
"""

from __future__ import annotations

import numpy as np


class History:
    """The newest ``size`` points (t s, θ1, θ2), oldest first from `points`."""

    __slots__ = ("_rows", "_written")

    def __init__(self, size: int) -> None:
        self._rows = np.full((size, 3), np.nan)
        self._written = 0  # points ever written; the next goes to row _written % size

    def append(self, t: float, theta1: float, theta2: float) -> None:
        row = self._rows[self._written % len(self._rows)]
        row[0] = t
        row[1] = theta1
        row[2] = theta2
        self._written += 1

    def extend(self, t: np.ndarray, theta1: np.ndarray, theta2: np.ndarray) -> None:
        """Points in time order (arrays of equal length, views welcome); only the newest
        ``size`` stay."""
        size = len(self._rows)
        count = len(t)
        keep = min(count, size)
        first = (self._written + count - keep) % size  # the row of the first point kept
        split = min(keep, size - first)  # points before the ring wraps
        for col, values in enumerate((t, theta1, theta2)):
            newest = values[count - keep :]
            self._rows[first : first + split, col] = newest[:split]
            self._rows[: keep - split, col] = newest[split:]
        self._written += count

    def points(self) -> np.ndarray:
        """The points held, oldest first: an array of rows (t, θ1, θ2)."""
        size = len(self._rows)
        if self._written <= size:
            held: np.ndarray = self._rows[: self._written].copy()
            return held
        start = self._written % size
        return np.concatenate([self._rows[start:], self._rows[:start]])
