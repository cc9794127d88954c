"""Model-based velocity: a complementary observer of the plant model and the accelerometer.

The accelerometer-only estimate v̂ = I(q)·HP(q)·ẍ (`core.velocity`) must high-pass ẍ before
integrating, and the high-pass leads: 60° at 2 Hz for a 1 Hz 3rd-order Butterworth, so on a
rig driven at low frequency sign(v̂) switches at the wrong instants. The plant model
x̂̈ = Ĝ(q) v_in (eq. 1) knows the motion at low frequency, the accelerometer at high
frequency; the observer takes each where it is right:

    v̂ = L(q)·x̂̈ + V(q)·r,     r = ẍ − x̂̈ (eq. 3)

    L(q) = I(q)·HP₁(q; f_leak)   a leaky trapezoid integrator of the model's acceleration
                                 (0.01–0.05 Hz: a bounded response to an offset of v_in or Ĝ)
    V(q) = I(q)·HPₙ(q; f_hp)     the estimator of `core.velocity` applied to the residual
                                 only (0.5–1 Hz): the part of the motion the model misses

Where the model is exact (r = 0) the lead of V does not matter and v̂ = L·ẍ, whose lead is
atan(f_leak/f) (0.6° at 2 Hz for 0.02 Hz). Above f_hp, L ≈ V ≈ I and v̂ ≈ I·ẍ, the
accelerometer's integral. Below f_hp only the model speaks. A first-order high-pass followed
by the trapezoid integrator *is* the leaky trapezoid integrator (one zero cancels the
integrator's pole exactly), so both paths are `VelocityEstimator`s.

Settings (the model file's ``velocity`` mapping with ``method: model_observer``)::

    {method: model_observer, leak_hz: 0.02, highpass_hz: 0.5, highpass_order: 2,
     integrator: trapezoid, lead_compensation_hz: null}

``highpass_*``, ``integrator`` and ``lead_compensation_hz`` are those of the residual path.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
import numpy.typing as npt

from fdi_daemon.core.velocity import DEFAULT_SETTINGS as HIGHPASS_SETTINGS
from fdi_daemon.core.velocity import VelocityEstimator
from fdi_daemon.core.velocity_position import POSITION_DEFAULTS, PositionVelocityObserver

__all__ = [
    "ModelVelocityObserver",
    "OBSERVER_DEFAULTS",
    "METHODS",
    "VelocityBlock",
    "velocity_from_settings",
    "velocity_setting_names",
    "trusted_from_hz",
]

#: ``velocity.method`` values; a mapping without ``method`` is ``highpass`` (today's models)
METHODS = ("highpass", "model_observer", "position_observer")

OBSERVER_DEFAULTS: dict[str, Any] = {
    "leak_hz": 0.02,
    "highpass_hz": 0.5,
    "highpass_order": 2,
    "integrator": "trapezoid",
    "lead_compensation_hz": None,
}


class ModelVelocityObserver:
    """v̂ = L(q)·x̂̈ + V(q)·(ẍ − x̂̈) with ``step(accel, xhat)`` / ``run(accel, xhat)``."""

    __slots__ = ("fs_hz", "leak_hz", "model_path", "residual_path")

    needs_model = True  # step/run take the plant model's x̂̈ as well
    needs_position = False

    def __init__(
        self,
        fs_hz: float,
        leak_hz: float = 0.02,
        highpass_hz: float = 0.5,
        highpass_order: int = 2,
        integrator: str = "trapezoid",
        lead_compensation_hz: float | None = None,
    ):
        leak_hz = float(leak_hz)
        if not (math.isfinite(leak_hz) and 0 < leak_hz < float(highpass_hz)):
            raise ValueError(
                f"leak_hz must lie in (0, highpass_hz = {highpass_hz!r}), got {leak_hz!r}"
            )
        self.residual_path = VelocityEstimator(
            fs_hz, highpass_hz, highpass_order, integrator, lead_compensation_hz
        )
        self.model_path = VelocityEstimator(fs_hz, leak_hz, 1, integrator)
        self.fs_hz = self.residual_path.fs_hz
        self.leak_hz = leak_hz

    @classmethod
    def from_settings(cls, settings: Mapping[str, Any], fs_hz: float) -> ModelVelocityObserver:
        merged = {
            **OBSERVER_DEFAULTS,
            **{k: v for k, v in settings.items() if k not in ("method", "fs_hz")},
        }
        unknown = set(merged) - set(OBSERVER_DEFAULTS)
        if unknown:
            raise ValueError(f"unknown velocity setting(s): {', '.join(sorted(unknown))}")
        return cls(fs_hz, **merged)

    def settings(self) -> dict[str, Any]:
        """The mapping stored in the model file's ``velocity`` key (round-trips)."""
        res = self.residual_path
        return {
            "method": "model_observer",
            "fs_hz": self.fs_hz,
            "leak_hz": self.leak_hz,
            "highpass_hz": res.highpass_hz,
            "highpass_order": res.highpass_order,
            "integrator": res.integrator,
            "lead_compensation_hz": res.lead_compensation_hz,
        }

    def step(self, accel: float, xhat: float) -> float:
        return self.model_path.step(xhat) + self.residual_path.step(accel - xhat)

    def run(self, accel: np.ndarray, xhat: np.ndarray) -> np.ndarray:
        accel = np.asarray(accel, dtype=float)
        xhat = np.asarray(xhat, dtype=float)
        out: np.ndarray = self.model_path.run(xhat) + self.residual_path.run(accel - xhat)
        return out

    @property
    def state(self) -> tuple[np.ndarray, np.ndarray]:
        return self.model_path.state, self.residual_path.state

    @state.setter
    def state(self, value: tuple[np.ndarray, np.ndarray]) -> None:
        self.model_path.state, self.residual_path.state = value

    def reset(self) -> None:
        self.model_path.reset()
        self.residual_path.reset()

    def response(self, f_hz: npt.ArrayLike, model_error: complex = 0.0) -> Any:
        """v̂/(ẍ/(jω)) at ``f_hz`` (Hz; a number or an array) when x̂̈ = (1 − model_error)·ẍ:
        1 for an exact integral.

        model_error 0 is an exact plant model, 1 a model that predicts nothing."""
        h_model = self.model_path.response(f_hz)
        h_res = self.residual_path.response(f_hz)
        return (1 - model_error) * h_model + model_error * h_res


def velocity_setting_names() -> tuple[str, ...]:
    """Every key the ``velocity`` mapping may hold (either method)."""
    return tuple(
        dict.fromkeys(
            ("method", "fs_hz", *HIGHPASS_SETTINGS, *OBSERVER_DEFAULTS, *POSITION_DEFAULTS)
        )
    )


VelocityBlock = VelocityEstimator | ModelVelocityObserver | PositionVelocityObserver


def velocity_from_settings(settings: Mapping[str, Any] | None, fs_hz: float) -> VelocityBlock:
    """The velocity block a model file's ``velocity`` mapping describes.

    No ``method`` (every model made before the observer existed) or ``method: highpass``:
    the accelerometer-only `VelocityEstimator`, exactly as before. ``model_observer``: the
    complementary observer above; ``position_observer``: position and acceleration
    (`core.velocity_position`). ValueError on a bad setting."""
    settings = dict(settings or {})
    method = settings.get("method", "highpass")
    if method not in METHODS:
        raise ValueError(f"method must be one of {', '.join(METHODS)}, got {method!r}")
    fs_in_map = settings.get("fs_hz")
    if fs_in_map is not None and float(fs_in_map) != float(fs_hz):
        raise ValueError(f"velocity.fs_hz = {fs_in_map} disagrees with fs = {fs_hz}")
    if method == "model_observer":
        return ModelVelocityObserver.from_settings(settings, fs_hz)
    if method == "position_observer":
        return PositionVelocityObserver.from_settings(settings, fs_hz)
    settings.pop("method", None)
    for key in ("leak_hz", *POSITION_DEFAULTS):
        if key in settings:
            raise ValueError(f"{key} does not belong to method highpass")
    return VelocityEstimator.from_settings(settings, fs_hz)


def trusted_from_hz(block: VelocityBlock, max_phase_error_deg: float) -> float:
    """The lowest frequency (Hz) from which up to fs/4 the block's phase error against the
    true velocity stays within ``max_phase_error_deg`` (its ``response``; for the observer
    with an exact plant model); 0.0 when it does from 0.01 Hz on. A 1 %-step grid; the
    high-pass estimator (1 Hz, order 3, 256 Hz): 3.9 Hz for 30°. Above fs/4 the bilinear
    transform's own warping dominates the error, and a rig's motion lies far below."""
    grid = np.geomspace(0.01, 0.25 * block.fs_hz, 1000)
    error = np.abs(np.degrees(np.angle(block.response(grid))))
    beyond = np.flatnonzero(error > max_phase_error_deg)
    if beyond.size == 0:
        return 0.0
    return float(grid[min(beyond[-1] + 1, grid.size - 1)])
