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


def _scale(a: np.ndarray, radius: float) -> np.ndarray:
    """a_k -> a_k·radius^k: the roots are multiplied by radius."""
    return np.asarray(a, dtype=float) * radius ** np.arange(len(a))


def eta_from_poly(a: np.ndarray, radius: float = 1.0) -> np.ndarray:
    """Unconstrained parameters eta = artanh(k) of a monic polynomial with roots inside `radius`."""
    return np.arctanh(reflection_from_poly(_scale(a, 1.0 / radius)))


def poly_from_eta(eta: np.ndarray, radius: float = 1.0) -> np.ndarray:
    """Monic polynomial with all roots strictly inside |z| < radius, from eta = artanh(k).

    a_k = radius^k · a'_k with a' Schur-stable, so the roots of a are radius × those of a'.
    """
    return _scale(poly_from_reflection(np.tanh(eta)), radius)


def poly_eta_jacobian(eta: np.ndarray, radius: float = 1.0, step: float = 1e-7) -> np.ndarray:
    """d[a1..an]/d eta (n x n) by central differences of the (cheap, smooth) step-up map."""
    eta = np.asarray(eta, dtype=float)
    n = len(eta)
    jac = np.empty((n, n))
    for j in range(n):
        d = np.zeros(n)
        d[j] = step
        jac[:, j] = (poly_from_eta(eta + d, radius)[1:] - poly_from_eta(eta - d, radius)[1:]) / (
            2 * step
        )
    return jac


def is_stable(a: np.ndarray, margin: float = 0.0) -> bool:
    """All roots of the monic polynomial a (in q⁻¹) have magnitude < 1 - margin."""
    a = np.asarray(a, dtype=float)
    if len(a) <= 1:
        return True
    return bool(np.all(np.abs(np.roots(a)) < 1.0 - margin))


def record_pole_radius(n_samples: int) -> float:
    """exp(−1/N): a pole slower than this decays by less than 1/e over the whole record.

    Such a pole cannot be told from an integrator by N samples; allowing it lets a fit park
    a near-cancelling pole/zero pair on z = 1 that drifts when the model is simulated.
    """
    return float(np.exp(-1.0 / max(int(n_samples), 1)))


def reflect_unstable(
    b: np.ndarray,
    a: np.ndarray,
    radius: float = 1.0,
) -> tuple[np.ndarray, np.ndarray, int]:
    """Reflect roots of A outside |z| = radius to radius²/conj(p).

    For radius 1 this keeps |B/A| on the unit circle (|z − p| = |p|·|z − 1/p*| there), so B
    is divided by |p| for each reflected root; for radius < 1 the same gain correction is
    applied as an approximation (the result is only a start for the refinement).
    Returns (b, a, number of reflected roots).
    """
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    if len(a) <= 1:
        return b.copy(), a.copy(), 0
    poles = np.roots(a)
    outside = np.abs(poles) >= radius
    if not outside.any():
        return b.copy(), a.copy(), 0
    gain = float(np.prod(np.abs(poles[outside]) / radius))
    # strictly inside: a root exactly on the circle is pulled in slightly
    poles = np.where(outside, radius**2 / np.conj(poles) * (1.0 - 1e-9), poles)
    a_new = np.real(np.poly(poles))
    return b / gain, a_new, int(outside.sum())
