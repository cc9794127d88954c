"""Sliding-window least squares of eqs. (15)–(17): θ = argmin Σ (y - θ1 g1 - θ2 g2)².

Over the last N samples (the window) the estimate is the solution of the 2×2 normal
equations (eq. 17)

    [S11 S12] [θ1]   [S1y]          S_ij = Σ g_i g_j,  S_iy = Σ g_i y,  Syy = Σ y²
    [S12 S22] [θ2] = [S2y]

The monitor keeps the six window sums and solves eq. (17) per tick inside its compiled
kernel (`detect.kernel.chain_tick`, sums by `core.kernels.sums_push`: O(1) per tick, exact
every N ticks). `solve_sums` is the same solve for an array of window sums (a batch's
``sums``, the commissioning baseline).

Ill-conditioned windows. When the rig is at rest (v ≈ 0) g2 ≈ 0 and g1 is the filtered sign
of noise; when g1 and g2 are nearly collinear (a single pure sine, say) the split between θ1
and θ2 is arbitrary. A window is *valid* when it is full, each regressor's mean square
exceeds ``min_mean_square`` and the normalised determinant 1 - ρ² = det / (S11 S22)
exceeds ``min_rcond``; otherwise θ is NaN and ``ok`` is False, and the detector holds
its decision (never an alarm on an invalid window).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["WindowSolution", "solve_sums", "N_SUMS", "MIN_RCOND"]

#: sums kept per window: S11, S12, S22, S1y, S2y, Syy
N_SUMS = 6
#: default floor of 1 - ρ² = det / (S11 S22) for a valid window
MIN_RCOND = 1e-6


@dataclass(frozen=True)
class WindowSolution:
    """Vectorised solution of the normal equations for a sequence of windows."""

    theta1: np.ndarray
    theta2: np.ndarray
    ok: np.ndarray  # bool
    sse: np.ndarray  # Σ e² of the window fit (NaN where not ok)
    det: np.ndarray  # S11 S22 - S12²


def solve_sums(
    sums: np.ndarray,
    counts: np.ndarray,
    window_samples: int,
    min_rcond: float,
    min_mean_square: tuple[float, float],
) -> WindowSolution:
    """Eq. (17) for every row of ``sums`` (same arithmetic as `detect.kernel.chain_tick`)."""
    s11, s12, s22, s1y, s2y, syy = (sums[:, i] for i in range(N_SUMS))
    det = s11 * s22 - s12 * s12
    ok = (
        (np.asarray(counts) == window_samples)
        & (s11 > min_mean_square[0] * window_samples)
        & (s22 > min_mean_square[1] * window_samples)
        & (det > min_rcond * (s11 * s22))
    )
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (s22 * s1y - s12 * s2y) / det
        t2 = (s11 * s2y - s12 * s1y) / det
        sse = syy - t1 * s1y - t2 * s2y
    sse = np.where(sse > 0.0, sse, 0.0)
    t1 = np.where(ok, t1, np.nan)
    t2 = np.where(ok, t2, np.nan)
    sse = np.where(ok, sse, np.nan)
    return WindowSolution(theta1=t1, theta2=t2, ok=ok, sse=sse, det=det)
