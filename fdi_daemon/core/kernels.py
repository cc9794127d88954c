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
  reference fit, standardised innovation, windowed mean of its square; a FIFO holds (φ, y)
  until a solve tick sums the rows the reference window has reached into one group row
  (`group_products`) of the window sums; its phases (``itest_*_p``) are inlined where p
  is constant.

Offsets are absolute indices into the float array ``f`` and the int array ``ii``.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from fdi_daemon.core.compiled import jit

__all__ = [
    "iir_step",
    "sums_push",
    "sums_floats",
    "solve_packed",
    "packed_row_into",
    "itest_tick",
    "itest_flush_p",
    "itest_insert_p",
    "itest_solve_p",
    "itest_statistic_p",
    "ITEST_INTS",
    "itest_floats",
    "itest_groups",
    "group_products",
]


#: an offset as an unsigned integer: indexing with it skips the test for a negative index
#: (the hot loops; every operand of its arithmetic must be unsigned too)
unsigned = np.uint64

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]
#: an offset or count: a Python int, or `unsigned` inside the hot loops
Index = int | np.uint64


@jit(inline=True)
def iir_step(
    f: F64, bo: Index, ao: Index, zo: Index, n: Index, x: float
) -> float:  # pragma: no cover - jit
    """One sample through b = f[bo:bo+n+1], a = f[ao:..] (a0 = 1), state f[zo:zo+n]
    (offsets `unsigned` inside)."""
    bo = unsigned(bo)
    if n == 0:
        y: float = f[bo] * x
        return y
    one = unsigned(1)
    ao = unsigned(ao)
    zo = unsigned(zo)
    n = unsigned(n)
    y = f[bo] * x + f[zo]
    for i in range(n - one):
        f[zo + i] = f[zo + i + one] + f[bo + i + one] * x - f[ao + i + one] * y
    f[zo + n - one] = f[bo + n] * x - f[ao + n] * y
    return y


def sums_floats(n: int, w: int) -> int:
    """Floats of a sums block: ring (n rows), fresh, previous total, sliding (w each)."""
    return (n + 3) * w


@jit(inline=True)
def sums_push(
    f: F64, ii: I64, ro: Index, n: Index, w: Index, ip: Index, src: Index
) -> None:  # pragma: no cover - jit
    """Push row f[src:src+w] into the sums block at ``ro`` (pos, count in ii[ip], ii[ip+1]);
    the window sums are then at ro + (n + 2)·w (module docstring)."""
    fresh, prev, sl, rp, end = _slot(ii, ro, n, w, ip)
    src = unsigned(src)
    for k in range(unsigned(w)):
        _column(f, fresh, prev, sl, rp, k, f[src + k], end)
    ii[ip] = 0 if end else ii[ip] + 1


@jit
def solve_packed(
    f: F64, so: Index, p: Index, min_pivot: float, scr: Index, to: Index
) -> tuple[float, bool]:  # pragma: no cover - jit
    """θ (into f[to:to+p]), SSE and ok from the packed sums f[so:..] of p regressors;
    scratch f[scr:scr + 2p² + p]. The float path of `core.normal_equations.solve_packed`."""
    return _solve(f, so, p, min_pivot, scr, to)


@jit(inline=True)
def _solve(
    f: F64, so: Index, p: Index, min_pivot: float, scr: Index, to: Index
) -> tuple[float, bool]:  # pragma: no cover - jit
    """`solve_packed`, inlined where p is a constant (the loops then unroll). One division
    per pivot: its reciprocal, kept on L's unit diagonal, multiplies. Offsets are
    `unsigned`: no negative-index test per access, and the compiler sees which scratch entries
    each step reads, so they stay in registers."""
    p = unsigned(p)
    one = unsigned(1)
    s = unsigned(scr)
    to = unsigned(to)
    low = s + p * p
    d = low + p * p
    k = unsigned(so)
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
ITEST_INTS = 25


def itest_groups(n: int, every: int) -> int:
    """Refit groups in the reference window: its n rows in whole groups of ``every`` (the
    window is then ``itest_groups(n, every)·every`` rows)."""
    return max(1, round(n / every))


def itest_floats(p: int, n: int, lag: int, m: int, every: int) -> int:
    """Floats of an innovation test block: φ and y, a group's packed sums and row count,
    the FIFO of (φ, y) of the ticks the reference window has not reached (lag + every rows),
    the reference sums (one row per group), the test sums, θ, scratch, scalars (σ² floor,
    σ², T, z², 1/σ², 1/M)."""
    w = p * (p + 1) // 2 + p + 1
    return (
        (p + 1)
        + (w + 1)
        + (lag + every) * (p + 1)
        + sums_floats(itest_groups(n, every), w + 1)
        + sums_floats(m, 1)
        + p
        + (2 * p * p + p)
        + 6
    )


@jit(inline=True)
def _slot(
    ii: I64, ro: Index, n: Index, w: Index, ip: Index
) -> tuple[Index, Index, Index, Index, bool]:  # pragma: no cover - jit
    """The `unsigned` offsets of a sums block's fresh, previous and sliding rows and
    of the ring row this push writes, and whether it ends the block (the row count grows up
    to n)."""
    pos = ii[ip]
    fresh = ro + n * w
    prev = fresh + w
    if ii[ip + 1] < n:
        ii[ip + 1] += 1
    return unsigned(fresh), unsigned(prev), unsigned(prev + w), unsigned(ro + pos * w), pos + 1 == n


@jit(inline=True)
def _column(
    f: F64, fresh: Index, prev: Index, sl: Index, rp: Index, k: Index, value: float, end: bool
) -> None:  # pragma: no cover - jit
    """One column of `sums_push`."""
    c = f[fresh + k] + value
    if end:
        f[rp + k] = c
        f[prev + k] = c
        f[fresh + k] = 0.0
        f[sl + k] = c
    else:
        f[sl + k] = f[prev + k] + (c - f[rp + k])
        f[rp + k] = c
        f[fresh + k] = c


@jit(inline=True)
def group_products(
    f: F64, fifo: Index, cap: Index, head: Index, count: Index, p: Index, dst: Index
) -> None:  # pragma: no cover - jit
    """The packed products of ``count`` rows of (φ, y) from a FIFO (``cap`` rows of p + 1
    floats at ``fifo``, the first at index ``head``), summed row after row into
    f[dst:dst+w], and the row count into f[dst+w]. With four regressors (the monitor's
    tests) the fifteen sums are held in registers."""
    if p == 4:
        _group_products_4(f, fifo, cap, head, count, dst)
        return
    q = p + 1
    k = dst
    for a in range(p):
        for b in range(a, p):
            _group_column(f, fifo, cap, head, count, q, a, b, k)
            k += 1
    for a in range(q):
        _group_column(f, fifo, cap, head, count, q, a, p, k)
        k += 1
    f[k] = float(count)


@jit(inline=True)
def _group_column(
    f: F64,
    fifo: Index,
    cap: Index,
    head: Index,
    count: Index,
    q: Index,
    a: Index,
    b: Index,
    dst: Index,
) -> None:  # pragma: no cover - jit
    """One column of `group_products`: Σ φ_a·φ_b over the rows (index p stands for y)."""
    c = 0.0
    slot = head
    for _ in range(count):
        c = c + f[fifo + slot * q + a] * f[fifo + slot * q + b]
        slot = slot + 1 if slot + 1 < cap else 0
    f[dst] = c


@jit(inline=True)
def _group_products_4(
    f: F64, fifo: Index, cap: Index, head: Index, count: Index, dst: Index
) -> None:  # pragma: no cover - jit
    """`group_products` for p = 4, the sums in registers (the order of `packed_row`)."""
    s00 = s01 = s02 = s03 = s11 = s12 = s13 = s22 = s23 = s33 = 0.0
    s0y = s1y = s2y = s3y = syy = 0.0
    slot = head
    for _ in range(count):
        r = fifo + slot * 5
        x0 = f[r]
        x1 = f[r + 1]
        x2 = f[r + 2]
        x3 = f[r + 3]
        y = f[r + 4]
        s00 = s00 + x0 * x0
        s01 = s01 + x0 * x1
        s02 = s02 + x0 * x2
        s03 = s03 + x0 * x3
        s11 = s11 + x1 * x1
        s12 = s12 + x1 * x2
        s13 = s13 + x1 * x3
        s22 = s22 + x2 * x2
        s23 = s23 + x2 * x3
        s33 = s33 + x3 * x3
        s0y = s0y + x0 * y
        s1y = s1y + x1 * y
        s2y = s2y + x2 * y
        s3y = s3y + x3 * y
        syy = syy + y * y
        slot = slot + 1 if slot + 1 < cap else 0
    f[dst] = s00
    f[dst + 1] = s01
    f[dst + 2] = s02
    f[dst + 3] = s03
    f[dst + 4] = s11
    f[dst + 5] = s12
    f[dst + 6] = s13
    f[dst + 7] = s22
    f[dst + 8] = s23
    f[dst + 9] = s33
    f[dst + 10] = s0y
    f[dst + 11] = s1y
    f[dst + 12] = s2y
    f[dst + 13] = s3y
    f[dst + 14] = syy
    f[dst + 15] = float(count)


@jit
def packed_row_into(f: F64, src: Index, p: Index, dst: Index) -> None:  # pragma: no cover - jit
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
def itest_tick(f: F64, ii: I64, io: Index) -> float:  # pragma: no cover - jit
    """One tick of the innovation test whose ints start at ``io``; φ and y in its phi slots.

    Reference fit on the window ending ``lag`` ticks ago (re-solved when tick % every ==
    phase), σ² = SSE/(N − p) floored, z² = (y − φᵀθ)²/σ², T = mean of z² over M ticks
    (both divisions by reciprocals kept in the block: 1/σ² set at the solve, 1/M). The
    reference window sums are current on solve ticks (their only reader): the rows wait in
    the FIFO until a solve tick adds them as one group. The tick is four phases,
    `itest_flush_p`, `itest_solve_p`, `itest_insert_p` and `itest_statistic_p`, inlined
    where p is a compile-time constant (the loops unroll): the monitor's kernel inlines
    those of its two four-regressor tests, phase by phase."""
    p = ii[io]
    if p == 4:
        return _itest_tick_p(f, ii, io, 4)
    return _itest_tick_p(f, ii, io, p)


@jit(inline=True)
def _itest_tick_p(f: F64, ii: I64, io: Index, p: Index) -> float:  # pragma: no cover - jit
    """`itest_tick`'s phases in their order: with a lag the reference is flushed and solved
    before this tick's row enters the FIFO (the row cannot be in it), without one after."""
    if ii[io + 2]:
        itest_flush_p(f, ii, io, p, ii[io + 2] - 1)
        itest_solve_p(f, ii, io, p)
        itest_insert_p(f, ii, io, p)
    else:
        itest_insert_p(f, ii, io, p)
        itest_flush_p(f, ii, io, p, 0)
        itest_solve_p(f, ii, io, p)
    return itest_statistic_p(f, ii, io, p)


@jit(inline=True)
def itest_flush_p(
    f: F64, ii: I64, io: Index, p: Index, keep: Index
) -> None:  # pragma: no cover - jit
    """On a solve tick (countdown ii[io+7] at 0): the FIFO's rows but its newest ``keep``
    (those the reference window has reached since the last refit) summed into one group
    row (`group_products`) and pushed into the reference sums; other ticks move nothing."""
    ln = ii[io + 10]
    if ii[io + 7] or ln <= keep:
        return
    count = ln - keep
    cap = ii[io + 23]
    head = ii[io + 9]
    row = ii[io + 16]
    group_products(f, ii[io + 17], cap, head, count, p, row)
    sums_push(f, ii, ii[io + 18], ii[io + 1], ii[io + 6] + 1, io + 11, row)
    head += count
    ii[io + 9] = head - cap if head >= cap else head
    ii[io + 10] = keep


@jit(inline=True)
def itest_insert_p(f: F64, ii: I64, io: Index, p: Index) -> None:  # pragma: no cover - jit
    """This tick's (φ, y) at the FIFO's tail (it holds the rows the reference window has
    not reached: at most lag + every − 1 before a flush; its capacity lag + every)."""
    q = p + 1
    cap = ii[io + 23]
    end = ii[io + 9] + ii[io + 10]
    slot = ii[io + 17] + (end if end < cap else end - cap) * q
    ii[io + 10] += 1
    ph = ii[io + 15]
    for k in range(q):
        f[slot + k] = f[ph + k]


@jit(inline=True)
def itest_solve_p(f: F64, ii: I64, io: Index, p: Index) -> None:  # pragma: no cover - jit
    """On a solve tick (countdown ii[io+7] at 0, then ``every`` − 1 again): θ, σ² (floored)
    and 1/σ² of the reference window, and whether it is ok (all its rows there, pivots
    above 1e-9)."""
    wait = ii[io + 7]
    if wait:
        ii[io + 7] = wait - 1
        return
    ii[io + 7] = ii[io + 4] - 1
    g = ii[io + 1]
    w = ii[io + 6]
    sl = ii[io + 18] + (g + 2) * (w + 1)
    n = ii[io + 24]
    if ii[io + 12] == g and f[sl + w] == n:  # every group of the window full
        sc = ii[io + 22]
        sse, ok = _solve(f, sl, p, 1e-9, ii[io + 21], ii[io + 20])
        s2 = sse / (n - p)
        f[sc + 1] = s2 if s2 > f[sc] else f[sc]
        f[sc + 4] = 1.0 / f[sc + 1]
        ii[io + 8] = 1 if ok else 0
    else:
        ii[io + 8] = 0


@jit(inline=True)
def itest_statistic_p(f: F64, ii: I64, io: Index, p: Index) -> float:  # pragma: no cover - jit
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
    stat: float = f[tst + (m + 2)] * f[sc + 5]
    f[sc + 2] = stat
    return stat
