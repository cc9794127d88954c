"""γ_f's 99 % interval from a moving-block bootstrap of the cost profile, eq. (13).

The fits of G_e along the γ grid leave a per-sample error e_t(γ). The profile SSE(γ) = Σ_t
e_t(γ)² is rebuilt from blocks of consecutive samples drawn with replacement (Künsch's moving
block bootstrap), and γ* = argmin of each rebuilt profile. Blocks keep the error's
correlation (a periodic misfit, an amplitude step that wants another γ) inside each draw, so
the spread of γ* says how well the window pins γ down, not how many samples it has.

G_e is not refitted per draw: along the profile path dŷ/dγ is the γ-sensitivity with G_e's
own directions projected out (the envelope theorem), so the path's Σ* e·dŷ/dγ is the
profiled score the refitted bootstrap would see, to first order.

Block length: Politis & White (2004, with Patton, Politis & White 2009's correction) for
the moving block bootstrap of the mean of that score, e_t(γ̂)·de_t/dγ.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: bootstrap draws (the 0.5 % and 99.5 % percentiles rest on about ten draws each)
DRAWS = 2000
#: the interval's coverage
LEVEL = 0.99


@dataclass(frozen=True)
class BootstrapInterval:
    """Percentile interval of γ (s/m) and how it was drawn."""

    low: float
    high: float
    block_samples: int
    draws: int


def optimal_block_length(x: np.ndarray) -> int:
    """Politis–White block length (samples) for the moving block bootstrap of mean(x)."""
    x = np.asarray(x, dtype=float) - np.mean(x)
    n = len(x)
    if n < 16 or not np.any(x):
        return 1
    nfft = int(2 ** np.ceil(np.log2(2 * n)))
    acov = np.fft.irfft(np.abs(np.fft.rfft(x, nfft)) ** 2, nfft)[:n] / n
    rho = acov / acov[0]
    max_lag = min(n // 4, int(np.ceil(np.sqrt(n))) + 5 * int(np.ceil(np.sqrt(np.log10(n)))))
    run = max(5, int(np.ceil(np.sqrt(np.log10(n)))))
    bound = 2.0 * np.sqrt(np.log10(n) / n)
    small = np.abs(rho[1 : max_lag + 1]) < bound
    m_hat = max_lag
    for m in range(max_lag - run + 1):
        if np.all(small[m : m + run]):
            m_hat = m
            break
    m = min(2 * max(m_hat, 1), max_lag)
    lags = np.arange(-m, m + 1)
    t = np.abs(lags) / m
    window = np.where(t <= 0.5, 1.0, np.where(t <= 1.0, 2.0 * (1.0 - t), 0.0))
    r = acov[np.abs(lags)]
    g = float(np.sum(window * np.abs(lags) * r))
    spectrum0 = float(np.sum(window * r))
    d_mbb = 4.0 / 3.0 * spectrum0**2
    if d_mbb <= 0:
        return 1
    block = (2.0 * g**2 / d_mbb) ** (1.0 / 3.0) * n ** (1.0 / 3.0)
    return int(np.clip(np.ceil(block), 1, n // 4))


def _minimisers(grid: np.ndarray, profiles: np.ndarray) -> np.ndarray:
    """argmin of each row, refined by the parabola through the least point and its
    neighbours (kept within them)."""
    best = np.argmin(profiles, axis=1)
    gamma = grid[best].astype(float)
    inner = (best > 0) & (best < len(grid) - 1)
    rows = np.flatnonzero(inner)
    i = best[rows]
    left, mid, right = profiles[rows, i - 1], profiles[rows, i], profiles[rows, i + 1]
    curve = left - 2.0 * mid + right
    step = grid[1] - grid[0]
    shift = np.where(curve > 0, 0.5 * (left - right) / np.where(curve > 0, curve, 1.0), 0.0)
    gamma[rows] += np.clip(shift, -1.0, 1.0) * step
    return gamma


def bootstrap_interval(
    grid: np.ndarray,
    errors: np.ndarray,
    best: int,
    draws: int = DRAWS,
    level: float = LEVEL,
    seed: int = 0,
    block_samples: int | None = None,
) -> BootstrapInterval:
    """The moving-block bootstrap percentile interval of γ.

    grid: the γ grid (uniform); errors: e_t(γ) on the fitted window, one row per grid point;
    best: the grid index of least SSE; block_samples: the block length (default: the
    Politis–White choice). Seeded: the same data give the same interval.
    """
    grid = np.asarray(grid, dtype=float)
    errors = np.asarray(errors, dtype=float)
    n = errors.shape[1]
    lo_i, hi_i = max(best - 1, 0), min(best + 1, len(grid) - 1)
    slope = (errors[hi_i] - errors[lo_i]) / max(grid[hi_i] - grid[lo_i], 1e-12)
    block = block_samples or optimal_block_length(errors[best] * slope)
    sums = np.zeros((len(grid), n + 1))
    np.cumsum(errors**2, axis=1, out=sums[:, 1:])
    block_sse = (sums[:, block:] - sums[:, : n + 1 - block]).T  # (starts, grid)
    blocks = int(np.ceil(n / block))
    rng = np.random.default_rng(seed)
    gammas = []
    for chunk in np.array_split(np.arange(draws), max(1, draws * blocks // 200_000)):
        starts = rng.integers(0, block_sse.shape[0], size=(len(chunk), blocks))
        profiles = np.zeros((len(chunk), len(grid)))
        for column in starts.T:  # block by block: one profile per draw held, never all blocks
            profiles += block_sse[column]
        gammas.append(_minimisers(grid, profiles))
    gamma = np.concatenate(gammas)
    tail = 100.0 * (1.0 - level) / 2.0
    low, high = np.percentile(gamma, [tail, 100.0 - tail])
    return BootstrapInterval(float(low), float(high), block, draws)
