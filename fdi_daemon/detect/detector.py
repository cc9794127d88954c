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
isolation window after the detection: a knock or glitch does not persist); gain (x̂̈) or offset (1) changes without it, or no
friction evidence within ``isolation_timeout_s``, are another fault.

The level path catches friction that creeps in (wear), that starts while the guard holds,
or that is there from the start: the friction level θ1 (eq. 17) above its fault-free value
by more than its margin for ``slow_persistence_s`` -> fault_detected, and the level itself
is the evidence. The fault-free value is the commissioning baseline of the operating
condition (``fdi baseline``; margin max(friction_min_level/2, band_k·σ), computed by the
monitor) or, without one, the median level of the calibration (margin friction_min_level).
A friction episode is cleared when the level has been back within half its margin for
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
from fdi_daemon.core.innovation_test import InnovationTest, innovation, packed_row
from fdi_daemon.core.normal_equations import packed_width, solve_packed
from fdi_daemon.core.sliding_sums import SlidingSums
from fdi_daemon.core.window_ls import MIN_RCOND
from fdi_daemon.detect import kernel as K
from fdi_daemon.detect.events import make_event
from fdi_daemon.detect.settings import DetectorSettings

__all__ = ["Detector", "STATES", "N_REGRESSORS"]

STATES = ("starting", "calibrating", "monitoring", "fault_detected", "friction_isolated",
          "other_fault")
_STATE_CODE = {name: i for i, name in enumerate(STATES)}
_EPISODE = ("fault_detected", "friction_isolated", "other_fault")

#: regressors of the reference fit: g1, g2, x̂̈, 1
N_REGRESSORS = 4
#: order of the autoregressive model of the valve command (the operating-point guard)
COMMAND_ORDER = 4
_WIDTH = packed_width(N_REGRESSORS)
#: isolation beyond a linear change of the plant: g1, x̂̈(k), x̂̈(k-1), 1
_LINEAR_REGRESSORS = 4
_LINEAR_WIDTH = packed_width(_LINEAR_REGRESSORS)
#: the load has stopped: the measured acceleration keeps at most this fraction of the
#: predicted energy (20 % of its RMS) ...
STOPPED_ENERGY_FRACTION = 0.04
#: ... and the accelerometer is alive: its sample-to-sample changes carry more than this
#: fraction of the predicted energy (a dead sensor repeats one value exactly)
FLAT_ENERGY_FRACTION = 1e-6
class Detector:
    """Decides on every tick from the pipeline's signals; see the module docstring."""

    def __init__(self, settings: DetectorSettings, fs_hz: float, gamma_f: float,
                 baseline: bool = False, arena: Arena | None = None,
                 baseline_bins: tuple | None = None) -> None:
        """``baseline``: the level's excess is taken over a commissioning baseline (else
        the calibration's level is the fault-free one); ``baseline_bins``: its (edges,
        median, margin) per velocity-RMS bin, for the kernel."""
        self.settings = settings
        self.has_baseline = bool(baseline)
        self.fs_hz = float(fs_hz)
        self.gamma_f = float(gamma_f)
        s = settings
        self.window_samples = s.samples(s.window_s, fs_hz, minimum=8)
        self.lag_samples = s.samples(s.reference_lag_s, fs_hz, minimum=0)
        self.test_samples = s.samples(s.test_window_s, fs_hz)
        self.calibration_samples = s.samples(s.calibration_s, fs_hz)
        self.warmup_samples = self.window_samples + self.lag_samples + self.test_samples
        hold = s.guard_hold_s if s.guard_hold_s is not None else (
            s.window_s + s.reference_lag_s + s.test_window_s)
        self.hold_samples = s.samples(hold, fs_hz)
        self.iso_samples = s.samples(s.isolation_window_s, fs_hz)
        self.timeout_samples = max(self.iso_samples, s.samples(s.isolation_timeout_s, fs_hz))
        self.clear_samples = s.samples(s.clear_s, fs_hz)
        self.friction_clear_samples = s.samples(s.friction_clear_s, fs_hz)
        self.level_samples = s.samples(s.slow_persistence_s, fs_hz)
        self.arena = arena = arena if arena is not None else Arena()
        # the residual test (φ = g1, g2, x̂̈, 1) and the command test (AR(4) of v_in)
        self.residual_test = InnovationTest(N_REGRESSORS, self.window_samples, self.lag_samples,
                                            self.test_samples, s.reference_every_samples,
                                            s.min_sigma_mps2, arena=arena)
        self.command_test = InnovationTest(COMMAND_ORDER, self.window_samples,
                                           self.lag_samples, self.test_samples,
                                           s.reference_every_samples, s.guard_min_sigma_v,
                                           arena=arena)
        bins = 0 if baseline_bins is None else len(baseline_bins[1])
        self.fo, self.io = fo, io = arena.alloc(
            K.E_CAL + 2 * self.calibration_samples + 3 * bins + 1, K.DET_INTS)
        ii, f = arena.i, arena.f
        ii[io + K.D_METHOD] = 1 if s.method == "band" else 0
        ii[io + K.D_HAS_BASELINE] = int(self.has_baseline)
        ii[io + K.D_HOLD] = self.hold_samples
        ii[io + K.D_LEVEL_SAMPLES] = self.level_samples
        ii[io + K.D_PERSISTENCE] = s.persistence_samples
        ii[io + K.D_CAL_SAMPLES] = self.calibration_samples
        ii[io + K.D_BINS] = bins
        ii[io + K.D_RES] = self.residual_test.io
        ii[io + K.D_CMD] = self.command_test.io
        ii[io + K.D_FLOATS] = fo
        f[fo + K.E_THRESHOLD] = s.threshold
        f[fo + K.E_GUARD_THRESHOLD] = s.guard_threshold
        f[fo + K.E_FRICTION_MIN] = s.friction_min_level
        if baseline_bins is not None:
            o = fo + K.E_CAL + 2 * self.calibration_samples
            f[o:o + 3 * bins + 1] = np.concatenate([np.asarray(v, dtype=float)
                                                   for v in baseline_bins])
        self.band: dict[str, list[float]] | None = None
        #: θ as reported for the newest tick: eq. (17) over the sliding window, or during an
        #: alarm episode over the data since the change (`_Episode.theta`)
        self.theta1 = self.theta2 = math.nan
        self.state = "calibrating"
        self._episode: _Episode | None = None
        #: the fault-free friction level without a baseline: θ1's median over the calibration
        self.level_base = math.nan
        self.restart()

    # ------------------------------------------------------------------ state in the arena
    def _int(k):  # noqa: N805 - a property factory for the ints of the kernel's block
        return property(lambda self: int(self.arena.i[self.io + k]),
                        lambda self, v: self.arena.i.__setitem__(self.io + k, int(v)))

    def _float(k):  # noqa: N805
        return property(lambda self: float(self.arena.f[self.fo + k]),
                        lambda self, v: self.arena.f.__setitem__(self.fo + k, float(v)))

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
    def state(self) -> str:
        return STATES[self.arena.i[self.io + K.D_STATE]]

    @state.setter
    def state(self, name: str) -> None:
        self.arena.i[self.io + K.D_STATE] = _STATE_CODE[name]

    @property
    def _episode(self) -> "_Episode | None":
        return self.__dict__.get("_episode_obj")

    @_episode.setter
    def _episode(self, episode: "_Episode | None") -> None:
        self.__dict__["_episode_obj"] = episode
        self.arena.i[self.io + K.D_EPISODE] = int(episode is not None)

    def restart(self) -> None:
        """Forget every window (start-up, data gap); the band and an episode are kept."""
        self._tick = 0
        self.residual_test.reset()
        self.command_test.reset()
        self.arena.f[self.fo + K.E_VHIST:self.fo + K.E_VHIST + COMMAND_ORDER] = 0.0
        self._guard_until = 0
        self._above = 0
        self._level_above = 0
        self._hold_until = self.warmup_samples
        if self.state == "calibrating":
            self._cal_count = 0
        if self._episode is not None:
            self._episode.restart(self)

    @property
    def threshold(self) -> float:
        return self.settings.threshold

    @property
    def statistic(self) -> float:
        return self.residual_test.statistic

    @property
    def over(self) -> float:
        """The newest tick's level excess (`level_over`)."""
        return float(self.arena.f[self.fo + K.E_OVER])

    def level_over(self, theta1, over_baseline):
        """The friction level's excess over its fault-free value in units of its margin
        (floats or arrays): the monitor's ``over_baseline`` with a commissioning baseline,
        else (θ1 − the calibration's median level)/friction_min_level (NaN before the
        calibration, and at rest)."""
        if self.has_baseline:
            return over_baseline
        return (theta1 - self.level_base) / self.settings.friction_min_level

    @property
    def level_path(self) -> str:
        """What the level path compares with (event field ``path``, ``friction_evidence``)."""
        return "baseline" if self.has_baseline else "level"

    # ------------------------------------------------------------------ decisions
    def decide(self, code: int, t: float, pipeline) -> list[dict[str, Any]]:
        """The Python part of a tick whose kernel code is not QUIET (`detect.kernel`);
        ``pipeline``: the tick's signals (g1, g2, x̂̈, r, θ)."""
        theta1, theta2 = self.theta1, self.theta2
        if code == K.EPISODE:
            phi = (pipeline.g1, pipeline.g2, pipeline.xhat, 1.0)
            r = pipeline.residual
            return self._episode.step(self, self._tick - 1, t, phi, packed_row(phi, r), r,
                                      self.over)
        if code == K.LEVEL_ALARM:
            self._episode = _Episode(self, self._tick - 1, level=True)
            self.state = "fault_detected"
            return [self._event(t, "fault_detected", theta1, theta2, path=self.level_path)]
        if code == K.FAST_ALARM:
            self._episode = _Episode(self, self._tick - 1)
            self.state = "fault_detected"
            return [self._event(t, "fault_detected", theta1, theta2, path="fast")]
        if code == K.CALIBRATED:
            return self._calibrate(t, theta1, theta2)
        return []

    def _calibrate(self, t, theta1, theta2) -> list[dict[str, Any]]:
        o = self.fo + K.E_CAL
        n = self.calibration_samples
        cal = self.arena.f[o:o + 2 * n].reshape(n, 2)
        valid = cal[np.all(np.isfinite(cal), axis=1)]
        if valid.shape[0] < max(2, n // 4):
            # the rig was mostly at rest: keep calibrating on the newest samples
            cal[:n - 1] = cal[1:].copy()
            self._cal_count = n - 1
            return []
        mean = valid.mean(axis=0)
        std = valid.std(axis=0, ddof=1)
        k = self.settings.band_k
        self.band = {"theta1": [float(mean[0] - k * std[0]), float(mean[0] + k * std[0])],
                     "theta2": [float(mean[1] - k * std[1]), float(mean[1] + k * std[1])]}
        self.arena.f[self.fo + K.E_LO1:self.fo + K.E_HI2 + 1] = (
            *self.band["theta1"], *self.band["theta2"])
        self.arena.i[self.io + K.D_HAS_BAND] = 1
        self.level_base = float(np.median(valid[:, 0]))
        self._cal_count = 0
        self.state = "monitoring"
        return [self._event(t, "calibrated", theta1, theta2, band=self.band,
                            samples=int(valid.shape[0]))]

    def _event(self, t, kind, theta1, theta2, **extra) -> dict[str, Any]:
        return make_event(t, kind, theta1, theta2, statistic=float(self.statistic),
                          threshold=float(self.threshold), friction_level=float(theta1),
                          method=self.settings.method, **extra)


class _Episode:
    """One alarm episode: from fault_detected until cleared (always run per tick)."""

    def __init__(self, det: Detector, tick: int, level: bool = False) -> None:
        """``level``: raised by the level path (the level is the evidence), else by the
        innovation test (fast path)."""
        test = det.residual_test
        self.theta_ref = list(test.theta)
        # the Coulomb coefficient of the innovation test's fits just before the change
        self.coulomb_base = self.theta_ref[0]
        self.sigma2_ref = test.sigma2
        self.post = SlidingSums(det.window_samples, _WIDTH)
        for row in test.recent_rows:  # data since the reference window ended, newest included
            self.post.push(row)
        # the same after the fault's onset transient (the first isolation window after the
        # detection, while the motion settles into its new periodic state): θ's window
        self.settled = SlidingSums(det.window_samples, _WIDTH)
        # on the settled window: the innovation against the frozen reference, regressed on
        # g1 and a linear change of the plant (x̂̈ and x̂̈ one tick earlier: any gain and
        # phase change at one frequency, a smooth one across a band) and an offset
        self.beyond_linear = SlidingSums(det.window_samples, _LINEAR_WIDTH)
        self._xhat_past = math.nan
        self.frozen_test = SlidingSums(det.test_samples, 1)
        # over the test window: Σ(ẍ(k) - ẍ(k-1))², Σẍ², Σx̂̈² (has the load stopped?)
        self.motion = SlidingSums(det.test_samples, 3)
        self._accel_past = math.nan
        self.ticks = 0
        self.quiet = 0
        self.track = 0
        self.level_change = math.nan
        self.evidence = math.nan  # Coulomb increase once held for track_samples (friction)
        self.evidence_kind: str | None = None  # and what showed it (`_friction_kind`)
        self.hold_until = 0
        # friction persists, a glitch does not: the fault must still be there (the frozen
        # test above h) on a test window made only of samples more than one isolation
        # window after the detection, long after the samples that raised the alarm.
        # The level path's alarm is persistence itself (slow_persistence_s of the level).
        self.persisted = level
        self.level = level

    def restart(self, det: Detector) -> None:
        """After a data gap: the windows restart, the episode goes on."""
        self.post.reset()
        self.settled.reset()
        self.beyond_linear.reset()
        self._xhat_past = math.nan
        self.frozen_test.reset()
        self.motion.reset()
        self._accel_past = math.nan
        self.quiet = 0
        self.track = 0
        self.hold_until = det.warmup_samples

    def theta(self, det: Detector) -> tuple[float, float]:
        """θ of eq. (17) fitted on the data since the change, without pre-fault data: on the
        settled window (from one isolation window after the detection: the fault's onset
        transient left out) once it holds ``isolation_window_s``, before that on the post
        window (from the end of the reference window) once that does. Falls back to the
        sliding-window θ (NaN at rest, early in the episode, ill-conditioned)."""
        if not math.isfinite(det.theta1):
            return det.theta1, det.theta2
        for window in (self.settled, self.post):
            if window.count >= det.iso_samples:
                s = window.sliding  # packed g1, g2, x̂̈, 1 (normal_equations layout)
                theta, _, ok = solve_packed((s[0], s[1], s[4], s[10], s[11], s[14]), 2,
                                            min_pivot=MIN_RCOND)  # 1 - ρ², as WindowLS
                if ok:
                    return theta[0], theta[1]
        return det.theta1, det.theta2

    def coulomb_beyond_linear(self, det: Detector) -> float:
        """The Coulomb coefficient of the innovation on the settled window once any linear
        change of the plant is allowed for: what g1 explains beyond it (the odd harmonics of
        sign v̂) is dry friction. NaN before the settled window holds
        ``isolation_window_s`` or if the fit is ill-conditioned."""
        if self.beyond_linear.count < det.iso_samples:
            return math.nan
        theta, _, ok = solve_packed(self.beyond_linear.sliding, _LINEAR_REGRESSORS)
        return theta[0] if ok else math.nan

    def load_stopped(self, det: Detector) -> bool:
        """The load has stopped although the model says it moves: over the last test window
        the measured acceleration keeps at most ``STOPPED_ENERGY_FRACTION`` of the energy of
        x̂̈, and it is not a flat line (a dead accelerometer repeats one value; a stopped
        load still shows the sensor's noise)."""
        if self.motion.count < det.test_samples:
            return False
        s_step, s_accel, s_xhat = self.motion.sliding
        return (s_xhat > 0.0 and s_accel <= STOPPED_ENERGY_FRACTION * s_xhat
                and s_step > FLAT_ENERGY_FRACTION * s_xhat)

    def _friction_kind(self, det: Detector) -> str | None:
        """Given a rise of the Coulomb coefficient: is it dry friction? ``"harmonics"``: g1
        explains the innovation beyond any linear change of the plant; ``"load_stopped"``:
        the load has stopped (friction holds it)."""
        if self.coulomb_beyond_linear(det) >= det.settings.friction_min_level:
            return "harmonics"
        return "load_stopped" if self.load_stopped(det) else None

    def step(self, det: Detector, tick, t, phi, row, r, over=math.nan):
        s = det.settings
        moving = math.isfinite(det.theta1)  # the pipeline's window θ: NaN at rest
        self.ticks += 1
        self.post.push(row)
        e = innovation(r, phi, self.theta_ref)
        g1, _, xhat, _ = phi
        if self.ticks > det.iso_samples:
            self.settled.push(row)
            if not math.isnan(self._xhat_past):
                self.beyond_linear.push(packed_row((g1, xhat, self._xhat_past, 1.0), e))
        self._xhat_past = xhat
        accel = r + xhat
        if not math.isnan(self._accel_past):
            step = accel - self._accel_past
            self.motion.push((step * step, accel * accel, xhat * xhat))
        self._accel_past = accel
        det.theta1, det.theta2 = theta1, theta2 = self.theta(det)
        frozen_stat = self.frozen_test.push((e * e / self.sigma2_ref,))[0] / det.test_samples
        if tick < self.hold_until:
            return []
        if self.ticks > det.iso_samples + det.test_samples and frozen_stat > det.threshold:
            self.persisted = True
        if s.method == "band":
            return self._step_band(det, t, theta1, theta2)
        kind = None  # what shows the friction on this tick (None: nothing)
        if self.post.count >= det.iso_samples:
            theta, _, ok = solve_packed(self.post.sliding, N_REGRESSORS)
            if ok:
                self.level_change = theta[0] - self.coulomb_base
                if self.level_change >= s.friction_min_level or over > 1.0:
                    kind = self._friction_kind(det)
        if self.level:
            kind = det.level_path if over > 1.0 else None
        if det.state in ("fault_detected", "other_fault"):
            # friction evidence that comes after the timeout (a fault that grows) turns an
            # other_fault into friction; the reverse never happens
            self.track = self.track + 1 if kind else 0
            if self.track >= s.track_samples and math.isnan(self.evidence):
                # on the level path: the level's excess over its fault-free value (margins)
                self.evidence = over if self.level else self.level_change
                self.evidence_kind = kind
            if not math.isnan(self.evidence) and self.persisted:
                self.level_change = self.evidence
                return self._to(det, "friction_isolated", t, theta1, theta2)
            if det.state == "fault_detected" and self.ticks >= det.timeout_samples:
                return self._to(det, "other_fault", t, theta1, theta2)
        if det.state == "friction_isolated":
            # gone when the level is back within half its margin of the fault-free value,
            # and the load moves freely (a load that friction holds part of the time shows
            # little of it in θ, whose regressors describe sliding)
            normal = over < 0.5 and _moves_freely(det.residual_test.reference_sums)
            needed = det.friction_clear_samples
        else:
            normal = frozen_stat <= det.threshold
            needed = det.clear_samples
        # at rest nothing shows a fault, nor its absence: no clearing
        self.quiet = self.quiet + 1 if normal and moving else 0
        if self.quiet >= needed:
            return self._clear(det, t, theta1, theta2)
        return []

    def _step_band(self, det, t, theta1, theta2):
        s = det.settings
        if det.state == "fault_detected":
            tol1 = s.track_tolerance
            tol2 = s.track_tolerance * max(abs(det.gamma_f), 1.0)
            tracking = abs(theta1 - 1.0) <= tol1 and abs(theta2 - det.gamma_f) <= tol2
            self.track = self.track + 1 if tracking else 0
            if self.track >= s.track_samples:
                return self._to(det, "friction_isolated", t, theta1, theta2)
            if self.ticks >= det.timeout_samples:
                return self._to(det, "other_fault", t, theta1, theta2)
        inside = math.isfinite(theta1) and not _outside_band(theta1, theta2, det.band)
        self.quiet = self.quiet + 1 if inside else 0
        if self.quiet >= det.clear_samples:
            return self._clear(det, t, theta1, theta2)
        return []

    def _to(self, det, state, t, theta1, theta2):
        det.state = state
        self.quiet = 0
        extra = {"friction_evidence": self.evidence_kind} if (
            state == "friction_isolated" and self.evidence_kind) else {}
        return [det._event(t, state, theta1, theta2, coulomb_change=float(self.level_change),
                           **extra)]

    def _clear(self, det, t, theta1, theta2):
        # an episode raised against the baseline: the calibration (if any) saw the friction
        # as normal, so calibrate again on the fault-free rig
        det.state = ("calibrating" if (self.level and det.has_baseline) or det.band is None
                     else "monitoring")
        det._cal_count = 0
        det._episode = None
        det._above = 0
        # the moving reference still holds fault data: wait until it has passed
        det._guard_until = max(det._guard_until, det._tick + det.hold_samples)
        return [det._event(t, "cleared", theta1, theta2)]


def _moves_freely(sums) -> bool:
    """Over the reference window the measured acceleration has at least half the energy the
    model predicts: Σẍ² = Σr² + 2Σx̂̈r + Σx̂̈² >= Σx̂̈²/2 (a load stuck by friction does not)."""
    s_xx, s_xr, s_rr = sums[7], sums[12], sums[14]
    return s_xx > 0.0 and s_rr + 2.0 * s_xr + s_xx >= 0.5 * s_xx


def _outside_band(theta1, theta2, band) -> bool:
    """θ outside the calibrated band (NaN θ is never outside)."""
    if band is None:
        return False
    lo1, hi1 = band["theta1"]
    lo2, hi2 = band["theta2"]
    return (theta1 < lo1) or (theta1 > hi1) or (theta2 < lo2) or (theta2 > hi2)
