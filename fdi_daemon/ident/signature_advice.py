"""What to change in *this* calibration run when γ_f's profile is flat or its interval wide.

Measured on the run itself: whether a fault-free reference pass was given, the velocity's
amplitude range over the window (RMS per 0.5 s block, 10th to 90th percentile), the
velocity's strongest frequency against the plant's resonance, and the window's length.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: velocity-amplitude ranges below this ratio hardly separate Coulomb from viscous friction
MIN_AMPLITUDE_RATIO = 1.6
#: a carrier within this fraction of the plant's resonance sees G_e change with amplitude
NEAR_RESONANCE = 0.25
#: block over which the velocity's RMS is taken (s)
BLOCK_S = 0.5


@dataclass(frozen=True)
class CalibrationContext:
    """What `fdi signature` knows about the run beyond the fitted window."""

    fs_hz: float = 256.0
    referenced: bool = False  # a fault-free pass of the same excitation was subtracted
    resonance_hz: float | None = None  # the plant's least-damped resonance


def plant_resonance_hz(plant_a: np.ndarray, fs_hz: float) -> float | None:
    """Frequency (Hz) of Ĝ's least-damped complex pole pair, None without one."""
    poles = np.roots(np.asarray(plant_a, dtype=float))
    complex_poles = poles[np.abs(poles.imag) > 1e-9]
    if complex_poles.size == 0:
        return None
    pole = complex_poles[np.argmax(np.abs(complex_poles))]
    return float(abs(np.angle(pole)) * fs_hz / (2.0 * np.pi))


def amplitude_range(velocity: np.ndarray, fs_hz: float) -> tuple[float, float]:
    """10th and 90th percentile (m/s) of the velocity's RMS over BLOCK_S blocks."""
    size = max(1, int(round(BLOCK_S * fs_hz)))
    count = len(velocity) // size
    if count < 2:
        rms = float(np.sqrt(np.mean(np.square(velocity))))
        return rms, rms
    blocks = np.asarray(velocity[: count * size], dtype=float).reshape(count, size)
    low, high = np.percentile(np.sqrt(np.mean(blocks**2, axis=1)), [10.0, 90.0])
    return float(low), float(high)


def dominant_frequency_hz(velocity: np.ndarray, fs_hz: float) -> float:
    """The frequency (Hz) of the velocity's largest periodogram line."""
    v = np.asarray(velocity, dtype=float) - np.mean(velocity)
    spectrum = np.abs(np.fft.rfft(v * np.hanning(len(v))))
    return float(np.fft.rfftfreq(len(v), 1.0 / fs_hz)[1 + int(np.argmax(spectrum[1:]))])


def advise(
    flat: bool,
    interval: tuple[float, float],
    span: float,
    velocity: np.ndarray,
    context: CalibrationContext,
) -> str:
    """The recommendation: why γ_f is not (well) identified, then what to change in this run."""
    if flat:
        head = (
            "gamma_f is not identifiable from this window: the cost profile is flat, so "
            "G_e absorbs the viscous part"
        )
    else:
        head = (
            f"gamma_f is poorly identified: its 99 % interval {interval[0]:.3g}..{interval[1]:.3g}"
            f" covers {100 * (interval[1] - interval[0]) / span:.0f} % of the gamma grid"
        )
    changes = []
    if not context.referenced:
        changes.append(
            "play its excitation once fault-free before the fault and pass "
            "--reference-window (the plant model's error, which at one amplitude looks like "
            "viscous friction, then cancels)"
        )
    low, high = amplitude_range(velocity, context.fs_hz)
    ratio = high / low if low > 0 else float("inf")
    if ratio < MIN_AMPLITUDE_RATIO:
        changes.append(
            f"step its amplitude: the velocity's RMS spans only {low * 1e3:.3g}-"
            f"{high * 1e3:.3g} mm/s ({ratio:.2g}:1) over the window; a 2.5:1 range "
            "(e.g. 1.0 to 2.5 V) lets the viscous part grow apart from the Coulomb part"
        )
    else:
        changes.append(
            f"widen its amplitude range beyond {low * 1e3:.3g}-{high * 1e3:.3g} mm/s "
            f"({ratio:.2g}:1), as far as the rig allows without sticking or saturating"
        )
    carrier = dominant_frequency_hz(velocity, context.fs_hz)
    res = context.resonance_hz
    if res is not None and abs(carrier - res) < NEAR_RESONANCE * res:
        changes.append(
            f"move its carrier from {carrier:.3g} Hz to below the plant's resonance at "
            f"{res:.3g} Hz (G_e changes with amplitude near it)"
        )
    seconds = len(velocity) / context.fs_hz
    changes.append(
        f"lengthen its fault window beyond {seconds:.3g} s (the interval narrows about as "
        "1/sqrt(length))"
    )
    return f"{head}. In this run: " + "; ".join(changes) + " (docs/identification.md)."
