"""Valve-voltage excitation signals and slow operating-condition profiles.

A program is a list of segments played one after another; each segment is a dict with a
``kind`` and the keys listed in `SEGMENT_KEYS` (time restarts at 0 in every segment). A segment
without ``duration_s`` must be the last one and lasts to the end; after the last segment the
valve voltage is 0 V. Every segment accepts ``offset_v`` (V, added).

Kinds:
- ``sine``: amplitude_v, frequency_hz [, phase_deg]
- ``chirp``: amplitude_v, f0_hz, f1_hz, period_s [, alternate_sign]: a linear sweep from f0 to
  f1 over period_s, repeated; with alternate_sign every second sweep is negated, so the
  repeated sweeps do not add up to a net displacement.
- ``multisine``: amplitudes_v, frequencies_hz [, phases_deg] (default: Schroeder phases)
- ``steps``: levels_v, hold_s: a staircase cycling through the levels
- ``zero``: 0 V
- ``random``: amplitude_v: [lo, hi], frequency_hz: [lo, hi], segment_s: [lo, hi]
  [, kinds: [sine, multisine, chirp]]: changing operation, a sequence of randomly drawn
  sub-segments from the scenario's seeded generator.
"""

from __future__ import annotations

import math

import numpy as np

#: kind -> (required keys, optional keys); every kind also takes duration_s and offset_v
SEGMENT_KEYS: dict[str, tuple[frozenset, frozenset]] = {
    "sine": (frozenset({"amplitude_v", "frequency_hz"}), frozenset({"phase_deg"})),
    "chirp": (
        frozenset({"amplitude_v", "f0_hz", "f1_hz", "period_s"}),
        frozenset({"alternate_sign"}),
    ),
    "multisine": (frozenset({"amplitudes_v", "frequencies_hz"}), frozenset({"phases_deg"})),
    "steps": (frozenset({"levels_v", "hold_s"}), frozenset()),
    "zero": (frozenset(), frozenset()),
    "random": (frozenset({"amplitude_v", "frequency_hz", "segment_s"}), frozenset({"kinds"})),
}
COMMON_KEYS = frozenset({"kind", "duration_s", "offset_v"})
RANDOM_KINDS = ("sine", "multisine", "chirp")


def sine(t_s: np.ndarray, amplitude_v: float, frequency_hz: float, phase_deg: float = 0.0):
    """A·sin(2πft + φ)."""
    return amplitude_v * np.sin(2.0 * np.pi * frequency_hz * t_s + math.radians(phase_deg))


def chirp(
    t_s: np.ndarray,
    amplitude_v: float,
    f0_hz: float,
    f1_hz: float,
    period_s: float,
    alternate_sign: bool = False,
) -> np.ndarray:
    """Linear sweep f0 -> f1 over period_s, repeated (as the paper's §III.B chirp)."""
    cycle = np.floor(t_s / period_s)
    tau = t_s - cycle * period_s
    rate = (f1_hz - f0_hz) / period_s
    u = amplitude_v * np.sin(2.0 * np.pi * (f0_hz * tau + 0.5 * rate * tau**2))
    if alternate_sign:
        u = np.where(cycle % 2 == 1, -u, u)
    return u


def schroeder_phases_deg(count: int) -> list[float]:
    """Schroeder phases for equal-amplitude components: a low crest factor."""
    return [math.degrees(-math.pi * k * (k - 1) / count) for k in range(1, count + 1)]


def multisine(t_s: np.ndarray, amplitudes_v, frequencies_hz, phases_deg=None) -> np.ndarray:
    """Σ A_k·sin(2πf_k t + φ_k)."""
    if phases_deg is None:
        phases_deg = schroeder_phases_deg(len(frequencies_hz))
    u = np.zeros_like(t_s, dtype=np.float64)
    for a, f, ph in zip(amplitudes_v, frequencies_hz, phases_deg):
        u += sine(t_s, a, f, ph)
    return u


def steps(t_s: np.ndarray, levels_v, hold_s: float) -> np.ndarray:
    """Staircase cycling through ``levels_v``, each held for hold_s."""
    levels = np.asarray(levels_v, dtype=np.float64)
    return levels[(np.floor(t_s / hold_s).astype(np.int64)) % len(levels)]


def random_operation(
    t_s: np.ndarray,
    rng: np.random.Generator,
    amplitude_v,
    frequency_hz,
    segment_s,
    kinds=RANDOM_KINDS,
) -> np.ndarray:
    """Changing operation: random sub-segments (kind, amplitude, frequency, length) drawn
    from ``rng``; multisines get 2-4 components whose amplitudes add up to the drawn peak."""
    u = np.zeros_like(t_s, dtype=np.float64)
    n = len(t_s)
    start = 0
    fs = 1.0 / (t_s[1] - t_s[0]) if n > 1 else 1.0
    while start < n:
        length = max(1, int(round(rng.uniform(*segment_s) * fs)))
        stop = min(n, start + length)
        tau = t_s[start:stop] - t_s[start]
        kind = kinds[int(rng.integers(len(kinds)))]
        amp = rng.uniform(*amplitude_v)
        if kind == "sine":
            u[start:stop] = sine(tau, amp, rng.uniform(*frequency_hz))
        elif kind == "chirp":
            f0, f1 = np.sort(rng.uniform(*frequency_hz, size=2))
            u[start:stop] = chirp(tau, amp, f0, f1, max(tau[-1], 1.0 / fs) + 1.0 / fs)
        else:
            count = int(rng.integers(2, 5))
            weights = rng.uniform(0.3, 1.0, size=count)
            u[start:stop] = multisine(
                tau,
                amp * weights / weights.sum(),
                rng.uniform(*frequency_hz, size=count),
                rng.uniform(0.0, 360.0, size=count),
            )
        start = stop
    return u


def segment_signal(segment: dict, t_s: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """The voltage of one validated segment over its local time t_s (from 0)."""
    kind = segment["kind"]
    if kind == "sine":
        u = sine(
            t_s, segment["amplitude_v"], segment["frequency_hz"], segment.get("phase_deg", 0.0)
        )
    elif kind == "chirp":
        u = chirp(
            t_s,
            segment["amplitude_v"],
            segment["f0_hz"],
            segment["f1_hz"],
            segment["period_s"],
            bool(segment.get("alternate_sign", False)),
        )
    elif kind == "multisine":
        u = multisine(
            t_s, segment["amplitudes_v"], segment["frequencies_hz"], segment.get("phases_deg")
        )
    elif kind == "steps":
        u = steps(t_s, segment["levels_v"], segment["hold_s"])
    elif kind == "zero":
        u = np.zeros_like(t_s)
    elif kind == "random":
        u = random_operation(
            t_s,
            rng,
            segment["amplitude_v"],
            segment["frequency_hz"],
            segment["segment_s"],
            tuple(segment.get("kinds", RANDOM_KINDS)),
        )
    else:
        raise ValueError(f"unknown excitation kind {kind!r}")
    return u + segment.get("offset_v", 0.0)


def build_program(
    segments: list[dict], fs_hz: float, n_samples: int, rng: np.random.Generator
) -> np.ndarray:
    """The excitation (V) of ``n_samples`` samples at ``fs_hz`` from validated segments."""
    u = np.zeros(n_samples)
    start = 0
    for segment in segments:
        if start >= n_samples:
            break
        if "duration_s" in segment:
            stop = min(n_samples, start + int(round(segment["duration_s"] * fs_hz)))
        else:
            stop = n_samples
        t_local = np.arange(stop - start) / fs_hz
        u[start:stop] = segment_signal(segment, t_local, rng)
        start = stop
    return u


def piecewise_linear(t_s: float | np.ndarray, times_s, values):
    """Profile value at t_s: linear between the points, held before the first/after the last."""
    return np.interp(t_s, times_s, values)
