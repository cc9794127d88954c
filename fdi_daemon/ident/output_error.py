"""Output-error model y = q^-nk B(q)/F(q) u + e, eq. (8), by the prediction-error method.

Orders follow MATLAB's ``oe``: nb = number of B coefficients (B = b0 + .. + b_{nb-1} q^-(nb-1)),
nf = order of the monic F, nk = input delay. The paper uses [nb, nf, nk] = [4, 3, 0].

1. Start: ARX (equation error, one least-squares solve), then Steiglitz–McBride iterations
   (ARX on u, y pre-filtered by 1/F of the previous step); unstable roots of F reflected.
2. Refinement: Levenberg–Marquardt (scipy.optimize.least_squares) on the simulated output
   error, analytic Jacobian by filtering (dŷ/db_k = q^-(nk+k) u/F, dŷ/df_k = −q^-k ŷ/F), F
   parameterised by reflection coefficients so every iterate has its poles inside
   exp(−1/N) (stable, and no slower than the window can tell from an integrator).
3. Initial conditions: the window starts with the filter in an unknown state. Its effect is
   exactly (1/F)·s with s a pulse sequence on the first max(nf, nb−1+nk) samples; those pulse
   heights are estimated with the other parameters, so no warm-up has to be thrown away.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import signal
from scipy.optimize import least_squares

from fdi_daemon.ident import stable_poly


@dataclass
class OEFit:
    """An output-error fit on one window."""

    b: np.ndarray  # [b0 .. b_{nb-1}] (without the nk leading zeros)
    f: np.ndarray  # [1, f1 .. f_nf]
    nk: int
    initial_pulses: np.ndarray  # s(0..ni-1), the window's initial-condition term
    sse: float  # Σ e² over the window
    y_sim: np.ndarray  # ŷ including the initial-condition term
    evaluations: int

    @property
    def b_delayed(self) -> np.ndarray:
        """B with the nk leading zeros, for lfilter(b_delayed, f, u)."""
        return np.concatenate([np.zeros(self.nk), self.b])


def initial_pulse_count(nb: int, nf: int, nk: int) -> int:
    """Number of samples at the window start that depend on the unknown initial state."""
    return max(nf, nb - 1 + nk)


def _regressors(u: np.ndarray, y: np.ndarray, nb: int, nf: int, nk: int, start: int):
    """ARX regressors [−y(t−1..t−nf), u(t−nk..t−nk−nb+1)] for t >= start."""
    n = len(u)
    cols = [-y[start - k : n - k] for k in range(1, nf + 1)]
    cols += [u[start - nk - k : n - nk - k] for k in range(nb)]
    return np.column_stack(cols), y[start:]


def arx_start(
    u: np.ndarray,
    y: np.ndarray,
    nb: int,
    nf: int,
    nk: int,
    sm_iterations: int = 20,
    tolerance: float = 1e-8,
) -> tuple[np.ndarray, np.ndarray]:
    """Stable (b, f) from ARX then Steiglitz–McBride iterations."""
    start = initial_pulse_count(nb, nf, nk)
    if len(u) <= start + nb + nf:
        raise ValueError(
            f"window of {len(u)} samples is too short for [nb nf nk] = [{nb} {nf} {nk}]"
        )
    f = np.ones(1 + nf)
    b = np.zeros(nb)
    best = None
    for _ in range(sm_iterations + 1):
        uf = signal.lfilter([1.0], f, u)
        yf = signal.lfilter([1.0], f, y)
        phi, target = _regressors(uf, yf, nb, nf, nk, start)
        theta = np.linalg.lstsq(phi, target, rcond=None)[0]
        f_new = np.concatenate([[1.0], theta[:nf]])
        b_new = theta[nf:]
        b_new, f_new, _ = stable_poly.reflect_unstable(b_new, f_new)
        change = np.linalg.norm(f_new - f) + np.linalg.norm(b_new - b)
        b, f = b_new, f_new
        sse = float(np.sum((y - signal.lfilter(np.concatenate([np.zeros(nk), b]), f, u)) ** 2))
        if best is None or sse < best[0]:
            best = (sse, b.copy(), f.copy())
        if change <= tolerance * (np.linalg.norm(f) + np.linalg.norm(b)):
            break
    assert best is not None  # the first iteration sets it
    return best[1], best[2]


class _Problem:
    """Residual and Jacobian of the output error for fixed data."""

    def __init__(self, u, y, nb, nf, nk, radius):
        self.u, self.y, self.radius = u, y, radius
        self.nb, self.nf, self.nk = nb, nf, nk
        self.ni = initial_pulse_count(nb, nf, nk)
        self.pulses = np.zeros((len(u), self.ni))
        self.pulses[np.arange(self.ni), np.arange(self.ni)] = 1.0
        self._cache_x = None

    def unpack(self, x):
        b = x[: self.nb]
        f = stable_poly.poly_from_eta(x[self.nb : self.nb + self.nf], self.radius)
        d = x[self.nb + self.nf :]
        return b, f, d

    def simulate(self, x):
        b, f, d = self.unpack(x)
        drive = np.zeros(len(self.u))
        drive[self.nk :] = signal.lfilter(b, [1.0], self.u)[: len(self.u) - self.nk]
        drive[: self.ni] += d
        return signal.lfilter([1.0], f, drive)

    def residual(self, x):
        return self.y - self.simulate(x)

    def jacobian(self, x):
        b, f, d = self.unpack(x)
        n = len(self.u)
        y_hat = self.simulate(x)
        u_f = signal.lfilter([1.0], f, self.u)
        y_f = signal.lfilter([1.0], f, y_hat)
        imp = signal.lfilter([1.0], f, self.pulses[:, 0])
        jac = np.zeros((n, self.nb + self.nf + self.ni))
        for k in range(self.nb):
            s = self.nk + k
            jac[s:, k] = -u_f[: n - s]
        dyf = np.zeros((n, self.nf))
        for k in range(1, self.nf + 1):
            dyf[k:, k - 1] = y_f[: n - k]
        eta = x[self.nb : self.nb + self.nf]
        jac[:, self.nb : self.nb + self.nf] = dyf @ stable_poly.poly_eta_jacobian(eta, self.radius)
        for k in range(self.ni):
            jac[k:, self.nb + self.nf + k] = -imp[: n - k]
        return jac

    def initial_pulses_for(self, b, f):
        """Least-squares initial-condition pulses for fixed (b, f)."""
        x = np.concatenate([b, stable_poly.eta_from_poly(f, self.radius), np.zeros(self.ni)])
        base = self.residual(x)
        imp = signal.lfilter([1.0], f, self.pulses[:, 0])
        basis = np.zeros((len(self.u), self.ni))
        for k in range(self.ni):
            basis[k:, k] = imp[: len(self.u) - k]
        return np.linalg.lstsq(basis, base, rcond=None)[0]


def fit_output_error(
    u: np.ndarray,
    y: np.ndarray,
    nb: int = 4,
    nf: int = 3,
    nk: int = 0,
    start: tuple[np.ndarray, np.ndarray] | None = None,
    max_evaluations: int = 100,
    max_pole_radius: float | None = None,
) -> OEFit:
    """Prediction-error fit of y = q^-nk B/F u + e (eq. 8) on one window.

    start: (b, f) to warm-start from (e.g. the fit at a neighbouring γ); default ARX then
    Steiglitz–McBride. The initial-condition pulses are always re-estimated.
    max_pole_radius: bound on the poles of 1/F (default exp(−1/N), `record_pole_radius`);
    a smaller bound limits the filter's memory (a pole of radius ρ decays as ρ^k).
    """
    u = np.asarray(u, dtype=float)
    y = np.asarray(y, dtype=float)
    if u.shape != y.shape:
        raise ValueError("u and y must have the same length")
    radius = stable_poly.record_pole_radius(len(u))
    if max_pole_radius is not None:
        if not 0 < max_pole_radius <= 1:
            raise ValueError(f"max_pole_radius must lie in (0, 1], got {max_pole_radius}")
        radius = min(radius, float(max_pole_radius))
    if start is None:
        b0, f0 = arx_start(u, y, nb, nf, nk)
    else:
        b0, f0 = start
    b0, f0, _ = stable_poly.reflect_unstable(b0, f0, radius)
    problem = _Problem(u, y, nb, nf, nk, radius)
    d0 = problem.initial_pulses_for(b0, f0)
    x0 = np.concatenate([b0, stable_poly.eta_from_poly(f0, radius), d0])
    sol = least_squares(
        problem.residual,
        x0,
        jac=problem.jacobian,
        method="lm",
        x_scale="jac",
        max_nfev=max_evaluations,
        xtol=1e-7,
        ftol=1e-7,
    )
    b, f, d = problem.unpack(sol.x)
    y_sim = problem.simulate(sol.x)
    return OEFit(
        b=b.copy(),
        f=f,
        nk=nk,
        initial_pulses=d.copy(),
        sse=float(np.sum((y - y_sim) ** 2)),
        y_sim=y_sim,
        evaluations=int(sol.nfev),
    )
