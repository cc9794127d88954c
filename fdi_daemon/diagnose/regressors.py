"""Regressor blocks: φ(u, v, x, ŷ₀) as streaming blocks (`step` per sample, `run` per array,
explicit state), so that the augmented model computes exactly what was fitted."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np


class Regressor:
    """Base: stateless φ; subclasses with memory override `run`/`step` and keep ``state``."""

    n_out = 1

    def run(self, u, v, x, y0) -> np.ndarray:  # (n, n_out)
        raise NotImplementedError

    def step(self, u: float, v: float, x: float, y0: float) -> list[float]:
        return [
            float(c)
            for c in self.run(np.array([u]), np.array([v]), np.array([x]), np.array([y0]))[0]
        ]


class Static(Regressor):
    """φ = fn(u, v, x, ŷ₀): a memoryless map (n_out columns)."""

    def __init__(self, fn: Callable[..., list[np.ndarray]], n_out: int = 1) -> None:
        self.fn = fn
        self.n_out = n_out

    def run(self, u, v, x, y0):
        return np.column_stack(
            self.fn(
                np.asarray(u, float),
                np.asarray(v, float),
                np.asarray(x, float),
                np.asarray(y0, float),
            )
        )
