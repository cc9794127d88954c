"""Detector settings: the model file's ``detector`` mapping, validated, with defaults.

Every setting has a unit in its name; docs/detector.md explains each one and the
false-alarm/detection trade-off it moves.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any

from fdi_daemon.core.velocity_observer import velocity_setting_names
from fdi_daemon.errors import ConfigError
from fdi_daemon.io.known_keys import known_settings

__all__ = ["DetectorSettings", "METHODS", "velocity_settings"]

METHODS = ("sequential", "band")


def velocity_settings(mapping: Mapping[str, Any] | None) -> dict[str, Any]:
    """The model's ``velocity`` mapping, reduced to the settings of the estimator."""
    return known_settings(mapping, velocity_setting_names(), "model velocity")


@dataclass(frozen=True)
class DetectorSettings:
    """What the detector does; times in seconds, converted to samples with ``fs``."""

    method: str = "sequential"
    """"sequential" (χ² test of the innovations, the default) or "band" (the paper's)."""
    window_s: float = 1.0
    """Sliding window of the least squares, both θ (eq. 17) and the reference fit."""
    calibration_s: float = 1.0
    """Fault-free period after the windows fill whose θ sets the band (mean ± band_k σ)."""
    band_k: float = 3.0
    """Band half-width in standard deviations (the paper uses 3)."""
    min_velocity_rms_mps: float = 0.0015
    """Below this velocity RMS over the window the rig is at rest: θ is not estimated
    (NaN) and the band method holds."""
    reference_lag_s: float = 0.0625
    """The reference fit ends this long before the newest sample (a fault must not leak in)."""
    reference_every_samples: int = 8
    """The reference fit is re-solved every this many ticks."""
    test_window_s: float = 0.0625
    """Window of the χ² statistic (mean squared standardised innovation)."""
    threshold: float = 30.0
    """Alarm when the statistic exceeds this (it is ≈ 1 without a fault)."""
    persistence_samples: int = 2
    """Consecutive ticks above the threshold before an alarm."""
    min_sigma_mps2: float = 0.01
    """Floor of the reference residual standard deviation (m/s²)."""
    guard_threshold: float = 20.0
    """The operating-point guard: the same test on the valve command (an AR(4) model of
    v_in over the reference window) above this value marks an operating-point change ..."""
    guard_min_sigma_v: float = 0.005
    """... with the command's innovation σ floored at this (V; about the ADC noise)."""
    guard_hold_s: float | None = None
    """Alarms are held this long after an operating-point change (default: window + lag +
    test window, the time the reference needs to describe the new operating point)."""
    isolation_window_s: float = 0.25
    """Data after the detection that the isolation fit needs before it decides."""
    isolation_timeout_s: float = 2.0
    """No friction evidence this long after the detection (an episode the growing-fault
    path raised: after the residual test's alarm): other_fault once a linear change of the
    residual fit describes the fault or the accelerometer clipped; until then
    fault_detected (docs/detector.md §3, "Isolation")."""
    friction_min_level: float = 0.3
    """Increase of the Coulomb coefficient (units of the calibrated signature) that counts
    as friction."""
    slow_persistence_s: float = 2.0
    """Level path: the Coulomb coefficient θ1 above its fault-free value (the commissioning
    baseline, else the calibration's median) by more than its margin for this long is a fault
    (friction that creeps in, starts while the guard holds, or is there from the start)."""
    drift_shift_level: float = 0.3
    """Growing-fault path (CUSUM): the shift of the innovations along the signature's
    regressor g1 + γ_f g2 that the test is matched to, in calibrated faults; 0 turns the path
    off."""
    drift_false_alarm_years: float = 10.0
    """... its threshold h = ln(ARL₀), ARL₀ this long in ticks: the mean time between false
    alarms of a CUSUM on white Gaussian innovations is at least e^h ticks (Lorden)."""
    drift_correlation_samples: int = 8
    """... and the innovations counted as independent once per this many ticks (their
    correlation time along the signature): h = this × ln(ARL₀ in ticks)."""
    track_tolerance: float = 0.15
    """band method: |θ - (1, γ_f)| within this fraction of the signature counts as tracking."""
    track_samples: int = 8
    """Consecutive ticks of friction evidence (sequential: the Coulomb increase above
    friction_min_level; band: θ tracking the signature) before friction is isolated."""
    clear_s: float = 1.0
    """A fault other than friction: back to normal (the innovations against the frozen
    reference) for this long, while the rig moves, before ``cleared``."""
    friction_clear_s: float = 10.0
    """Friction: the level back within half its margin of its fault-free value, the load
    moving freely, for this long while the rig moves, before ``cleared``. Friction goes away
    by maintenance, not within a second; a stretch of operation at which θ under-reads it
    (docs/detector.md §4a) must not end the episode."""
    level_median_s: float = 10.0
    """The reported friction level is the median of the window's level (the residual's
    multiple of the calibrated regressor g1 + γ_f g2) over this much of the windows where it
    measures friction (velocity trusted), picked four times a second since the last episode
    began or ended; NaN where it does not (`detect.friction_level`)."""
    velocity_trust_phase_deg: float = 30.0
    """The velocity estimate is trusted above the frequency where its phase error against the
    true velocity falls below this (degrees; from its transfer function: 3.9 Hz for the 1 Hz
    high-pass, none for the observers) ..."""
    velocity_trust_share: float = 0.3
    """... and a window counts as evidence that friction is gone only when at most this
    share of its velocity energy lies below that frequency: elsewhere sign v̂ is wrong for
    much of each cycle and θ1 under-reads friction, so the clearing count holds."""
    signature_band_fraction: float = 0.5
    """... or below this fraction of the lowest frequency the signature was calibrated at
    (the model's ``fault_filter.band_hz``; 0.5: an octave below it), whichever is higher:
    G_e describes the friction of its calibration's frequencies, not of slower motion (one
    fitted at 6-11.4 Hz reads the calibrated fault at -0.2 under a 2.9 Hz sine)."""

    @classmethod
    def from_mapping(
        cls, mapping: Mapping[str, Any] | None, source: str = "detector"
    ) -> DetectorSettings:
        """Validate a ``detector`` mapping; bad values and typos of known keys raise
        ConfigError, other unknown keys are ignored (`known_settings`)."""
        known = {f.name: f for f in fields(cls)}
        mapping = known_settings(mapping, known, source)
        values: dict[str, Any] = {}
        for name, value in mapping.items():
            default = known[name].default
            if name == "method":
                if value not in METHODS:
                    raise ConfigError(f"{source}.method must be one of {', '.join(METHODS)}")
            elif name == "guard_hold_s" and value is None:
                pass
            elif isinstance(default, int) and not isinstance(default, bool):
                if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                    raise ConfigError(f"{source}.{name} must be a whole number >= 1")
            else:
                if (
                    isinstance(value, bool)
                    or not isinstance(value, (int, float))
                    or not math.isfinite(value)
                    or value < 0
                ):
                    raise ConfigError(f"{source}.{name} must be a finite number >= 0")
                value = float(value)
            values[name] = value
        settings = cls(**values)
        for name in (
            "window_s",
            "test_window_s",
            "threshold",
            "isolation_window_s",
            "clear_s",
            "friction_clear_s",
            "band_k",
            "guard_threshold",
            "level_median_s",
            "drift_false_alarm_years",
        ):
            if getattr(settings, name) <= 0:
                raise ConfigError(f"{source}.{name} must be > 0")
        return settings

    def samples(self, seconds: float, fs_hz: float, minimum: int = 1) -> int:
        """A duration in ticks (rounded, at least ``minimum``)."""
        return max(minimum, int(round(seconds * fs_hz)))
