"""The detector: from the pipeline's signals to events (docs/detector.md has the equations).

Two methods share one state machine (calibrating -> monitoring -> fault_detected ->
friction_isolated | other_fault -> cleared -> monitoring):

``band`` (the paper, §IV-C): θ = (θ1, θ2) of eq. (17) leaves the band mean ± k·σ of a
fault-free calibration period -> fault_detected; θ tracks the signature (1, γ_f) within
``track_tolerance`` -> friction_isolated, else other_fault after ``isolation_timeout_s``;
back inside the band -> cleared.

``sequential`` (default): a reference fit of the residual on φ = (g1, g2, x̂̈, 1) over a
window that ends ``reference_lag_s`` ago absorbs the operating-point dependent part
(pre-fault seal friction, the plant model's gain/phase error, a sensor offset). The
innovation e = r - φᵀθ_ref, standardised by the reference residual σ, gives the statistic
T = mean over the test window of (e/σ)² (≈ 1 without a fault); T > threshold for
``persistence_samples`` ticks -> fault_detected, unless the valve command just changed its
character: the same test on an AR(4) model of v_in (the operating-point guard) holds
alarms for ``guard_hold_s`` after it fires. Isolation fits φ again on the data since the
reference ended: an increase of the Coulomb coefficient by ``friction_min_level`` (units of
the calibrated signature), held for ``track_samples`` ticks, is friction once the fault
has persisted (the frozen-reference test still above the threshold on samples an
isolation window after the detection: a knock or glitch does not persist). Without it
within ``isolation_timeout_s``, a fault that a gain (x̂̈) or offset (1) change of the
residual fit describes, or a clipping accelerometer, is another fault; a fault that nothing
describes stays ``fault_detected`` (friction under slow operation). An episode the
growing-fault path raised (a CUSUM along friction's direction only) counts that timeout
from the residual test's alarm: until then it stays ``fault_detected``, unconfirmed.

The level path catches friction that creeps in (wear), that starts while the guard holds,
or that is there from the start: the Coulomb coefficient θ1 (eq. 17) above its fault-free
value by more than its margin for ``slow_persistence_s`` -> fault_detected, and θ1 itself is
the evidence. The fault-free value is the commissioning baseline of the operating condition
(``fdi baseline``; margin max(friction_min_level/2, band_k·σ), computed by the monitor) or,
without one, the median θ1 of the calibration (margin friction_min_level). (The reported
friction level, `detect.friction_level`, is another quantity: θ held to the signature.)
A friction episode is cleared when θ1 has been back within half its margin for
``friction_clear_s`` while the rig moves.

The per-tick arithmetic (both innovation tests, the guard, the level's excess, the quiet
path's counters and the calibration buffer) is the compiled `detect.kernel.detector_tick`
on state the detector owns in the monitor's `Arena`; ``decide`` is the Python part, called
only on the ticks the kernel hands over (an event, the end of the calibration, an episode).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from fdi_daemon.core.compiled import Arena
from fdi_daemon.core.cusum import cusum_threshold
from fdi_daemon.core.innovation_test import InnovationTest
from fdi_daemon.detect import episode_kernel as E
from fdi_daemon.detect import kernel as K
from fdi_daemon.detect.events import make_event
from fdi_daemon.detect.friction_level import FrictionLevel
from fdi_daemon.detect.settings import DetectorSettings

__all__ = ["Detector", "STATES", "N_REGRESSORS"]

STATES = (
    "starting",
    "calibrating",
    "monitoring",
    "fault_detected",
    "friction_isolated",
    "other_fault",
)
_STATE_CODE = {name: i for i, name in enumerate(STATES)}
#: what showed the friction (`episode_kernel` KIND_*): event field ``friction_evidence``
_KINDS = (None, "harmonics", "level")

#: regressors of the reference fit: g1, g2, x̂̈, 1
N_REGRESSORS = 4
#: order of the autoregressive model of the valve command (the operating-point guard)
COMMAND_ORDER = 4
#: `detect.kernel.detector_tick` is compiled for these two (four regressors each)
assert N_REGRESSORS == COMMAND_ORDER == 4


class Detector:
    """Decides on every tick from the pipeline's signals; see the module docstring."""

    def __init__(
        self,
        settings: DetectorSettings,
        fs_hz: float,
        gamma_f: float,
        baseline: bool = False,
        arena: Arena | None = None,
        baseline_bins: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
        drift_reference: bool = False,
    ) -> None:
        """``baseline``: the level's excess is taken over a commissioning baseline (else
        the calibration's level is the fault-free one); ``baseline_bins``: its (edges,
        median, margin) per velocity-RMS bin, for the kernel; ``drift_reference``: the
        model has a drift signature (``fault_filter.drift``), whose regressors get their
        own reference fit for the growing-fault path (`kernel._drift_fit_tick`)."""
        self.settings = settings
        self.has_baseline = bool(baseline)
        self.fs_hz = float(fs_hz)
        self.gamma_f = float(gamma_f)
        s = settings
        self._set_sample_counts()
        self.arena = arena = arena if arena is not None else Arena()

        def innovation_test(order: int, min_sigma: float) -> InnovationTest:
            return InnovationTest(
                order,
                self.window_samples,
                self.lag_samples,
                self.test_samples,
                s.reference_every_samples,
                min_sigma,
                arena=arena,
            )

        # the residual test (φ = g1, g2, x̂̈, 1) and the command test (AR(4) of v_in)
        self.residual_test = innovation_test(N_REGRESSORS, s.min_sigma_mps2)
        self.command_test = innovation_test(COMMAND_ORDER, s.guard_min_sigma_v)
        #: the growing-fault path's reference: (R) with the drift signature's regressors
        #: (G_d[sign v̂_d], G_d[v̂_d], x̂̈, 1), fitted as the residual test's is
        self.drift_test = (
            innovation_test(N_REGRESSORS, s.min_sigma_mps2)
            if drift_reference and s.method == "sequential"
            else None
        )
        bins = 0 if baseline_bins is None else len(baseline_bins[1])
        self.fo, self.io = arena.alloc(
            K.E_CAL + 2 * self.calibration_samples + 3 * bins + 1, K.DET_INTS
        )
        self.epo, self.epi = arena.alloc(
            E.episode_floats(self.window_samples, self.test_samples), E.EPISODE_INTS
        )
        #: the growing-fault path's threshold h = τ·ln(ARL₀): τ ticks per independent innovation (`core.cusum`)
        self.drift_threshold = s.drift_correlation_samples * cusum_threshold(
            s.drift_false_alarm_years, fs_hz
        )
        self._set_episode_block()
        self._set_detector_block(baseline_bins)
        #: the friction level as reported (`detect.friction_level`), restarted by the kernel
        #: when an episode begins or ends; events carry its value at their tick
        self.level = FrictionLevel(
            s.level_median_s, fs_hz, arena, settle_samples=self.window_samples
        )
        arena.i[self.io + K.D_LEVEL] = self.level.io
        self.band: dict[str, list[float]] | None = None
        #: θ as reported for the newest tick: eq. (17) over the sliding window, or during an
        #: alarm episode over the data since the change (`_Episode.theta`)
        self.theta1 = self.theta2 = math.nan
        self.state = "calibrating"
        #: the fault-free friction level without a baseline: θ1's median over the calibration
        self.level_base = math.nan
        self.restart()

    def _set_sample_counts(self) -> None:
        """The settings' durations (s) as whole samples at ``fs_hz``."""
        s, fs_hz = self.settings, self.fs_hz
        self.window_samples = s.samples(s.window_s, fs_hz, minimum=8)
        self.lag_samples = s.samples(s.reference_lag_s, fs_hz, minimum=0)
        self.test_samples = s.samples(s.test_window_s, fs_hz)
        self.calibration_samples = s.samples(s.calibration_s, fs_hz)
        self.warmup_samples = self.window_samples + self.lag_samples + self.test_samples
        hold = (
            s.guard_hold_s
            if s.guard_hold_s is not None
            else (s.window_s + s.reference_lag_s + s.test_window_s)
        )
        self.hold_samples = s.samples(hold, fs_hz)
        self.iso_samples = s.samples(s.isolation_window_s, fs_hz)
        self.timeout_samples = max(self.iso_samples, s.samples(s.isolation_timeout_s, fs_hz))
        self.clear_samples = s.samples(s.clear_s, fs_hz)
        self.friction_clear_samples = s.samples(s.friction_clear_s, fs_hz)
        self.level_samples = s.samples(s.slow_persistence_s, fs_hz)

    def _set_episode_block(self) -> None:
        """The episode kernel's sizes and settings (`detect.episode_kernel`)."""
        s, ii, f, epi = self.settings, self.arena.i, self.arena.f, self.epi
        n, m = self.window_samples, self.test_samples
        ii[epi + E.P_N], ii[epi + E.P_M] = n, m
        ii[epi + E.P_ISO], ii[epi + E.P_TIMEOUT] = self.iso_samples, self.timeout_samples
        ii[epi + E.P_CLEAR] = self.clear_samples
        ii[epi + E.P_FRICTION_CLEAR] = self.friction_clear_samples
        ii[epi + E.P_TRACK_SAMPLES] = s.track_samples
        ii[epi + E.P_BAND] = int(s.method == "band")
        ii[epi + E.P_WARMUP] = self.warmup_samples
        ii[epi + E.P_O_POST : epi + E.P_O_G + 1] = E.episode_layout(self.epo, n, m)
        sc = int(ii[epi + E.P_O_SCAL])
        f[sc + E.S_FMIN] = s.friction_min_level
        f[sc + E.S_THRESHOLD] = s.threshold
        f[sc + E.S_TOL1] = s.track_tolerance
        f[sc + E.S_TOL2] = s.track_tolerance * max(abs(self.gamma_f), 1.0)
        f[sc + E.S_GAMMA_F] = self.gamma_f
        f[sc + E.S_DRIFT_SHIFT] = s.drift_shift_level if s.method == "sequential" else 0.0
        f[sc + E.S_DRIFT_H] = self.drift_threshold

    def _set_detector_block(
        self, baseline_bins: tuple[np.ndarray, np.ndarray, np.ndarray] | None
    ) -> None:
        """The detector kernel's sizes, settings, the blocks it reads (the tests, the
        episode) and the baseline's bins (`detect.kernel.detector_tick`)."""
        s, ii, f, io, fo = self.settings, self.arena.i, self.arena.f, self.io, self.fo
        bins = 0 if baseline_bins is None else len(baseline_bins[1])
        ii[io + K.D_EPI] = self.epi
        ii[io + K.D_METHOD] = 1 if s.method == "band" else 0
        ii[io + K.D_HAS_BASELINE] = int(self.has_baseline)
        ii[io + K.D_HOLD] = self.hold_samples
        ii[io + K.D_LEVEL_SAMPLES] = self.level_samples
        ii[io + K.D_PERSISTENCE] = s.persistence_samples
        ii[io + K.D_CAL_SAMPLES] = self.calibration_samples
        ii[io + K.D_BINS] = bins
        ii[io + K.D_RES] = self.residual_test.io
        ii[io + K.D_CMD] = self.command_test.io
        ii[io + K.D_DRIFT_RES] = -1 if self.drift_test is None else self.drift_test.io
        ii[io + K.D_FLOATS] = fo
        f[fo + K.E_THRESHOLD] = s.threshold
        f[fo + K.E_GUARD_THRESHOLD] = s.guard_threshold
        f[fo + K.E_FRICTION_MIN] = s.friction_min_level
        f[fo + K.E_DRIFT_SHIFT] = s.drift_shift_level
        f[fo + K.E_DRIFT_H] = self.drift_threshold
        if baseline_bins is not None:
            o = fo + K.E_CAL + 2 * self.calibration_samples
            f[o : o + 3 * bins + 1] = np.concatenate(
                [np.asarray(v, dtype=float) for v in baseline_bins]
            )

    # ------------------------------------------------------------------ state in the arena
    @staticmethod
    def _int(k: int) -> property:  # a property factory for the ints of the kernel's block
        return property(
            lambda self: int(self.arena.i[self.io + k]),
            lambda self, v: self.arena.i.__setitem__(self.io + k, int(v)),
        )

    @staticmethod
    def _float(k: int) -> property:
        return property(
            lambda self: float(self.arena.f[self.fo + k]),
            lambda self, v: self.arena.f.__setitem__(self.fo + k, float(v)),
        )

    _tick = _int(K.D_TICK)
    _guard_until = _int(K.D_GUARD_UNTIL)
    _above = _int(K.D_ABOVE)
    _level_above = _int(K.D_LEVEL_ABOVE)
    _hold_until = _int(K.D_HOLD_UNTIL)
    _cal_count = _int(K.D_CAL_COUNT)
    theta1 = _float(K.E_THETA1)
    theta2 = _float(K.E_THETA2)
    level_base = _float(K.E_LEVEL_BASE)
    del _int, _float

    @property
    def drift_statistic(self) -> float:
        """The growing-fault path's CUSUM S (`detect.kernel._drift_tick`), 0 outside a run."""
        return float(self.arena.f[self.fo + K.E_DRIFT])

    @drift_statistic.setter
    def drift_statistic(self, value: float) -> None:
        self.arena.f[self.fo + K.E_DRIFT] = float(value)

    @property
    def state(self) -> str:
        return STATES[self.arena.i[self.io + K.D_STATE]]

    @state.setter
    def state(self, name: str) -> None:
        self.arena.i[self.io + K.D_STATE] = _STATE_CODE[name]

    @property
    def in_episode(self) -> bool:
        """An alarm episode runs (from fault_detected until cleared)."""
        return bool(self.arena.i[self.io + K.D_EPISODE])

    def restart(self) -> None:
        """Forget every window (start-up, data gap); the band and an episode are kept."""
        self._tick = 0
        self.residual_test.reset()
        self.command_test.reset()  # and the history of v_in (its regressors)
        if self.drift_test is not None:
            self.drift_test.reset()
        self._guard_until = 0
        self._above = 0
        self._level_above = 0
        self.drift_statistic = 0.0
        self._hold_until = self.warmup_samples
        if self.state == "calibrating":
            self._cal_count = 0
        if self.in_episode:
            E.episode_restart(self.arena.f, self.arena.i, self.epi)

    @property
    def threshold(self) -> float:
        return self.settings.threshold

    @property
    def statistic(self) -> float:
        return self.residual_test.statistic

    @property
    def level_path(self) -> str:
        """What the level path compares with (event field ``path``, ``friction_evidence``)."""
        return "baseline" if self.has_baseline else "level"

    # ------------------------------------------------------------------ decisions
    def decide(self, code: int, t: float) -> list[dict[str, Any]]:
        """The event of a tick whose kernel code is not QUIET (`detect.kernel`): the kernel
        has applied the decision; the end of the calibration is computed here."""
        theta1, theta2 = self.theta1, self.theta2
        if code == K.CALIBRATED:
            return self._calibrate(t, theta1, theta2)
        if code == K.LEVEL_ALARM:
            return [self._event(t, "fault_detected", theta1, theta2, path=self.level_path)]
        if code == K.FAST_ALARM:
            return [self._event(t, "fault_detected", theta1, theta2, path="fast")]
        if code == K.DRIFT_ALARM:
            # the growing-fault path (CUSUM): a fault, not yet confirmed as friction
            return [
                self._event(
                    t,
                    "fault_detected",
                    theta1,
                    theta2,
                    path="drift",
                    unconfirmed=True,
                    drift_statistic=float(self.arena.f[self.fo + K.E_DRIFT]),
                    drift_threshold=self.drift_threshold,
                )
            ]
        if code == K.CLEARED:
            return [self._event(t, "cleared", theta1, theta2)]
        ii, sc = self.arena.i, int(self.arena.i[self.epi + E.P_O_SCAL])
        change = float(self.arena.f[sc + E.S_LEVEL_CHANGE])
        if code == K.OTHER_FAULT:
            # a clipping accelerometer is no friction evidence (`episode_tick`), and a load
            # that stopped may be held by friction or have lost its drive: say so
            why = {"accel_clipping": True} if ii[self.epi + E.P_CLIPPED] else {}
            if E.load_stopped(self.arena.f, ii, self.epi):  # over the window of this tick
                why["load_stopped"] = True
            return [self._event(t, "other_fault", theta1, theta2, coulomb_change=change, **why)]
        kind = _KINDS[int(ii[self.epi + E.P_KIND])]
        extra = {"friction_evidence": self.level_path if kind == "level" else kind} if kind else {}
        return [self._event(t, "friction_isolated", theta1, theta2, coulomb_change=change, **extra)]

    def _calibrate(self, t: float, theta1: float, theta2: float) -> list[dict[str, Any]]:
        o = self.fo + K.E_CAL
        n = self.calibration_samples
        cal = self.arena.f[o : o + 2 * n].reshape(n, 2)
        valid = cal[np.all(np.isfinite(cal), axis=1)]
        if valid.shape[0] < max(2, n // 4):
            # the rig was mostly at rest: keep calibrating on the newest samples
            cal[: n - 1] = cal[1:].copy()
            self._cal_count = n - 1
            return []
        mean = valid.mean(axis=0)
        std = valid.std(axis=0, ddof=1)
        k = self.settings.band_k
        self.band = {
            "theta1": [float(mean[0] - k * std[0]), float(mean[0] + k * std[0])],
            "theta2": [float(mean[1] - k * std[1]), float(mean[1] + k * std[1])],
        }
        self.arena.f[self.fo + K.E_LO1 : self.fo + K.E_HI2 + 1] = (
            *self.band["theta1"],
            *self.band["theta2"],
        )
        self.arena.i[self.io + K.D_HAS_BAND] = 1
        self.level_base = float(np.median(valid[:, 0]))
        self._cal_count = 0
        self.state = "monitoring"
        return [
            self._event(
                t, "calibrated", theta1, theta2, band=self.band, samples=int(valid.shape[0])
            )
        ]

    def _event(
        self, t: float, kind: str, theta1: float | None, theta2: float | None, **extra: Any
    ) -> dict[str, Any]:
        return make_event(
            t,
            kind,
            theta1,
            theta2,
            statistic=float(self.statistic),
            threshold=float(self.threshold),
            friction_level=self.level.level,
            method=self.settings.method,
            **extra,
        )
