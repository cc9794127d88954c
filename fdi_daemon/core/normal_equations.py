"""Least squares from window sums: the normal equations S θ = s_y solved by LDLᵀ.

The window sums of a p-regressor model y = φᵀθ + e are kept packed as one row
``[S_00, S_01, .., S_0p-1, S_11, .., S_p-1p-1, s_0y, .., s_p-1y, Σy²]`` (upper triangle of
S = Σ φφᵀ row by row, then s_y = Σ φ y, then Σ y²): ``packed_width(p)`` numbers.

`solve_packed` works on Python floats (one window, the daemon's tick) and on numpy arrays
(one entry per window, the batch replay) with the same operations in the same order, so
both give bit-equal results. It uses only + - * / (LDLᵀ, no square roots), and marks a
window invalid when a pivot falls below ``min_pivot`` times its diagonal entry (rank
deficient or nearly so: the rig at rest, collinear regressors).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from fdi_daemon.core.compiled import jit

__all__ = ["packed_width", "packed_products", "solve_packed"]


def packed_width(p: int) -> int:
    """Numbers in a packed row for p regressors."""
    return p * (p + 1) // 2 + p + 1


def packed_products(phi: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Rows to add up: φ_i φ_j (i <= j), φ_i y, y² for every sample; phi has shape (n, p)."""
    phi = np.ascontiguousarray(phi, dtype=float)
    y = np.ascontiguousarray(y, dtype=float)
    out = np.empty((phi.shape[0], packed_width(phi.shape[1])))
    _products_kernel(phi, y, out)
    return out


@jit
def _products_kernel(
    phi: np.ndarray, y: np.ndarray, out: np.ndarray
) -> None:  # pragma: no cover - jit
    n, p = phi.shape
    for k in range(n):
        c = 0
        for i in range(p):
            for j in range(i, p):
                out[k, c] = phi[k, i] * phi[k, j]
                c += 1
        for i in range(p):
            out[k, c] = phi[k, i] * y[k]
            c += 1
        out[k, c] = y[k] * y[k]


def solve_packed(row: Sequence[Any], p: int, min_pivot: float = 1e-9) -> tuple[list[Any], Any, Any]:
    """θ, SSE and validity from one packed row (floats) or from columns (arrays).

    ``row`` is a sequence whose items are floats (one window) or 1-D arrays (many windows).
    Returns (theta: list of p items, sse, ok); invalid windows have ok False (θ and SSE then
    hold meaningless finite numbers or NaN; callers test ok).
    """
    # unpack S (upper triangle) and s_y
    k = 0
    # items are floats or arrays (module docstring): Any
    s: list[list[Any]] = [[None] * p for _ in range(p)]
    for i in range(p):
        for j in range(i, p):
            s[i][j] = row[k]
            k += 1
    sy = [row[k + i] for i in range(p)]
    syy = row[k + p]
    # LDLᵀ: S = L D Lᵀ with unit lower-triangular L
    low: list[list[Any]] = [[None] * p for _ in range(p)]
    d: list[Any] = [None] * p
    inv: list[Any] = [None] * p  # 1/d: one division per pivot, then products
    ok = True
    for j in range(p):
        acc = s[j][j]
        for m in range(j):
            acc = acc - low[j][m] * low[j][m] * d[m]
        d[j] = acc
        ok = ok & (acc > min_pivot * s[j][j])
        inv[j] = 1.0 / acc if _nonzero(acc) else 0.0
        for i in range(j + 1, p):
            acc = s[j][i]
            for m in range(j):
                acc = acc - low[i][m] * low[j][m] * d[m]
            low[i][j] = acc * inv[j]
    # forward: L z = s_y ; diagonal: w = z / d ; backward: Lᵀ θ = w
    z: list[Any] = [None] * p
    for i in range(p):
        acc = sy[i]
        for m in range(i):
            acc = acc - low[i][m] * z[m]
        z[i] = acc
    theta: list[Any] = [None] * p
    for i in range(p - 1, -1, -1):
        acc = z[i] * inv[i]
        for m in range(i + 1, p):
            acc = acc - low[m][i] * theta[m]
        theta[i] = acc
    sse = syy
    for i in range(p):
        sse = sse - theta[i] * sy[i]
    return theta, sse, ok


def _nonzero(value: Any) -> bool:
    """For floats: value != 0. Arrays divide anyway (errors suppressed by the caller)."""
    if isinstance(value, float):
        return value != 0.0
    return True
