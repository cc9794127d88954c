"""The friction signature: G_e and γ_f from a window with a friction fault, eqs. (11)–(13).

    r = ẍ − Ĝ v_in                        acceleration residual, eq. (3)
    x_f(γ) = sign(v) + γ v                normalised Coulomb + viscous friction, eq. (11)
    r = G_e(q) x_f(γ) + e                 G_e output error [nb nf nk] = [4 3 0], eq. (12)

For each γ on a grid (default 0..10 step 0.2) G_e is fitted by the prediction-error method
(`output_error`), each fit warm-started from its neighbour; the grid is swept up and down,
then outwards from the best point, and the best fit kept at each point. The γ with the least ‖e‖₂ (eq. 13) is then refined by a
bounded scalar minimisation between its grid neighbours.

Calibration run (`reference_difference`, `lowpass_prefilter`, `plant_pole_bound`). The
excitation that identifies γ varies the velocity amplitude, so the viscous part of x_f grows
with the input amplitude, and so does any error of Ĝ: r = (ẍ_true − Ĝ v_in) + friction part,
and a linear model error δĜ v_in is, at one frequency, collinear with γ·G_e v. Playing the same
excitation fault-free first and taking r_fault(t) − r_ref(t − lag) cancels the deterministic
model error (linear or not). A low-pass L applied alike to r and x_f (L r = G_e L x_f) fits γ
on the excitation's fundamentals, where Coulomb + viscous describes the friction, rather than
on the switching harmonics that stick, Stribeck and sub-sample reversal timing distort. A
pole-radius bound keeps G_e from parking a slow resonance on the carrier that trades with γ.

Identifiability. sign(v) and v share their fundamental, so with a single sine G_e can absorb
γ and the cost hardly depends on it. γ_f's 99 % interval is the hull of
- the likelihood-ratio interval {γ : N_eff·ln(SSE(γ)/SSE_min) <= χ²₁(0.99) = 6.63}, N_eff =
  N/(1 + 2Σρ_k²) the independent samples in the error (a periodic misfit is worth few
  samples, however long the window), its ends where the tabulated profile crosses 6.63
  between grid points, and
- the moving-block bootstrap interval of the profile's minimiser (`gamma_interval`), which
  keeps the error's correlation and its changes across the window;
the whole grid when the least cost lies at the grid's end. Status: *flat* where the profile is
(its depth max SSE/min SSE − 1 below `min_depth`, default 0.01, or an interval that excludes
no γ of the grid), *poorly identified* where the interval covers more than `flat_fraction`
of the grid, else *identified*; for the first two a recommendation names what to change in
this run (`signature_advice`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import cast

import numpy as np
from scipy import signal
from scipy.optimize import minimize_scalar

from fdi_daemon.ident.gamma_interval import BootstrapInterval, bootstrap_interval
from fdi_daemon.ident.output_error import OEFit, fit_output_error
from fdi_daemon.ident.signature_advice import CalibrationContext, advise
from fdi_daemon.ident.spectral import informative_mask, smooth_input_psd, welch_segment_samples

#: χ² quantile with one degree of freedom at 99 %
CHI2_1_99 = 6.634896601021214

EDGE_RECOMMENDATION = (
    "gamma_f is not identified: the least cost lies at an end of the gamma grid, so the "
    "minimum may lie beyond it or the signature does not describe the residual. Check the "
    "share of the residual G_e explains, use the model-based velocity (`--velocity-method "
    "model_observer`) and a calibration run with low-frequency content "
    "(configs/scenarios/signature_calibration_multisine.yaml), or widen --gamma-grid."
)

#: below this share of the fault residual's variance explained by G_e·x_f, warn
LOW_VAF_PERCENT = 50.0


#: most points of a γ grid (each is one output-error fit)
MAX_GRID_POINTS = 2001


def gamma_grid(lo: float = 0.0, hi: float = 10.0, step: float = 0.2) -> np.ndarray:
    """The γ grid lo, lo+step, .., hi (inclusive, as in the paper: 51 points by default)."""
    if not (step > 0 and hi > lo):
        raise ValueError(f"gamma grid needs hi > lo and step > 0 (got {lo}:{hi}:{step})")
    count = int(np.floor((hi - lo) / step + 1e-9)) + 1
    if count > MAX_GRID_POINTS:
        raise ValueError(
            f"{lo:g}:{hi:g}:{step:g} has {count:.3g} points, more than "
            f"{MAX_GRID_POINTS} (one fit each): use a larger step"
        )
    return lo + step * np.arange(count)


def plant_residual(plant, v_in: np.ndarray, accel: np.ndarray) -> np.ndarray:
    """r = ẍ − Ĝ(q) v_in, eq. (3); ``plant`` is the monitor's nominal-model block (anything
    with ``run``: the Ĝ IIR, or Ĝ plus `fdi diagnose` effects), started at rest at the first
    sample as in the monitor."""
    return np.asarray(accel, dtype=float) - plant.run(np.asarray(v_in, dtype=float))


def calibration_band_hz(v_in: np.ndarray, fs_hz: float) -> tuple[float, float]:
    """The frequencies (Hz) a calibration ran at: the span of its input's spectrum within
    20 dB of the peak (Welch, `spectral.smooth_input_psd`: the rule `fdi identify` takes for
    Ĝ's excited band). G_e is fitted on the friction of these frequencies only, and the
    monitor trusts its friction level only where a window's motion lies near them
    (`detect.pipeline`, ``signature_band_fraction``)."""
    v_in = np.asarray(v_in, dtype=float)
    freq = np.fft.rfftfreq(min(welch_segment_samples(len(v_in)), len(v_in)), 1.0 / fs_hz)
    psd = smooth_input_psd(v_in, fs_hz, freq)
    excited = freq[informative_mask(freq, np.ones_like(freq), psd, 0.0)]
    return float(excited[0]), float(excited[-1])


def reference_difference(residual: np.ndarray, lag_samples: int) -> np.ndarray:
    """r(t) − r(t − lag) for t >= lag (0 before): the fault pass minus the fault-free pass of
    the same excitation played `lag_samples` earlier. Ĝ's error, a function of the input,
    cancels; what friction changed remains."""
    residual = np.asarray(residual, dtype=float)
    lag = int(lag_samples)
    if not 0 < lag < len(residual):
        raise ValueError(f"reference lag of {lag} samples lies outside the data")
    out = np.zeros_like(residual)
    out[lag:] = residual[lag:] - residual[:-lag]
    return out


def lowpass_prefilter(cutoff_hz: float, fs_hz: float, order: int = 8) -> np.ndarray:
    """Butterworth low-pass (second-order sections) for `estimate_signature(prefilter=)`."""
    if not 0 < cutoff_hz < fs_hz / 2:
        raise ValueError(f"low-pass cut-off must lie in (0, {fs_hz / 2:g}) Hz, got {cutoff_hz}")
    return signal.butter(order, cutoff_hz, btype="low", fs=fs_hz, output="sos")


def plant_pole_bound(plant_a: np.ndarray) -> float:
    """√(max |pole of Ĝ|): G_e's memory at most twice the plant's slowest mode. Friction acts
    on the acceleration through the same mechanics as the valve force does."""
    radius = float(np.max(np.abs(np.roots(plant_a)))) if len(plant_a) > 1 else 0.0
    return float(np.sqrt(min(max(radius, 1e-6), 1.0)))


def apply_prefilter(prefilter, x: np.ndarray) -> np.ndarray:
    """Filter x by L: (b, a) or second-order sections (shape (n, 6))."""
    if isinstance(prefilter, np.ndarray) and prefilter.ndim == 2:
        return signal.sosfilt(prefilter, x)
    return signal.lfilter(prefilter[0], prefilter[1], x)


def friction_signal(velocity: np.ndarray, gamma: float) -> np.ndarray:
    """x_f = sign(v) + γ v, eq. (11)."""
    return np.sign(velocity) + gamma * velocity


@dataclass
class SignatureResult:
    """G_e, γ_f and the cost profile that chose them."""

    gamma_f: float
    fit: OEFit
    grid: np.ndarray
    sse: np.ndarray  # Σ e² per grid point
    sse_min: float  # at gamma_f (after refinement)
    interval: tuple[float, float]  # 99 % interval for γ (s/m): profile LR ∪ block bootstrap
    effective_samples: float
    flat: bool
    recommendation: str | None
    orders: tuple[int, int, int]
    evaluations: int = 0
    info: dict = field(default_factory=dict)
    residual: np.ndarray | None = None  # the fitted (prefiltered) residual of the window
    at_edge: bool = False  # the least SSE lies at an end of the grid: γ_f is not identified
    wide: bool = False  # not flat, but the interval covers more than flat_fraction of the grid

    @property
    def status(self) -> str:
        """ "identified", "poorly identified", "flat" or "not identified (edge)"."""
        if self.at_edge:
            return "not identified (edge)"
        if self.flat:
            return "flat"
        return "poorly identified" if self.wide else "identified"

    def relative_cost(self) -> np.ndarray:
        """SSE(γ)/SSE(γ_f) on the grid."""
        return self.sse / self.sse_min

    def summary(self) -> dict:
        """Plain-data summary for the model file's provenance."""
        rel = self.relative_cost()
        return {
            "gamma_f": float(self.gamma_f),
            "grid": [
                float(self.grid[0]),
                float(self.grid[-1]),
                float(self.grid[1] - self.grid[0]) if len(self.grid) > 1 else 0.0,
            ],
            "orders_nb_nf_nk": list(self.orders),
            "interval_99": [float(self.interval[0]), float(self.interval[1])],
            "effective_samples": float(self.effective_samples),
            "relative_cost_range": [float(rel.min()), float(rel.max())],
            "depth": float(self.info.get("depth", rel.max() - 1.0)),
            "flat": bool(self.flat),
            "interval_99_profile": self.info.get("interval_99_profile"),
            "interval_99_bootstrap": self.info.get("interval_99_bootstrap"),
            "bootstrap_block_samples": self.info.get("bootstrap_block_samples"),
            "fit_percent": float(self.info.get("fit_percent", float("nan"))),
            "vaf_percent": float(self.info.get("vaf_percent", float("nan"))),
            "status": self.status,
        }


def _hull(
    *intervals: tuple[float, float] | BootstrapInterval | None,
) -> tuple[float, float]:
    """The least interval holding all given ones."""
    ends = [
        (i.low, i.high) if isinstance(i, BootstrapInterval) else i
        for i in intervals
        if i is not None
    ]
    return float(min(e[0] for e in ends)), float(max(e[1] for e in ends))


def likelihood_ratio_interval(
    grid: np.ndarray, lr: np.ndarray, threshold: float
) -> tuple[float, float] | None:
    """{γ : lr(γ) <= threshold} from the profile tabulated on the grid: from the outermost
    accepted grid points, each end moved out to where lr, interpolated linearly, crosses the
    threshold towards the rejected neighbour (a grid end stays where it is). None when no grid
    point is accepted. Read on the grid points alone, an end falls up to a step short of the
    crossing, and the interval could miss a γ just outside it that the data do not reject."""
    accepted = np.flatnonzero(lr <= threshold)
    if accepted.size == 0:
        return None
    ends = []
    for inner, outer in ((accepted[0], accepted[0] - 1), (accepted[-1], accepted[-1] + 1)):
        if outer < 0 or outer >= len(grid):
            ends.append(float(grid[inner]))
            continue
        share = (threshold - lr[inner]) / (lr[outer] - lr[inner])
        ends.append(float(grid[inner] + share * (grid[outer] - grid[inner])))
    return ends[0], ends[1]


def _effective_samples(error: np.ndarray) -> float:
    """N / (1 + 2 Σ_k ρ_k²), k = 1..N/4: the number of independent samples that give Σe² the
    same variance as the (coloured) error has. A white error gives N; a periodic misfit, whose
    correlation never dies out, gives a handful."""
    e = error - error.mean()
    n = len(e)
    denom = float(np.dot(e, e))
    if denom == 0 or n < 8:
        return float(n)
    nfft = int(2 ** np.ceil(np.log2(2 * n)))
    spec = np.abs(np.fft.rfft(e, nfft)) ** 2
    rho = np.fft.irfft(spec, nfft)[1 : n // 4 + 1] / denom
    return float(np.clip(n / (1.0 + 2.0 * np.sum(rho**2)), 1.0, n))


class _FrictionSignals:
    """x_f(γ) = L·sign(v) + γ·L·v on the fitted samples (L: the optional prefilter)."""

    def __init__(self, velocity, prefilter, fit_from):
        sign_v, v = np.sign(velocity), np.asarray(velocity, dtype=float)
        if prefilter is not None:
            sign_v = apply_prefilter(prefilter, sign_v)
            v = apply_prefilter(prefilter, v)
        self.coulomb, self.viscous = sign_v[fit_from:], v[fit_from:]

    def __call__(self, gamma: float) -> np.ndarray:
        return self.coulomb + gamma * self.viscous


def _sweep(residual, signals, grid, orders, order_idx, fits, on_step, radius, start=None):
    for i in order_idx:
        fit = fit_output_error(
            signals(grid[i]), residual, *orders, start=start, max_pole_radius=radius
        )
        if fits[i] is None or fit.sse < fits[i].sse:
            fits[i] = fit
        start = (fits[i].b, fits[i].f)
        if on_step is not None:
            on_step()


def sweep_fits(grid_points: int) -> int:
    """OE fits in the sweeps: up, down, and outwards from the best point."""
    return 3 * grid_points - 1


def estimate_signature(
    residual: np.ndarray,
    velocity: np.ndarray,
    grid: np.ndarray | None = None,
    orders: tuple[int, int, int] = (4, 3, 0),
    refine: bool = True,
    flat_fraction: float = 0.2,
    min_depth: float = 0.01,
    prefilter: tuple | np.ndarray | None = None,
    fit_from: int = 0,
    max_pole_radius: float | None = None,
    on_step: Callable[[], None] | None = None,
    context: CalibrationContext | None = None,
) -> SignatureResult:
    """Grid search over γ with an OE fit of G_e at each point (eq. 13), then refinement.

    residual, velocity: r (eq. 3) and v; the fit uses samples fit_from.. (the fault window),
    earlier samples only run the prefilter in. prefilter: (b, a) of a filter L applied to r
    and to x_f alike — L r = G_e L x_f + L e keeps G_e and γ, and a high-pass L removes the
    slow residual content that friction computed from a high-passed velocity cannot explain;
    (b, a) or second-order sections. max_pole_radius: bound on G_e's poles (default: the
    record's, exp(−1/N)).
    on_step is called once per OE fit of the sweeps (`sweep_fits(len(grid))` calls).
    context: what the recommendation needs to know about the run (sampling rate, reference
    pass, plant resonance).
    """
    residual = np.asarray(residual, dtype=float)
    velocity = np.asarray(velocity, dtype=float)
    grid = gamma_grid() if grid is None else np.asarray(grid, dtype=float)
    if residual.shape != velocity.shape:
        raise ValueError("residual and velocity differ in length")
    if not 0 <= fit_from < len(residual):
        raise ValueError("fit_from lies outside the data")
    if not np.any(velocity[fit_from:] != 0):
        raise ValueError("velocity is zero throughout the window: no friction signal")
    signals = _FrictionSignals(velocity, prefilter, fit_from)
    if prefilter is not None:
        residual = apply_prefilter(prefilter, residual)
    residual = residual[fit_from:]
    fits: list[OEFit | None] = [None] * len(grid)
    _sweep(residual, signals, grid, orders, range(len(grid)), fits, on_step, max_pole_radius)
    _sweep(
        residual,
        signals,
        grid,
        orders,
        range(len(grid) - 1, -1, -1),
        fits,
        on_step,
        max_pole_radius,
    )
    done = cast("list[OEFit]", fits)  # the two sweeps fit every point (the same list)
    # carry the best basin found outwards (a sweep can sit in a poorer local minimum)
    best = int(np.argmin([f.sse for f in done]))
    for side in (range(best - 1, -1, -1), range(best + 1, len(grid))):
        _sweep(
            residual,
            signals,
            grid,
            orders,
            side,
            fits,
            on_step,
            max_pole_radius,
            start=(done[best].b, done[best].f),
        )
    sse = np.array([f.sse for f in done])
    evaluations = sum(f.evaluations for f in done)
    best = int(np.argmin(sse))
    gamma_f, best_fit = float(grid[best]), done[best]
    at_edge = len(grid) > 1 and (best == len(grid) - 1 or (best == 0 and grid[0] > 0))

    if refine and len(grid) > 1:
        lo, hi = grid[max(best - 1, 0)], grid[min(best + 1, len(grid) - 1)]
        cache: dict[float, OEFit] = {}
        warm = (best_fit.b, best_fit.f)

        def cost(gamma: float) -> float:
            fit = fit_output_error(
                signals(gamma), residual, *orders, start=warm, max_pole_radius=max_pole_radius
            )
            cache[gamma] = fit
            return fit.sse

        minimize_scalar(
            cost, bounds=(lo, hi), method="bounded", options={"xatol": 1e-3 * (grid[1] - grid[0])}
        )
        refined = min(cache, key=lambda g: cache[g].sse)
        evaluations += sum(f.evaluations for f in cache.values())
        if cache[refined].sse < best_fit.sse:
            gamma_f, best_fit = float(refined), cache[refined]

    n_eff = _effective_samples(residual - best_fit.y_sim)
    lr = n_eff * np.log(sse / best_fit.sse)
    profile_interval = likelihood_ratio_interval(grid, lr, CHI2_1_99) or (gamma_f, gamma_f)
    span = float(grid[-1] - grid[0]) if len(grid) > 1 else 0.0
    depth = float(np.max(sse) / best_fit.sse - 1.0)
    boot = None
    if len(grid) > 2:
        errors = np.array([residual - f.y_sim for f in fits if f is not None])
        boot = bootstrap_interval(grid, errors, int(np.argmin(sse)))
    interval = _hull(profile_interval, (gamma_f, gamma_f), boot)
    if at_edge:  # the minimum is no minimum: the data exclude no γ of the grid
        interval = (float(grid[0]), float(grid[-1]))
    flat = span > 0 and (depth < min_depth or interval[1] - interval[0] >= span - 1e-9)
    wide = span > 0 and not flat and (interval[1] - interval[0]) > flat_fraction * span
    fit_pct = fit_percent(residual, best_fit.y_sim)
    vaf = variance_accounted_for(residual, best_fit.y_sim)
    if at_edge:
        flat, recommendation = True, EDGE_RECOMMENDATION
    elif flat or wide:
        recommendation = advise(
            flat, interval, span, velocity[fit_from:], context or CalibrationContext()
        )
    else:
        recommendation = None
    return SignatureResult(
        gamma_f=gamma_f,
        fit=best_fit,
        grid=grid,
        sse=sse,
        sse_min=best_fit.sse,
        interval=interval,
        effective_samples=n_eff,
        flat=bool(flat),
        wide=bool(wide),
        recommendation=recommendation,
        orders=(orders[0], orders[1], orders[2]),
        evaluations=evaluations,
        info={
            "fit_percent": float(fit_pct),
            "vaf_percent": float(vaf),
            "depth": depth,
            "interval_99_profile": list(profile_interval),
            "interval_99_bootstrap": None if boot is None else [boot.low, boot.high],
            "bootstrap_block_samples": None if boot is None else boot.block_samples,
            "bootstrap_draws": None if boot is None else boot.draws,
        },
        residual=residual,
        at_edge=bool(at_edge),
    )


def fit_fault_filter(
    residual: np.ndarray,
    velocity: np.ndarray,
    gamma_f: float,
    orders: tuple[int, int, int] = (4, 3, 0),
    fit_from: int = 0,
    max_pole_radius: float | None = None,
) -> OEFit:
    """G_e at a fixed γ_f on the unfiltered window (eq. 12): the filter the monitor runs on
    full-band signals, after γ_f was chosen on prefiltered data."""
    u = friction_signal(np.asarray(velocity, dtype=float), gamma_f)[fit_from:]
    return fit_output_error(
        u, np.asarray(residual, dtype=float)[fit_from:], *orders, max_pole_radius=max_pole_radius
    )


def variance_accounted_for(residual: np.ndarray, y_sim: np.ndarray) -> float:
    """VAF = 100·(1 − var(r − ŷ)/var(r)): % of the residual's variance that ŷ explains."""
    r = np.asarray(residual, dtype=float)
    spread = float(np.var(r))
    return 100.0 * (1.0 - float(np.var(r - y_sim)) / spread) if spread > 0 else float("nan")


def fit_percent(residual: np.ndarray, y_sim: np.ndarray) -> float:
    """100·(1 − ‖r − ŷ‖/‖r − mean r‖): % of the residual explained."""
    r = np.asarray(residual, dtype=float)
    spread = float(np.sum((r - r.mean()) ** 2))
    err = float(np.sum((r - y_sim) ** 2))
    return 100.0 * (1.0 - np.sqrt(err / spread)) if spread > 0 else float("nan")
