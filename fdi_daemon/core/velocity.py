"""Velocity from measured acceleration (§IV-A.1): high-pass Butterworth, then an integrator.

The paper removes the DC content of ẍ with a 3rd-order high-pass Butterworth filter and
integrates the result with a discrete-time integrator. Here both are one IIR filter:

    HP_n(q) = k (1 - q⁻¹)ⁿ / A_hp(q)         (bilinear Butterworth: n zeros exactly at z = 1)
    I(q)    = T/2 (1 + q⁻¹)/(1 - q⁻¹)         trapezoid (bilinear; the default)
            = T / (1 - q⁻¹)                   backward Euler
            = T q⁻¹ / (1 - q⁻¹)               forward Euler

One zero of the high-pass cancels the integrator's pole at z = 1 exactly (by construction,
not numerically), so the estimator ``V(q) = k (1 - q⁻¹)ⁿ⁻¹ N_I(q) / A_hp(q)`` is a stable
n-th order filter whose state never drifts, whatever the accelerometer offset.
The trapezoid integrator has exactly -90° phase at every frequency below Nyquist, the Euler
ones do not (forward Euler lags by another ωT/2), which is why it is the default.

Phase lead. The high-pass leads an ideal integrator: a 1 Hz 3rd-order Butterworth at
256 Hz leads by 14.3° at 8 Hz (``phase_lead_deg``), i.e. the estimated velocity crosses
zero about 5 ms early and sign(v̂) switches early. The signature is identified with the
same estimator, so G_e absorbs most of it; where that is not wanted,
``lead_compensation_hz: f0`` appends a first-order all-pass (c + q⁻¹)/(1 + c q⁻¹) whose
phase lag equals the lead at f0 (exact at f0, unit gain everywhere, slightly over- or
under-compensating elsewhere). Lowering ``highpass_hz`` reduces the lead too (≈ 1/f).

Settings (the model file's ``velocity`` mapping)::

    {highpass_hz: 1.0, highpass_order: 3, integrator: trapezoid, lead_compensation_hz: null}
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
import numpy.typing as npt

from fdi_daemon.core.filter_design import butter
from fdi_daemon.core.iir import Coeffs, IIRFilter, frequency_response

__all__ = ["VelocityEstimator", "DEFAULT_SETTINGS", "INTEGRATORS"]

INTEGRATORS = ("trapezoid", "backward_euler", "forward_euler")

DEFAULT_SETTINGS: dict[str, Any] = {
    "highpass_hz": 1.0,
    "highpass_order": 3,
    "integrator": "trapezoid",
    "lead_compensation_hz": None,
}


class VelocityEstimator:
    """v̂ = I(q) HP(q) ẍ as one frozen IIR block with ``step``/``run``/``reset``/``state``."""

    __slots__ = (
        "fs_hz",
        "highpass_hz",
        "highpass_order",
        "integrator",
        "lead_compensation_hz",
        "_filter",
        "step",
        "run",
    )

    needs_model = False  # step/run take ẍ only (core.velocity_observer's take x̂̈ too)
    needs_position = False

    def __init__(
        self,
        fs_hz: float,
        highpass_hz: float = 1.0,
        highpass_order: int = 3,
        integrator: str = "trapezoid",
        lead_compensation_hz: float | None = None,
    ):
        fs_hz = float(fs_hz)
        if not (math.isfinite(fs_hz) and fs_hz > 0):
            raise ValueError(f"fs_hz must be a positive number, got {fs_hz!r}")
        if (
            isinstance(highpass_order, bool)
            or not isinstance(highpass_order, (int, np.integer))
            or not 1 <= int(highpass_order) <= 8
        ):
            raise ValueError(f"highpass_order must be a whole number 1..8, got {highpass_order!r}")
        highpass_hz = float(highpass_hz)
        if not (math.isfinite(highpass_hz) and 0 < highpass_hz < fs_hz / 2):
            raise ValueError(
                f"highpass_hz must lie in (0, fs/2) = (0, {fs_hz / 2:g}), got {highpass_hz!r}"
            )
        if integrator not in INTEGRATORS:
            raise ValueError(
                f"integrator must be one of {', '.join(INTEGRATORS)}, got {integrator!r}"
            )
        self.fs_hz = fs_hz
        self.highpass_hz = highpass_hz
        self.highpass_order = int(highpass_order)
        self.integrator = integrator
        self.lead_compensation_hz = None
        b, a = _design(fs_hz, highpass_hz, self.highpass_order, integrator)
        if lead_compensation_hz is not None:
            f0 = float(lead_compensation_hz)
            if not (math.isfinite(f0) and 0 < f0 < fs_hz / 2):
                raise ValueError(f"lead_compensation_hz must lie in (0, fs/2), got {f0!r}")
            lead_rad = math.radians(_phase_lead_deg(b, a, fs_hz, f0))
            if not 0 < lead_rad < math.pi:
                raise ValueError(
                    f"cannot compensate a lead of {math.degrees(lead_rad):.1f}° "
                    f"at {f0:g} Hz with a first-order all-pass"
                )
            k = math.tan(lead_rad / 2) / math.tan(math.pi * f0 / fs_hz)
            c = (1 - k) / (1 + k)
            b = np.convolve(b, [c, 1.0])
            a = np.convolve(a, [1.0, c])
            self.lead_compensation_hz = f0
        self._filter = IIRFilter(b, a)
        # bound methods of the inner filter: no extra call layer in the 256 Hz loop
        self.step = self._filter.step
        self.run = self._filter.run

    @classmethod
    def from_settings(
        cls, settings: Mapping[str, Any] | None, fs_hz: float | None = None
    ) -> VelocityEstimator:
        """Build from a model file's ``velocity`` mapping (missing keys take the defaults).

        ``fs_hz`` comes from the argument or from the mapping's ``fs_hz`` key; when both
        are given they must agree.
        """
        settings = dict(settings or {})
        unknown = set(settings) - set(DEFAULT_SETTINGS) - {"fs_hz"}
        if unknown:
            raise ValueError(f"unknown velocity setting(s): {', '.join(sorted(unknown))}")
        fs_in_map = settings.pop("fs_hz", None)
        if fs_hz is None and fs_in_map is None:
            raise ValueError("the velocity estimator needs fs_hz")
        if fs_hz is not None and fs_in_map is not None and float(fs_in_map) != float(fs_hz):
            raise ValueError(f"velocity.fs_hz = {fs_in_map} disagrees with fs = {fs_hz}")
        merged = {**DEFAULT_SETTINGS, **settings}
        return cls(fs_hz if fs_hz is not None else float(fs_in_map), **merged)

    def settings(self) -> dict[str, Any]:
        """The mapping stored in the model file's ``velocity`` key (round-trips)."""
        return {
            "fs_hz": self.fs_hz,
            "highpass_hz": self.highpass_hz,
            "highpass_order": self.highpass_order,
            "integrator": self.integrator,
            "lead_compensation_hz": self.lead_compensation_hz,
        }

    @property
    def b(self) -> np.ndarray:
        return self._filter.b

    @property
    def a(self) -> np.ndarray:
        return self._filter.a

    @property
    def state(self) -> np.ndarray:
        return self._filter.state

    @state.setter
    def state(self, value: Coeffs) -> None:
        self._filter.state = value

    def reset(self) -> None:
        self._filter.reset()

    def response(self, f_hz: npt.ArrayLike) -> Any:
        """V(e^jω)·jω at ``f_hz`` (Hz; a number or an array): v̂ over the true velocity, 1 for
        an exact integral."""
        return frequency_response(self.b, self.a, f_hz, self.fs_hz) * (
            2j * np.pi * np.asarray(f_hz)
        )

    def phase_lead_deg(self, f_hz: float) -> float:
        """Phase of the estimator minus that of an ideal integrator (-90°) at ``f_hz``."""
        return float(np.degrees(np.angle(self.response(f_hz))))

    def gain_error(self, f_hz: float) -> float:
        """|V(e^jω)| · 2πf: 1 where the estimator integrates exactly."""
        return float(abs(self.response(f_hz)))


def _design(
    fs_hz: float, highpass_hz: float, order: int, integrator: str
) -> tuple[np.ndarray, np.ndarray]:
    b_hp, a_hp = butter(order, highpass_hz, fs_hz, "high")
    gain = b_hp[0]  # b_hp = gain · (1 - q⁻¹)^order for the bilinear Butterworth
    zeros = np.array([1.0])
    for _ in range(order - 1):
        zeros = np.convolve(zeros, [1.0, -1.0])
    T = 1.0 / fs_hz
    if integrator == "trapezoid":
        num_i = [T / 2, T / 2]
    elif integrator == "backward_euler":
        num_i = [T]
    else:
        num_i = [0.0, T]
    return gain * np.convolve(zeros, num_i), np.asarray(a_hp, dtype=float)


def _phase_lead_deg(b: npt.ArrayLike, a: npt.ArrayLike, fs_hz: float, f_hz: float) -> float:
    """Phase of B/A minus that of an ideal integrator 1/(jω), in degrees."""
    return float(np.degrees(np.angle(frequency_response(b, a, float(f_hz), fs_hz) * 1j)))
