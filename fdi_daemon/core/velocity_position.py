"""Velocity from position and acceleration: a second-order complementary filter.

When the rig measures the load's position (LVDT, encoder), its derivative is the velocity
at low frequency, without any model, and the accelerometer's integral is the velocity at
high frequency. With ω_c = 2π·``crossover_hz`` and ζ = ``damping``:

    v̂(s) = [s·(2ζω_c s + ω_c²)·x(s) + s·ẍ(s)] / (s² + 2ζω_c s + ω_c²)

The two weights, (2ζω_c s + ω_c²)/D and s²/D, add up to one, so v̂ = s·x whenever ẍ = s²x:
the filter has no phase or gain error of its own. Below ω_c the position dominates (a load
held by friction reads exactly zero velocity), above it the accelerometer (the position's
derivative noise passes with gain at most 2ζω_c: 2 µm of LVDT noise give 0.27 mm/s at
15 Hz). The default crossover, 15 Hz, lets the position carry the motion through the
operating band (1–10 Hz): on the simulated rig a 5 Hz crossover left the 8 Hz motion to the
accelerometer and a supply-cut fault was not isolated (docs/detector.md §4a). Both paths
are discretised by the bilinear transform, which maps a sum to a sum, so
the discrete weights still add up to one. A non-finite position (a link that dropped it)
holds the last good one.

Settings (the model file's ``velocity`` mapping)::

    {method: position_observer, crossover_hz: 15.0, damping: 0.7071}
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
import numpy.typing as npt

from fdi_daemon.core.iir import IIRFilter, frequency_response

__all__ = ["PositionVelocityObserver", "POSITION_DEFAULTS"]

POSITION_DEFAULTS: dict[str, Any] = {"crossover_hz": 15.0, "damping": 0.7071}


class PositionVelocityObserver:
    """v̂ from position and acceleration with ``step(accel, position)`` / ``run(...)``."""

    __slots__ = (
        "fs_hz",
        "crossover_hz",
        "damping",
        "position_path",
        "accel_path",
        "_last_position",
    )

    needs_model = False
    needs_position = True

    def __init__(self, fs_hz: float, crossover_hz: float = 15.0, damping: float = 0.7071):
        fs_hz = float(fs_hz)
        crossover_hz = float(crossover_hz)
        damping = float(damping)
        if not (math.isfinite(fs_hz) and fs_hz > 0):
            raise ValueError(f"fs_hz must be a positive number, got {fs_hz!r}")
        if not (math.isfinite(crossover_hz) and 0 < crossover_hz < fs_hz / 4):
            raise ValueError(
                f"crossover_hz must lie in (0, fs/4) = (0, {fs_hz / 4:g}), got {crossover_hz!r}"
            )
        if not (math.isfinite(damping) and 0.3 <= damping <= 2.0):
            raise ValueError(f"damping must lie in [0.3, 2], got {damping!r}")
        self.fs_hz, self.crossover_hz, self.damping = fs_hz, crossover_hz, damping
        # here, used by position-fusing models only: scipy.signal's import is slow
        from scipy.signal import bilinear

        w = 2 * math.pi * crossover_hz
        den = [1.0, 2 * damping * w, w * w]
        self.position_path = IIRFilter(*bilinear([2 * damping * w, w * w, 0.0], den, fs_hz))
        self.accel_path = IIRFilter(*bilinear([1.0, 0.0], den, fs_hz))
        self._last_position = math.nan

    @classmethod
    def from_settings(cls, settings: Mapping[str, Any], fs_hz: float) -> PositionVelocityObserver:
        merged = {
            **POSITION_DEFAULTS,
            **{k: v for k, v in settings.items() if k not in ("method", "fs_hz")},
        }
        unknown = set(merged) - set(POSITION_DEFAULTS)
        if unknown:
            raise ValueError(
                f"unknown velocity setting(s) for position_observer: {', '.join(sorted(unknown))}"
            )
        return cls(fs_hz, **merged)

    def settings(self) -> dict[str, Any]:
        return {
            "method": "position_observer",
            "fs_hz": self.fs_hz,
            "crossover_hz": self.crossover_hz,
            "damping": self.damping,
        }

    def step(self, accel: float, position: float) -> float:
        if math.isfinite(position):
            self._last_position = position
        elif math.isfinite(self._last_position):
            position = self._last_position
        else:
            position = 0.0
        return self.position_path.step(position) + self.accel_path.step(accel)

    def run(self, accel: np.ndarray, position: np.ndarray) -> np.ndarray:
        accel = np.asarray(accel, dtype=float)
        position = np.asarray(position, dtype=float)
        good = np.isfinite(position)
        if not good.all():  # hold the last good position (0 before the first one)
            last = np.maximum.accumulate(np.where(good, np.arange(position.size), -1))
            start = self._last_position if math.isfinite(self._last_position) else 0.0
            position = np.where(last >= 0, position[np.maximum(last, 0)], start)
        if good.any():
            self._last_position = float(position[np.flatnonzero(good)[-1]])
        out: np.ndarray = self.position_path.run(position) + self.accel_path.run(accel)
        return out

    @property
    def state(self) -> tuple[np.ndarray, np.ndarray, float]:
        return self.position_path.state, self.accel_path.state, self._last_position

    @state.setter
    def state(self, value: tuple[np.ndarray, np.ndarray, float]) -> None:
        self.position_path.state, self.accel_path.state, self._last_position = value

    def reset(self) -> None:
        self.position_path.reset()
        self.accel_path.reset()
        self._last_position = math.nan

    def response(self, f_hz: npt.ArrayLike) -> Any:
        """v̂/(jω x) at ``f_hz`` (Hz; a number or an array) for a consistent pair
        ẍ = (jω)² x: 1 up to the bilinear transform's warping (the weights add up to one
        exactly for its own derivative)."""
        hx = frequency_response(self.position_path.b, self.position_path.a, f_hz, self.fs_hz)
        ha = frequency_response(self.accel_path.b, self.accel_path.a, f_hz, self.fs_hz)
        jw = 2j * np.pi * np.asarray(f_hz)
        return (hx + ha * jw * jw) / jw
