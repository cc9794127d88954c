"""The library of physical effects that a nominal linear model may be missing, and their fit.

Each effect is a regressor φ(u, v, x, ŷ₀; p) with at most one nonlinear parameter p (found
by search) and linear coefficients (least squares). Where it enters (``source``):

- input (`input_effects`): through B_e(q)/Â(q), Â the nominal denominator, B_e free
  (Ĝ N(u) − Ĝ u = Ĝ [N(u) − u]); G_e φ = Σᵢ bᵢ q⁻ⁱ (Â⁻¹ φ), linear in bᵢ;
- state (force on the moving mass, `force`): the same filter as a start, with the nominal
  motion; then in the loop with the augmented motion (`force.in_the_loop`);
- output (`output_effects`): a static map of ŷ₀ with a gain.

| effect             | source | φ                                    | nonlinear parameter   |
|--------------------|--------|--------------------------------------|-----------------------|
| coulomb_friction   | state  | sign(v)                              | —                     |
| viscous_friction   | state  | v                                    | —                     |
| stribeck_friction  | state  | sign(v), sign(v)·exp(−(v/v_s)²)       | Stribeck velocity v_s |
| cubic_stiffness    | state  | x³                                   | —                     |
| force_offset       | state  | 1                                    | —                     |
| stiffness_change   | state  | x (free B_F: the mode's ω and ζ move) | —                    |
| mass_change        | state  | x (stiffness_change's, by the mode)  | —                     |
| input_saturation   | input  | sat_L(u − u_c) − (u − u_c)           | level L               |
| dead_zone          | input  | dz_w(u − u_c) − (u − u_c)            | half-width w          |
| backlash           | input  | play_g(u) − u                        | gap g                 |
| dead_time          | output | ŷ₀(t − τ) − ŷ₀(t) (linear interp.)   | dead time τ           |
| gain_fault         | output | ŷ₀                                   | —                     |
| output_saturation  | output | sat_L(ŷ₀) − ŷ₀                       | level L               |
| sensor_offset      | output | 1                                    | —                     |
| mode_damping       | output | ŷ_r − ŷ₀, the mode's c/m × r          | ratio r = c₁/c₀       |
| mode_stiffness     | output | ŷ_r − ŷ₀, the mode's k/m × r          | ratio r = k₁/k₀       |
| mode_mass          | output | ŷ_r − ŷ₀, the mode's c/m, k/m, 1/m ÷ r | ratio r = m₁/m₀      |

``mass_change`` is not fitted on its own: it is the name of ``stiffness_change``'s fit when
the mode it moves scales its stiffness and damping per unit mass alike (`force.mode_shift`).
The ``mode_*`` lines (`mode_lines`) are the numerator refit's explanations, not candidates of
the rounds (`select.linear_round`); each is named as the effect it stands for
(``named_as``: viscous friction, a stiffness or a mass change).

Base terms, never named: ``linear_refit`` (B_e/Â on u), ``loop_stiffness`` (x in the force
loop), ``force_balance`` (mass and damping of the inverse-dynamics form). In the
inverse-dynamics form every φ is taken from the measured motion and low-passed
(`columns`). Every regressor is a streaming block, so the augmented model
(`augment.AugmentedPlant`) computes exactly what was fitted.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any, overload

import numpy as np
from scipy import signal
from scipy.optimize import minimize_scalar

from fdi_daemon.diagnose.input_effects import BacklashRegressor, dead_zone, saturate
from fdi_daemon.diagnose.mode_lines import LINES, ModeLineRegressor, mode_report, nominal_pole
from fdi_daemon.diagnose.output_effects import DelayedOutputRegressor, out_saturate
from fdi_daemon.diagnose.regressors import Regressor, Static

EFFECT_NAMES = (
    "coulomb_friction",
    "viscous_friction",
    "stribeck_friction",
    "cubic_stiffness",
    "dead_time",
    "input_saturation",
    "output_saturation",
    "dead_zone",
    "backlash",
    "sensor_offset",
    "force_offset",
    "gain_fault",
    "stiffness_change",
    "mass_change",
)
#: effects named from another candidate's fit (`force.mechanics_name`), not candidates
NAMED_BY_MODE = ("mass_change",)


# regressor blocks: `regressors` (base), `input_effects`, `output_effects`; force effects'
# regressors are the memoryless maps below (their loop is in `force`)


def _stribeck(vs):
    return lambda u, v, x, y0: [np.sign(v), np.sign(v) * np.exp(-((v / vs) ** 2))]


# ----------------------------------------------------------------------------- effect specs


@dataclass(frozen=True)
class EffectSpec:
    """One candidate: how its regressor is built and where its parameter is searched."""

    name: str
    source: str  # "input", "state" or "output"
    dynamic: bool  # through B_e/Â (True) or a static gain (False)
    param: str | None  # name of the nonlinear parameter (searched), None if none
    unit: str  # of the searched parameter
    #: (parameter, centre, Â of the domain) -> regressor; the parameter is a float when
    #: ``param`` names one, else None
    build: Callable[[Any, float, np.ndarray], Regressor]
    grid: Callable[[Context], np.ndarray] | None = None
    integer_coarse: bool = False
    #: the value reported is searched again with the regressor's coefficient held at 1 (a
    #: pure shift: the free coefficient of the fit trades with the delay, and its size is
    #: what tells a shift from a linear change that only looks like one)
    reported_at_unit_weight: bool = False
    #: the parameter is searched with the coefficient held at 1 (a mode line: near ratio 1
    #: a free coefficient times a small move is any derivative of the response), the
    #: coefficient fitted at the value found tells a pure change (≈ 1) from another
    searched_at_unit_weight: bool = False
    #: it acts at the sensor, on the measured output after the force loop: it does not move
    #: the mass, so the loop's motion is without it (an output effect that is not: ŷ₀'s
    #: gain, shift or mode line, which change the plant's response)
    at_sensor: bool = False


def _ratios(c: Context) -> np.ndarray:
    """Ratios of a mode line, 1/4 to 4 (log-spaced, 1 among them); none without a mode."""
    return np.geomspace(0.25, 4.0, 25) if nominal_pole(c.a_dom) is not None else np.array([])


def _mode_line(line: str, param: str, unit: str) -> EffectSpec:
    """The spec of one line of `mode_lines` (``mode_<line>``), a linear explanation of the
    numerator refit (`select.linear_round`)."""
    return EffectSpec(
        f"mode_{line}",
        "output",
        False,
        param,
        unit,
        lambda p, c, a: ModeLineRegressor(line, p, a),
        _ratios,
        searched_at_unit_weight=True,
    )


def _q(values: np.ndarray, qs, centre: float = 0.0) -> np.ndarray:
    return np.unique(np.quantile(np.abs(values - centre), qs))


def _delays(c: Context) -> np.ndarray:
    """Whole-sample dead times 1..max, log-spaced beyond 16 samples (at most ~40 fits)."""
    short = np.arange(1, min(16, c.max_delay_samples) + 1)
    long = np.geomspace(16, max(16, c.max_delay_samples), 24).round()
    return np.unique(np.concatenate([short, long[long <= c.max_delay_samples]])).astype(float)


SPECS: dict[str, EffectSpec] = {
    "coulomb_friction": EffectSpec(
        "coulomb_friction",
        "state",
        True,
        None,
        "",
        lambda p, c, a: Static(lambda u, v, x, y0: [np.sign(v)]),
    ),
    "viscous_friction": EffectSpec(
        "viscous_friction", "state", True, None, "", lambda p, c, a: Static(lambda u, v, x, y0: [v])
    ),
    "stribeck_friction": EffectSpec(
        "stribeck_friction",
        "state",
        True,
        "stribeck_velocity",
        "velocity units",
        lambda p, c, a: Static(_stribeck(p), 2),
        lambda c: _q(c.v[c.split.fit], [0.02, 0.05, 0.1, 0.2, 0.3, 0.5]),
    ),
    "cubic_stiffness": EffectSpec(
        "cubic_stiffness",
        "state",
        True,
        None,
        "",
        lambda p, c, a: Static(lambda u, v, x, y0: [x**3]),
    ),
    "dead_time": EffectSpec(
        "dead_time",
        "output",
        False,
        "dead_time_s",
        "s",
        lambda p, c, a: DelayedOutputRegressor(p),
        _delays,
        integer_coarse=True,
        reported_at_unit_weight=True,
    ),
    "gain_fault": EffectSpec(
        "gain_fault", "output", False, None, "", lambda p, c, a: Static(lambda u, v, x, y0: [y0])
    ),
    "input_saturation": EffectSpec(
        "input_saturation",
        "input",
        True,
        "level",
        "input units",
        lambda p, c, a: Static(saturate(p, c)),
        lambda c: _q(
            c.u[c.split.fit], [0.5, 0.6, 0.7, 0.8, 0.85, 0.9, 0.94, 0.97, 0.99, 0.995], c.u_centre
        ),
    ),
    "output_saturation": EffectSpec(
        "output_saturation",
        "output",
        False,
        "level",
        "output units",
        lambda p, c, a: Static(out_saturate(p, c)),
        lambda c: _q(c.y0[c.split.fit], [0.8, 0.9, 0.95, 0.97, 0.98, 0.99, 0.995, 0.999]),
        at_sensor=True,
    ),
    "dead_zone": EffectSpec(
        "dead_zone",
        "input",
        True,
        "half_width",
        "input units",
        lambda p, c, a: Static(dead_zone(p, c)),
        lambda c: _q(
            c.u[c.split.fit], [0.01, 0.03, 0.06, 0.1, 0.15, 0.2, 0.3, 0.4, 0.5], c.u_centre
        ),
    ),
    "backlash": EffectSpec(
        "backlash",
        "input",
        True,
        "gap",
        "input units",
        lambda p, c, a: BacklashRegressor(p),
        lambda c: (
            np.ptp(c.u[c.split.fit])
            * np.array([0.005, 0.01, 0.02, 0.04, 0.07, 0.1, 0.15, 0.2, 0.3])
        ),
    ),
    "force_offset": EffectSpec(
        "force_offset",
        "state",
        True,
        None,
        "",
        lambda p, c, a: Static(lambda u, v, x, y0: [np.ones_like(u)]),
    ),
    "sensor_offset": EffectSpec(
        "sensor_offset",
        "output",
        False,
        None,
        "",
        lambda p, c, a: Static(lambda u, v, x, y0: [np.ones_like(u)]),
        at_sensor=True,
    ),
    # the loop's spring alone (`force.mode_shift` says what it changes)
    "stiffness_change": EffectSpec(
        "stiffness_change", "state", True, None, "", lambda p, c, a: Static(lambda u, v, x, y0: [x])
    ),
    # not a candidate: corrections of the inverse-dynamics form's mass, damping [, stiffness]
    # refitted with every candidate (columns from `Context.base_columns`)
    "force_balance": EffectSpec(
        "force_balance",
        "state",
        False,
        None,
        "",
        lambda p, c, a: None,  # type: ignore[arg-type,return-value]  # never built: not a candidate
    ),
    # not a candidate: in the force loop with any force effect (`force.in_the_loop`)
    "loop_stiffness": EffectSpec(
        "loop_stiffness", "state", True, None, "", lambda p, c, a: Static(lambda u, v, x, y0: [x])
    ),
    # not a candidate: with a fitted linear baseline, the baseline's numerator is refitted
    # together with every candidate (the baseline absorbed part of the missing effect)
    "linear_refit": EffectSpec(
        "linear_refit", "input", True, None, "", lambda p, c, a: Static(lambda u, v, x, y0: [u])
    ),
}

#: the same fit as stiffness_change, named by the mode it moves (`force.mechanics_name`)
SPECS["mass_change"] = replace(SPECS["stiffness_change"], name="mass_change")
#: a change of one parameter of the nominal mode (`mode_lines`), named by the effect it is
#: (``LINES``): damping c₁/c₀, stiffness k₁/k₀, mass m₁/m₀
MODE_LINES = {f"mode_{line}": line for line in LINES}
SPECS.update(
    {
        "mode_damping": _mode_line("damping", "damping_scale", "c1/c0"),
        "mode_stiffness": _mode_line("stiffness", "stiffness_ratio", "k1/k0"),
        "mode_mass": _mode_line("mass", "mass_ratio", "m1/m0"),
    }
)

#: the share of a pure change a linear explanation's coefficient may have (a dead time's
#: shift, a mode line's move; `select.map_share` holds a static map to it too)
SHARE_RANGE = (0.5, 1.5)

#: terms of the base, never named: the nominal numerator refit and the force loop's spring
BASE_TERMS = ("linear_refit", "loop_stiffness", "force_balance")

#: static input maps that act around the input's operating point (its training median)
CENTRED = ("input_saturation", "dead_zone")


@dataclass
class Context:
    """Everything the fits need, computed once per recording (see `baseline.prepare`)."""

    u: np.ndarray
    v: np.ndarray
    x: np.ndarray
    y0: np.ndarray  # nominal simulated output (comparison domain)
    target: np.ndarray  # measured output (comparison domain) − y0
    a_dom: np.ndarray  # Â of the domain plant
    b_dom: np.ndarray
    split: Any
    fs_hz: float
    output_kind: str
    ref_hz: float  # centre of the input's band, for the physical parameter report
    max_delay_samples: int
    u_centre: float = 0.0  # operating point of the input maps (median training input)
    candidates: tuple[str, ...] = EFFECT_NAMES
    chain: tuple = ()  # (n, b, a, fs) of the state chain (`signals.StateChain.coefficients`)
    form: str = "simulation"  # or "inverse_dynamics" (`inverse`): φ of the measured motion
    lowpass: tuple = ()  # (b, a) of L in the inverse-dynamics form
    base_columns: Any = None  # L a, L v [, L x] (inverse dynamics: the force balance)
    inverse_base: dict = field(default_factory=dict)  # its fitted mass, damping [, stiffness]
    highpass_hz: float = 1.0
    cache: dict = field(default_factory=dict, repr=False)

    def centre(self, spec: EffectSpec) -> float:
        """Input maps act around the input's operating point; a sensor clips around its 0."""
        return self.u_centre if spec.name in CENTRED else 0.0

    def regressors(self, spec: EffectSpec, param: float | None) -> np.ndarray:
        """φ of one effect over the record (the last few are cached: some are slow loops)."""
        if spec.name == "force_balance":
            return self.base_columns
        key = (spec.name, param)
        if key not in self.cache:
            if len(self.cache) >= 8:
                self.cache.pop(next(iter(self.cache)))
            self.cache[key] = spec.build(param, self.centre(spec), self.a_dom).run(
                self.u, self.v, self.x, self.y0
            )
        return self.cache[key]

    def head(self, n: int) -> Context:
        """The first n samples, all of them for fitting (for parameter searches)."""
        from fdi_daemon.diagnose.signals import Split

        cut = slice(0, n)
        return replace(
            self,
            u=self.u[cut],
            v=self.v[cut],
            x=self.x[cut],
            y0=self.y0[cut],
            target=self.target[cut],
            base_columns=None if self.base_columns is None else self.base_columns[cut],
            split=Split(warmup=self.split.warmup, train_end=n, n=n),
            cache={},
        )


# ----------------------------------------------------------------------------- fitting


@dataclass
class FittedEffect:
    """An effect with its searched parameter and fitted linear coefficients."""

    name: str
    param: float | None
    coefficients: list[np.ndarray]  # dynamic: numerators B_e (one per regressor); static: [gain]
    n_linear: int = 0
    physical: dict[str, Any] = field(default_factory=dict)
    centre: float = 0.0  # operating point of a centred static map
    n_free: int | None = None  # fitted numbers when fewer than the coefficients (force loop)

    def regressor(self, a_dom: np.ndarray) -> Regressor:
        """A fresh streaming regressor block with this effect's parameters (a_dom: Â of the
        domain plant, whose mode a mode line moves)."""
        return SPECS[self.name].build(self.param, self.centre, a_dom)

    @property
    def named_as(self) -> str:
        """The effect the fit stands for, by its size (``physical["named_as"]``: a Stribeck
        form that takes friction away at rest is a Coulomb friction, `friction_form`);
        otherwise its own name."""
        return self.physical.get("named_as", self.name)

    @property
    def n_params(self) -> int:
        free = self.n_linear if self.n_free is None else self.n_free
        return free + (0 if self.param is None else 1)


@overload
def stored_param(spec: EffectSpec, param: float, fs_hz: float) -> float: ...
@overload
def stored_param(spec: EffectSpec, param: None, fs_hz: float) -> None: ...
@overload
def stored_param(spec: EffectSpec, param: float | None, fs_hz: float) -> float | None: ...
def stored_param(spec: EffectSpec, param: float | None, fs_hz: float) -> float | None:
    """The searched value in the unit of the report (dead time in s, the rest as searched)."""
    if param is None:
        return None
    return param / fs_hz if spec.name == "dead_time" else param


def regressor_param(spec: EffectSpec, value: float | None, fs_hz: float) -> float | None:
    """Inverse of `stored_param`."""
    if value is None:
        return None
    return value * fs_hz if spec.name == "dead_time" else value


def columns(
    spec: EffectSpec, param: float | None, ctx: Context, phi: np.ndarray | None = None
) -> np.ndarray:
    """Design-matrix columns of one effect over the whole record (φ computed if not given)."""
    if spec.name == "force_balance":
        return ctx.base_columns
    if phi is None:
        phi = spec.build(param, ctx.centre(spec), ctx.a_dom).run(ctx.u, ctx.v, ctx.x, ctx.y0)
    if ctx.form == "inverse_dynamics":  # L φ at the moving samples: one force per regressor
        return signal.lfilter(*ctx.lowpass, phi, axis=0) * (ctx.base_columns[:, :1] != 0)
    if not spec.dynamic:
        return phi
    order = len(ctx.a_dom) - 1
    cols = []
    for j in range(phi.shape[1]):
        w = signal.lfilter([1.0], ctx.a_dom, phi[:, j])
        for i in range(order + 1):
            cols.append(np.concatenate([np.zeros(i), w[: len(w) - i]]) if i else w)
    return np.column_stack(cols)


def effect_columns(ctx: Context, effects: list[FittedEffect]) -> np.ndarray:
    """The design matrix of ``effects`` side by side (`columns` of each, φ from the
    context's cache)."""
    return np.column_stack(
        [
            columns(SPECS[e.name], e.param, ctx, ctx.regressors(SPECS[e.name], e.param))
            for e in effects
        ]
    )


def effect_coefficients(effects: list[FittedEffect]) -> np.ndarray:
    """The coefficients of ``effects`` in the order of `effect_columns`' columns."""
    return np.concatenate([np.ravel(c) for e in effects for c in e.coefficients])


#: at most this many training samples are used to search a nonlinear parameter
SEARCH_SAMPLES = 65536

#: eigenvalues of the scaled Gram matrix below this fraction of the largest are dropped
GRAM_CUTOFF = 1e-13


def least_squares(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Least squares by the column-scaled normal equations, pseudo-inverse by eigh.

    The filtered regressors are nearly collinear; directions with a scaled eigenvalue below
    GRAM_CUTOFF·max carry no measurable output and are left out (minimum-norm solution).
    Normal equations (not a tall SVD) keep each fit to two matrix products: the parameter
    searches make hundreds of fits.
    """
    return solve_gram(x.T @ x, x.T @ y)


def solve_gram(gram: np.ndarray, xty: np.ndarray) -> np.ndarray:
    """θ from the normal equations G θ = Xᵀy, scaled to unit diagonal, pseudo-inverse."""
    scale = np.sqrt(np.diag(gram).copy())
    scale[scale == 0] = 1.0
    w, vecs = np.linalg.eigh(gram / np.outer(scale, scale))
    keep = w > GRAM_CUTOFF * w[-1]
    vk = vecs[:, keep]
    return (vk @ ((vk.T @ (xty / scale)) / w[keep])) / scale


class _SearchFit:
    """Training-part SSE of [base, new] fits with the base's Gram blocks computed once."""

    def __init__(self, ctx: Context, base: np.ndarray | None) -> None:
        fit = ctx.split.fit
        self.fit = fit
        self.y = ctx.target[fit]
        self.yy = float(self.y @ self.y)
        self.base = None if base is None else base[fit]
        if self.base is not None:
            self.gbb = self.base.T @ self.base
            self.bty = self.base.T @ self.y

    def sse(self, x: np.ndarray) -> float:
        xf = x[self.fit]
        gxx, xty = xf.T @ xf, xf.T @ self.y
        if self.base is None:
            gram, rhs = gxx, xty
        else:
            gxb = xf.T @ self.base
            gram = np.block([[self.gbb, gxb.T], [gxb, gxx]])
            rhs = np.concatenate([self.bty, xty])
        theta = solve_gram(gram, rhs)
        return max(self.yy - float(theta @ rhs), 0.0)  # Σe² at the least-squares optimum

    def sse_at_unit_weight(self, x: np.ndarray) -> float:
        """Σe² of y − x: the one column x with coefficient 1, against y alone."""
        e = self.y - x[self.fit, 0]
        return float(e @ e)


class NotApplicable(Exception):
    """The data do not allow this effect (e.g. an input that never leaves its median)."""


def search_param(
    spec: EffectSpec, ctx: Context, base: np.ndarray | None = None, unit_weight: bool = False
) -> float | None:
    """Nonlinear parameter by search on the training part: grid, then bounded refinement.
    unit_weight: the effect's one column enters with coefficient 1 (not fitted), against the
    target alone (``base`` is not used)."""
    if spec.param is None:
        return None
    assert spec.grid is not None  # a searched parameter has its grid
    grid = np.asarray(spec.grid(ctx), float)
    grid = grid[np.isfinite(grid) & (grid > 0)]
    if grid.size == 0:
        raise NotApplicable(f"{spec.name}: the data give no {spec.param} to search")
    search = _SearchFit(ctx, base)
    cost = search.sse_at_unit_weight if unit_weight else search.sse
    costs = np.array([cost(columns(spec, g, ctx)) for g in grid])
    best = int(np.argmin(costs))
    lo = grid[best - 1] if best > 0 else grid[best] * (0.5 if not spec.integer_coarse else 0.0)
    hi = grid[best + 1] if best + 1 < grid.size else grid[best] * 1.5
    if spec.integer_coarse:
        lo, hi = max(lo, 0.0), hi
    res = minimize_scalar(
        lambda p: cost(columns(spec, p, ctx)),
        bounds=(lo, hi),
        method="bounded",
        options={"xatol": max(1e-6, 0.01 * (hi - lo)), "maxiter": 25},
    )
    return float(res.x) if res.fun < costs[best] else float(grid[best])


def fit_effect(
    name: str,
    ctx: Context,
    base: list[FittedEffect] | None = None,
    base_columns: np.ndarray | None = None,
) -> tuple[FittedEffect, list[FittedEffect]]:
    """Fit effect ``name`` on top of already chosen effects ``base`` (refitted jointly).

    Returns the new effect and the refitted base effects.
    """
    spec = SPECS[name]
    part, n_search = _search_part(ctx)
    param = search_param(
        spec,
        part,
        None if base_columns is None else base_columns[:n_search],
        unit_weight=spec.searched_at_unit_weight,
    )
    x_new = columns(spec, param, ctx, ctx.regressors(spec, param))
    xx = x_new if base_columns is None else np.column_stack([base_columns, x_new])
    theta = least_squares(xx[ctx.split.fit], ctx.target[ctx.split.fit])
    refitted = []
    pos = 0
    for eff in base or []:
        k = eff.n_linear
        refitted.append(_with_theta(eff.name, eff.param, theta[pos : pos + k], ctx))
        pos += k
    new = _with_theta(name, param, theta[pos:], ctx)
    return new, refitted


def _search_part(ctx: Context) -> tuple[Context, int]:
    """The context a parameter is searched on, and its length: a long record's first part."""
    n_search = ctx.split.warmup + SEARCH_SAMPLES
    if ctx.split.train_end > n_search:
        return ctx.head(n_search), n_search
    return ctx, len(ctx.u)


def _with_theta(name: str, param: float | None, theta: np.ndarray, ctx: Context) -> FittedEffect:
    spec = SPECS[name]
    if spec.dynamic:
        width = len(ctx.a_dom)
        coefs = [np.asarray(theta[j : j + width], float) for j in range(0, len(theta), width)]
    else:
        coefs = [np.asarray(theta, float)]
    eff = FittedEffect(name, param, coefs, n_linear=len(theta), centre=ctx.centre(spec))
    eff.physical = physical_report(eff, ctx)
    return eff


_LABELS = {
    "coulomb_friction": ["coulomb_level"],
    "viscous_friction": ["viscous_coefficient"],
    "stribeck_friction": ["coulomb_level", "stribeck_excess"],
    "cubic_stiffness": ["cubic_coefficient"],
}

#: friction effects: reported with the sign flipped so that a force opposing motion is
#: positive on a plant whose force path has the input's sign (the §V model)
FRICTION = ("coulomb_friction", "viscous_friction", "stribeck_friction")


def friction_form(out: dict, coulomb_level: float, stribeck_excess: float) -> bool:
    """Whether a Stribeck form sign(v)·(F_c + E·exp(−(v/v_s)²)) is physical, from its
    Coulomb level F_c and excess E (any common scale and sign convention), and what it
    stands for. An excess that adds friction at rest is the Stribeck effect (static
    friction above the Coulomb level). One that takes friction away, down to none at rest,
    is a Coulomb friction whose force builds up after each reversal over v_s (a reversal
    that the model resolves only smoothly, or presliding): ``out["named_as"]`` is then
    ``coulomb_friction``. One that reverses the friction at rest is not physical."""
    if coulomb_level * stribeck_excess > 0.0:
        return True
    if abs(stribeck_excess) <= abs(coulomb_level):
        out["named_as"] = "coulomb_friction"
        return True
    return False


def physical_report(eff: FittedEffect, ctx: Context) -> dict[str, Any]:
    """Fitted physical parameters.

    The searched parameter in its unit. A dynamic effect's coefficient is referred to the
    input: c = ⟨Ĝφ, G_eφ⟩/⟨Ĝφ, Ĝφ⟩ over the training part, the input (e.g. valve voltage)
    per unit of φ that Ĝ would need to produce the same output (on the §V model: F_c/gain for
    Coulomb friction, c_v/gain for viscous). Where the effect's force does not enter like the
    input (a pneumatic actuator between valve and piston) this is only an order of magnitude.

    ``plausible``: a Stribeck form's excess and its Coulomb part, both referred to the input
    the same way, must give a friction of the Coulomb level's sign at rest
    (`friction_form`; ``named_as`` when the form is a Coulomb friction). The sign of a
    single friction term cannot be judged without knowing how force enters.
    """
    spec = SPECS[eff.name]
    if ctx.form == "inverse_dynamics":
        from fdi_daemon.diagnose.inverse import physical

        return physical(eff.name, np.concatenate(eff.coefficients), eff.param, ctx)
    out: dict[str, Any] = {}
    if spec.param is not None:
        out[spec.param] = stored_param(spec, eff.param, ctx.fs_hz)
        out[f"{spec.param}_unit"] = spec.unit
    plausible = True
    if spec.dynamic:
        phi = ctx.regressors(spec, eff.param)
        fit = ctx.split.fit
        labels = _LABELS.get(eff.name, ["input_gain"])
        for j, (label, b) in enumerate(zip(labels, eff.coefficients)):
            w = signal.lfilter(ctx.b_dom, ctx.a_dom, phi[:, j])[fit]
            g = signal.lfilter(b, ctx.a_dom, phi[:, j])[fit]
            ww = float(w @ w)
            c = float(w @ g) / ww if ww > 0 else 0.0
            if eff.name in _LABELS:
                out[f"{label}_input_equivalent"] = -c if eff.name in FRICTION else c
            else:
                out[label] = c
        if eff.name == "stribeck_friction":
            plausible = friction_form(
                out, out["coulomb_level_input_equivalent"], out["stribeck_excess_input_equivalent"]
            )
    elif eff.name == "gain_fault":  # y = (1 + g) ŷ₀
        out["gain_ratio"] = 1.0 + float(eff.coefficients[0][0])
    elif eff.name == "dead_time":  # y = ŷ₀ + c (ŷ₀(t − τ) − ŷ₀(t)); a pure shift has c = 1
        out["shift_share"] = float(eff.coefficients[0][0])
        plausible = SHARE_RANGE[0] <= out["shift_share"] <= SHARE_RANGE[1]
        # the delay itself is the pure shift's (c held at 1), read against the nominal
        # model: beside the free c it trades with c (c·τ is the first-order shift)
        assert spec.param is not None  # dead_time_s
        out["fitted_shift_s"] = out[spec.param]
        out[spec.param] = stored_param(
            spec, search_param(spec, _search_part(ctx)[0], unit_weight=True), ctx.fs_hz
        )
    elif eff.name in MODE_LINES:  # y = ŷ₀ + c (ŷ_r − ŷ₀); a pure change has c = 1
        line = MODE_LINES[eff.name]
        pole = nominal_pole(ctx.a_dom)
        # fitted only with a mode (`_ratios`), at a searched ratio
        assert pole is not None and eff.param is not None
        out.update(mode_report(pole, line, eff.param, ctx.fs_hz))
        out["mode_change"] = line  # as `force.mode_shift` reads the loop's spring
        out["line_share"] = float(eff.coefficients[0][0])
        out["named_as"] = LINES[line]
        # a viscous friction adds damping (lost damping is no friction)
        plausible = SHARE_RANGE[0] <= out["line_share"] <= SHARE_RANGE[1] and (
            line != "damping" or eff.param > 1.0
        )
    else:
        key = "offset" if eff.name == "sensor_offset" else "gain"
        out[key] = float(eff.coefficients[0][0])
    out["plausible"] = plausible
    return out
