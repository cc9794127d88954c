"""An alarm episode's per-tick arithmetic and decisions, compiled (`Detector`'s episode).

From ``fault_detected`` until ``cleared`` the detector keeps, on top of the quiet path
(docs/detector.md §3, "Isolation"):

- the *post* window: the packed rows of the residual fit (φ = g1, g2, x̂̈, 1; y = r) since
  the reference window ended, and the *settled* window from one isolation window after the
  detection on: θ of eqs. (16)–(17) on them (g1, g2 only) is the θ reported;
- the refit of φ on the post window: the Coulomb coefficient's change since the reference
  (friction evidence when it exceeds ``friction_min_level``), checked by the innovation
  e = r − φᵀθ_ref regressed on (g1, x̂̈(k), x̂̈(k−1), 1) (what g1 explains beyond any linear
  change of the plant);
- whether the load has stopped although the model says it moves (energies of ẍ, Δẍ and x̂̈
  over the test window): said in an ``other_fault`` event, never taken as friction nor as
  evidence of another fault (a weak valve or a lost supply stops the load as friction
  does, and the accelerometer cannot tell them apart);
- whether a linear change of the residual fit describes the fault (the evidence of another
  fault, `_described_by_linear_change`);
- the frozen-reference test T = mean over M of e²/σ²_ref (persistence, clearing), and for
  clearing the mean of e²/σ²_ref over the window of n (the alarm's deadband) and the power
  the fault as measured (Δθ once a linear change describes it, `measure_fault`) would show
  under the window's operation.

``episode_tick`` returns the transition of the tick (none, isolated, other fault, cleared)
and applies it to the detector's state; Python only formats the event. The cost of a tick
does not depend on whether an episode runs: it stays inside the same kernel.
"""

from __future__ import annotations

import math

import numpy as np

from fdi_daemon.core.compiled import jit
from fdi_daemon.core.cusum import cusum_increment
from fdi_daemon.core.kernels import (
    F64,
    I64,
    packed_row_into,
    solve_packed,
    sums_floats,
    sums_push,
)

__all__ = [
    "episode_start",
    "episode_restart",
    "episode_rebase",
    "episode_tick",
    "load_stopped",
    "EPISODE_INTS",
    "episode_floats",
    "NO_CHANGE",
    "TO_ISOLATED",
    "TO_OTHER",
    "TO_CLEARED",
    "KIND_NONE",
    "KIND_HARMONICS",
    "KIND_LEVEL",
]

NO_CHANGE, TO_ISOLATED, TO_OTHER, TO_CLEARED = range(4)
KIND_NONE, KIND_HARMONICS, KIND_LEVEL = range(3)

W = 15  # packed width of 4 regressors
#: the load has stopped: Σẍ² at most this fraction of Σx̂̈² ...
STOPPED_ENERGY_FRACTION = 0.04
#: ... and the accelerometer is alive (Σ(Δẍ)² above this fraction of Σx̂̈²)
FLAT_ENERGY_FRACTION = 1e-6
MIN_RCOND = 1e-6

# ints
(
    P_TICKS,
    P_QUIET,
    P_TRACK,
    P_HOLD_UNTIL,
    P_PERSISTED,
    P_LEVEL,
    P_KIND,
    P_N,
    P_M,
    P_ISO,
    P_TIMEOUT,
    P_CLEAR,
    P_FRICTION_CLEAR,
    P_TRACK_SAMPLES,
    P_BAND,
    P_POST,
    P_SETTLED,
    P_BEYOND,
    P_FROZEN,
    P_MOTION,
    P_O_POST,
    P_O_SETTLED,
    P_O_BEYOND,
    P_O_FROZEN,
    P_O_MOTION,
    P_O_SCAL,
    P_O_ROW,
    P_O_SCR,
    P_O_TH,
    P_O_G,
    P_WARMUP,
    P_CLIPPED,
    P_FAULT_AT,
) = (
    0,
    1,
    2,
    3,
    4,
    5,
    6,
    7,
    8,
    9,
    10,
    11,
    12,
    13,
    14,
    15,
    17,
    19,
    21,
    23,
    25,
    26,
    27,
    28,
    29,
    30,
    31,
    32,
    33,
    34,
    35,
    36,
    37,
)
EPISODE_INTS = 38
# floats at P_O_SCAL
(
    S_THETA_REF,
    S_COULOMB_BASE,
    S_SIGMA2_REF,
    S_XHAT_PAST,
    S_ACCEL_PAST,
    S_LEVEL_CHANGE,
    S_EVIDENCE,
    S_FMIN,
    S_THRESHOLD,
    S_TOL1,
    S_TOL2,
    S_GAMMA_F,
    S_Z,
    S_MOTION,
    S_DRIFT,
    S_DRIFT_SHIFT,
    S_DRIFT_H,
    S_DRIFT_S,
    S_FAULT_CHANGE,
) = (0, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16, 19, 20, 21, 22, 23)
SCAL_FLOATS = 27


def episode_floats(n: int, m: int) -> int:
    """Floats of an episode block (windows of n and m samples)."""
    return (
        3 * sums_floats(n, W)
        + sums_floats(m, 1)
        + sums_floats(m, 3)
        + SCAL_FLOATS
        + W
        + (2 * 16 + 4)
        + 4
        + 6
    )


def episode_layout(fo: int, n: int, m: int) -> tuple[int, ...]:
    """Float offsets (post, settled, beyond, frozen, motion, scal, row, scr, th, g)."""
    post = fo
    settled = post + sums_floats(n, W)
    beyond = settled + sums_floats(n, W)
    frozen = beyond + sums_floats(n, W)
    motion = frozen + sums_floats(m, 1)
    scal = motion + sums_floats(m, 3)
    row = scal + SCAL_FLOATS
    scr = row + W
    th = scr + 2 * 16 + 4
    g = th + 4
    return post, settled, beyond, frozen, motion, scal, row, scr, th, g


@jit
def _reset_sums(
    f: F64, ii: I64, ro: int, n: int, w: int, ip: int
) -> None:  # pragma: no cover - jit
    for k in range(ro, ro + (n + 3) * w):
        f[k] = 0.0
    ii[ip] = 0
    ii[ip + 1] = 0


@jit
def episode_restart(f: F64, ii: I64, eo: int) -> None:  # pragma: no cover - jit
    """After a data gap: the windows restart, the episode goes on."""
    n = ii[eo + P_N]
    m = ii[eo + P_M]
    _reset_sums(f, ii, ii[eo + P_O_POST], n, W, eo + P_POST)
    _reset_sums(f, ii, ii[eo + P_O_SETTLED], n, W, eo + P_SETTLED)
    _reset_sums(f, ii, ii[eo + P_O_BEYOND], n, W, eo + P_BEYOND)
    _reset_sums(f, ii, ii[eo + P_O_FROZEN], m, 1, eo + P_FROZEN)
    _reset_sums(f, ii, ii[eo + P_O_MOTION], m, 3, eo + P_MOTION)
    sc = ii[eo + P_O_SCAL]
    f[sc + S_XHAT_PAST] = math.nan
    f[sc + S_ACCEL_PAST] = math.nan
    ii[eo + P_QUIET] = 0
    ii[eo + P_TRACK] = 0
    ii[eo + P_HOLD_UNTIL] = ii[eo + P_WARMUP]


@jit
def episode_start(
    f: F64, ii: I64, eo: int, res: int, level: int, drift: int
) -> None:  # pragma: no cover - jit
    """A new episode against the residual test ``res`` (its ints' base) as it is now: θ_ref
    and σ²_ref frozen, the post window filled with the rows since the reference ended
    (``level``, ``drift``: raised by the level path, by the growing-fault path)."""
    episode_restart(f, ii, eo)
    sc = ii[eo + P_O_SCAL]
    th = ii[res + 20]
    for q in range(4):
        f[sc + S_THETA_REF + q] = f[th + q]
    f[sc + S_COULOMB_BASE] = f[th]
    f[sc + S_SIGMA2_REF] = f[ii[res + 22] + 1]
    cap = ii[res + 23]
    fifo = ii[res + 17]
    post = ii[eo + P_O_POST]
    n = ii[eo + P_N]
    ln = ii[res + 10]
    newest = min(ln, ii[res + 2])  # (φ, y) of the last lag ticks, oldest first
    first = ii[res + 9] + ln - newest
    row = ii[eo + P_O_ROW]
    for k in range(first, first + newest):
        packed_row_into(f, fifo + (k % cap) * 5, 4, row)
        sums_push(f, ii, post, n, W, eo + P_POST, row)
    ii[eo + P_TICKS] = 0
    ii[eo + P_HOLD_UNTIL] = 0
    ii[eo + P_PERSISTED] = level
    ii[eo + P_LEVEL] = level
    # the isolation timeout counts from the detection, except for the growing-fault path,
    # which tests friction's direction only: from the residual test's alarm (below)
    ii[eo + P_FAULT_AT] = -1 if drift else 0
    ii[eo + P_KIND] = KIND_NONE
    ii[eo + P_CLIPPED] = 0
    f[sc + S_LEVEL_CHANGE] = math.nan
    f[sc + S_EVIDENCE] = math.nan
    f[sc + S_FAULT_CHANGE] = math.nan
    # the growing-fault test against the frozen reference starts at its threshold: what
    # raised the episode is there until the innovations say otherwise
    f[sc + S_DRIFT] = f[sc + S_DRIFT_H]


@jit
def episode_rebase(f: np.ndarray, ii: np.ndarray, eo: int, ref: int) -> None:  # pragma: no cover
    """An episode the growing-fault path raised is judged against the reference as it was
    when that path's CUSUM run began (θ at f[ref..ref+3], 1/σ² at f[ref+4]): the moving
    reference at the detection has learnt part of a fault that grows."""
    sc = ii[eo + P_O_SCAL]
    for q in range(4):
        f[sc + S_THETA_REF + q] = f[ref + q]
    f[sc + S_COULOMB_BASE] = f[ref]
    f[sc + S_SIGMA2_REF] = 1.0 / f[ref + 4]


@jit
def _window_theta(f: F64, ii: I64, eo: int, ro: int, ip: int) -> bool:  # pragma: no cover - jit
    """θ (g1, g2 only) of a window's packed sums into th[0:2]; ok."""
    n = ii[eo + P_N]
    if ii[ip + 1] < ii[eo + P_ISO]:
        return False
    s = ro + (n + 2) * W
    g = ii[eo + P_O_G]
    f[g] = f[s]
    f[g + 1] = f[s + 1]
    f[g + 2] = f[s + 4]
    f[g + 3] = f[s + 10]
    f[g + 4] = f[s + 11]
    f[g + 5] = f[s + 14]
    _, ok = solve_packed(f, g, 2, MIN_RCOND, ii[eo + P_O_SCR], ii[eo + P_O_TH])
    return ok


@jit
def _friction_kind(f: F64, ii: I64, eo: int, fmin: float) -> int:  # pragma: no cover - jit
    """Given a rise of the Coulomb coefficient: harmonics (g1 explains the innovation
    beyond a linear change of the plant), or nothing."""
    n = ii[eo + P_N]
    if ii[eo + P_BEYOND + 1] >= ii[eo + P_ISO]:
        s = ii[eo + P_O_BEYOND] + (n + 2) * W
        th = ii[eo + P_O_TH]
        _, ok = solve_packed(f, s, 4, 1e-9, ii[eo + P_O_SCR], th)
        if ok and f[th] >= fmin:
            return KIND_HARMONICS
    return KIND_NONE


@jit
def _clear_excess(ii: I64, eo: int, threshold: float) -> float:  # pragma: no cover - jit
    """(h − 1)·√(m/n): the test window's excess over the fault-free mean of e²/σ²_ref (1),
    taken from m samples to the window's n at the same significance (the excess of a mean
    of n terms shrinks as 1/√n): the alarm's deadband (`innovations_back_to_normal`)."""
    excess: float = (threshold - 1.0) * math.sqrt(ii[eo + P_M] / ii[eo + P_N])
    return excess


@jit
def innovations_back_to_normal(
    f: F64, ii: I64, eo: int, excess: float
) -> bool:  # pragma: no cover - jit
    """The alarm's deadband (ISA-18.2: an alarm clears below the level that raised it):
    the mean of e²/σ²_ref over the window of n samples (the ``beyond`` window's Σe²) is
    within ``excess`` (`_clear_excess`) of its fault-free value 1. One test window of m below h says
    only that this window shows no fault: under weak operation a valve at 40 % gave T of
    10-27 against h = 30 for a second, 19 times the reference's noise. False until the
    window holds n samples."""
    n = ii[eo + P_N]
    if ii[eo + P_BEYOND + 1] < n:
        return False
    sigma2 = f[ii[eo + P_O_SCAL] + S_SIGMA2_REF]
    mean_z = f[ii[eo + P_O_BEYOND] + (n + 2) * W + 14] / (n * sigma2)
    back: bool = mean_z <= 1.0 + excess
    return back


@jit
def fault_power(f: F64, ii: I64, eo: int) -> float:  # pragma: no cover - jit
    """The mean of (φᵀΔθ)²/σ²_ref over the post window (φ = g1, g2, x̂̈, 1): the innovation
    power that the fault as measured (Δθ at S_FAULT_CHANGE, `measure_fault`) would show
    under the window's operation. A valve's loss of gain shows in proportion to x̂̈, so
    hardly at 1-2 Hz, where the acceleration is small."""
    n = ii[eo + P_N]
    sc = ii[eo + P_O_SCAL]
    q = _packed_quadratic(f, ii[eo + P_O_POST] + (n + 2) * W, sc + S_FAULT_CHANGE)
    rows = max(ii[eo + P_POST + 1], 1)
    power: float = q / (rows * f[sc + S_SIGMA2_REF])
    return power


@jit(inline=True)
def _packed_quadratic(f: F64, s: int, v: int) -> float:  # pragma: no cover - jit
    """Σ (φᵀv)² over a window from its packed sums at ``s`` (4 regressors,
    `packed_row_into`); v = f[v:v+4]."""
    q = 0.0
    k = 0
    for i in range(4):
        for j in range(i, 4):
            q += (1.0 if i == j else 2.0) * f[v + i] * f[v + j] * f[s + k]
            k += 1
    return q


@jit
def measure_fault(f: F64, ii: I64, eo: int, described: bool) -> None:  # pragma: no cover - jit
    """Δθ = θ_post − θ_ref, the fault as a linear change of the residual fit (eq. 16's φ
    with x̂̈ and 1), from the post window when the episode becomes another fault; kept only
    where it describes the fault (``described``: `_described_by_linear_change` of this
    tick), NaN otherwise (a clipping accelerometer: the clearing test alone decides). The
    post window is solved again: this tick's `_friction_kind` reused the solution's slots."""
    n = ii[eo + P_N]
    sc = ii[eo + P_O_SCAL]
    d = sc + S_FAULT_CHANGE
    f[d] = math.nan
    th = ii[eo + P_O_TH]
    _, ok = solve_packed(f, ii[eo + P_O_POST] + (n + 2) * W, 4, 1e-9, ii[eo + P_O_SCR], th)
    if not ok:
        return
    for q in range(4):
        f[d + q] = f[th + q] - f[sc + S_THETA_REF + q]
    if not described:
        f[d] = math.nan


@jit
def _described_by_linear_change(
    f: F64, ii: I64, eo: int, sse: float, threshold: float
) -> bool:  # pragma: no cover - jit
    """The fault is a linear change of the residual fit (a bias in 1, a valve's gain in x̂̈,
    a sensor gone): refitted on the post window (φ = g1, g2, x̂̈, 1; ``sse`` its residual
    sum of squares), the innovations e = r − φᵀθ_ref are back within the alarm's deadband
    (`_clear_excess`, as `innovations_back_to_normal` judges them for clearing), and the
    refit took more of their excess over the fault-free level than it left. Friction whose
    harmonics g1 does not describe (operation below the signature's band) leaves several
    times the deadband, or barely shows (docs/detector.md §3, "Isolation")."""
    n = ii[eo + P_N]
    s = ii[eo + P_O_POST] + (n + 2) * W
    sc = ii[eo + P_O_SCAL]
    th = sc + S_THETA_REF
    # Σe² = Σy² − 2 θ_refᵀ Σφy + θ_refᵀ Σφφᵀ θ_ref from the packed sums (`packed_row_into`)
    see = f[s + 14] + _packed_quadratic(f, s, th)
    for i in range(4):
        see -= 2.0 * f[th + i] * f[s + 10 + i]
    scale = ii[eo + P_POST + 1] * f[sc + S_SIGMA2_REF]
    left = sse / scale
    taken = (see - sse) / scale
    described: bool = left <= 1.0 + _clear_excess(ii, eo, threshold) and taken > left - 1.0
    return described


@jit
def load_stopped(f: F64, ii: I64, eo: int) -> bool:  # pragma: no cover - jit
    """Over the last test window the load has stopped although the model says it moves
    (Σẍ² ≤ ``STOPPED_ENERGY_FRACTION``·Σx̂̈²) and the accelerometer is alive (Σ(Δẍ)² above
    ``FLAT_ENERGY_FRACTION``·Σx̂̈²: a dead sensor repeats one value, a held load still shows
    the sensor's noise)."""
    m = ii[eo + P_M]
    if ii[eo + P_MOTION + 1] < m:
        return False
    s = ii[eo + P_O_MOTION] + (m + 2) * 3
    s_step = f[s]
    s_accel = f[s + 1]
    s_xhat = f[s + 2]
    stopped: bool = (
        s_xhat > 0.0
        and s_accel <= STOPPED_ENERGY_FRACTION * s_xhat
        and s_step > FLAT_ENERGY_FRACTION * s_xhat
    )
    return stopped


@jit(inline=True)
def _drift_hold(f: F64, sc: int, e: float) -> None:  # pragma: no cover - jit
    """The growing-fault CUSUM against the frozen reference along its regressor s
    (S_DRIFT_S, set by the caller), capped at twice its threshold so that it falls below
    the threshold within a bounded time once the shift is gone."""
    if f[sc + S_DRIFT_SHIFT] > 0.0:
        cap = 2.0 * f[sc + S_DRIFT_H]
        d = f[sc + S_DRIFT] + cusum_increment(
            e, f[sc + S_DRIFT_S], 1.0 / f[sc + S_SIGMA2_REF], f[sc + S_DRIFT_SHIFT]
        )
        f[sc + S_DRIFT] = cap if d > cap else (d if d > 0.0 else 0.0)


@jit(inline=True)
def _push_evidence(
    f: F64, ii: I64, eo: int, beyond: bool, motion: bool, g1: float, xhat: float, e: float, r: float
) -> None:  # pragma: no cover - jit
    """This tick's rows of the friction evidence's windows: ``beyond``, the innovation e
    against (g1, x̂̈, x̂̈ one tick back, 1) (the innovation beyond a linear change);
    ``motion``, (Δẍ², ẍ², x̂̈²) for the stopped load (`load_stopped`)."""
    n = ii[eo + P_N]
    sc = ii[eo + P_O_SCAL]
    xp = f[sc + S_XHAT_PAST]
    if beyond and not math.isnan(xp):
        b = ii[eo + P_O_ROW]
        f[b] = g1 * g1
        f[b + 1] = g1 * xhat
        f[b + 2] = g1 * xp
        f[b + 3] = g1 * 1.0
        f[b + 4] = xhat * xhat
        f[b + 5] = xhat * xp
        f[b + 6] = xhat * 1.0
        f[b + 7] = xp * xp
        f[b + 8] = xp * 1.0
        f[b + 9] = 1.0 * 1.0
        f[b + 10] = g1 * e
        f[b + 11] = xhat * e
        f[b + 12] = xp * e
        f[b + 13] = 1.0 * e
        f[b + 14] = e * e
        sums_push(f, ii, ii[eo + P_O_BEYOND], n, W, eo + P_BEYOND, b)
    f[sc + S_XHAT_PAST] = xhat
    accel = r + xhat
    ap = f[sc + S_ACCEL_PAST]
    if motion and not math.isnan(ap):
        step = accel - ap
        mo = sc + S_MOTION
        f[mo] = step * step
        f[mo + 1] = accel * accel
        f[mo + 2] = xhat * xhat
        sums_push(f, ii, ii[eo + P_O_MOTION], ii[eo + P_M], 3, eo + P_MOTION, mo)
    f[sc + S_ACCEL_PAST] = accel


@jit(inline=True)
def _reported_theta(
    f: F64, ii: I64, eo: int, moving: bool, theta1: float, theta2: float, out: F64
) -> None:  # pragma: no cover - jit
    """θ as reported, into out[0], out[1]: the settled window's, else the post window's,
    else the sliding window's (``theta1``, ``theta2``; NaN at rest)."""
    out[0] = theta1
    out[1] = theta2
    if moving:
        th = ii[eo + P_O_TH]
        if _window_theta(f, ii, eo, ii[eo + P_O_SETTLED], eo + P_SETTLED):
            out[0] = f[th]
            out[1] = f[th + 1]
        elif _window_theta(f, ii, eo, ii[eo + P_O_POST], eo + P_POST):
            out[0] = f[th]
            out[1] = f[th + 1]


@jit(inline=True)
def _clearing(
    f: F64,
    ii: I64,
    eo: int,
    state: int,
    over: float,
    frozen_stat: float,
    threshold: float,
    moving: bool,
    trusted: bool,
    sliding: bool,
) -> int:  # pragma: no cover - jit
    """The clearing count of an episode that did not change state this tick: TO_CLEARED
    once normal for the clearing time (friction: ``friction_clear_s``; an unconfirmed
    episode: ``clear_s``), else NO_CHANGE (``over``: the friction level's excess over its
    margin; ``frozen_stat``: the frozen-reference test's statistic, against ``threshold``)."""
    sc = ii[eo + P_O_SCAL]
    if state == 4:
        if not trusted:
            # sign v̂ is wrong for much of each cycle: θ1 cannot show that friction is gone
            # (nor that it is there), so the clearing count holds
            return NO_CHANGE
        # the level back within half its margin, the load moving freely (a load that
        # friction holds shows little of it in θ) and what raised the episode gone: an
        # episode the residual test raised also needs its innovations against the frozen
        # pre-fault reference back below h (a level episode's reference may hold the
        # fault: the level alone)
        normal = over < 0.5 and sliding and (ii[eo + P_LEVEL] != 0 or frozen_stat <= threshold)
        needed = ii[eo + P_FRICTION_CLEAR]
    else:
        # an unconfirmed episode (fault_detected, other_fault) holds while the friction
        # level is still at least half its margin above normal (issue 43): a fault that
        # creeps in keeps its episode until the level path confirms it, never raise-clear
        # ... and (growing-fault path) while the innovations against the frozen reference
        # still show the shift along the signature (its CUSUM at or above h); it clears on
        # the innovations' mean power over the window, not one test window
        # (`innovations_back_to_normal`), and only under operation that would show the
        # fault as measured: elsewhere the count holds (`fault_power`)
        excess = _clear_excess(ii, eo, threshold)
        if not math.isnan(f[sc + S_FAULT_CHANGE]) and fault_power(f, ii, eo) < excess:
            return NO_CHANGE
        normal = (
            frozen_stat <= threshold
            and innovations_back_to_normal(f, ii, eo, excess)
            and not over >= 0.5
            and f[sc + S_DRIFT] < f[sc + S_DRIFT_H]
        )
        needed = ii[eo + P_CLEAR]
    ii[eo + P_QUIET] = ii[eo + P_QUIET] + 1 if normal and moving else 0
    if ii[eo + P_QUIET] >= needed:
        return TO_CLEARED
    return NO_CHANGE


@jit(inline=True)
def _friction_evidence(
    f: F64, ii: I64, eo: int, evidence: bool, over: float, clipped: bool
) -> tuple[int, float]:  # pragma: no cover - jit
    """This tick's friction evidence (KIND_*) and the post window's refit SSE (inf where
    not refitted): the Coulomb coefficient's change since the reference (S_LEVEL_CHANGE)
    at least ``friction_min_level``, or the level above its margin (``over`` > 1), opens
    `_friction_kind`; an episode the level path raised has the level alone; a clipped
    window has none (and the episode remembers it saw one)."""
    n = ii[eo + P_N]
    sc = ii[eo + P_O_SCAL]
    fmin = f[sc + S_FMIN]
    kind = KIND_NONE
    sse = math.inf
    if evidence and ii[eo + P_POST + 1] >= ii[eo + P_ISO]:
        th = ii[eo + P_O_TH]
        fit_sse, ok = solve_packed(
            f, ii[eo + P_O_POST] + (n + 2) * W, 4, 1e-9, ii[eo + P_O_SCR], th
        )
        if ok:
            sse = fit_sse
            f[sc + S_LEVEL_CHANGE] = f[th] - f[sc + S_COULOMB_BASE]
            if f[sc + S_LEVEL_CHANGE] >= fmin or over > 1.0:
                kind = _friction_kind(f, ii, eo, fmin)
    if ii[eo + P_LEVEL]:
        kind = KIND_LEVEL if over > 1.0 else KIND_NONE
    if clipped:
        kind = KIND_NONE
        ii[eo + P_CLIPPED] = 1
    return kind, sse


@jit(inline=True)
def _isolation(
    f: F64,
    ii: I64,
    eo: int,
    state: int,
    ticks: int,
    kind: int,
    over: float,
    sse: float,
    threshold: float,
) -> int:  # pragma: no cover - jit
    """An unconfirmed episode's decision (``state`` 3 fault_detected, 5 other_fault):
    friction once its evidence held ``track_samples`` ticks and the fault persisted; another
    fault once the timeout from the fault's evidence passed without friction's and there is
    evidence of another fault — a linear change of the plant describes it
    (`_described_by_linear_change`), or the accelerometer clipped. A fault that neither
    describes (friction below the band where g1 shows it, or holding the load part of each
    cycle) stays unconfirmed. An episode the growing-fault path raised (friction's direction
    only) has the fault's evidence once the residual test's alarm holds (P_FAULT_AT); until
    then it stays unconfirmed, its timeout counted from the detection, and the first linear
    change that describes it is measured for the clearing gate (`measure_fault`)."""
    sc = ii[eo + P_O_SCAL]
    ii[eo + P_TRACK] = ii[eo + P_TRACK] + 1 if kind != KIND_NONE else 0
    if ii[eo + P_TRACK] >= ii[eo + P_TRACK_SAMPLES] and math.isnan(f[sc + S_EVIDENCE]):
        f[sc + S_EVIDENCE] = over if ii[eo + P_LEVEL] else f[sc + S_LEVEL_CHANGE]
        ii[eo + P_KIND] = kind
    if not math.isnan(f[sc + S_EVIDENCE]) and ii[eo + P_PERSISTED]:
        f[sc + S_LEVEL_CHANGE] = f[sc + S_EVIDENCE]
        ii[eo + P_QUIET] = 0
        return TO_ISOLATED
    fault_at = ii[eo + P_FAULT_AT]
    if state != 3 or ticks - max(fault_at, 0) < ii[eo + P_TIMEOUT]:
        return NO_CHANGE
    alarmed = fault_at >= 0
    if not (alarmed or math.isnan(f[sc + S_FAULT_CHANGE])):
        return NO_CHANGE
    described = _described_by_linear_change(f, ii, eo, sse, threshold)
    if described or ii[eo + P_CLIPPED]:
        measure_fault(f, ii, eo, described)  # the clearing gate's fault as measured
        if alarmed:
            ii[eo + P_QUIET] = 0
            return TO_OTHER
    return NO_CHANGE


@jit
def episode_tick(
    f: F64,
    ii: I64,
    eo: int,
    tick: int,
    state: int,
    r: float,
    g1: float,
    g2: float,
    xhat: float,
    theta1: float,
    theta2: float,
    over: float,
    trusted: bool,
    sliding: bool,
    clipped: bool,
    alarm: bool,
    row: int,
    band: int,
    out: F64,
) -> int:  # pragma: no cover - jit
    """One episode tick; θ as reported in out[0], out[1]; returns the transition.

    ``state``: 3 fault_detected, 4 friction_isolated, 5 other_fault (`detector.STATES`);
    ``row``: the residual fit's packed row of this tick; ``band``: the offset of the
    calibrated band (lo1, hi1, lo2, hi2), −1 without one; θ: the pipeline's window θ (NaN
    at rest); ``trusted``, ``sliding``, ``clipped``: the window's velocity lies where v̂ is
    right, the load moves freely, the accelerometer sits at its rail (`kernel.chain_tick`;
    a clipped window is no friction evidence; the episode remembers it saw one); ``alarm``:
    the residual test's alarm holds (T > h for ``persistence_samples`` ticks, armed)."""
    n = ii[eo + P_N]
    m = ii[eo + P_M]
    iso = ii[eo + P_ISO]
    sc = ii[eo + P_O_SCAL]
    moving = math.isfinite(theta1)
    ticks = ii[eo + P_TICKS] + 1
    ii[eo + P_TICKS] = ticks
    if alarm and ii[eo + P_FAULT_AT] < 0:
        ii[eo + P_FAULT_AT] = ticks
    sums_push(f, ii, ii[eo + P_O_POST], n, W, eo + P_POST, row)
    tr = sc + S_THETA_REF
    acc = f[tr] * g1
    acc = acc + f[tr + 1] * g2
    acc = acc + f[tr + 2] * xhat
    acc = acc + f[tr + 3] * 1.0
    e = r - acc
    _drift_hold(f, sc, e)
    # isolated, the episode reports θ and waits to clear: the friction evidence (the post
    # window's refit, the innovation beyond a linear change) and the stopped load are not
    # looked at again, so their windows are not kept
    evidence = state != 4
    if ticks > iso:
        sums_push(f, ii, ii[eo + P_O_SETTLED], n, W, eo + P_SETTLED, row)
    _push_evidence(f, ii, eo, ticks > iso and evidence, evidence, g1, xhat, e, r)
    _reported_theta(f, ii, eo, moving, theta1, theta2, out)
    rep1 = out[0]
    rep2 = out[1]
    f[sc + S_Z] = e * e / f[sc + S_SIGMA2_REF]
    fz = ii[eo + P_O_FROZEN]
    sums_push(f, ii, fz, m, 1, eo + P_FROZEN, sc + S_Z)
    frozen_stat = f[fz + (m + 2)] / m
    if tick < ii[eo + P_HOLD_UNTIL]:
        return NO_CHANGE
    threshold = f[sc + S_THRESHOLD]
    if ticks > iso + m and frozen_stat > threshold:
        ii[eo + P_PERSISTED] = 1
    if ii[eo + P_BAND]:
        return _band_decision(f, ii, eo, state, ticks, rep1, rep2, band)
    kind, sse = _friction_evidence(f, ii, eo, evidence, over, clipped)
    if state == 3 or state == 5:
        change = _isolation(f, ii, eo, state, ticks, kind, over, sse, threshold)
        if change != NO_CHANGE:
            return change
    return _clearing(f, ii, eo, state, over, frozen_stat, threshold, moving, trusted, sliding)


@jit
def _band_decision(
    f: F64, ii: I64, eo: int, state: int, ticks: int, theta1: float, theta2: float, band: int
) -> int:  # pragma: no cover - jit
    """The paper's band method: track the signature (1, γ_f), clear inside the band."""
    sc = ii[eo + P_O_SCAL]
    if state == 3:
        tracking = (
            abs(theta1 - 1.0) <= f[sc + S_TOL1]
            and abs(theta2 - f[sc + S_GAMMA_F]) <= f[sc + S_TOL2]
        )
        ii[eo + P_TRACK] = ii[eo + P_TRACK] + 1 if tracking else 0
        if ii[eo + P_TRACK] >= ii[eo + P_TRACK_SAMPLES]:
            ii[eo + P_QUIET] = 0
            return TO_ISOLATED
        if ticks >= ii[eo + P_TIMEOUT]:
            ii[eo + P_QUIET] = 0
            return TO_OTHER
    inside = math.isfinite(theta1) and not (
        band >= 0
        and (
            theta1 < f[band] or theta1 > f[band + 1] or theta2 < f[band + 2] or theta2 > f[band + 3]
        )
    )
    ii[eo + P_QUIET] = ii[eo + P_QUIET] + 1 if inside else 0
    if ii[eo + P_QUIET] >= ii[eo + P_CLEAR]:
        return TO_CLEARED
    return NO_CHANGE
