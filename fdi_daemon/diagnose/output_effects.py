"""Effects at the output: what the sensor and the whole response add — clipping, an offset
(a gain on a constant), a pure gain change and a pure shift (dead time) of the nominal
response ŷ₀. They are static maps of ŷ₀ with a gain."""

from __future__ import annotations

import math

import numpy as np

from fdi_daemon.diagnose.regressors import Regressor


class DeadTimeRegressor(Regressor):
    """u(t − τ) − u(t) with τ = d + f samples, linear interpolation; history starts at 0."""

    def __init__(self, delay_samples: float) -> None:
        self.d = int(math.floor(delay_samples))
        self.frac = float(delay_samples - self.d)
        self.state = np.zeros(self.d + 1)  # u[k-1] .. u[k-d-1]

    def run(self, u, v, x, y0):
        u = np.asarray(u, float)
        ext = np.concatenate([self.state[::-1], u])  # ext[j + d + 1] = u[j]
        h = self.d + 1
        n = len(u)
        delayed = (1 - self.frac) * ext[h - self.d : h - self.d + n] + self.frac * ext[
            h - self.d - 1 : h - self.d - 1 + n
        ]
        self.state = ext[::-1][: self.d + 1].copy()
        return (delayed - u)[:, None]

    def step(self, u, v, x, y0):
        s = self.state
        delayed_d = s[self.d - 1] if self.d > 0 else u
        delayed = (1 - self.frac) * delayed_d + self.frac * s[self.d]
        self.state = np.concatenate([[u], s[:-1]])
        return [float(delayed - u)]


class DelayedOutputRegressor(DeadTimeRegressor):
    """ŷ₀(t − τ) − ŷ₀(t): the nominal response shifted by a dead time τ (a dead time at the
    input of a linear model shifts its whole response)."""

    def run(self, u, v, x, y0):
        return super().run(y0, v, x, y0)

    def step(self, u, v, x, y0):
        return super().step(y0, v, x, y0)


def out_saturate(level, c):
    return lambda u, v, x, y0: [np.clip(y0 - c, -level, level) - (y0 - c)]
