"""Stable monic polynomials in q⁻¹: reflection-coefficient parameterisation and pole reflection.

A monic A(q) = 1 + a1 q⁻¹ + ... + an q⁻ⁿ has all roots strictly inside the unit circle
exactly when its reflection (PARCOR) coefficients satisfy |k_i| < 1 (Schur–Cohn). Writing
k_i = tanh(eta_i) gives an unconstrained parameterisation in which every point is stable; the
optimisers of `rational_fit` and `output_error` search over eta, so stability is enforced by
construction rather than checked afterwards.
"""

from __future__ import annotations

import numpy as np

#: reflection coefficients are clipped to this magnitude when converting a start
MAX_REFLECTION = 1.0 - 1e-6


def poly_from_reflection(k: np.ndarray) -> np.ndarray:
    """Step-up recursion: reflection coefficients -> monic [1, a1..an]."""
    a = np.ones(1)
    for km in np.asarray(k, dtype=float):
        a = np.concatenate([a, [0.0]]) + km * np.concatenate([[0.0], a[::-1]])
    return a


def reflection_from_poly(a: np.ndarray) -> np.ndarray:
    """Step-down recursion: monic [1, a1..an] -> reflection coefficients (clipped to < 1)."""
    a = np.asarray(a, dtype=float).copy()
    n = len(a) - 1
    k = np.zeros(n)
    for m in range(n, 0, -1):
        km = float(np.clip(a[m], -MAX_REFLECTION, MAX_REFLECTION))
        k[m - 1] = km
        a = (a[:m] - km * a[m:0:-1]) / (1.0 - km * km)
    return k


def eta_from_poly(a: np.ndarray) -> np.ndarray:
    """Unconstrained parameters eta = artanh(k) of a stable monic polynomial."""
    return np.arctanh(reflection_from_poly(a))


def poly_from_eta(eta: np.ndarray) -> np.ndarray:
    """Monic polynomial with all roots inside the unit circle, from eta = artanh(k)."""
    return poly_from_reflection(np.tanh(eta))


def poly_eta_jacobian(eta: np.ndarray, step: float = 1e-7) -> np.ndarray:
    """d[a1..an]/d eta (n x n) by central differences of the (cheap, smooth) step-up map."""
    eta = np.asarray(eta, dtype=float)
    n = len(eta)
    jac = np.empty((n, n))
    for j in range(n):
        d = np.zeros(n)
        d[j] = step
        jac[:, j] = (poly_from_eta(eta + d)[1:] - poly_from_eta(eta - d)[1:]) / (2 * step)
    return jac


def is_stable(a: np.ndarray, margin: float = 0.0) -> bool:
    """All roots of the monic polynomial a (in q⁻¹) have magnitude < 1 - margin."""
    a = np.asarray(a, dtype=float)
    if len(a) <= 1:
        return True
    return bool(np.all(np.abs(np.roots(a)) < 1.0 - margin))


def reflect_unstable(b: np.ndarray, a: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """Reflect roots of A outside the unit circle to 1/conj(p), keeping |B/A| on the circle.

    On |z| = 1, |z - p| = |p|·|z - 1/p*|, so each reflected root divides B by |p|.
    Returns (b, a, number of reflected roots).
    """
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    if len(a) <= 1:
        return b.copy(), a.copy(), 0
    poles = np.roots(a)
    outside = np.abs(poles) > 1.0
    if not outside.any():
        return b.copy(), a.copy(), 0
    gain = float(np.prod(np.abs(poles[outside])))
    poles = np.where(outside, 1.0 / np.conj(poles), poles)
    a_new = np.real(np.poly(poles))
    return b / gain, a_new, int(outside.sum())
