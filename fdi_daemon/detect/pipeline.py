"""The monitor's signal chain (§IV-C), per tick and batch, built from the core blocks.

Per tick::

    x̂̈  = Ĝ(q) v_in                          eq. (1), plant IIR
    r   = ẍ - x̂̈                              eq. (3), acceleration residual
    v̂  = V(q) ẍ                               high-pass + integrator (core.velocity), or
    v̂  = L(q) x̂̈ + V(q) r                      the model-based observer (core.velocity_observer)
    v̂  = P(q) x + A(q) ẍ                       position fusion (core.velocity_position)
    g1  = G_e(q)[sign v̂],  g2 = G_e(q)[v̂]     eq. (15), G_e = q^-nk B/F, two IIR states
    θ   = argmin Σ_N (r - θ1 g1 - θ2 g2)²      eqs. (16)–(17), core.window_ls
    s_d = G_d(q)[sign v̂_d] + γ_d G_d(q)[v̂_d]   the growing-fault path's regressor, on its
          own high-pass velocity v̂_d (a lower cut-off) where the model has a drift signature
          (``fault_filter.drift``), else g1 + γ g2 (docs/detector.md §3, "Growing friction")

θ is reported as NaN while the rig is at rest: the RMS of v̂ over the window below
``min_velocity_rms_mps`` (at rest g1 is the filtered sign of noise, and the fit means nothing).

``trusted``: the window's velocity lies mostly where v̂ is right and where the signature
describes friction, i.e. at most ``trust_share`` of Σ v̂² passes a 2nd-order low-pass at
``trusted_from_hz``, the higher of
- the frequency below which v̂'s phase error exceeds ``trust_phase_deg``
  (`core.velocity_observer.trusted_from_hz`: 3.9 Hz for the 1 Hz high-pass at 30°, 1.9 Hz
  for 0.5 Hz, none for the observers): below it sign v̂ is wrong for a large part of each
  cycle and θ1 under-reads friction (docs/detector.md §4a);
- ``band_fraction`` of the lowest frequency of the signature's calibration (the model's
  ``fault_filter.band_hz``; none when the model does not record it): G_e, fitted on the
  friction of those frequencies, does not describe it far below them (docs/detector.md §3,
  "The 1–3 Hz ramp without position": 2.6 Hz for README step 2's six carriers).

The blocks (`core.iir.IIRFilter`, the velocity estimators) give the coefficients; the
state lives in an `Arena` and every tick is the compiled `detect.kernel.chain_tick`:
``step`` is one call per sample, ``run`` one call over arrays, bit-equal, and a replay can
switch between them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from fdi_daemon.core.compiled import Arena
from fdi_daemon.core.filter_design import butter
from fdi_daemon.core.iir import IIRFilter
from fdi_daemon.core.kernels import sums_floats
from fdi_daemon.core.velocity import DEFAULT_SETTINGS, VelocityEstimator
from fdi_daemon.core.velocity_observer import (
    ModelVelocityObserver,
    trusted_from_hz,
    velocity_from_settings,
)
from fdi_daemon.core.velocity_position import PositionVelocityObserver
from fdi_daemon.core.window_ls import MIN_RCOND, solve_sums
from fdi_daemon.detect import kernel as K
from fdi_daemon.detect.settings import DetectorSettings, velocity_settings
from fdi_daemon.errors import ConfigError
from fdi_daemon.io.model_file import DriftFilter, FaultFilter, FdiModel

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


class WindowView:
    """Eq. (17) of the newest window, as the kernel left it (θ, SSE, ok, sums, count)."""

    __slots__ = ("_pl", "window_samples", "min_rcond", "min_mean_square")

    def __init__(self, pipeline: Pipeline, window_samples: int, min_rcond: float) -> None:
        self._pl = pipeline
        self.window_samples = window_samples
        self.min_rcond = min_rcond
        self.min_mean_square = (0.0, 0.0)

    @property
    def theta1(self) -> float:
        return self._pl._out(K.O_WT1)

    @property
    def theta2(self) -> float:
        return self._pl._out(K.O_WT2)

    @property
    def ok(self) -> bool:
        return bool(self._pl._out(K.O_WOK))

    @property
    def sse(self) -> float:
        return self._pl._out(K.O_WSSE)

    @property
    def count(self) -> int:
        return int(self._pl.arena.i[self._pl.io + K.C_COUNT])

    @property
    def sums(self) -> tuple[float, ...]:
        """Current (S11, S12, S22, S1y, S2y, Syy)."""
        pl = self._pl
        so = int(pl.arena.i[pl.io + K.C_SUMS]) + (self.window_samples + 2) * K.SUMS_WIDTH
        return tuple(pl.arena.f[so : so + 6].tolist())


def _calibrated_from_hz(ff: FaultFilter) -> float:
    """The lowest frequency (Hz) of the signature's calibration, 0.0 where the model does
    not record it (a model made before `fdi signature` did)."""
    return 0.0 if ff.band_hz is None else ff.band_hz[0]


def _drift_filters(model: FdiModel, drift: DriftFilter | None) -> list[Any]:
    """The growing-fault path's velocity V_d, the high-pass estimator at the drift
    signature's cut-off (the model's own settings when its velocity is the high-pass one, as
    `fdi signature --drift-highpass-hz` requires, else the estimator's defaults), and its G_d
    for sign v̂_d and v̂_d (eq. 15); [None] * 3 without a drift signature (the path then uses
    g1 + γ g2, `kernel.chain_tick`)."""
    if drift is None:
        return [None] * 3
    settings = velocity_settings(model.velocity)
    if settings.get("method", "highpass") != "highpass":
        settings = velocity_settings(DEFAULT_SETTINGS)
    try:
        velocity = velocity_from_settings({**settings, "highpass_hz": drift.highpass_hz}, model.fs)
    except ValueError as exc:
        raise ConfigError(f"fault_filter.drift: {exc}") from None
    b_d = np.concatenate([np.zeros(int(drift.nk)), np.asarray(drift.b, dtype=float)])
    return [velocity, IIRFilter(b_d, drift.f), IIRFilter(b_d, drift.f)]


class Pipeline:
    """Ĝ, residual, velocity, G_e regressors and the window least squares of one rig."""

    __slots__ = (
        "plant",
        "velocity",
        "model_velocity",
        "needs_position",
        "ge_sign",
        "ge_velocity",
        "wls",
        "window_samples",
        "external_plant",
        "arena",
        "fo",
        "io",
        "_zo",
        "_zn",
        "_out_o",
        "trusted_from_hz",
        "signature_gamma",
    )

    def __init__(
        self,
        model: FdiModel,
        window_samples: int,
        min_rcond: float = MIN_RCOND,
        min_velocity_rms_mps: float = 0.0,
        arena: Arena | None = None,
        trust_phase_deg: float = DetectorSettings.velocity_trust_phase_deg,
        trust_share: float = DetectorSettings.velocity_trust_share,
        band_fraction: float = DetectorSettings.signature_band_fraction,
    ) -> None:
        ff = model.fault_filter
        if ff is None:
            raise ConfigError(
                "the model has no fault_filter (G_e, γ_f): run `fdi signature` "
                "on a recording with a friction fault first"
            )
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
        self.external_plant = not isinstance(self.plant, IIRFilter)
        b_e = np.concatenate([np.zeros(int(ff.nk)), np.asarray(ff.b, dtype=float)])
        self.ge_sign = IIRFilter(b_e, ff.f)
        self.ge_velocity = IIRFilter(b_e, ff.f)
        self.window_samples = n = int(window_samples)
        self.wls = WindowView(self, n, float(min_rcond))
        vel = self.velocity
        vel_a: IIRFilter | VelocityEstimator
        vel_b: IIRFilter | VelocityEstimator | None
        if self.model_velocity:
            assert isinstance(vel, ModelVelocityObserver)  # the one that needs_model
            vel_a, vel_b, method = vel.model_path, vel.residual_path, 1
        elif self.needs_position:
            assert isinstance(vel, PositionVelocityObserver)  # the one that needs_position
            vel_a, vel_b, method = vel.position_path, vel.accel_path, 2
        else:
            assert isinstance(vel, VelocityEstimator)  # neither needs_model nor needs_position
            vel_a, vel_b, method = vel, None, 0
        plant = self.plant if isinstance(self.plant, IIRFilter) else None  # not external_plant
        self.trusted_from_hz = max(
            trusted_from_hz(vel, trust_phase_deg), band_fraction * _calibrated_from_hz(ff)
        )
        low = (
            IIRFilter(*(c.tolist() for c in butter(2, self.trusted_from_hz, model.fs)))
            if self.trusted_from_hz > 0
            else None
        )  # None: v̂ is trusted everywhere
        filters = [plant, vel_a, vel_b, self.ge_sign, self.ge_velocity, low]
        filters += _drift_filters(model, ff.drift)
        width = max(f.b.size for f in filters if f is not None)
        self.arena = arena if arena is not None else Arena()
        nf = K.CHAIN_FILTERS
        n_float = nf * (3 * width - 1) + sums_floats(n, K.SUMS_WIDTH) + K.SUMS_WIDTH + K.CHAIN_OUT
        self.fo, self.io = fo, io = self.arena.alloc(n_float, K.CHAIN_INTS)
        b_o, a_o = fo, fo + nf * width
        self._zo = z_o = a_o + nf * width
        sums_o = z_o + nf * (width - 1)
        row_o = sums_o + sums_floats(n, K.SUMS_WIDTH)
        self._out_o = out_o = row_o + K.SUMS_WIDTH
        self._zn = sums_o - z_o
        f, ii = self.arena.f, self.arena.i
        orders = []
        for r, filt in enumerate(filters):
            if filt is None:
                orders.append(0)
                continue
            f[b_o + r * width : b_o + r * width + filt.b.size] = filt.b
            f[a_o + r * width : a_o + r * width + filt.a.size] = filt.a
            orders.append(filt.b.size - 1)
        ii[io : io + K.CHAIN_INTS] = (
            method,
            int(self.external_plant),
            n,
            width,
            *orders,
            0,
            0,
            b_o,
            a_o,
            z_o,
            sums_o,
            row_o,
            out_o,
            int(ff.drift is not None),
        )
        f[out_o + K.O_MIN_V2] = float(min_velocity_rms_mps) ** 2 * n
        f[out_o + K.O_MIN_RCOND] = float(min_rcond)
        f[out_o + K.O_TRUST_SHARE] = float(trust_share)
        f[out_o + K.O_GAMMA] = self.signature_gamma = model.signature_gamma()
        f[out_o + K.O_DRIFT_GAMMA] = math.nan if ff.drift is None else ff.drift.gamma
        self.reset()

    def _out(self, k: int) -> float:
        return float(self.arena.f[self._out_o + k])

    @property
    def xhat(self) -> float:
        return self._out(K.O_XHAT)

    @property
    def residual(self) -> float:
        return self._out(K.O_R)

    @property
    def v(self) -> float:
        return self._out(K.O_V)

    @property
    def g1(self) -> float:
        return self._out(K.O_G1)

    @property
    def g2(self) -> float:
        return self._out(K.O_G2)

    @property
    def theta1(self) -> float:
        return self._out(K.O_T1)

    @property
    def theta2(self) -> float:
        return self._out(K.O_T2)

    @property
    def level(self) -> float:
        """The window's friction level: the residual's least-squares multiple of the
        calibrated fault's regressor g1 + γ g2 (units of the calibrated fault; NaN at rest)."""
        return self._out(K.O_LEVEL)

    @property
    def moving(self) -> bool:
        return bool(self._out(K.O_MOVING))

    @property
    def v_rms(self) -> float:
        return self._out(K.O_VRMS)

    @property
    def trusted(self) -> bool:
        """The window's velocity lies mostly where v̂ is right (module docstring)."""
        return bool(self._out(K.O_TRUSTED))

    @property
    def clipped(self) -> bool:
        """The window holds ẍ at the accelerometer's rail (`kernel.chain_tick`)."""
        return bool(self._out(K.O_CLIPPED))

    def reset(self) -> None:
        """Zero every state (after a data gap)."""
        f, ii, io = self.arena.f, self.arena.i, self.io
        f[self._zo : self._out_o + K.O_LAST_POS + 1] = 0.0  # filters, sums, row, signals
        ii[io + K.C_POS] = ii[io + K.C_COUNT] = 0
        out = self._out_o
        f[out + K.O_T1] = f[out + K.O_T2] = f[out + K.O_WT1] = f[out + K.O_WT2] = math.nan
        f[out + K.O_WSSE] = f[out + K.O_LAST_POS] = math.nan
        f[out + K.O_ACCEL_LAST] = f[out + K.O_RAIL_POS] = f[out + K.O_RAIL_NEG] = math.nan
        f[out + K.O_RAIL_AGE_POS] = f[out + K.O_RAIL_AGE_NEG] = f[out + K.O_CLIP_AGE] = math.inf
        if self.external_plant:
            self.plant.reset()

    def step(self, v_in: float, accel: float | None, position: float = math.nan) -> None:
        """Advance one tick; results in the attributes and in ``wls`` (θ, sums, ok).

        ``accel`` None (a bad sample) is replaced by the model's x̂̈: residual 0, and the
        velocity estimator integrates the model's acceleration instead of a bad value.
        ``position`` (m) is read only by the position observer (NaN: hold the last one).
        """
        xext = self.plant.step(v_in) if self.external_plant else 0.0
        K.chain_tick(
            self.arena.f,
            self.arena.i,
            self.io,
            float(v_in),
            math.nan if accel is None else float(accel),
            float(position),
            xext,
        )

    def external_xhat(self, v_in: np.ndarray) -> np.ndarray:
        """x̂̈ of a plant the kernel does not hold (effects); else ``v_in`` itself, a
        placeholder of the right length that the kernel does not read."""
        if self.external_plant:
            return np.ascontiguousarray(self.plant.run(v_in), dtype=float)
        return v_in

    def run(
        self,
        v_in: np.ndarray,
        accel: np.ndarray,
        bad_accel: np.ndarray | None = None,
        position: np.ndarray | None = None,
    ) -> PipelineBatch:
        """Batch ``step`` over arrays (continuing from, and updating, the same state).

        ``bad_accel``: a mask of samples to replace by x̂̈ (``step(v, None)``); ``position``:
        the position column (None: not carried, all NaN)."""
        v_in = np.ascontiguousarray(v_in, dtype=float)
        accel = np.ascontiguousarray(accel, dtype=float)
        if bad_accel is not None and bad_accel.any():
            accel = np.where(bad_accel, np.nan, accel)
        n = v_in.size
        position = (
            np.full(n, np.nan) if position is None else np.ascontiguousarray(position, dtype=float)
        )
        xhat, r, v, g1, g2 = (np.empty(n) for _ in range(5))
        sums = np.empty((n, 6))
        counts = np.empty(n, dtype=np.int64)
        moving = np.empty(n, dtype=np.bool_)
        v_rms = np.empty(n)
        K.chain_run(
            self.arena.f,
            self.arena.i,
            self.io,
            v_in,
            accel,
            position,
            self.external_xhat(v_in),
            xhat,
            r,
            v,
            g1,
            g2,
            sums,
            counts,
            moving,
            v_rms,
        )
        return PipelineBatch(
            xhat=xhat,
            residual=r,
            velocity=v,
            g1=g1,
            g2=g2,
            sums=sums,
            counts=counts,
            moving=moving,
            v_rms=v_rms,
        )

    def thetas(self, batch: PipelineBatch) -> tuple[np.ndarray, np.ndarray]:
        """θ1, θ2 of a batch as ``step`` reports them (NaN: invalid window or at rest)."""
        sol = solve_sums(
            batch.sums,
            batch.counts,
            self.wls.window_samples,
            self.wls.min_rcond,
            self.wls.min_mean_square,
        )
        return (
            np.where(batch.moving, sol.theta1, np.nan),
            np.where(batch.moving, sol.theta2, np.nan),
        )

    def levels(self, batch: PipelineBatch) -> np.ndarray:
        """The friction level of a batch as ``step`` reports it (`level`; NaN: a window not
        yet full, or at rest)."""
        s11, s12, s22, s1y, s2y = batch.sums[:, :5].T
        gamma = self.signature_gamma
        s_level = s11 + gamma * (2.0 * s12 + gamma * s22)
        ok = batch.moving & (batch.counts == self.wls.window_samples) & (s_level > 0.0)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(ok, (s1y + gamma * s2y) / s_level, np.nan)
