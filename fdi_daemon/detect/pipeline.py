"""The monitor's signal chain (§IV-C), per tick and batch, built from the core blocks.

Per tick::

    x̂̈  = Ĝ(q) v_in                          eq. (1), plant IIR
    r   = ẍ - x̂̈                              eq. (3), acceleration residual
    v̂  = V(q) ẍ                               high-pass + integrator (core.velocity), or
    v̂  = L(q) x̂̈ + V(q) r                      the model-based observer (core.velocity_observer)
    v̂  = P(q) x + A(q) ẍ                       position fusion (core.velocity_position)
    g1  = G_e(q)[sign v̂],  g2 = G_e(q)[v̂]     eq. (15), G_e = q^-nk B/F, two IIR states
    θ   = argmin Σ_N (r - θ1 g1 - θ2 g2)²      eqs. (16)–(17), core.window_ls

θ is reported as NaN while the rig is at rest: the RMS of v̂ over the window below
``min_velocity_rms_mps`` (at rest g1 is the filtered sign of noise, and the fit means nothing).

``step`` uses every block's ``step``; ``run`` uses every block's ``run`` on whole arrays.
Both leave the blocks in the same state, so a replay can switch between them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fdi_daemon.core.iir import IIRFilter
from fdi_daemon.core.sliding_sums import SlidingSums
from fdi_daemon.core.velocity_observer import velocity_from_settings
from fdi_daemon.core.window_ls import MIN_RCOND, WindowLS, solve_sums
from fdi_daemon.detect.settings import velocity_settings
from fdi_daemon.errors import ConfigError
from fdi_daemon.io.model_file import FdiModel

__all__ = ["Pipeline", "PipelineBatch"]


@dataclass
class PipelineBatch:
    """Signals of a batch, one entry per sample; ``sums`` are the window sums (n, 6)."""

    xhat: np.ndarray
    residual: np.ndarray
    velocity: np.ndarray
    g1: np.ndarray
    g2: np.ndarray
    sums: np.ndarray
    counts: np.ndarray
    moving: np.ndarray  # bool: the window's velocity RMS is above the rest floor
    v_rms: np.ndarray  # the window's velocity RMS (m/s): the operating condition


class Pipeline:
    """Ĝ, residual, velocity, G_e regressors and the window least squares of one rig."""

    __slots__ = ("plant", "velocity", "model_velocity", "needs_position", "ge_sign",
                 "ge_velocity", "wls", "speed",
                 "min_v2_sum", "window_samples",
                 "xhat", "residual", "v", "g1", "g2", "moving", "v_rms", "theta1", "theta2")

    def __init__(self, model: FdiModel, window_samples: int, min_rcond: float = MIN_RCOND,
                 min_velocity_rms_mps: float = 0.0) -> None:
        ff = model.fault_filter
        if ff is None:
            raise ConfigError("the model has no fault_filter (G_e, γ_f): run `fdi signature` "
                              "on a recording with a friction fault first")
        try:
            self.velocity = velocity_from_settings(velocity_settings(model.velocity), model.fs)
        except ValueError as exc:
            raise ConfigError(f"model velocity settings: {exc}") from None
        self.model_velocity = self.velocity.needs_model
        self.needs_position = self.velocity.needs_position
        if model.extra.get("effects"):  # Ĝ plus the effects `fdi diagnose` added (same API)
            from fdi_daemon.diagnose.augment import nominal_plant

            self.plant = nominal_plant(model)
        else:
            self.plant = IIRFilter(model.plant_b, model.plant_a)
        b_e = np.concatenate([np.zeros(int(ff.nk)), np.asarray(ff.b, dtype=float)])
        self.ge_sign = IIRFilter(b_e, ff.f)
        self.ge_velocity = IIRFilter(b_e, ff.f)
        self.wls = WindowLS(window_samples, min_rcond=min_rcond)
        self.speed = SlidingSums(window_samples, 1)  # Σ v̂² over the window
        self.min_v2_sum = float(min_velocity_rms_mps) ** 2 * window_samples
        self.window_samples = window_samples
        self._clear()

    def _clear(self) -> None:
        self.xhat = self.residual = self.v = self.g1 = self.g2 = self.v_rms = 0.0
        self.moving = False
        self.theta1 = self.theta2 = float("nan")

    def reset(self) -> None:
        """Zero every state (after a data gap)."""
        for block in (self.plant, self.velocity, self.ge_sign, self.ge_velocity, self.wls,
                      self.speed):
            block.reset()
        self._clear()

    def step(self, v_in: float, accel: float | None, position: float = math.nan) -> None:
        """Advance one tick; results in the attributes and in ``wls`` (θ, sums, ok).

        ``accel`` None (a bad sample) is replaced by the model's x̂̈: residual 0, and the
        velocity estimator integrates the model's acceleration instead of a bad value.
        ``position`` (m) is read only by the position observer (NaN: hold the last one).
        """
        xhat = self.plant.step(v_in)
        if accel is None:
            accel = xhat
        r = accel - xhat
        if self.model_velocity:
            v = self.velocity.step(accel, xhat)
        elif self.needs_position:
            v = self.velocity.step(accel, position)
        else:
            v = self.velocity.step(accel)
        s = 1.0 if v > 0.0 else (-1.0 if v < 0.0 else 0.0)
        g1 = self.ge_sign.step(s)
        g2 = self.ge_velocity.step(v)
        t1, t2 = self.wls.step(g1, g2, r)
        v2_sum = self.speed.push((v * v,))[0]
        self.moving = moving = v2_sum >= self.min_v2_sum
        self.v_rms = math.sqrt(max(v2_sum, 0.0) / self.window_samples)
        self.theta1, self.theta2 = (t1, t2) if moving else (float("nan"), float("nan"))
        self.xhat, self.residual, self.v, self.g1, self.g2 = xhat, r, v, g1, g2

    def run(self, v_in: np.ndarray, accel: np.ndarray, bad_accel: np.ndarray | None = None,
            position: np.ndarray | None = None) -> PipelineBatch:
        """Batch ``step`` over arrays (continuing from, and updating, the same state).

        ``bad_accel``: a mask of samples to replace by x̂̈ (``step(v, None)``); ``position``:
        the position column (None: not carried, all NaN)."""
        v_in = np.asarray(v_in, dtype=float)
        accel = np.asarray(accel, dtype=float)
        xhat = self.plant.run(v_in)
        if bad_accel is not None and bad_accel.any():
            accel = np.where(bad_accel, xhat, accel)
        r = accel - xhat
        if self.model_velocity:
            v = self.velocity.run(accel, xhat)
        elif self.needs_position:
            v = self.velocity.run(accel, np.full(accel.shape, np.nan) if position is None
                                  else np.asarray(position, dtype=float))
        else:
            v = self.velocity.run(accel)
        g1 = self.ge_sign.run(np.sign(v))
        g2 = self.ge_velocity.run(v)
        sums, counts = self.wls.run_sums(g1, g2, r)
        v2_sum = self.speed.run((v * v)[:, None])[0][:, 0]
        moving = v2_sum >= self.min_v2_sum
        v_rms = np.sqrt(np.maximum(v2_sum, 0.0) / self.window_samples)
        if v.size:
            self.xhat, self.residual, self.v = float(xhat[-1]), float(r[-1]), float(v[-1])
            self.g1, self.g2 = float(g1[-1]), float(g2[-1])
            self.moving = bool(moving[-1])
            self.v_rms = float(v_rms[-1])
            wls = self.wls
            self.theta1, self.theta2 = ((wls.theta1, wls.theta2) if self.moving
                                        else (float("nan"), float("nan")))
        return PipelineBatch(xhat=xhat, residual=r, velocity=v, g1=g1, g2=g2, sums=sums,
                             counts=counts, moving=moving, v_rms=v_rms)

    def thetas(self, batch: PipelineBatch) -> tuple[np.ndarray, np.ndarray]:
        """θ1, θ2 of a batch as ``step`` reports them (NaN: invalid window or at rest)."""
        sol = solve_sums(batch.sums, batch.counts, self.wls.window_samples, self.wls.min_rcond,
                         self.wls.min_mean_square)
        return (np.where(batch.moving, sol.theta1, np.nan),
                np.where(batch.moving, sol.theta2, np.nan))
