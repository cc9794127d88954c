"""Effects at the input: the input reaches the plant late, clipped, through a dead zone or
with play. They act through Ĝ itself (Ĝ N(u) − Ĝ u = Ĝ [N(u) − u]), so each enters as
B_e/Â on φ = N(u) − u (`effects.columns`). A dead time at the input shifts the whole
linear response: it is tested as a pure shift of ŷ₀ (`output_effects`, by the refit check
`select.linear_round`).
"""

from __future__ import annotations

import numpy as np

from fdi_daemon.diagnose.regressors import Regressor


class BacklashRegressor(Regressor):
    """play_g(u) − u: the output follows the input with a gap g (starts centred on u[0])."""

    def __init__(self, gap: float) -> None:
        self.half = 0.5 * float(gap)
        self.state: float | None = None

    def step(self, u, v, x, y0):
        y = u if self.state is None else self.state
        if u - y > self.half:
            y = u - self.half
        elif y - u > self.half:
            y = u + self.half
        self.state = y
        return [float(y - u)]

    def run(self, u, v, x, y0):
        u = np.asarray(u, float)
        if u.size == 0:
            return np.zeros((0, 1))
        half = self.half
        y = u[0] if self.state is None else self.state
        out = []
        append = out.append
        for ui in u.tolist():  # the same arithmetic as step(), without the call per sample
            if ui - y > half:
                y = ui - half
            elif y - ui > half:
                y = ui + half
            append(y)
        self.state = y
        return (np.array(out) - u).reshape(-1, 1)


def saturate(level, c):
    return lambda u, v, x, y0: [np.clip(u - c, -level, level) - (u - c)]


def dead_zone(width, c):
    return lambda u, v, x, y0: [np.sign(u - c) * np.maximum(np.abs(u - c) - width, 0.0) - (u - c)]
