"""Force effects on the moving mass, in feedback with the motion: y = G_u u + G_F F(x, v).

Friction (Coulomb, viscous, Stribeck), a cubic spring and a constant force act on the mass.
The force they produce moves the mass, and the motion sets the force: the velocity v and
position x that enter F are those of the *augmented* model's own output, not of the nominal
simulation. Per sample k (all filters share Â, the nominal model's denominator):

    z_pre[k] = Σ_{i≥1} (−a_i z[k−i] + Σ_j b_ji φ_j[k−i])      (G_F F without this sample's force)
    y[k]      = y_ff[k] + z_pre[k] + Σ_j b_j0 φ_j(v[k], x[k])   (sign v, v, x³, 1, ...)
    (v, x)[k] = states(y[k])                                    (`signals` state chain)

This sample's force moves this sample's output (b_j0 ≠ 0: an acceleration follows a force at
once), and the states depend on that output: the pair is solved by a few fixed-point passes
(the chain's direct term is T/2 per integration, so the passes converge fast).

Stick–slip (time-stepping Coulomb, as `hil_sim.msd`): at v = 0 the dry-friction columns
(sign v and a Stribeck excess) take one value s ∈ [−1, 1] instead of sign v. If the dry
friction available stops the mass within the step (|v with s = 0| ≤ |dv/ds|), the mass is
held by s (v = 0; an acceleration output is 0 too, and the velocity state is cleared) when
that takes |s| ≤ 1. Otherwise it slides and the friction opposes the motion (at a reversal
that the friction cannot hold, the fixed point may end on either sign for one sample).

y_ff is everything fed forward from the input (Ĝ u, the linear refit, input effects, ŷ₀'s
gain, shift and mode lines); the sensor's effects (`EffectSpec.at_sensor`: an offset, a clip)
are added to the loop's output, so the motion (v, x) is the plant's. The force path
G_F = B_F/Â: its poles are the nominal model's (eq. 6: m ẍ + c ẋ + k x = F − F_f moves
with the plant's poles), and its numerator B_F (one per regressor, same order as Â) is
identified: first by linear least squares with the nominal motion (the feed-forward first
approximation, `effects.fit_effect`), then refined by output-error least squares with the
motion in the loop (`_LoopFit`). A valve or an input
filter between the input and the force (poles of Ĝ that are not the mechanics') is
cancelled by B_F's zeros; a force input makes B_F ∝ B̂.

The loop is a streaming block (`ForceLoop`: `run` and `step` run the same compiled kernel).
"""

from __future__ import annotations

import cmath
import math
from dataclasses import replace

import numpy as np
from scipy import signal
from scipy.optimize import least_squares as least_squares_nl

from fdi_daemon.core.compiled import jit
from fdi_daemon.diagnose.effects import (
    SPECS,
    FittedEffect,
    effect_coefficients,
    effect_columns,
    friction_form,
    physical_report,
    solve_gram,
)
from fdi_daemon.diagnose.mode_lines import nominal_pole

#: effects that are forces on the moving mass
FORCE_EFFECTS = (
    "coulomb_friction",
    "viscous_friction",
    "stribeck_friction",
    "cubic_stiffness",
    "force_offset",
    "stiffness_change",
    "mass_change",
)
#: everything in the loop: the force effects and the loop's linear spring correction
LOOPED = FORCE_EFFECTS + ("loop_stiffness",)
#: the loop's linear force of x (a free B_F): the base's spring, or the candidate itself
#: (named after the parameter of the mode it moves, `mechanics_name`)
SPRINGS = ("loop_stiffness", "stiffness_change", "mass_change")
#: the name of the loop's linear force of x by what it does to the mode (`mode_shift`;
#: added damping is viscous friction, whose own fit `select` names)
MECHANICS = {"stiffness": "stiffness_change", "mass": "mass_change"}

# regressor kinds of the kernel
_SIGN, _VEL, _STRIBECK, _CUBE, _ONE, _X = 0, 1, 2, 3, 4, 5


def kinds(name: str, param: float | None) -> list[tuple[int, float]]:
    """(kind, parameter) of each regressor column of a force effect."""
    if name == "coulomb_friction":
        return [(_SIGN, 0.0)]
    if name == "viscous_friction":
        return [(_VEL, 0.0)]
    if name == "stribeck_friction":
        assert param is not None  # its velocity is searched
        return [(_SIGN, 0.0), (_STRIBECK, float(param))]
    if name == "cubic_stiffness":
        return [(_CUBE, 0.0)]
    if name == "force_offset":
        return [(_ONE, 0.0)]
    if name in SPRINGS:
        return [(_X, 0.0)]
    raise ValueError(f"{name} is not a force effect")


@jit
def _df2t(b, a, s, x):
    out = b[0] * x + s[0]
    n = s.size
    for i in range(n - 1):
        s[i] = s[i + 1] + b[i + 1] * x - a[i + 1] * out
    s[n - 1] = b[n] * x - a[n] * out
    return out


@jit
def _states(chain_n, vb0, s1, s2, prev, fs, y):
    """(v, x) the state chain would give for output y this sample (no state change)."""
    if chain_n == 0:
        v = vb0 * y + s1[0]
        return v, vb0 * v + s2[0]
    if chain_n == 1:
        return y, vb0 * y + s1[0]
    return (y - prev[0]) * fs, y


@jit
def _phi_k(kind, par, v, x):
    if kind == 0:
        return 1.0 if v > 0 else (-1.0 if v < 0 else 0.0)
    if kind == 1:
        return v
    if kind == 2:
        sg = 1.0 if v > 0 else (-1.0 if v < 0 else 0.0)
        return sg * math.exp(-((v / par) ** 2))
    if kind == 3:
        return x * x * x
    if kind == 4:
        return 1.0
    return x


#: fixed-point passes for this sample's force, which moves this sample's output (b_j0 ≠ 0)
_PASSES = 4


@jit
def _slope(chain_n, vb0, fs):
    """dv/dy of the state chain this sample (`_states` is affine in y)."""
    if chain_n == 0:
        return vb0
    if chain_n == 1:
        return 1.0
    return fs


@jit(nrt=True)
def _kernel(
    y_ff, a, bmat, kind, par, chain_n, vb, va, s1, s2, prev, zhist, phist, fs, phi_out, v_out
):
    n = a.size - 1
    m = bmat.shape[1] - 1
    ncol = bmat.shape[0]
    y = np.empty(y_ff.size)
    phi = np.zeros(ncol)
    # stick: at v = 0 every dry-friction column (sign v; a Stribeck excess is at its full
    # value there) takes the same s ∈ [−1, 1]; g = dv/ds this sample
    dry = 0.0
    for j in range(ncol):
        if kind[j] == 0 or kind[j] == 2:
            dry += bmat[j, 0]
    g = dry * _slope(chain_n, vb[0], fs)
    for k in range(y_ff.size):
        acc = 0.0
        for i in range(n):
            acc -= a[i + 1] * zhist[i]
        for i in range(m):
            for j in range(ncol):
                acc += bmat[j, i + 1] * phist[j, i]
        base = y_ff[k] + acc
        stopped = False
        if g < 0.0:
            # held at rest: the other forces at v = 0, then the s that keeps v = 0
            yk = base
            for _ in range(_PASSES):
                v, x = _states(chain_n, vb[0], s1, s2, prev, fs, yk)
                yk = base
                for j in range(ncol):
                    if kind[j] != 0 and kind[j] != 2:
                        phi[j] = _phi_k(kind[j], par[j], 0.0, x)
                        yk += bmat[j, 0] * phi[j]
            v0, x = _states(chain_n, vb[0], s1, s2, prev, fs, yk)
            if abs(v0) <= -g:  # the dry friction available stops the mass within the step
                # held if it can be: v = 0 (velocity, position output); an acceleration
                # output must be 0 too (the trapezoid's v = 0 alone would make it ring)
                sk = -yk / dry if chain_n == 0 else -v0 / g
                if abs(sk) <= 1.0:
                    stopped = True
                    for j in range(ncol):
                        if kind[j] == 0 or kind[j] == 2:
                            phi[j] = sk
                            yk += bmat[j, 0] * sk
                    if chain_n == 0:
                        s1[:] = 0.0  # at rest within the step: no velocity carried over
        if not stopped:  # slides through the step: friction opposes the motion
            yk = base
            for _ in range(_PASSES):
                v, x = _states(chain_n, vb[0], s1, s2, prev, fs, yk)
                yk = base
                for j in range(ncol):
                    phi[j] = _phi_k(kind[j], par[j], v, x)
                    yk += bmat[j, 0] * phi[j]
        # commit the chain with the sample's output
        if chain_n == 0:
            v = _df2t(vb, va, s1, yk)
            _df2t(vb, va, s2, v)
        elif chain_n == 1:
            v = yk
            _df2t(vb, va, s1, yk)
        else:
            v = (yk - prev[0]) * fs
            prev[0] = yk
        v_out[k] = v
        for i in range(n - 1, 0, -1):
            zhist[i] = zhist[i - 1]
        if n > 0:
            zhist[0] = yk - y_ff[k]
        for i in range(m - 1, 0, -1):
            for j in range(ncol):
                phist[j, i] = phist[j, i - 1]
        if m > 0:
            for j in range(ncol):
                phist[j, 0] = phi[j]
        for j in range(ncol):
            phi_out[k, j] = phi[j]
        y[k] = yk
    return y


class ForceLoop:
    """The force effects' loop around a fed-forward output y_ff (frozen parameters).

    a_dom: Â; columns: [(kind, parameter)]; numerators: B_F per column (len(Â) each);
    chain: (n, b, a, fs) of the state chain (`signals.StateChain.coefficients`).
    """

    def __init__(self, a_dom, columns, numerators, chain) -> None:
        self.a = np.asarray(a_dom, float)
        self.kind = np.array([c[0] for c in columns], dtype=np.int64)
        self.par = np.array([c[1] if c[1] else 1.0 for c in columns], dtype=float)
        self.bmat = np.array(numerators, dtype=float).reshape(len(columns), -1)
        self.chain_n, vb, va, self.fs = chain
        self.vb, self.va = np.asarray(vb, float), np.asarray(va, float)
        self.reset()

    def reset(self) -> None:
        order = max(self.va.size - 1, 1)
        self.s1, self.s2 = np.zeros(order), np.zeros(order)
        self.prev = np.zeros(1)
        self.zhist = np.zeros(max(self.a.size - 1, 1))
        self.phist = np.zeros((self.kind.size, max(self.bmat.shape[1] - 1, 1)))

    def run(self, y_ff: np.ndarray) -> np.ndarray:
        """y = y_ff + G_F F(v, x) over an array, continuing from the current state."""
        return self.trace(y_ff)[0]

    def trace(self, y_ff: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(y, φ, v): the output, the regressors the loop applied (per sample, per column;
        a dry-friction column holds the stick value s ∈ [−1, 1] while the mass is at rest)
        and the loop's velocity (0 while held)."""
        y_ff = np.ascontiguousarray(y_ff, dtype=float)
        phi = np.empty((y_ff.size, self.kind.size))
        v = np.empty(y_ff.size)
        y = _kernel(
            y_ff,
            self.a,
            self.bmat,
            self.kind,
            self.par,
            self.chain_n,
            self.vb,
            self.va,
            self.s1,
            self.s2,
            self.prev,
            self.zhist,
            self.phist,
            float(self.fs),
            phi,
            v,
        )
        return y, phi, v

    def step(self, y_ff: float) -> float:
        return float(self.run(np.array([y_ff]))[0])

    @property
    def state(self) -> list[np.ndarray]:
        return [
            self.s1.copy(),
            self.s2.copy(),
            self.prev.copy(),
            self.zhist.copy(),
            self.phist.copy(),
        ]


#: at most this many passes of the loop refinement (each: states from the last loop run,
#: numerators by least squares)
PASSES = 8

#: iterations of the final joint fit (step 4; each costs a loop run per coefficient): on
#: a hardening spring 3 took the gap left from 0.109 to 0.009, 6 to 0.0067, 40 to 0.0047
JOINT_ITERATIONS = 6

#: halvings of the force amplitudes of a feed-forward start whose loop diverges (a
#: hardening spring fitted on the nominal motion, fed back at the largest amplitudes):
#: towards the linear model, which the loop runs stably, until the loop runs
SHRINKS = 8


def _padded(b: np.ndarray, width: int) -> np.ndarray:
    out = np.zeros(width)
    out[: min(width, len(b))] = np.asarray(b, float)[:width]
    return out


def _held(eff, before: dict) -> np.ndarray:
    """The coefficients of ``eff`` as fitted before (``before``: by name), else zeros."""
    if eff.name in before:
        return effect_coefficients([before[eff.name]])
    return np.zeros(sum(np.size(c) for c in eff.coefficients))


def _shifts(w: np.ndarray, width: int) -> np.ndarray:
    return np.column_stack([np.concatenate([np.zeros(i), w[: len(w) - i]]) for i in range(width)])


#: regressor kinds whose force dissipates (a friction: it opposes the motion); a Stribeck
#: excess is friction too, static above the Coulomb level (F_s ≥ F_c)
DISSIPATIVE = (_SIGN, _VEL, _STRIBECK)


def friction_bounds(cols: list, n_ff: int, width: int, per_column: int) -> np.ndarray:
    """Upper bounds of a force-loop parameter vector [fed-forward, per column] (``width``
    numbers per column when ``per_column`` is ``width``, an amplitude when 1): a friction
    column's leading coefficient ≤ 0, every other number free (+inf).

    The leading coefficient b_j0 of B_F/Â (Â monic) is the force path's high-frequency
    gain: a force on the mass accelerates it at once in the force's direction (+1/m), so
    a friction F = −F_c sign v (or −c v) with F_c, c ≥ 0 has b_j0 ≤ 0, and so has a
    Stribeck excess −(F_s − F_c) e^{−(v/v_s)²} sign v with F_s ≥ F_c (static friction above
    the Coulomb level). An amplitude on the input's path B̂ is minus the friction's input
    equivalent (the reported level), ≤ 0 too. A column whose b_j0 ends at its bound 0 is
    that friction at size zero (`at_bound`).
    """
    upper = np.full(n_ff + len(cols) * per_column, np.inf)
    for j, (kind, _) in enumerate(cols):
        if kind in DISSIPATIVE:
            upper[n_ff + j * per_column] = 0.0
    return upper


#: a friction column is at its bound (b_j0 = 0) when −b_j0 is within this share of its
#: numerator's largest coefficient: bounded least squares stops at 0, the joint fit's
#: trust region (a few iterations, strictly inside the bound) near it — on the rig's
#: payload record a Stribeck excess ended at −2·10⁻⁷ beside lagged terms of 4·10⁻³. A
#: friction that acts has b_j0 of the size of its numerator's other terms (0.2 of the
#: largest on that record's Coulomb column)
AT_BOUND = 1e-3


def at_bound(b: np.ndarray) -> bool:
    """Whether a friction column's force path B_F (b_j0 ≤ 0 by `friction_bounds`) sits at
    its bound: no high-frequency gain, so no force on the mass — a force accelerates the
    mass at once. What the rest of B_F fits (lagged terms of sign v or v) is then a filter
    on the velocity's sign, not a friction: the effect contributes nothing and is never
    named (`force_report`: ``*_at_bound``, not ``plausible``)."""
    b = np.asarray(b, float)
    return bool(-b[0] <= AT_BOUND * (float(np.max(np.abs(b))) if b.size else 0.0))


def bounded_least_squares(x: np.ndarray, y: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """min ‖y − xθ‖ subject to θ ≤ ``upper`` (0 or +inf per number): an active set, each
    violating number held at its bound in turn (the worst first) and the rest refitted
    (`effects.least_squares` on the Gram matrix), until every number is within bounds."""
    gram, xty = x.T @ x, x.T @ y
    held = np.zeros(len(upper), dtype=bool)
    theta = np.zeros(len(upper))
    for _ in range(int(np.sum(np.isfinite(upper))) + 1):
        free = ~held
        theta[:] = 0.0
        theta[free] = solve_gram(gram[np.ix_(free, free)], xty[free])
        over = np.where(free & (theta > upper), theta - upper, 0.0)
        if not np.any(over > 0):
            break
        held[int(np.argmax(over))] = True
    return np.minimum(theta, upper)


def in_the_loop(
    ctx, effects: list, previous: list | None = None, spring: bool = True, joint: bool = True
) -> tuple[list, np.ndarray]:
    """Refit ``effects`` with the force effects in the loop; returns the refitted effects
    (``loop_stiffness`` added when no spring is among them, `SPRINGS`) and their
    contribution y − ŷ₀ over the record.

    The force path G_F = B_F/Â is identified on the training part in four steps:
    1. feed-forward start: B_F = θ B̂ (a force enters where the input does), θ and the
       fed-forward coefficients by least squares with the nominal motion;
    2. the amplitudes θ (and fed-forward coefficients) by output-error least squares with
       the motion in the loop;
    3. the free numerators B_F (same order as Â: a valve or input filter in Ĝ is not on the
       force path, B_F's zeros cancel its poles) by passes of least squares on the states of
       the last loop run, each pass kept only if the loop's training error falls
       (backtracking: a full step may destabilise the loop);
    4. (``joint``) every coefficient at once by output-error least squares with the motion
       in the loop, from the best of step 3 (its passes regress on the previous run's
       states and stop short of the optimum: a hardening spring under a rising excitation
       left 0.109 of a 0.199 gap, the joint fit 0.007); kept where its training error is
       lower and its effects are physically possible, or step 3's were not either.
    Step 3 also starts from ``previous`` (the effects named so far, as fitted in their
    loop), the rest at zero, when they hold a loop.
    ``loop_stiffness`` (x through its own B_F) lets the loop move the nominal poles, as a
    spring that the nominal model mis-sized would; it is part of the base, never named.
    Alone it is the candidate ``stiffness_change`` (`select`: every other force effect must
    do significantly better than it).
    """
    width = len(ctx.a_dom)
    if spring and not any(e.name in SPRINGS for e in effects):
        effects = [
            FittedEffect("loop_stiffness", None, [np.zeros(width)], n_linear=width, n_free=width)
        ] + list(effects)
    loop = _LoopFit(ctx, effects)
    fits = [loop.from_start(b) for b in loop.starts()]
    held = loop.from_previous(previous)
    if held is not None:
        fits.append(held)
    best, best_ff, best_nums, y, phi, v = min(fits, key=lambda f: f[0])
    out = loop.fitted(best_ff, best_nums, y, phi, v)
    if joint and np.isfinite(best):
        joined = loop.joint_fit(best, best_ff, best_nums, y, phi, v)
        if joined[0] < best:
            effects_joined = loop.fitted(*joined[1:])
            # the joint optimum may lie where the effects are not physically possible (a
            # Stribeck excess that pushes the motion): the best possible fit is kept then
            if possible(effects_joined) or not possible(out):
                out, y = effects_joined, joined[3]
    return out, y - ctx.y0


class _LoopFit:
    """The fit of `in_the_loop` for one set of effects (``loop_stiffness`` already among
    them), by stage: `from_start` (steps 1-3), `from_previous` (step 3 from the effects
    named so far), `joint_fit` (step 4), `fitted` (the effects and their reports).

    The parameter vector is [θ_ff, B_F per force column]: θ_ff the fed-forward effects'
    coefficients (their columns ``x_ff``, ``n_ff`` of them), B_F a numerator of ``width``
    = len(Â) numbers per column of ``cols`` [(kind, parameter)]. A fit is the tuple
    (training SSE, θ_ff, B_F (columns × width), y, φ, v), the last three from the loop run
    over the record (`ForceLoop.trace`)."""

    def __init__(self, ctx, effects: list) -> None:
        self.ctx = ctx
        self.effects = effects
        self.width = width = len(ctx.a_dom)
        self.ff = [e for e in effects if e.name not in LOOPED]
        self.fb = [e for e in effects if e.name in LOOPED]
        self.y_meas = ctx.target + ctx.y0
        blocks = [effect_columns(ctx, [e]) for e in self.ff]
        self.x_ff = np.column_stack(blocks) if blocks else np.zeros((len(ctx.u), 0))
        self.n_ff = n_ff = self.x_ff.shape[1]
        # the sensor's columns act on the output after the loop: the motion is the plant's
        self.sensor = np.concatenate(
            [np.full(b.shape[1], SPECS[e.name].at_sensor) for e, b in zip(self.ff, blocks)]
            or [np.zeros(0, bool)]
        )
        self.cols = cols = [c for e in self.fb for c in kinds(e.name, e.param)]
        # a friction's force path: its high-frequency gain b_j0 ≤ 0 (`friction_bounds`); on
        # an acceleration output b_j0 is the direct term, elsewhere the path's leading terms
        # are the state chain's and are left free
        self.upper = (
            friction_bounds(cols, n_ff, width, width)
            if ctx.chain[0] == 0
            else np.full(n_ff + len(cols) * width, np.inf)
        )
        # the same for [θ_ff, an amplitude per column] (steps 1 and 2)
        self.amp_upper = friction_bounds(cols, n_ff, width, 1)
        # the clip of a diverging trial's residual (`training_error`)
        self.scale = 1e3 * (float(np.std(self.y_meas[ctx.split.fit])) or 1.0)

    def run(self, theta_ff, nums):
        """The loop over the record: ((y, φ, v), the training SSE; inf where it diverges)."""
        ctx = self.ctx
        with np.errstate(all="ignore"):
            y_mech, y_sensor = self.fed_forward(theta_ff)
            y, phi, v = ForceLoop(ctx.a_dom, self.cols, nums, ctx.chain).trace(y_mech)
            y = y + y_sensor
            sse = float(np.sum((self.y_meas - y)[ctx.split.fit] ** 2))
        return (y, phi, v), (sse if np.isfinite(sse) else np.inf)

    def fed_forward(self, theta_ff):
        """(what moves the mass: Ĝ u and the input side's effects; what the sensor adds).
        Without a sensor column, x_ff @ θ as a whole: summed in another order the loop fits
        end elsewhere (docs/diagnose_probes.md, "A measure of the fragility")."""
        if not self.sensor.any():
            return self.ctx.y0 + self.x_ff @ theta_ff, np.zeros(len(self.ctx.y0))
        mech = self.x_ff[:, ~self.sensor] @ theta_ff[~self.sensor]
        return self.ctx.y0 + mech, self.x_ff[:, self.sensor] @ theta_ff[self.sensor]

    def training_error(self, theta_ff, nums):
        """The loop's output error on the training part (the loop run over it only)."""
        ctx, end = self.ctx, self.ctx.split.train_end
        with np.errstate(all="ignore"):
            y_mech, y_sensor = self.fed_forward(theta_ff)
            y = ForceLoop(ctx.a_dom, self.cols, nums, ctx.chain).run(y_mech[:end])
            y = y + y_sensor[:end]
            e = (self.y_meas[:end] - y)[ctx.split.fit]
        # an unstable trial diverges: a large, finite residual keeps the solver going
        return np.clip(np.nan_to_num(e, nan=self.scale), -self.scale, self.scale)

    def starts(self) -> list[np.ndarray]:
        """The start paths of step 1, each fitted and the lower training error kept: the
        input's path B̂ (a force input) and, on an acceleration output, a force that moves
        the acceleration at once (B_F = θ Â, G_F = θ: the path of a force on the mass where
        the input acts through a valve's lag). On a velocity or position output G_F = θ Â
        is not a force on the mass: only the input's path."""
        starts = [_padded(self.ctx.b_dom, self.width), _padded(self.ctx.a_dom, self.width)]
        return starts if self.ctx.chain[0] == 0 else starts[:1]

    def from_start(self, b_path: np.ndarray) -> tuple:
        """Steps 1-3 from the force path B_F = θ b_path: the fit (class docstring)."""
        theta = self.feed_forward_start(b_path)
        theta = self.amplitudes_in_the_loop(theta, b_path)
        return self.refine(theta[: self.n_ff], np.outer(theta[self.n_ff :], b_path))

    def feed_forward_start(self, b_path: np.ndarray) -> np.ndarray:
        """Step 1: [θ_ff, amplitudes θ on b_path] by bounded least squares with the nominal
        motion (a friction's amplitude ≤ 0, `friction_bounds`); a start whose loop diverges
        has its amplitudes halved, up to SHRINKS times, towards the linear model."""
        ctx, n_ff = self.ctx, self.n_ff
        x_fb = np.column_stack(
            [signal.lfilter(b_path, ctx.a_dom, _phi(k, p, ctx.v, ctx.x)) for k, p in self.cols]
        )
        theta = bounded_least_squares(
            np.column_stack([self.x_ff, x_fb])[ctx.split.fit],
            ctx.target[ctx.split.fit],
            self.amp_upper,
        )
        for _ in range(SHRINKS):  # a start whose loop diverges: towards the linear model
            if np.isfinite(self.run(theta[:n_ff], np.outer(theta[n_ff:], b_path))[1]):
                break
            theta[n_ff:] *= 0.5
        return theta

    def amplitudes_in_the_loop(self, theta: np.ndarray, b_path: np.ndarray) -> np.ndarray:
        """Step 2: θ (fed-forward coefficients, amplitudes on b_path) by output-error least
        squares with the motion in the loop, from ``theta``; kept where it lowers the
        training error."""
        n_ff = self.n_ff

        def residual(th):
            return self.training_error(th[:n_ff], np.outer(th[n_ff:], b_path))

        r0 = residual(theta)
        with np.errstate(all="ignore"):
            sol = least_squares_nl(
                residual,
                theta,
                bounds=(-np.inf, self.amp_upper),
                method="trf",
                x_scale="jac",
                max_nfev=30 * theta.size,
            )
        return sol.x if float(sol.fun @ sol.fun) < float(r0 @ r0) else theta

    def refine(self, best_ff: np.ndarray, best_nums: np.ndarray) -> tuple:
        """Step 3 from the given fed-forward coefficients and numerators: at most PASSES
        passes of bounded least squares for the free numerators on the regressors the loop
        applied (its own motion; the stick value while the mass is held), each step halved
        until the loop's training error falls; stops when a pass gains under 0.1 %."""
        ctx, fit, n_ff = self.ctx, self.ctx.split.fit, self.n_ff
        shape = (len(self.cols), self.width)
        (y, phi, v), best = self.run(best_ff, best_nums)
        for _ in range(PASSES if np.isfinite(best) else 0):
            xs = [self.x_ff] + [
                _shifts(signal.lfilter([1.0], ctx.a_dom, phi[:, j]), self.width)
                for j in range(len(self.cols))
            ]
            target = bounded_least_squares(np.column_stack(xs)[fit], ctx.target[fit], self.upper)
            start = np.concatenate([best_ff, best_nums.ravel()])
            before = best
            for frac in (1.0, 0.5, 0.25, 0.125):
                trial = start + frac * (target - start)
                traced, sse = self.run(trial[:n_ff], trial[n_ff:].reshape(shape))
                if sse < best:
                    (y, phi, v), best = traced, sse
                    best_ff, best_nums = trial[:n_ff], trial[n_ff:].reshape(shape)
                    break
            if best > 0.999 * before:
                break
        return best, best_ff, best_nums, y, phi, v

    def from_previous(self, previous: list | None) -> tuple | None:
        """Step 3 from the loop fitted before (``previous``: the effects named so far, as
        they were fitted), anything new at zero: the fit never starts further from the data
        than the model it extends. None when ``previous`` holds no loop."""
        before = {e.name: e for e in previous or []}
        if not any(e.name in LOOPED for e in before.values()):
            return None
        return self.refine(
            np.concatenate([_held(e, before) for e in self.ff] + [np.zeros(0)]),
            np.concatenate([_held(e, before) for e in self.fb]).reshape(-1, self.width),
        )

    def joint_fit(self, best, best_ff, best_nums, y, phi, v) -> tuple:
        """Step 4: every coefficient at once by output-error least squares with the motion
        in the loop (finite-difference Jacobian, JOINT_ITERATIONS), from the fit given: the
        passes of step 3 regress on the states of the previous run and stop short of the
        optimum. The fit given where the joint one is not better or diverges later."""
        n_ff, shape = self.n_ff, (len(self.cols), self.width)
        x0 = np.minimum(np.concatenate([best_ff, best_nums.ravel()]), self.upper)

        def residual(th):
            return self.training_error(th[:n_ff], th[n_ff:].reshape(shape))

        with np.errstate(all="ignore"):
            sol = least_squares_nl(
                residual,
                x0,
                bounds=(-np.inf, self.upper),
                method="trf",
                x_scale="jac",
                max_nfev=JOINT_ITERATIONS,
            )
        theta_ff, nums = sol.x[:n_ff], sol.x[n_ff:].reshape(shape)
        traced, sse = self.run(theta_ff, nums)
        if sse < best and np.all(np.isfinite(traced[0])):  # not one that diverges later
            return sse, theta_ff, nums, *traced
        return best, best_ff, best_nums, y, phi, v

    def input_path(self, best_ff: np.ndarray) -> np.ndarray:
        """The loop's input numerator: B̂, plus B_e where the nominal one is refitted
        (``linear_refit``, whose coefficients lie where its columns do in x_ff)."""
        pos = 0
        for e in self.ff:
            if e.name == "linear_refit":
                return _padded(self.ctx.b_dom, self.width) + best_ff[pos : pos + self.width]
            pos += e.n_linear
        return self.ctx.b_dom

    def fitted(self, best_ff, best_nums, y, phi, v) -> list:
        """The effects with these coefficients, each with its report (`force_report`, a
        fed-forward one `effects.physical_report`), in the order of ``effects``."""
        ctx, width, cols = self.ctx, self.width, self.cols
        viscous = next((best_nums[j] for j, (kind, _) in enumerate(cols) if kind == _VEL), None)
        spring = next(
            ((best_nums[j], phi[:, j]) for j, (kind, _) in enumerate(cols) if kind == _X), None
        )
        b_input = self.input_path(best_ff)
        out, pos, row = [], 0, 0
        for e in self.effects:
            if e.name in LOOPED:
                k = len(kinds(e.name, e.param))
                new = FittedEffect(
                    e.name,
                    e.param,
                    list(best_nums[row : row + k]),
                    n_linear=k * width,
                    centre=e.centre,
                    n_free=k * width,
                )
                new.physical = force_report(
                    new, ctx, y, phi[:, row : row + k], v, b_input, viscous, spring
                )
                row += k
            else:
                k = e.n_linear
                flat = best_ff[pos : pos + k]
                coefs = (
                    [flat[j : j + width] for j in range(0, k, width)]
                    if SPECS[e.name].dynamic
                    else [flat]
                )
                new = FittedEffect(e.name, e.param, coefs, n_linear=k, centre=e.centre)
                new.physical = physical_report(new, ctx)
                pos += k
            out.append(new)
        _damper_by_the_mode(out)
        return out


def _damper_by_the_mode(effects: list) -> None:
    """A viscous friction beside the loop's linear force of x (`SPRINGS`) is a damper: the
    loop's linear part must move the mode by damping (`mode_shift`, with the spring beside
    it), not by stiffness, and add damping, not remove it. Its size per unit mass, Δ(c/m)
    (1/s, ``damping_change_per_s``), is read from the mode like the damping: the split of
    the damping between the spring's and the viscous column's free numerators is not
    determined by the data. A damper that does not move the mode by the record's
    resolution ("none") adds no damping: it contributes nothing (what its free numerator
    fits is not a damper) and is never named. Sets the reports in place."""
    linear = next((e for e in effects if e.name in SPRINGS), None)
    for e in effects:
        if e.name == "viscous_friction" and linear is not None:
            e.physical["mode_change"] = linear.physical.get("mode_change")
            added = linear.physical.get("damping_change_per_s")
            e.physical["damping_change_per_s"] = added
            e.physical["plausible"] = bool(
                e.physical["plausible"]
                and e.physical["mode_change"] not in MECHANICS
                and e.physical["mode_change"] != "none"
                and (added is None or added >= 0.0)
            )


def possible(effects: list) -> bool:
    """Every effect physically possible (its report's ``plausible``)."""
    return all(e.physical.get("plausible", True) for e in effects)


_FORCE_LABELS = {
    "coulomb_friction": ["coulomb_level"],
    "viscous_friction": ["viscous_coefficient"],
    "stribeck_friction": ["coulomb_level", "stribeck_excess"],
    "cubic_stiffness": ["cubic_coefficient"],
    "force_offset": ["offset"],
    "loop_stiffness": ["stiffness"],
    "stiffness_change": ["stiffness"],
    "mass_change": ["stiffness"],
}
_FRICTION = ("coulomb_friction", "viscous_friction", "stribeck_friction")
#: the largest share of a force effect's output energy (acceleration) that may be its
#: mean: an effect that is mostly a constant acceleration is not a force of the motion (on
#: the rig, a spring fitted beside an accelerometer bias: 0.9996; friction, springs and
#: masses where the simulator has them: below 0.001)
STEADY_SHARE = 0.5


def force_report(
    eff,
    ctx,
    y: np.ndarray,
    phi: np.ndarray,
    v: np.ndarray,
    b_input: np.ndarray,
    b_v: np.ndarray | None = None,
    spring: tuple[np.ndarray, np.ndarray] | None = None,
) -> dict:
    """Size and physical check of a force effect, from the augmented motion: output ``y``,
    the regressors ``phi`` (samples × the effect's columns) and the velocity ``v`` of the
    loop (`ForceLoop.trace`); b_input: the loop's input numerator (B̂, refitted where the
    base refits it); b_v: the numerator of a viscous friction in the same loop
    (a spring's mode is that of the loop's linear forces together, `mode_shift`); spring:
    (numerator, x) of the loop's spring, whose free B_F holds a damper as well: a viscous
    friction is sized and tested on the two linear forces together (how the fit splits
    the damping between them is not determined by the data; their sum is).

    ``<label>_input_equivalent``: the input per unit of φ that the force takes away,
    c = −⟨G_uφ, G_Fφ⟩/⟨G_uφ, G_uφ⟩ on the training part (v, x the augmented motion): the
    friction level, the cubic spring coefficient, the constant force — newtons when the
    input is a force; on a plant whose input acts through a valve only an order of
    magnitude. G_u = b_input/Â is the loop's own input path: both paths share the loop's
    denominator, so c does not depend on the loop; referred to the nominal B̂ it would
    carry the refit's gain (a Silverbox-like cubic spring under a refit of −51 % read
    0.137 V/V³ for 0.435).
    Friction must take energy out of the motion: the velocity w_j that regressor j causes
    (its output contribution G_Fj φ_j, turned into velocity) must oppose the motion,
    P_j = ⟨w_j, v⟩/⟨v, v⟩ < 0 (``*_power_ratio``); a Stribeck excess must too, and with
    the Coulomb level it must give a friction of that level's sign at rest
    (`effects.friction_form`: an excess that takes friction away near v = 0 makes the form
    a Coulomb friction, ``named_as``). Otherwise the fit is not ``plausible`` and is never
    named. The power test needs no knowledge of how force enters, unlike the sign of c.
    On an acceleration output (``steady_share``, `_steady_share`): a force of the motion
    holds no steady acceleration; an effect whose output is mostly its mean is a sensor's
    offset.
    """
    if not np.all(np.isfinite(y)):
        return {"diverged": True, "plausible": False}
    fit = ctx.split.fit
    out: dict = {}
    if eff.param is not None:
        out["stribeck_velocity"] = float(eff.param)
        out["stribeck_velocity_unit"] = "velocity units"
    plausible = True
    total = np.zeros(len(y))  # the effect's own output, its columns together
    for j, (label, b) in enumerate(zip(_FORCE_LABELS[eff.name], eff.coefficients)):
        c = signal.lfilter(b, ctx.a_dom, phi[:, j])
        total += c
        if eff.name == "viscous_friction" and spring is not None:
            c = c + signal.lfilter(spring[0], ctx.a_dom, spring[1])
        out[f"{label}_input_equivalent"] = _input_equivalent(ctx, b_input, phi[:, j], c)
        if eff.name in _FRICTION:
            if ctx.chain[0] == 0:  # the fit holds b_j0 ≤ 0 (`friction_bounds`): at 0 no force
                out[f"{label}_at_bound"] = at_bound(b)
                plausible = plausible and not out[f"{label}_at_bound"]
            out[f"{label}_power_ratio"] = power = _power_ratio(ctx, c, v)
            plausible = plausible and power < 0.0
    if eff.name == "stribeck_friction":
        plausible = plausible and friction_form(
            out, out["coulomb_level_input_equivalent"], out["stribeck_excess_input_equivalent"]
        )
    if ctx.chain[0] == 0 and eff.name != "force_offset":
        out["steady_share"] = _steady_share(total[fit])
        plausible = plausible and out["steady_share"] <= STEADY_SHARE
    if eff.name in SPRINGS:  # the base's spring is reported too (`report`: loop_spring)
        out.update(mode_shift(ctx, eff.coefficients[0], b_v))
        plausible = plausible and (eff.name == "loop_stiffness" or out["mode_change"] in MECHANICS)
    out["plausible"] = plausible
    return out


def _input_equivalent(ctx, b_input: np.ndarray, phi: np.ndarray, c: np.ndarray) -> float:
    """The input per unit of φ that a force column takes away, c = −⟨G_uφ, G_Fφ⟩/⟨G_uφ, G_uφ⟩
    on the training part (`force_report`): ``phi`` the column's regressor, ``c`` its output
    G_Fφ over the record, G_u = b_input/Â the loop's input path; 0 where G_uφ is 0."""
    fit = ctx.split.fit
    g = signal.lfilter(b_input, ctx.a_dom, phi)[fit]
    gg = float(g @ g)
    return -float(g @ c[fit]) / gg if gg > 0 else 0.0


def _power_ratio(ctx, c: np.ndarray, v: np.ndarray) -> float:
    """P = ⟨w, v⟩/⟨v, v⟩ on the training part (`force_report`: a friction's < 0, it takes
    energy out of the motion): w the velocity that an output contribution ``c`` moves
    (through the state chain: its filter on an acceleration, ``c`` itself on a velocity,
    its differences on a position), v the loop's velocity."""
    n, vb, va, fs = ctx.chain
    if n == 0:
        w = signal.lfilter(vb, va, c)
    elif n == 1:
        w = c
    else:
        w = np.diff(c, prepend=0.0) * fs
    fit = ctx.split.fit
    vv = float(v[fit] @ v[fit]) or 1.0
    return float(w[fit] @ v[fit]) / vv


def _steady_share(total: np.ndarray) -> float:
    """The share of an effect's output energy (its acceleration ``total`` on the training
    part) that is its mean, mean²/mean square (0 for no output). A force of the motion holds
    no steady acceleration (the mean acceleration of a bounded motion is zero): above
    STEADY_SHARE the effect is a sensor's offset (`force_report`)."""
    mean_square = float(np.mean(total**2))
    return float(np.mean(total)) ** 2 / mean_square if mean_square > 0 else 0.0


def mode_shift(ctx, b_x: np.ndarray, b_v: np.ndarray | None = None) -> dict:
    """What the loop's linear forces, x through B_x/Â (and v through B_v/Â, a viscous
    friction in the same loop), do to the mechanics: the lightly damped pole pair of Â (the
    nominal mode, eq. 6's m ẍ + c ẋ + k x) against the nearest pole pair of the loop, whose
    denominator is Â·D − B_x·N_x − B_v·N_v (x = (N_x/D) y, v = (N_v/D) y: the state chain).

    Per unit mass a mode s² + 2ζω s + ω² moves its pole by Δ(ω²)/(2ω₀) along the frequency
    when the spring changes, by Δ(ζω) along the damping when the damper changes, and by the
    same relative amount in both when the mass changes (ω² = k/m, 2ζω = c/m): the move
    (Δ(ω²)/(2ω₀), Δ(ζω)) is then ρ·(ω₀/2, ζ₀ω₀), with 1 + ρ = m₀/m₁. ``mode_change`` is the
    parameter whose line lies nearest the move, nearer by at least the record's frequency
    resolution (1/T of the training part) than the next: "stiffness" (``stiffness_ratio`` =
    ω₁²/ω₀² at the same mass), "mass" (then ``mass_ratio`` = m₁/m₀ = 1/(1 + ρ), ρ fitted
    to the move) or "damping" (``damping_change_per_s`` = Δ(c/m); added damping is viscous
    friction, `select`). Not that much nearer: "stiffness" between a spring and a mass (a
    mass is told from a spring only by the damping it moves), otherwise "unresolved" (no
    one parameter explains the move). "none" when the pole moves less than the
    resolution (no measured change); "unknown" when Â has no pole pair."""
    n, vb, va, fs = ctx.chain
    # products of polynomials in z⁻¹ are convolutions (numpy.polymul would drop a leading
    # zero, which in z⁻¹ is a delay)
    den, num_x, num_v = {
        0: (np.convolve(va, va), np.convolve(vb, vb), np.convolve(vb, va)),
        1: (va, vb, va),
    }.get(n, ([1.0], [1.0], [fs, -fs]))
    a = np.asarray(ctx.a_dom, float)
    loop = _minus(np.convolve(a, den), np.convolve(b_x, num_x))
    if b_v is not None:
        loop = _minus(loop, np.convolve(b_v, num_v))
    pole = nominal_pole(a)
    if pole is None:
        return {"mode_change": "unknown"}
    s0 = cmath.log(pole) * fs  # the least damped pair
    s1 = min((s for s in s_roots(loop, fs) if s.imag > 0), key=lambda s: abs(s - s0), default=None)
    if s1 is None:
        return {"mode_change": "unknown"}
    w0, w1 = abs(s0), abs(s1)
    zw0 = -s0.real  # ζ₀ω₀
    k_move = (w1**2 - w0**2) / (2.0 * w0)  # rad/s
    c_move = s0.real - s1.real  # Δ(ζω), rad/s
    rho = (k_move * w0 / 2.0 + c_move * zw0) / ((w0 / 2.0) ** 2 + zw0**2)
    off = {
        "stiffness": abs(c_move),
        "damping": abs(k_move),
        "mass": (
            abs(k_move * zw0 - c_move * w0 / 2.0) / math.hypot(w0 / 2.0, zw0)
            if rho > -1.0
            else math.inf
        ),
    }  # a mass is positive
    moved_hz = abs(s1 - s0) / (2 * math.pi)
    resolution_hz = fs / max(ctx.split.train_end - ctx.split.warmup, 1)
    best, second = sorted(off, key=lambda k: off[k])[:2]
    if moved_hz < resolution_hz:
        change = "none"
    elif off[second] - off[best] >= 2 * math.pi * resolution_hz:
        change = best
    elif {best, second} == {"stiffness", "mass"}:
        change = "stiffness"  # a lightly damped mode: a mass is not told from a spring
    else:
        change = "unresolved"
    return {
        "resonance_hz_nominal": w0 / (2 * math.pi),
        "resonance_hz": w1 / (2 * math.pi),
        "damping_ratio_nominal": zw0 / w0,
        "damping_ratio": -s1.real / w1,
        "stiffness_ratio": (w1 / w0) ** 2,
        **({"mass_ratio": 1.0 / (1.0 + rho)} if change == "mass" else {}),
        "damping_change_per_s": 2.0 * c_move,
        "mode_moved_hz": moved_hz,
        "resolution_hz": resolution_hz,
        "mode_change": change,
    }


def mechanics_name(effect):
    """A named linear change of the mechanics (``stiffness_change``'s fit, also when
    refitted) named after the parameter of the mode it moves now (`MECHANICS`); any other
    effect as it is."""
    name = MECHANICS.get(effect.physical.get("mode_change"))
    if effect.name not in MECHANICS.values() or name is None or name == effect.name:
        return effect
    return replace(effect, name=name)


def _minus(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """p − q for polynomials in z⁻¹ (aligned at the z⁰ term, unlike `numpy.polysub`)."""
    out = np.zeros(max(len(p), len(q)))
    out[: len(p)] += p
    out[: len(q)] -= q
    return out


def s_roots(poly: np.ndarray, fs: float) -> np.ndarray:
    """Roots of a polynomial in z⁻¹ (poles or zeros) in continuous time, s = fs·ln z (1/s);
    roots at z = 0 are left out."""
    z = np.roots(poly).astype(complex)
    return np.log(z[z != 0]) * fs


def _phi(kind: int, par: float, v: np.ndarray, x: np.ndarray) -> np.ndarray:
    if kind == _SIGN:
        return np.sign(v)
    if kind == _VEL:
        return v
    if kind == _STRIBECK:
        return np.sign(v) * np.exp(-((v / par) ** 2))
    if kind == _CUBE:
        return x**3
    if kind == _X:
        return x.copy()
    return np.ones_like(v)
