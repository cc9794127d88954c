"""Weighted rational fit of a discrete-time model to frequency-response data, eq. (2).

Model (eq. 1): Ĝ(z) = B/A with B = b1 z⁻¹ + .. + bn z⁻ⁿ (b0 = 0) and A = 1 + a1 z⁻¹ + .. + an z⁻ⁿ.
Cost (eq. 2): Σ_k |W_k (Ĝ(e^{jω_k}) − G_k)|², with W = 1/|G| (relative error) by default.

1. Levy: the linearised cost Σ |W (B − G A)|², one linear least-squares solve;
2. Sanathanan–Koerner: the same, re-weighted by 1/|A_prev| until the coefficients settle;
3. roots of A outside the allowed radius (1, or the record's bound) reflected inside;
4. Levenberg–Marquardt on the true cost (scipy.optimize.least_squares, analytic Jacobian),
   with A parameterised by reflection coefficients of A(z/ρ) so every iterate has its poles
   inside the radius ρ.
The best of the refined Levy and SK starts is returned.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from fdi_daemon.core.iir import frequency_response
from fdi_daemon.ident import stable_poly


@dataclass
class RationalFit:
    """Ĝ = B/A in powers of z⁻¹ and how it was found."""

    b: np.ndarray  # [0, b1..bn]
    a: np.ndarray  # [1, a1..an]
    cost: float  # Σ |W(Ĝ − G)|² on the fitted points
    rms_relative_error: float  # sqrt(mean |Ĝ − G|²/|G|²) on the fitted points
    start: str  # which linearised start won: "levy" or "sanathanan-koerner"
    sk_iterations: int
    reflected_poles: int
    info: dict = field(default_factory=dict)

    def response(self, freq_hz: np.ndarray, fs_hz: float) -> np.ndarray:
        return frequency_response(self.b, self.a, freq_hz, fs_hz)

    @property
    def poles(self) -> np.ndarray:
        return np.roots(self.a)

    @property
    def zeros(self) -> np.ndarray:
        return np.roots(np.trim_zeros(self.b, "f"))


def _powers(zinv: np.ndarray, order: int) -> np.ndarray:
    """Columns z⁻¹ .. z⁻ⁿ."""
    return zinv[:, None] ** np.arange(1, order + 1)[None, :]


def _linearised(G, weight, zb, za, extra_weight):
    """Solve min Σ |w (B − G A)|² for θ = [b1..bn, a1..an] (Levy / one SK step)."""
    w = (weight * extra_weight)[:, None]
    lhs = np.hstack([zb, -G[:, None] * za]) * w
    rhs = G * w[:, 0]
    lhs_ri = np.vstack([lhs.real, lhs.imag])
    rhs_ri = np.concatenate([rhs.real, rhs.imag])
    scale = np.linalg.norm(lhs_ri, axis=0)
    scale[scale == 0] = 1.0
    theta = np.linalg.lstsq(lhs_ri / scale, rhs_ri, rcond=None)[0] / scale
    nb = zb.shape[1]
    return theta[:nb], theta[nb:]


def _residual_and_jacobian(params, G, weight, zb, za, nb, radius, want_jac):
    b, eta = params[:nb], params[nb:]
    a = stable_poly.poly_from_eta(eta, radius)
    B = zb @ b
    A = 1.0 + za @ a[1:]
    model = B / A
    r = weight * (model - G)
    res = np.concatenate([r.real, r.imag])
    if not want_jac:
        return res
    jb = weight[:, None] * zb / A[:, None]
    ja = -weight[:, None] * (model / A)[:, None] * za
    jeta = ja @ stable_poly.poly_eta_jacobian(eta, radius)
    jac = np.hstack([jb, jeta])
    return np.vstack([jac.real, jac.imag])


def _refine(b, a, G, weight, zb, za, radius):
    """Levenberg–Marquardt on the true weighted cost from a stable start."""
    nb = zb.shape[1]
    x0 = np.concatenate([b, stable_poly.eta_from_poly(a, radius)])
    sol = least_squares(
        lambda p: _residual_and_jacobian(p, G, weight, zb, za, nb, radius, False),
        x0,
        jac=lambda p: _residual_and_jacobian(p, G, weight, zb, za, nb, radius, True),
        method="lm",
        x_scale="jac",
        xtol=1e-10,
        ftol=1e-10,
        max_nfev=200,
    )
    b_new = sol.x[:nb]
    a_new = stable_poly.poly_from_eta(sol.x[nb:], radius)
    return b_new, a_new, float(2.0 * sol.cost), int(sol.nfev)


def fit_rational(
    freq_hz: np.ndarray,
    G: np.ndarray,
    fs_hz: float,
    order: int = 4,
    weight: np.ndarray | None = None,
    max_pole_radius: float = 1.0,
    max_sk_iterations: int = 50,
    sk_tolerance: float = 1e-9,
) -> RationalFit:
    """Fit Ĝ = B/A of the given order (b0 = 0) to G on freq_hz, eq. (2).

    weight: W_k (default 1/|G_k|, the paper's choice). Needs at least `order` points.
    max_pole_radius: all poles end strictly inside this radius (1: stability only; see
    `stable_poly.record_pole_radius` for the bound a record of N samples supports).
    """
    freq_hz = np.asarray(freq_hz, dtype=float)
    G = np.asarray(G, dtype=complex)
    if order < 1:
        raise ValueError("model order must be >= 1")
    if len(freq_hz) < order:
        raise ValueError(
            f"{len(freq_hz)} frequency points are too few for order {order} (need >= {order})"
        )
    if weight is None:
        mag = np.abs(G)
        if np.any(mag == 0):
            raise ValueError("|G| = 0 at a fitted frequency: W = 1/|G| is undefined")
        weight = 1.0 / mag
    weight = np.asarray(weight, dtype=float)
    zinv = np.exp(-2j * np.pi * freq_hz / fs_hz)
    zb, za = _powers(zinv, order), _powers(zinv, order)
    ones = np.ones(len(G))

    b_levy, a_tail = _linearised(G, weight, zb, za, ones)
    starts = {"levy": (b_levy, np.concatenate([[1.0], a_tail]))}
    b_sk, a_sk = starts["levy"]
    iterations = 0
    for iterations in range(1, max_sk_iterations + 1):  # noqa: B007 - read after the loop
        A_prev = np.abs(1.0 + za @ a_sk[1:])
        b_next, a_tail = _linearised(G, weight, zb, za, 1.0 / A_prev)
        a_next = np.concatenate([[1.0], a_tail])
        change = np.linalg.norm(np.concatenate([b_next - b_sk, a_next - a_sk]))
        size = np.linalg.norm(np.concatenate([b_next, a_next]))
        b_sk, a_sk = b_next, a_next
        if change <= sk_tolerance * size:
            break
    starts["sanathanan-koerner"] = (b_sk, a_sk)

    best = None
    for name, (b0, a0) in starts.items():
        b0, a0, reflected = stable_poly.reflect_unstable(b0, a0, max_pole_radius)
        b_fit, a_fit, cost, nfev = _refine(b0, a0, G, weight, zb, za, max_pole_radius)
        if best is None or cost < best[2]:
            best = (b_fit, a_fit, cost, name, reflected, nfev)
    assert best is not None  # starts holds the Levy and SK starts
    b_fit, a_fit, cost, name, reflected, nfev = best
    model = (zb @ b_fit) / (1.0 + za @ a_fit[1:])
    rel = np.abs(model - G) / np.maximum(np.abs(G), np.finfo(float).tiny)
    return RationalFit(
        b=np.concatenate([[0.0], b_fit]),
        a=a_fit,
        cost=cost,
        rms_relative_error=float(np.sqrt(np.mean(rel**2))),
        start=name,
        sk_iterations=iterations,
        reflected_poles=reflected,
        info={"lm_evaluations": nfev, "points": int(len(G))},
    )
