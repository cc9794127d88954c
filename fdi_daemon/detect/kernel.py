"""The monitor's tick as one compiled kernel: the signal chain, the detector's arithmetic
and its quiet-path decisions (`Pipeline`, `Detector` and `Monitor` own the state in a
`core.compiled.Arena` and call these).

``chain_tick`` (the paper's chain, §IV-C)::

    x̂̈ = Ĝ(q) v_in                      eq. (1)  (or given: a plant with `fdi diagnose` effects)
    r  = ẍ − x̂̈                          eq. (3)  (a bad ẍ, NaN, is replaced by x̂̈)
    v̂  = V(q) ẍ | L(q) x̂̈ + V(q) r | P(q) x + A(q) ẍ    the three velocity methods
    g1 = G_e(q)[sign v̂], g2 = G_e(q)[v̂]  eq. (15)
    s_d = G_d(q)[sign v̂_d] + γ_d G_d(q)[v̂_d]   the growing-fault path's regressor: a
             second high-pass velocity v̂_d = V_d(q) ẍ (lower cut-off) and its own G_d, γ_d
             where the model has them (``fault_filter.drift``), else g1 + γ g2
    θ  = argmin Σ_N (r − θ1 g1 − θ2 g2)²  eqs. (16)–(17): six window sums + Σ v̂²
    level = Σ s·r / Σ s²,  s = g1 + γ g2    the friction level: eq. (17) on the calibrated
             signature's direction (1, γ), in units of the calibrated fault
    trusted: Σ (LP v̂)² <= share · Σ v̂²   at most that share of the window's velocity energy
             below the frequency where v̂'s phase error exceeds its bound (`Pipeline`)
    sliding: Σ ẍ² >= ½ Σ x̂̈²               the load moves freely (friction holds it little)
    clipped: the window holds a flat top of ẍ (``CLIP_RUN`` equal samples) at the value of
             the previous flat top of its sign, less than a window before: the
             accelerometer sits at its rail, and its residual pulses are no evidence of
             friction (clipping slower than one cycle per window is not seen)
    level valid: moving, trusted and not clipped: the window's level measures friction

``detector_tick``: the residual test on φ = (g1, g2, x̂̈, 1), the command test on an AR(4)
of v_in (`core.kernels.itest_tick`, phase by phase; their reference fits are pushed and
re-solved before the chain, ``detector_pre``), where the model has a drift signature the
growing-fault path's own reference fit on φ_d = (d1, d2, x̂̈, 1) (s_d's G_d pair in place of
g1, g2; the same fit, not tested), the operating-point guard, the friction
level's excess over its fault-free value, the quiet path's counters (level path, fast path,
calibration buffer) and a running alarm episode (`detect.episode_kernel`). It returns a
code; anything but ``QUIET`` is an event that Python formats (`Detector.decide`).
``monitor_tick`` also keeps the reported friction level (`detect.friction_level`).

``monitor_run`` loops ``monitor_tick`` over arrays and stops after a tick that needs
Python, so ``Monitor.step`` (one call per sample) and ``Monitor.run`` are bit-equal.
"""

from __future__ import annotations

import math

import numpy as np

from fdi_daemon.core.compiled import jit
from fdi_daemon.core.cusum import cusum_increment
from fdi_daemon.core.kernels import (
    F64,
    I64,
    iir_step,
    itest_flush_p,
    itest_insert_p,
    itest_solve_p,
    itest_statistic_p,
    packed_row_into,
    sums_push,
)
from fdi_daemon.detect import episode_kernel as E
from fdi_daemon.detect.friction_level import L_CAPACITY, L_FLOATS, level_restart, level_tick

__all__ = [
    "chain_tick",
    "chain_run",
    "detector_pre",
    "detector_tick",
    "monitor_tick",
    "monitor_run",
    "QUIET",
    "LEVEL_ALARM",
    "CALIBRATED",
    "FAST_ALARM",
    "ISOLATED",
    "OTHER_FAULT",
    "CLEARED",
    "DRIFT_ALARM",
]

#: codes of a tick: nothing to tell, or the event Python formats (the calibration's end is
#: computed there too)
QUIET, LEVEL_ALARM, CALIBRATED, FAST_ALARM, ISOLATED, OTHER_FAULT, CLEARED, DRIFT_ALARM = range(8)

# filters
(F_PLANT, F_VEL_A, F_VEL_B, F_GE_SIGN, F_GE_VEL, F_VEL_LOW, F_VEL_DRIFT, F_GD_SIGN, F_GD_VEL) = (
    range(9)
)
CHAIN_FILTERS = 9
# --- chain ints (offsets from the chain's int base)
C_METHOD, C_EXTERNAL, C_N, C_WIDTH, C_ORDER = 0, 1, 2, 3, 4  # C_ORDER .. +9: the filters
C_POS, C_COUNT, C_B, C_A, C_Z, C_SUMS, C_ROW, C_OUT, C_DRIFT = range(
    C_ORDER + CHAIN_FILTERS, C_ORDER + CHAIN_FILTERS + 9
)
CHAIN_INTS = C_DRIFT + 1
# --- chain floats at C_OUT
(
    O_XHAT,
    O_R,
    O_V,
    O_G1,
    O_G2,
    O_T1,
    O_T2,
    O_WT1,
    O_WT2,
    O_WOK,
    O_WSSE,
    O_VRMS,
    O_MOVING,
    O_TRUSTED,
    O_SLIDING,
    O_LEVEL_VALID,
    O_CLIPPED,
    O_ACCEL_LAST,
    O_RUN,
    O_RAIL_POS,
    O_RAIL_NEG,
    O_RAIL_AGE_POS,
    O_RAIL_AGE_NEG,
    O_CLIP_AGE,
    O_LAST_POS,
    O_MIN_V2,
    O_MIN_RCOND,
    O_MIN_S11,
    O_MIN_S22,
    O_TRUST_SHARE,
    O_GAMMA,
    O_LEVEL,
    O_DRIFT_GAMMA,
    O_DRIFT_S,
    O_DRIFT_G1,
    O_DRIFT_G2,
) = range(36)
CHAIN_OUT = 36
SUMS_WIDTH = 10  # S11, S12, S22, S1y, S2y, Syy, Σv̂², Σ(LP v̂)², Σẍ², Σx̂̈²
#: a run of this many equal, non-zero ẍ samples is a flat top; two flat tops at one value
#: within a window are the accelerometer's rail (clipping)
CLIP_RUN = 3
#: the load moves freely when Σẍ² over the window is at least this share of Σx̂̈² (a load that
#: friction holds part of the time accelerates less than the model says)
SLIDING_SHARE = 0.5

# --- detector ints
(
    D_METHOD,
    D_HAS_BAND,
    D_HAS_BASELINE,
    D_STATE,
    D_TICK,
    D_GUARD_UNTIL,
    D_ABOVE,
    D_LEVEL_ABOVE,
    D_HOLD_UNTIL,
    D_HOLD,
    D_LEVEL_SAMPLES,
    D_PERSISTENCE,
    D_CAL_COUNT,
    D_CAL_SAMPLES,
    D_EPISODE,
    D_BINS,
    D_RES,
    D_CMD,
    D_CHAIN,
    D_FLOATS,
    D_CODE,
    D_EPI,
    D_LEVEL,
    D_DRIFT_RES,
) = range(24)
DET_INTS = 24
# --- detector floats
(
    E_THRESHOLD,
    E_GUARD_THRESHOLD,
    E_LO1,
    E_HI1,
    E_LO2,
    E_HI2,
    E_LEVEL_BASE,
    E_FRICTION_MIN,
    E_THETA1,
    E_THETA2,
    E_OVER,
    E_DRIFT,
    E_DRIFT_SHIFT,
    E_DRIFT_H,
    E_DRIFT_REF,  # .. +4: the reference θ (4) and 1/σ² frozen at the start of a CUSUM run
) = range(15)
#: .. +4: the CUSUM's own reference θ (4) and 1/σ² frozen at the start of its run: the drift
#: reference's (on s_d's regressors) where the model has a drift signature, else E_DRIFT_REF's
E_DRIFT_FIT = 19
E_CAL = 24  # calibration buffer (θ1, θ2) × calibration samples, then the baseline bins
STATE_CALIBRATING, STATE_MONITORING, STATE_DETECTED, STATE_ISOLATED, STATE_OTHER = range(1, 6)


@jit
def chain_tick(
    f: F64, ii: I64, io: int, v_in: float, accel: float, position: float, xext: float
) -> None:  # pragma: no cover - jit
    """One tick of the signal chain (see the module docstring); results at its C_OUT."""
    L = ii[io + C_WIDTH]
    bo = ii[io + C_B]
    ao = ii[io + C_A]
    zo = ii[io + C_Z]
    out = ii[io + C_OUT]
    od = io + C_ORDER
    if ii[io + C_EXTERNAL]:
        xhat = xext
    else:
        xhat = iir_step(f, bo, ao, zo, ii[od], v_in)
    clipped = _clip_tick(f, out, accel, ii[io + C_N])
    if accel != accel:
        accel = xhat
    r = accel - xhat
    v = _velocity(f, ii, io, out, xhat, accel, position)
    s = 1.0 if v > 0.0 else (-1.0 if v < 0.0 else 0.0)
    g1 = iir_step(f, bo + 3 * L, ao + 3 * L, zo + 3 * (L - 1), ii[od + 3], s)
    g2 = iir_step(f, bo + 4 * L, ao + 4 * L, zo + 4 * (L - 1), ii[od + 4], v)
    v_low = iir_step(f, bo + 5 * L, ao + 5 * L, zo + 5 * (L - 1), ii[od + 5], v)
    if ii[io + C_DRIFT]:
        f[out + O_DRIFT_S] = _drift_regressor(f, ii, io, accel)
    else:
        f[out + O_DRIFT_S] = g1 + f[out + O_GAMMA] * g2
    sl = _window_push(f, ii, io, g1, g2, r, v, v_low, accel, xhat)
    t1, t2 = _window_fit(f, ii, io, out, sl)
    moving = _window_flags(f, out, sl, ii[io + C_N], clipped)
    f[out + O_T1] = t1 if moving else math.nan
    f[out + O_T2] = t2 if moving else math.nan
    _friction_level(f, ii, io, out, sl, moving)
    f[out + O_XHAT] = xhat
    f[out + O_R] = r
    f[out + O_V] = v
    f[out + O_G1] = g1
    f[out + O_G2] = g2


@jit(inline=True)
def _velocity(
    f: F64, ii: I64, io: int, out: int, xhat: float, accel: float, position: float
) -> float:  # pragma: no cover - jit
    """v̂ (m/s) by the chain's method (C_METHOD): 0, V(q) ẍ; 1, L(q) x̂̈ + V(q) r; 2,
    P(q) x + A(q) ẍ on the position x (m), held at its last finite value (0 before one)."""
    L = ii[io + C_WIDTH]
    bo = ii[io + C_B]
    ao = ii[io + C_A]
    zo = ii[io + C_Z]
    od = io + C_ORDER
    method = ii[io + C_METHOD]
    if method == 0:
        v = iir_step(f, bo + L, ao + L, zo + (L - 1), ii[od + 1], accel)
    elif method == 1:
        v = iir_step(f, bo + L, ao + L, zo + (L - 1), ii[od + 1], xhat) + iir_step(
            f, bo + 2 * L, ao + 2 * L, zo + 2 * (L - 1), ii[od + 2], accel - xhat
        )
    else:
        if math.isfinite(position):
            f[out + O_LAST_POS] = position
        elif math.isfinite(f[out + O_LAST_POS]):
            position = f[out + O_LAST_POS]
        else:
            position = 0.0
        v = iir_step(f, bo + L, ao + L, zo + (L - 1), ii[od + 1], position) + iir_step(
            f, bo + 2 * L, ao + 2 * L, zo + 2 * (L - 1), ii[od + 2], accel
        )
    return v


@jit(inline=True)
def _window_push(
    f: F64,
    ii: I64,
    io: int,
    g1: float,
    g2: float,
    r: float,
    v: float,
    v_low: float,
    accel: float,
    xhat: float,
) -> int:  # pragma: no cover - jit
    """This tick's row of the window sums (g1², g1 g2, g2², g1 r, g2 r, r², v̂², v_low²,
    ẍ², x̂̈²) pushed into the window; returns the offset of the window's sums."""
    row = ii[io + C_ROW]
    f[row] = g1 * g1
    f[row + 1] = g1 * g2
    f[row + 2] = g2 * g2
    f[row + 3] = g1 * r
    f[row + 4] = g2 * r
    f[row + 5] = r * r
    f[row + 6] = v * v
    f[row + 7] = v_low * v_low
    f[row + 8] = accel * accel
    f[row + 9] = xhat * xhat
    n = ii[io + C_N]
    so = ii[io + C_SUMS]
    sums_push(f, ii, so, n, SUMS_WIDTH, io + C_POS, row)
    sl: int = so + (n + 2) * SUMS_WIDTH
    return sl


@jit(inline=True)
def _window_fit(
    f: F64, ii: I64, io: int, out: int, sl: int
) -> tuple[float, float]:  # pragma: no cover - jit
    """The window's θ = (θ1, θ2) (eqs. 16–17, from its sums at ``sl``), NaN while the
    window is not full or its regressors too weak or collinear; also at O_WT1, O_WT2,
    with O_WOK and the fit's residual sum of squares O_WSSE."""
    s11 = f[sl]
    s12 = f[sl + 1]
    s22 = f[sl + 2]
    s1y = f[sl + 3]
    s2y = f[sl + 4]
    syy = f[sl + 5]
    det = s11 * s22 - s12 * s12
    if (
        ii[io + C_COUNT] == ii[io + C_N]
        and s11 > f[out + O_MIN_S11]
        and s22 > f[out + O_MIN_S22]
        and det > f[out + O_MIN_RCOND] * (s11 * s22)
    ):
        t1 = (s22 * s1y - s12 * s2y) / det
        t2 = (s11 * s2y - s12 * s1y) / det
        sse = syy - t1 * s1y - t2 * s2y
        f[out + O_WOK] = 1.0
        f[out + O_WSSE] = sse if sse > 0.0 else 0.0
    else:
        t1 = t2 = math.nan
        f[out + O_WOK] = 0.0
        f[out + O_WSSE] = math.nan
    f[out + O_WT1] = t1
    f[out + O_WT2] = t2
    return t1, t2


@jit(inline=True)
def _window_flags(
    f: F64, out: int, sl: int, n: int, clipped: bool
) -> bool:  # pragma: no cover - jit
    """The window's flags (module docstring: moving, trusted, sliding, clipped, level
    valid) and its velocity RMS (m/s) at C_OUT; returns moving."""
    v2 = f[sl + 6]
    moving: bool = v2 >= f[out + O_MIN_V2]
    f[out + O_MOVING] = 1.0 if moving else 0.0
    trusted = f[sl + 7] <= f[out + O_TRUST_SHARE] * v2
    sliding = f[sl + 9] > 0.0 and f[sl + 8] >= SLIDING_SHARE * f[sl + 9]
    f[out + O_TRUSTED] = 1.0 if trusted else 0.0
    f[out + O_SLIDING] = 1.0 if sliding else 0.0
    f[out + O_CLIPPED] = 1.0 if clipped else 0.0
    f[out + O_LEVEL_VALID] = 1.0 if moving and trusted and not clipped else 0.0
    f[out + O_VRMS] = math.sqrt((0.0 if v2 < 0.0 else v2) / n)
    return moving


@jit(inline=True)
def _friction_level(
    f: F64, ii: I64, io: int, out: int, sl: int, moving: bool
) -> None:  # pragma: no cover - jit
    """The window's friction level at O_LEVEL (in calibrated faults): the residual's
    least-squares multiple of the calibrated fault's regressor g1 + γ g2 (eq. 17 with θ on
    the signature's direction (1, γ)); NaN unless moving with a full window."""
    gamma = f[out + O_GAMMA]
    s_level = f[sl] + gamma * (2.0 * f[sl + 1] + gamma * f[sl + 2])
    if moving and ii[io + C_COUNT] == ii[io + C_N] and s_level > 0.0:
        f[out + O_LEVEL] = (f[sl + 3] + gamma * f[sl + 4]) / s_level
    else:
        f[out + O_LEVEL] = math.nan


@jit(inline=True)
def _drift_regressor(f: F64, ii: I64, io: int, accel: float) -> float:  # pragma: no cover - jit
    """s_d = d1 + γ_d d2, d1 = G_d[sign v̂_d], d2 = G_d[v̂_d] (eqs. 15 and 11 on the drift
    signature) with v̂_d = V_d(q) ẍ (m/s), the high-pass velocity at the drift signature's
    cut-off; d1, d2 also at O_DRIFT_G1, O_DRIFT_G2 (the drift reference's regressors)."""
    L = ii[io + C_WIDTH]
    bo = ii[io + C_B] + F_VEL_DRIFT * L
    ao = ii[io + C_A] + F_VEL_DRIFT * L
    zo = ii[io + C_Z] + F_VEL_DRIFT * (L - 1)
    od = io + C_ORDER + F_VEL_DRIFT
    v = iir_step(f, bo, ao, zo, ii[od], accel)
    s = 1.0 if v > 0.0 else (-1.0 if v < 0.0 else 0.0)
    d1 = iir_step(f, bo + L, ao + L, zo + (L - 1), ii[od + 1], s)
    d2 = iir_step(f, bo + 2 * L, ao + 2 * L, zo + 2 * (L - 1), ii[od + 2], v)
    out = ii[io + C_OUT]
    f[out + O_DRIFT_G1] = d1
    f[out + O_DRIFT_G2] = d2
    gamma: float = f[out + O_DRIFT_GAMMA]
    return d1 + gamma * d2


@jit(inline=True)
def _clip_tick(f: F64, out: int, accel: float, n: int) -> bool:  # pragma: no cover - jit
    """Rail detection on the raw ẍ (module docstring, ``clipped``): a flat top at the value
    of the previous one of its sign, which ended at most ``n`` ticks before, is clipping to
    its last sample. True while the last clipped sample is less than ``n`` ticks old."""
    run = f[out + O_RUN] + 1.0 if accel == f[out + O_ACCEL_LAST] and accel != 0.0 else 1.0
    f[out + O_RUN] = run
    f[out + O_ACCEL_LAST] = accel
    f[out + O_RAIL_AGE_POS] += 1.0
    f[out + O_RAIL_AGE_NEG] += 1.0
    clip_age: float = f[out + O_CLIP_AGE] + 1.0
    if run >= CLIP_RUN:
        rail, age = (O_RAIL_POS, O_RAIL_AGE_POS) if accel > 0.0 else (O_RAIL_NEG, O_RAIL_AGE_NEG)
        if run == CLIP_RUN:
            at_rail = accel == f[out + rail] and f[out + age] <= n
        else:
            at_rail = clip_age == 1.0  # this flat top was found at the rail
        if at_rail:
            clip_age = 0.0
        f[out + rail] = accel
        f[out + age] = 0.0
    f[out + O_CLIP_AGE] = clip_age
    return clip_age < n


@jit
def chain_run(
    f: F64,
    ii: I64,
    io: int,
    v_in: np.ndarray,
    accel: np.ndarray,
    position: np.ndarray,
    xext: np.ndarray,
    xhat: np.ndarray,
    r: np.ndarray,
    vel: np.ndarray,
    g1: np.ndarray,
    g2: np.ndarray,
    sums: np.ndarray,
    counts: np.ndarray,
    moving: np.ndarray,
    v_rms: np.ndarray,
) -> None:  # pragma: no cover - jit
    """``chain_tick`` over arrays, every tick's signals and window sums kept."""
    out = ii[io + C_OUT]
    n = ii[io + C_N]
    sl = ii[io + C_SUMS] + (n + 2) * SUMS_WIDTH
    for k in range(v_in.shape[0]):
        chain_tick(f, ii, io, v_in[k], accel[k], position[k], xext[k])
        xhat[k] = f[out + O_XHAT]
        r[k] = f[out + O_R]
        vel[k] = f[out + O_V]
        g1[k] = f[out + O_G1]
        g2[k] = f[out + O_G2]
        for j in range(6):
            sums[k, j] = f[sl + j]
        counts[k] = ii[io + C_COUNT]
        moving[k] = f[out + O_MOVING] != 0.0
        v_rms[k] = f[out + O_VRMS]


@jit(inline=True)
def detector_pre(f: F64, ii: I64, io: int) -> None:  # pragma: no cover - jit
    """The detector's work that does not need this tick's signals, done before the chain so
    that the reference solves' chains of divisions overlap with it: with a lag, the rows
    the reference windows have reached into their sums and the reference fits
    (`itest_tick` of both tests and of the drift reference where there is one, four
    regressors each, inlined phase by phase; all have the same lag)."""
    res = ii[io + D_RES]
    cmd = ii[io + D_CMD]
    lag = ii[res + 2]
    if lag:
        itest_flush_p(f, ii, res, 4, lag - 1)
        itest_flush_p(f, ii, cmd, 4, lag - 1)
        itest_solve_p(f, ii, res, 4)
        itest_solve_p(f, ii, cmd, 4)
        drt = ii[io + D_DRIFT_RES]
        if drt >= 0:
            itest_flush_p(f, ii, drt, 4, lag - 1)
            itest_solve_p(f, ii, drt, 4)


@jit(inline=True)
def detector_tick(
    f: F64, ii: I64, io: int, v_in: float, over_baseline: float
) -> int:  # pragma: no cover - jit
    """The detector's per-tick arithmetic and quiet decisions on this tick's signals (read
    at the chain's C_OUT, `chain_tick`); returns the tick's code."""
    out = ii[ii[io + D_CHAIN] + C_OUT]
    fo = ii[io + D_FLOATS]
    res = ii[io + D_RES]
    stat, guard_stat = _tests_tick(f, ii, io, out, v_in)
    tick = _guard_tick(f, ii, io, fo, guard_stat)
    over = _friction_excess(f, ii, io, fo, out, over_baseline)
    armed = ii[res + 8] != 0 and tick >= ii[io + D_GUARD_UNTIL]
    if ii[io + D_EPISODE]:
        # the residual test's alarm, counted as on the quiet path: the evidence of a fault
        # an episode of the growing-fault path waits for (`episode_tick`)
        ii[io + D_ABOVE] = ii[io + D_ABOVE] + 1 if armed and stat > f[fo + E_THRESHOLD] else 0
        return _episode(
            f,
            ii,
            io,
            fo,
            res,
            tick,
            f[out + O_R],
            f[out + O_G1],
            f[out + O_G2],
            f[out + O_XHAT],
            f[out + O_T1],
            f[out + O_T2],
            over,
            f[out + O_TRUSTED] != 0.0,
            f[out + O_SLIDING] != 0.0,
            f[out + O_CLIPPED] != 0.0,
            ii[io + D_ABOVE] >= ii[io + D_PERSISTENCE],
        )
    return _quiet_tick(f, ii, io, fo, res, out, tick, stat, armed, over)


@jit(inline=True)
def _tests_tick(
    f: F64, ii: I64, io: int, out: int, v_in: float
) -> tuple[float, float]:  # pragma: no cover - jit
    """This tick's rows of the residual test (φ = (g1, g2, x̂̈, 1), y = r), the command test
    (φ = v_in(k−1..k−4), y = v_in) and the drift reference where there is one: the rest of
    their `itest_tick` after `detector_pre`; returns the statistics (residual, command)."""
    xhat = f[out + O_XHAT]
    r = f[out + O_R]
    res = ii[io + D_RES]
    cmd = ii[io + D_CMD]
    ph = ii[res + 15]
    f[ph] = f[out + O_G1]
    f[ph + 1] = f[out + O_G2]
    f[ph + 2] = xhat
    f[ph + 3] = 1.0
    f[ph + 4] = r
    ph = ii[cmd + 15]  # φ = v_in(k−1..k−4): the command test's regressors are its history
    f[ph + 4] = v_in
    itest_insert_p(f, ii, res, 4)
    itest_insert_p(f, ii, cmd, 4)
    if ii[res + 2] == 0:  # no lag: the reference fits end with this tick's rows
        itest_flush_p(f, ii, res, 4, 0)
        itest_flush_p(f, ii, cmd, 4, 0)
        itest_solve_p(f, ii, res, 4)
        itest_solve_p(f, ii, cmd, 4)
    if ii[io + D_DRIFT_RES] >= 0:
        _drift_fit_tick(f, ii, ii[io + D_DRIFT_RES], out, xhat, r)
    stat = itest_statistic_p(f, ii, res, 4)
    guard_stat = itest_statistic_p(f, ii, cmd, 4)
    for q in range(3, 0, -1):
        f[ph + q] = f[ph + q - 1]
    f[ph] = v_in
    return stat, guard_stat


@jit(inline=True)
def _guard_tick(
    f: F64, ii: I64, io: int, fo: int, guard_stat: float
) -> int:  # pragma: no cover - jit
    """The operating-point guard (held D_HOLD ticks after the command test's statistic
    exceeds its threshold) and the tick counter; returns this tick's number."""
    tick: int = ii[io + D_TICK]
    if guard_stat > f[fo + E_GUARD_THRESHOLD]:
        ii[io + D_GUARD_UNTIL] = tick + ii[io + D_HOLD]
    ii[io + D_TICK] = tick + 1
    return tick


@jit(inline=True)
def _friction_excess(
    f: F64, ii: I64, io: int, fo: int, out: int, over_baseline: float
) -> float:  # pragma: no cover - jit
    """This tick's θ (E_THETA1, E_THETA2) and the friction level's excess over its
    fault-free value (E_OVER, in units of friction_min_level): ``over_baseline`` against
    a baseline, else θ1's over the calibrated level; returns the excess."""
    theta1 = f[out + O_T1]
    f[fo + E_THETA1] = theta1
    f[fo + E_THETA2] = f[out + O_T2]
    if ii[io + D_HAS_BASELINE]:
        over = over_baseline
    else:
        over = (theta1 - f[fo + E_LEVEL_BASE]) / f[fo + E_FRICTION_MIN]
    f[fo + E_OVER] = over
    return over


@jit(inline=True)
def _quiet_tick(
    f: F64,
    ii: I64,
    io: int,
    fo: int,
    res: int,
    out: int,
    tick: int,
    stat: float,
    armed: bool,
    over: float,
) -> int:  # pragma: no cover - jit
    """A tick with no episode running: the warm-up hold (D_HOLD_UNTIL: the windows fill),
    then the level path, the calibration buffer, the fast path and the growing-fault path;
    returns the tick's code."""
    if tick < ii[io + D_HOLD_UNTIL]:
        _clear_counts(ii, io)
        f[fo + E_DRIFT] = 0.0
        return QUIET
    ii[io + D_LEVEL_ABOVE] = ii[io + D_LEVEL_ABOVE] + 1 if over > 1.0 else 0
    if ii[io + D_LEVEL_ABOVE] >= ii[io + D_LEVEL_SAMPLES]:
        _clear_counts(ii, io)
        _start(f, ii, io, res, 1, 0)
        return LEVEL_ALARM
    if ii[io + D_STATE] == STATE_CALIBRATING:
        return _calibration_tick(f, ii, io, fo)
    if ii[io + D_METHOD] == 1:
        alarm = _outside_band(f, ii, io, fo)
    else:
        alarm = armed and stat > f[fo + E_THRESHOLD]
        _drift_tick(
            f,
            ii,
            res,
            ii[io + D_DRIFT_RES],
            fo,
            out,
            armed,
            f[out + O_R],
            f[out + O_G1],
            f[out + O_G2],
            f[out + O_XHAT],
        )
    ii[io + D_ABOVE] = ii[io + D_ABOVE] + 1 if alarm else 0
    if ii[io + D_ABOVE] >= ii[io + D_PERSISTENCE]:
        _clear_counts(ii, io)
        f[fo + E_DRIFT] = 0.0
        _start(f, ii, io, res, 0, 0)
        return FAST_ALARM
    if f[fo + E_DRIFT] > f[fo + E_DRIFT_H]:
        _clear_counts(ii, io)
        _start(f, ii, io, res, 0, 1)
        E.episode_rebase(f, ii, ii[io + D_EPI], fo + E_DRIFT_REF)
        return DRIFT_ALARM
    return QUIET


@jit(inline=True)
def _clear_counts(ii: I64, io: int) -> None:  # pragma: no cover - jit
    """The fast and level paths' counts of alarming ticks back to 0."""
    ii[io + D_ABOVE] = 0
    ii[io + D_LEVEL_ABOVE] = 0


@jit(inline=True)
def _calibration_tick(f: F64, ii: I64, io: int, fo: int) -> int:  # pragma: no cover - jit
    """This tick's θ into the calibration buffer (E_CAL); CALIBRATED once it is full."""
    c = ii[io + D_CAL_COUNT]
    if c < ii[io + D_CAL_SAMPLES]:  # full until `Detector.decide` takes it: not past it
        f[fo + E_CAL + 2 * c] = f[fo + E_THETA1]
        f[fo + E_CAL + 2 * c + 1] = f[fo + E_THETA2]
        c += 1
        ii[io + D_CAL_COUNT] = c
    return CALIBRATED if c >= ii[io + D_CAL_SAMPLES] else QUIET


@jit(inline=True)
def _outside_band(f: F64, ii: I64, io: int, fo: int) -> bool:  # pragma: no cover - jit
    """The band method's alarm: this tick's θ outside the calibrated band."""
    theta1 = f[fo + E_THETA1]
    theta2 = f[fo + E_THETA2]
    outside: bool = ii[io + D_HAS_BAND] != 0 and (
        theta1 < f[fo + E_LO1]
        or theta1 > f[fo + E_HI1]
        or theta2 < f[fo + E_LO2]
        or theta2 > f[fo + E_HI2]
    )
    return outside


@jit(inline=True)
def _drift_fit_tick(
    f: F64, ii: I64, drt: int, out: int, xhat: float, r: float
) -> None:  # pragma: no cover - jit
    """This tick's row of the drift reference (an innovation test block on φ_d = (d1, d2,
    x̂̈, 1), y = r: the residual fit (R) with g1, g2 replaced by the drift signature's
    G_d[sign v̂_d], G_d[v̂_d], `_drift_regressor`), and its fit when the reference has no lag
    (with one, `detector_pre` refits it). Its statistic is not needed: the CUSUM takes only
    its θ and σ² (`_drift_tick`)."""
    ph = ii[drt + 15]
    f[ph] = f[out + O_DRIFT_G1]
    f[ph + 1] = f[out + O_DRIFT_G2]
    f[ph + 2] = xhat
    f[ph + 3] = 1.0
    f[ph + 4] = r
    itest_insert_p(f, ii, drt, 4)
    if ii[drt + 2] == 0:
        itest_flush_p(f, ii, drt, 4, 0)
        itest_solve_p(f, ii, drt, 4)


@jit(inline=True)
def _freeze(f: F64, ii: I64, test: int, ref: int) -> None:  # pragma: no cover - jit
    """An innovation test's reference θ (4) and 1/σ² into f[ref:ref+5]."""
    th = ii[test + 20]
    for q in range(4):
        f[ref + q] = f[th + q]
    f[ref + 4] = f[ii[test + 22] + 4]


@jit(inline=True)
def _drift_tick(
    f: np.ndarray,
    ii: np.ndarray,
    res: int,
    drt: int,
    fo: int,
    out: int,
    armed: bool,
    r: float,
    g1: float,
    g2: float,
    xhat: float,
) -> None:  # pragma: no cover - jit
    """The growing-fault path's statistic: Page's CUSUM (`core.cusum`) of the innovation
    along the signature's regressor s (``chain_tick``'s s_d: g1 + γ g2, or the drift
    signature's on its own low-cut-off velocity), matched to a shift of
    ``drift_shift_level`` calibrated faults, against a reference as it was when the CUSUM's
    run began (at S = 0; B&N §8.1's two-model approach: the moving reference would learn a
    fault that grows, the frozen one does not). The reference is the drift reference
    (test block ``drt``, `_drift_fit_tick`: (R) on the drift signature's regressors, the
    ones s_d is made of) where the model has a drift signature (``drt`` ≥ 0), else the
    residual test's; the residual test's is frozen too, for the episode the path raises
    (`episode_rebase`). Restarted from 0 while a reference is not ready or the
    operating-point guard holds (the innovations then describe the operating point, not
    friction)."""
    shift = f[fo + E_DRIFT_SHIFT]
    if not armed or shift <= 0.0 or (drt >= 0 and ii[drt + 8] == 0):
        f[fo + E_DRIFT] = 0.0
        return
    ref = fo + E_DRIFT_FIT
    if f[fo + E_DRIFT] == 0.0:
        _freeze(f, ii, res, fo + E_DRIFT_REF)
        _freeze(f, ii, res if drt < 0 else drt, ref)
    if drt >= 0:
        g1 = f[out + O_DRIFT_G1]
        g2 = f[out + O_DRIFT_G2]
    e = r - (f[ref] * g1 + f[ref + 1] * g2 + f[ref + 2] * xhat + f[ref + 3])
    total = f[fo + E_DRIFT] + cusum_increment(e, f[out + O_DRIFT_S], f[ref + 4], shift)
    f[fo + E_DRIFT] = total if total > 0.0 else 0.0


@jit
def _start(
    f: F64, ii: I64, io: int, res: int, level: int, drift: int
) -> None:  # pragma: no cover - jit
    """fault_detected: an episode starts (level, drift: raised by the level path, by the
    growing-fault path); the reported friction level restarts from the new picks."""
    E.episode_start(f, ii, ii[io + D_EPI], res, level, drift)
    level_restart(f, ii, ii[io + D_LEVEL])
    ii[io + D_EPISODE] = 1
    ii[io + D_STATE] = STATE_DETECTED


@jit
def _episode(
    f: F64,
    ii: I64,
    io: int,
    fo: int,
    res: int,
    tick: int,
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
) -> int:  # pragma: no cover - jit
    """A tick of the running episode, and its transition applied to the detector."""
    ep = ii[io + D_EPI]
    band = fo + E_LO1 if ii[io + D_HAS_BAND] else -1
    out = ii[ii[io + D_CHAIN] + C_OUT]
    f[ii[ep + E.P_O_SCAL] + E.S_DRIFT_S] = f[out + O_DRIFT_S]
    packed_row_into(f, ii[res + 15], 4, ii[res + 16])  # this tick's row of the residual fit
    change = E.episode_tick(
        f,
        ii,
        ep,
        tick,
        ii[io + D_STATE],
        r,
        g1,
        g2,
        xhat,
        theta1,
        theta2,
        over,
        trusted,
        sliding,
        clipped,
        alarm,
        ii[res + 16],
        band,
        f[fo + E_THETA1 : fo + E_THETA2 + 1],
    )
    if change == E.NO_CHANGE:
        return QUIET
    if change == E.TO_ISOLATED:
        ii[io + D_STATE] = STATE_ISOLATED
        return ISOLATED
    if change == E.TO_OTHER:
        ii[io + D_STATE] = STATE_OTHER
        return OTHER_FAULT
    # cleared: an episode raised against the baseline saw the friction calibrated as normal,
    # so calibrate again; the moving reference still holds fault data: hold the guard
    if (ii[ep + E.P_LEVEL] and ii[io + D_HAS_BASELINE]) or not ii[io + D_HAS_BAND]:
        ii[io + D_STATE] = STATE_CALIBRATING
    else:
        ii[io + D_STATE] = STATE_MONITORING
    ii[io + D_CAL_COUNT] = 0
    ii[io + D_EPISODE] = 0
    level_restart(f, ii, ii[io + D_LEVEL])
    ii[io + D_ABOVE] = 0
    f[fo + E_DRIFT] = 0.0
    ii[io + D_GUARD_UNTIL] = max(ii[io + D_GUARD_UNTIL], ii[io + D_TICK] + ii[io + D_HOLD])
    return CLEARED


@jit
def monitor_tick(
    f: F64, ii: I64, io: int, v_in: float, accel: float, position: float, xext: float
) -> int:  # pragma: no cover - jit
    """``detector_pre``, ``chain_tick``, the reported friction level, then ``detector_tick``
    (with the level's excess over the baseline of the window's operating condition); returns
    the tick's code (also in ii[io + D_CODE])."""
    detector_pre(f, ii, io)
    chain = ii[io + D_CHAIN]
    chain_tick(f, ii, chain, v_in, accel, position, xext)
    out = ii[chain + C_OUT]
    level_tick(f, ii, ii[io + D_LEVEL], f[out + O_LEVEL], f[out + O_LEVEL_VALID] != 0.0)
    theta1 = f[out + O_T1]
    over = math.nan
    nb = ii[io + D_BINS]
    if ii[io + D_HAS_BASELINE]:
        fo = ii[io + D_FLOATS]
        edges = fo + E_CAL + 2 * ii[io + D_CAL_SAMPLES]
        v_rms = f[out + O_VRMS]
        if v_rms != v_rms:
            b = nb - 1
        else:
            b = -1
            for k in range(nb + 1):
                if f[edges + k] <= v_rms:
                    b = k
            b = min(max(b, 0), nb - 1)
        over = (theta1 - f[edges + nb + 1 + b]) / f[edges + 2 * nb + 1 + b]
    code = detector_tick(f, ii, io, v_in, over)
    ii[io + D_CODE] = code
    return code


@jit
def monitor_run(
    f: F64,
    ii: I64,
    io: int,
    v_in: np.ndarray,
    accel: np.ndarray,
    position: np.ndarray,
    xext: np.ndarray,
    start: int,
    stat: np.ndarray,
    state: np.ndarray,
    theta1: np.ndarray,
    theta2: np.ndarray,
    residual: np.ndarray,
    v_rms: np.ndarray,
    level: np.ndarray,
) -> int:  # pragma: no cover - jit
    """``monitor_tick`` from index ``start`` on, traces kept; returns the index after the
    first tick whose code is not QUIET (its code in ii[io + D_CODE]), or the length."""
    chain = ii[io + D_CHAIN]
    out = ii[chain + C_OUT]
    fo = ii[io + D_FLOATS]
    stat_o = ii[ii[io + D_RES] + 22] + 2
    lo = ii[io + D_LEVEL]
    level_out = ii[lo + L_FLOATS] + 2 * ii[lo + L_CAPACITY]
    for k in range(start, v_in.shape[0]):
        code = monitor_tick(f, ii, io, v_in[k], accel[k], position[k], xext[k])
        stat[k] = f[stat_o]
        state[k] = ii[io + D_STATE]
        theta1[k] = f[fo + E_THETA1]
        theta2[k] = f[fo + E_THETA2]
        residual[k] = f[out + O_R]
        v_rms[k] = f[out + O_VRMS]
        level[k] = f[level_out]
        if code != QUIET:
            return k + 1
    ii[io + D_CODE] = QUIET
    return int(v_in.shape[0])
