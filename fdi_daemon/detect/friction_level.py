"""The friction level as reported: the window's level where it measures friction, robust
over seconds.

The window's level (`detect.kernel.chain_tick`: the residual's least-squares multiple of the
calibrated signature's regressor g1 + γ g2, units of the calibrated fault) measures friction
only where the rig moves and the window's velocity is trusted (*level valid*): elsewhere it
reads 0 or below under a friction that is there (docs/detector.md §3, "Clearing"). The
reported level is the median of the window's level picked four times a second at valid
windows, over the last ``level_median_s`` worth of picks since the last alarm episode began
or ended, the first of them one window after it (`level_restart`: a level that jumps at a
fault is reported at its new value from one window after the detection, never a mix of the
windows before and after it). It is reported only while the current window is valid (NaN
elsewhere, as at rest: a level that cannot be measured is not shown, and the alarm
lifecycle and the trend take no reading), and NaN before the first pick. Its spread, the 25–75 % range of the same
picks, is the level's uncertainty.

``level_tick`` is compiled and inlined into `detect.kernel.monitor_tick`, so
``Monitor.step`` and ``Monitor.run`` report the same level.
"""

from __future__ import annotations

import math

from fdi_daemon.core.compiled import Arena, jit
from fdi_daemon.core.kernels import F64, I64

__all__ = ["FrictionLevel", "level_tick", "level_restart", "LEVEL_INTS", "PICKS_PER_S"]

PICKS_PER_S = 4.0
# ints: pick period (ticks), capacity (picks), countdown to the next pick, picks held, next
# slot, float base (ring, sorted copy, then level and spread as reported, then as held),
# the countdown a restart sets (the first pick on the window's length-th tick after it)
L_PICK, L_CAPACITY, L_WAIT, L_COUNT, L_HEAD, L_FLOATS, L_SETTLE = range(7)
LEVEL_INTS = 7


@jit(inline=True)
def level_tick(
    f: F64, ii: I64, lo: int, level: float, valid: bool
) -> None:  # pragma: no cover - jit
    """One tick: on a pick tick with a valid window, the window's level enters the ring and
    the median and the 25–75 % spread of the ring are recomputed (`_pick`); on every tick
    they are reported if the window is valid, else NaN. Inlined into the monitor's tick (as
    a call it cost about 12 of its 155 ns); the pick stays a call, made four times a
    second."""
    cap = ii[lo + L_CAPACITY]
    ring = ii[lo + L_FLOATS]
    out = ring + 2 * cap
    valid = valid and math.isfinite(level)
    wait = ii[lo + L_WAIT]
    if wait > 0:
        ii[lo + L_WAIT] = wait - 1
    else:
        ii[lo + L_WAIT] = ii[lo + L_PICK] - 1
        if valid:
            _pick(f, ii, lo, ring, cap, out + 2, level)
    f[out] = f[out + 2] if valid else math.nan
    f[out + 1] = f[out + 3] if valid else math.nan


@jit
def level_restart(f: F64, ii: I64, lo: int) -> None:  # pragma: no cover - jit
    """Forget the picks (an alarm episode begins or ends); the level is NaN until the next.
    The first pick comes one window after the restart, from the first window that holds
    none of the data before it, and the pick period counts from there: the level after a
    fault depends on the data, not on the sample the monitor started at."""
    ii[lo + L_WAIT] = ii[lo + L_SETTLE]
    ii[lo + L_COUNT] = 0
    ii[lo + L_HEAD] = 0
    held = ii[lo + L_FLOATS] + 2 * ii[lo + L_CAPACITY] + 2
    f[held] = math.nan
    f[held + 1] = math.nan


@jit
def _pick(
    f: F64, ii: I64, lo: int, ring: int, cap: int, held: int, level: float
) -> None:  # pragma: no cover - jit
    """The level into the ring and into its sorted copy (in place of the value it
    overwrites, once the ring is full: one pass, not a sort); the median and 25–75 % range
    into f[held], f[held + 1]."""
    head = ii[lo + L_HEAD]
    count = ii[lo + L_COUNT]
    srt = ring + cap
    if count == cap:  # the oldest pick leaves the sorted copy
        old = f[ring + head]
        j = 0
        while f[srt + j] != old:
            j += 1
        for i in range(j, count - 1):
            f[srt + i] = f[srt + i + 1]
        count -= 1
    f[ring + head] = level
    ii[lo + L_HEAD] = head + 1 if head + 1 < cap else 0
    j = count
    while j > 0 and f[srt + j - 1] > level:
        f[srt + j] = f[srt + j - 1]
        j -= 1
    f[srt + j] = level
    count += 1
    ii[lo + L_COUNT] = count
    half = count // 2
    f[held] = f[srt + half] if count % 2 else 0.5 * (f[srt + half - 1] + f[srt + half])
    f[held + 1] = f[srt + (3 * (count - 1)) // 4] - f[srt + (count - 1) // 4]


class FrictionLevel:
    """State of the reported friction level in an `Arena` (see the module docstring)."""

    __slots__ = ("arena", "fo", "io", "pick_samples", "capacity", "settle_samples")

    def __init__(
        self, level_median_s: float, fs_hz: float, arena: Arena, settle_samples: int = 0
    ) -> None:
        """``settle_samples``: the first pick comes on the settle_samples-th tick after a
        restart (the next one for 0): with the sliding window's length, no pick mixes data
        from before the restart."""
        self.arena = arena
        self.pick_samples = max(1, int(round(fs_hz / PICKS_PER_S)))
        self.capacity = max(1, int(round(level_median_s * PICKS_PER_S)))
        self.settle_samples = max(0, int(settle_samples))
        self.fo, self.io = arena.alloc(2 * self.capacity + 4, LEVEL_INTS)
        ii = arena.i
        ii[self.io + L_PICK] = self.pick_samples
        ii[self.io + L_CAPACITY] = self.capacity
        ii[self.io + L_FLOATS] = self.fo
        ii[self.io + L_SETTLE] = max(0, self.settle_samples - 1)
        self.reset()

    @property
    def out(self) -> int:
        """Offset of (level, spread) as reported in the float array."""
        return self.fo + 2 * self.capacity

    def reset(self) -> None:
        """No pick yet: the level is NaN."""
        level_restart(self.arena.f, self.arena.i, self.io)
        self.arena.f[self.out : self.out + 2] = math.nan

    @property
    def level(self) -> float:
        """Median window level of the last valid picks (units of the calibrated fault) while
        the window is valid; NaN elsewhere and before the first pick."""
        return float(self.arena.f[self.out])

    @property
    def spread(self) -> float:
        """25–75 % range of the same picks (the level's uncertainty); NaN with the level."""
        return float(self.arena.f[self.out + 1])
