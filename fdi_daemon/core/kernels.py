"""Compiled per-sample building blocks on flat state arrays (`core.compiled.Arena`).

Each helper does the arithmetic of one streaming block, in the order of the block's
reference implementation, so compiled and reference results agree:

- ``iir_step``: a B/A filter in transposed direct form II (the recursion of
  ``scipy.signal.lfilter``; Ĝ of eq. 1, G_e of eq. 15, the velocity filters);
- ``sums_push``: window sums of the last N rows, cut in blocks of N rows (exact at the end
  of every block, no drift; the window sums of eqs. 16–17);
- ``solve_packed``: least squares from packed window sums by LDLᵀ
  (`core.normal_equations.solve_packed`, the float path);
- ``itest_tick``: one tick of the innovation test (`core.innovation_test`): lagged
  reference fit, standardised innovation, windowed mean of its square; the FIFO of the lag
  holds (φ, y), and the packed row is formed while it is added (`push_products`); its
  phases (``itest_*_p``) are inlined where p is constant.

Offsets are absolute indices into the float array ``f`` and the int array ``ii``.
"""

from __future__ import annotations

import numpy as np

from fdi_daemon.core.compiled import jit

__all__ = ["iir_step", "sums_push", "sums_floats", "solve_packed", "push_products",
           "packed_row_into", "itest_tick", "itest_pop_p", "itest_insert_p", "itest_solve_p",
           "itest_statistic_p",
           "ITEST_INTS", "itest_floats"]


#: an offset as an unsigned integer: indexing with it skips the test for a negative index
#: (the hot loops; every operand of its arithmetic must be unsigned too)
_u = np.uint64


@jit(inline=True)
def iir_step(f, bo, ao, zo, n, x):  # pragma: no cover - jit
    """One sample through b = f[bo:bo+n+1], a = f[ao:..] (a0 = 1), state f[zo:zo+n]
    (offsets unsigned inside, `_u`)."""
    bo = _u(bo)
    if n == 0:
        return f[bo] * x
    one = _u(1)
    ao = _u(ao)
    zo = _u(zo)
    n = _u(n)
    y = f[bo] * x + f[zo]
    for i in range(n - one):
        f[zo + i] = f[zo + i + one] + f[bo + i + one] * x - f[ao + i + one] * y
    f[zo + n - one] = f[bo + n] * x - f[ao + n] * y
    return y


def sums_floats(n: int, w: int) -> int:
    """Floats of a sums block: ring (n rows), fresh, previous total, sliding (w each)."""
    return (n + 3) * w


@jit(inline=True)
def sums_push(f, ii, ro, n, w, ip, src):  # pragma: no cover - jit
    """Push row f[src:src+w] into the sums block at ``ro`` (pos, count in ii[ip], ii[ip+1]);
    the window sums are then at ro + (n + 2)·w (module docstring)."""
    fresh, prev, sl, rp, end = _slot(ii, ro, n, w, ip)
    src = _u(src)
    for k in range(_u(w)):
        _column(f, fresh, prev, sl, rp, k, f[src + k], end, True)
    ii[ip] = 0 if end else ii[ip] + 1


@jit
def solve_packed(f, so, p, min_pivot, scr, to):  # pragma: no cover - jit
    """θ (into f[to:to+p]), SSE and ok from the packed sums f[so:..] of p regressors;
    scratch f[scr:scr + 2p² + p]. The float path of `core.normal_equations.solve_packed`."""
    return _solve(f, so, p, min_pivot, scr, to)


@jit(inline=True)
def _solve(f, so, p, min_pivot, scr, to):  # pragma: no cover - jit
    """`solve_packed`, inlined where p is a constant (the loops then unroll). One division
    per pivot: its reciprocal, kept on L's unit diagonal, multiplies. Offsets are unsigned
    (`_u`): no negative-index test per access, and the compiler sees which scratch entries
    each step reads, so they stay in registers."""
    p = _u(p)
    one = _u(1)
    s = _u(scr)
    to = _u(to)
    low = s + p * p
    d = low + p * p
    k = _u(so)
    for i in range(p):
        for j in range(i, p):
            f[s + i * p + j] = f[k]
            k += one
    sy = k
    syy = f[k + p]
    ok = True
    for j in range(p):
        acc = f[s + j * p + j]
        for m in range(j):
            acc = acc - f[low + j * p + m] * f[low + j * p + m] * f[d + m]
        f[d + j] = acc
        ok = ok & (acc > min_pivot * f[s + j * p + j])
        inv = 1.0 / acc if acc != 0.0 else 0.0
        f[low + j * p + j] = inv  # 1/d on L's (unit) diagonal
        for i in range(j + one, p):
            acc = f[s + j * p + i]
            for m in range(j):
                acc = acc - f[low + i * p + m] * f[low + j * p + m] * f[d + m]
            f[low + i * p + j] = acc * inv
    # forward L z = s_y (z kept in θ's slots), then θ backward
    for i in range(p):
        acc = f[sy + i]
        for m in range(i):
            acc = acc - f[low + i * p + m] * f[to + m]
        f[to + i] = acc
    for r in range(p):
        i = p - one - r
        acc = f[to + i] * f[low + i * p + i]
        for m in range(i + one, p):
            acc = acc - f[low + m * p + i] * f[to + m]
        f[to + i] = acc
    sse = syy
    for i in range(p):
        sse = sse - f[to + i] * f[sy + i]
    return sse, ok


#: ints of an innovation test block (see `InnovationTest`)
ITEST_INTS = 23


def itest_floats(p: int, n: int, lag: int, m: int) -> int:
    """Floats of an innovation test block: φ and y, the packed row, the FIFO of (φ, y) of
    the last ``lag`` ticks, the reference and test sums, θ, scratch, scalars (σ² floor,
    σ², T, z², 1/σ², 1/M)."""
    w = p * (p + 1) // 2 + p + 1
    return (p + 1) + w + lag * (p + 1) + sums_floats(n, w) + sums_floats(m, 1) + p \
        + (2 * p * p + p) + 6


@jit(inline=True)
def _slot(ii, ro, n, w, ip):  # pragma: no cover - jit
    """The offsets (unsigned, `_u`) of a sums block's fresh, previous and sliding rows and
    of the ring row this push writes, and whether it ends the block (the row count grows up
    to n)."""
    pos = ii[ip]
    fresh = ro + n * w
    prev = fresh + w
    if ii[ip + 1] < n:
        ii[ip + 1] += 1
    return _u(fresh), _u(prev), _u(prev + w), _u(ro + pos * w), pos + 1 == n


@jit(inline=True)
def _column(f, fresh, prev, sl, rp, k, value, end, need):  # pragma: no cover - jit
    """One column of `sums_push` (the window sums only when ``need``: the reader's tick)."""
    c = f[fresh + k] + value
    if end:
        f[rp + k] = c
        f[prev + k] = c
        f[fresh + k] = 0.0
        if need:
            f[sl + k] = c
    else:
        if need:
            f[sl + k] = f[prev + k] + (c - f[rp + k])
        f[rp + k] = c
        f[fresh + k] = c


@jit(inline=True)
def push_products(f, ii, ro, n, ip, src, p, need):  # pragma: no cover - jit
    """`sums_push` of the packed row of (φ, y) = f[src:src+p+1], formed column by column
    (the products of `innovation_test.packed_row`); the window sums are written only when
    ``need`` (a block's other sums are exact whatever the ticks that read them)."""
    w = p * (p + 1) // 2 + p + 1
    fresh, prev, sl, rp, end = _slot(ii, ro, n, w, ip)
    p = _u(p)
    one = _u(1)
    src = _u(src)
    y = f[src + p]
    k = _u(0)
    for a in range(p):
        for b in range(a, p):
            _column(f, fresh, prev, sl, rp, k, f[src + a] * f[src + b], end, need)
            k += one
    for a in range(p):
        _column(f, fresh, prev, sl, rp, k, f[src + a] * y, end, need)
        k += one
    _column(f, fresh, prev, sl, rp, k, y * y, end, need)
    ii[ip] = 0 if end else ii[ip] + 1


@jit
def packed_row_into(f, src, p, dst):  # pragma: no cover - jit
    """The packed row of (φ, y) = f[src:src+p+1] into f[dst:..]."""
    y = f[src + p]
    c = dst
    for a in range(p):
        for b in range(a, p):
            f[c] = f[src + a] * f[src + b]
            c += 1
    for a in range(p):
        f[c] = f[src + a] * y
        c += 1
    f[c] = y * y


@jit
def itest_tick(f, ii, io):  # pragma: no cover - jit
    """One tick of the innovation test whose ints start at ``io``; φ and y in its phi slots.

    Reference fit on the window ending ``lag`` ticks ago (re-solved when tick % every ==
    phase), σ² = SSE/(N − p) floored, z² = (y − φᵀθ)²/σ², T = mean of z² over M ticks
    (both divisions by reciprocals kept in the block: 1/σ² set at the solve, 1/M). The
    reference window sums are current on solve ticks (their only reader). The tick is four
    phases, `itest_pop_p`, `itest_insert_p`, `itest_solve_p`
    and `itest_statistic_p`, inlined where p is a compile-time constant (the loops unroll):
    the monitor's kernel inlines those of its two four-regressor tests, phase by phase."""
    p = ii[io]
    if p == 4:
        itest_pop_p(f, ii, io, 4)
        itest_insert_p(f, ii, io, 4)
        itest_solve_p(f, ii, io, 4)
        return itest_statistic_p(f, ii, io, 4)
    itest_pop_p(f, ii, io, p)
    itest_insert_p(f, ii, io, p)
    itest_solve_p(f, ii, io, p)
    return itest_statistic_p(f, ii, io, p)


@jit(inline=True)
def itest_pop_p(f, ii, io, p):  # pragma: no cover - jit
    """The row leaving the lag's FIFO (its oldest, once it is full) into the reference
    window sums (current on a solve tick). It does not read this tick's
    (φ, y): the monitor calls it, and the solve, before the signal chain."""
    lag = ii[io + 2]
    if lag and ii[io + 10] == lag:
        push_products(f, ii, ii[io + 18], ii[io + 1], io + 11,
                      ii[io + 17] + ii[io + 9] * (p + 1), p, ii[io + 7] == 0)


@jit(inline=True)
def itest_insert_p(f, ii, io, p):  # pragma: no cover - jit
    """This tick's (φ, y) into the lag's FIFO, in the slot `itest_pop_p` emptied (without a
    lag: straight into the reference window sums, current on a solve tick)."""
    lag = ii[io + 2]
    ph = ii[io + 15]
    if lag == 0:
        push_products(f, ii, ii[io + 18], ii[io + 1], io + 11, ph, p, ii[io + 7] == 0)
        return
    q = p + 1
    ln = ii[io + 10]
    head = ii[io + 9]
    if ln == lag:
        slot = ii[io + 17] + head * q
        ii[io + 9] = head + 1 if head + 1 < lag else 0
    else:
        slot = ii[io + 17] + (head + ln if head + ln < lag else head + ln - lag) * q
        ii[io + 10] = ln + 1
    for k in range(q):
        f[slot + k] = f[ph + k]


@jit(inline=True)
def itest_solve_p(f, ii, io, p):  # pragma: no cover - jit
    """On a solve tick (countdown ii[io+7] at 0, then ``every`` − 1 again): θ, σ² (floored)
    and 1/σ² of the reference window, and whether it is ok (full, pivots above 1e-9)."""
    wait = ii[io + 7]
    if wait:
        ii[io + 7] = wait - 1
        return
    ii[io + 7] = ii[io + 4] - 1
    n = ii[io + 1]
    if ii[io + 12] == n:
        sc = ii[io + 22]
        sse, ok = _solve(f, ii[io + 18] + (n + 2) * ii[io + 6], p, 1e-9, ii[io + 21],
                         ii[io + 20])
        s2 = sse / (n - p)
        f[sc + 1] = s2 if s2 > f[sc] else f[sc]
        f[sc + 4] = 1.0 / f[sc + 1]
        ii[io + 8] = 1 if ok else 0
    else:
        ii[io + 8] = 0


@jit(inline=True)
def itest_statistic_p(f, ii, io, p):  # pragma: no cover - jit
    """z² of this tick against the reference θ (0 while it is not ok) into the test window;
    returns T (also kept at the block's scalars)."""
    ph = ii[io + 15]
    th = ii[io + 20]
    sc = ii[io + 22]
    m = ii[io + 3]
    tst = ii[io + 19]
    if ii[io + 8]:
        acc = f[th] * f[ph]
        for a in range(1, p):
            acc = acc + f[th + a] * f[ph + a]
        e = f[ph + p] - acc
        f[sc + 3] = e * e * f[sc + 4]
    else:
        f[sc + 3] = 0.0
    sums_push(f, ii, tst, m, 1, io + 13, sc + 3)
    stat = f[tst + (m + 2)] * f[sc + 5]
    f[sc + 2] = stat
    return stat
