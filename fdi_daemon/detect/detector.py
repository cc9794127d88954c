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

Per tick (``step``) and batch (``run``) give the same events and statistics: the
monitoring path of ``run`` is vectorised with the same arithmetic (bit-equal), and the
rare alarm episodes run through ``step``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from fdi_daemon.core.innovation_test import InnovationTest, innovation, packed_row
from fdi_daemon.core.normal_equations import packed_width, solve_packed
from fdi_daemon.core.sliding_sums import SlidingSums
from fdi_daemon.core.window_ls import MIN_RCOND
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
_CHUNK = 16384


@dataclass
class DetectorTrace:
    """Per-sample outputs of the detector (batch): statistic and state code."""

    statistic: np.ndarray
    state: np.ndarray  # int8 codes into STATES
    theta1: np.ndarray  # θ as reported (`Detector.theta1`)
    theta2: np.ndarray


class Detector:
    """Decides on every tick from the pipeline's signals; see the module docstring."""

    def __init__(self, settings: DetectorSettings, fs_hz: float, gamma_f: float,
                 baseline: bool = False) -> None:
        """``baseline``: the monitor passes the level's excess over a commissioning baseline
        to ``step``/``run`` (else the calibration's level is the fault-free one)."""
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
        # the residual test (φ = g1, g2, x̂̈, 1) and the command test (AR(4) of v_in)
        self.residual_test = InnovationTest(N_REGRESSORS, self.window_samples, self.lag_samples,
                                            self.test_samples, s.reference_every_samples,
                                            s.min_sigma_mps2)
        self.command_test = InnovationTest(COMMAND_ORDER, self.window_samples,
                                           self.lag_samples, self.test_samples,
                                           s.reference_every_samples, s.guard_min_sigma_v)
        self.band: dict[str, list[float]] | None = None
        #: θ as reported for the newest tick: eq. (17) over the sliding window, or during an
        #: alarm episode over the data since the change (`_Episode.theta`)
        self.theta1 = self.theta2 = math.nan
        self.state = "calibrating"
        self._episode: _Episode | None = None
        self._calibration: list[tuple[float, float]] = []
        self.level_samples = s.samples(s.slow_persistence_s, fs_hz)
        #: the fault-free friction level without a baseline: θ1's median over the calibration
        self.level_base = math.nan
        self.restart()

    # ------------------------------------------------------------------ state
    def restart(self) -> None:
        """Forget every window (start-up, data gap); the band and an episode are kept."""
        self._tick = 0
        self.residual_test.reset()
        self.command_test.reset()
        self._v_hist = [0.0] * COMMAND_ORDER  # v[k-1], v[k-2], ...
        self._guard_until = 0
        self._above = 0
        self._level_above = 0
        self._hold_until = self.warmup_samples
        if self.state == "calibrating":
            self._calibration = []
        if self._episode is not None:
            self._episode.restart(self)

    @property
    def threshold(self) -> float:
        return self.settings.threshold

    @property
    def statistic(self) -> float:
        return self.residual_test.statistic

    def _snapshot_state(self) -> dict[str, Any]:
        return {"tick": self._tick, "res": self.residual_test.get_state(),
                "cmd": self.command_test.get_state(), "v": list(self._v_hist),
                "guard": self._guard_until, "above": self._above,
                "level": self._level_above, "calibration": list(self._calibration)}

    def _restore_state(self, st: dict[str, Any]) -> None:
        self._tick = st["tick"]
        self.residual_test.set_state(st["res"])
        self.command_test.set_state(st["cmd"])
        self._v_hist = list(st["v"])
        self._guard_until = st["guard"]
        self._above = st["above"]
        self._level_above = st["level"]
        self._calibration = list(st["calibration"])

    # ------------------------------------------------------------------ per tick
    def step(self, t: float, v_in: float, xhat: float, r: float, g1: float, g2: float,
             theta1: float, theta2: float, over_baseline: float = math.nan
             ) -> list[dict[str, Any]]:
        """One tick; returns the events it raised (usually none). ``over_baseline``: the
        friction level's excess over the commissioning baseline in units of its margin,
        (θ1 − median)/max(friction_min_level/2, k·σ) (NaN: θ not valid; ignored without a
        baseline)."""
        tick = self._tick
        phi = (g1, g2, xhat, 1.0)
        row = packed_row(phi, r)
        self.residual_test.step(phi, r, row)
        hist = self._v_hist
        guard_stat = self.command_test.step(hist, v_in)
        self._v_hist = [v_in] + hist[:-1]
        if guard_stat > self.settings.guard_threshold:
            self._guard_until = tick + self.hold_samples
        self._tick = tick + 1
        self.theta1, self.theta2 = theta1, theta2
        over = self.level_over(theta1, over_baseline)
        return self._decide(tick, t, phi, row, r, theta1, theta2, over)

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

    def _decide(self, tick, t, phi, row, r, theta1, theta2, over) -> list[dict[str, Any]]:
        if self._episode is not None:
            return self._episode.step(self, tick, t, phi, row, r, over)
        if tick < self._hold_until:
            self._above = self._level_above = 0
            return []
        # the level path: from the first valid window against a baseline, else once calibrated
        self._level_above = self._level_above + 1 if over > 1.0 else 0
        if self._level_above >= self.level_samples:
            self._above = self._level_above = 0
            self._episode = _Episode(self, tick, level=True)
            self.state = "fault_detected"
            return [self._event(t, "fault_detected", theta1, theta2, path=self.level_path)]
        if self.state == "calibrating":
            return self._calibrate(t, theta1, theta2)
        self._above = self._above + 1 if self._alarm_condition(tick, theta1, theta2) else 0
        if self._above >= self.settings.persistence_samples:
            self._above = self._level_above = 0
            self._episode = _Episode(self, tick)
            self.state = "fault_detected"
            return [self._event(t, "fault_detected", theta1, theta2, path="fast")]
        return []

    def _alarm_condition(self, tick, theta1, theta2) -> bool:
        if self.settings.method == "band":
            return _outside_band(theta1, theta2, self.band)
        return (self.residual_test.ok and tick >= self._guard_until
                and self.residual_test.statistic > self.threshold)

    def _calibrate(self, t, theta1, theta2) -> list[dict[str, Any]]:
        self._calibration.append((theta1, theta2))
        if len(self._calibration) < self.calibration_samples:
            return []
        cal = np.array(self._calibration, dtype=float)
        valid = cal[np.all(np.isfinite(cal), axis=1)]
        if valid.shape[0] < max(2, self.calibration_samples // 4):
            # the rig was mostly at rest: keep calibrating on the newest samples
            self._calibration = self._calibration[-(self.calibration_samples - 1):]
            return []
        mean = valid.mean(axis=0)
        std = valid.std(axis=0, ddof=1)
        k = self.settings.band_k
        self.band = {"theta1": [float(mean[0] - k * std[0]), float(mean[0] + k * std[0])],
                     "theta2": [float(mean[1] - k * std[1]), float(mean[1] + k * std[1])]}
        self.level_base = float(np.median(valid[:, 0]))
        self._calibration = []
        self.state = "monitoring"
        return [self._event(t, "calibrated", theta1, theta2, band=self.band,
                            samples=int(valid.shape[0]))]

    def _event(self, t, kind, theta1, theta2, **extra) -> dict[str, Any]:
        return make_event(t, kind, theta1, theta2, statistic=float(self.statistic),
                          threshold=float(self.threshold), friction_level=float(theta1),
                          method=self.settings.method, **extra)

    # ------------------------------------------------------------------ batch
    def run(self, t: np.ndarray, v_in: np.ndarray, xhat: np.ndarray, r: np.ndarray,
            g1: np.ndarray, g2: np.ndarray, theta1: np.ndarray, theta2: np.ndarray,
            over_baseline: np.ndarray | None = None
            ) -> tuple[list[dict[str, Any]], DetectorTrace]:
        """Batch ``step`` over arrays: the same events, statistic, states and reported θ."""
        n = len(t)
        over = np.full(n, np.nan) if over_baseline is None else over_baseline
        stat = np.empty(n)
        codes = np.empty(n, dtype=np.int8)
        reported1, reported2 = theta1, theta2  # copied when an episode reports its own θ
        events: list[dict[str, Any]] = []
        pos = 0
        while pos < n:
            if self._episode is None:
                stop = min(n, pos + _CHUNK)
                done = self._run_quiet(pos, stop, t, v_in, xhat, r, g1, g2, theta1, theta2,
                                       over, stat, codes)
                pos += done
                if pos == stop:
                    continue
            # per tick: the tick that raises an event, then an episode until it ends
            while pos < n:
                events.extend(self.step(t[pos], v_in[pos], xhat[pos], r[pos], g1[pos], g2[pos],
                                        theta1[pos], theta2[pos], over[pos]))
                stat[pos] = self.statistic
                codes[pos] = _STATE_CODE[self.state]
                if reported1 is theta1:
                    reported1, reported2 = theta1.copy(), theta2.copy()
                reported1[pos], reported2[pos] = self.theta1, self.theta2
                pos += 1
                if self._episode is None:
                    break
        return events, DetectorTrace(statistic=stat, state=codes, theta1=reported1,
                                     theta2=reported2)

    def _run_quiet(self, pos, stop, t, v_in, xhat, r, g1, g2, theta1, theta2, over, stat,
                   codes) -> int:
        """Vectorised ticks [pos, stop) up to the first one that raises an event (which is
        left to ``step``); returns how many ticks it took."""
        saved = self._snapshot_state()
        sl = slice(pos, stop)
        arrays = self._vector_stats(v_in[sl], xhat[sl], r[sl], g1[sl], g2[sl])
        first = self._first_event(arrays, theta1[sl], theta2[sl], over[sl])
        count = stop - pos
        if first is not None:
            self._restore_state(saved)
            if first == 0:
                return 0
            sl = slice(pos, pos + first)
            arrays = self._vector_stats(v_in[sl], xhat[sl], r[sl], g1[sl], g2[sl])
            count = first
        self._commit_quiet(arrays, theta1[pos:pos + count], theta2[pos:pos + count],
                           over[pos:pos + count])
        if count:
            self.theta1, self.theta2 = theta1[pos + count - 1], theta2[pos + count - 1]
        stat[pos:pos + count] = arrays["stat"]
        codes[pos:pos + count] = _STATE_CODE[self.state]
        return count

    def _vector_stats(self, v_in, xhat, r, g1, g2) -> dict[str, np.ndarray]:
        """The per-tick quantities of ``step`` for arrays (advances the tests)."""
        n = len(r)
        ticks = self._tick + np.arange(n)
        stat, ok, _ = self.residual_test.run(np.column_stack([g1, g2, xhat, np.ones(n)]),
                                                     r)
        hist = np.concatenate([self._v_hist[::-1], v_in])  # oldest first
        m = COMMAND_ORDER
        phi_v = np.column_stack([hist[m - 1 - i:m - 1 - i + n] for i in range(m)])
        guard_stat = self.command_test.run(phi_v, v_in)[0]
        self._v_hist = hist[-1:-m - 1:-1].tolist()
        trig = guard_stat > self.settings.guard_threshold
        until = np.where(trig, ticks + self.hold_samples, -1)
        until = np.maximum(np.maximum.accumulate(until), self._guard_until)
        self._guard_until = int(until[-1])
        self._tick += n
        return {"ticks": ticks, "stat": stat, "ok": ok, "guard_until": until}

    def _quiet_condition(self, arrays, theta1, theta2) -> np.ndarray:
        """Per tick: the fast alarm condition."""
        ticks = arrays["ticks"]
        if self.settings.method == "band":
            fast = _outside_band(theta1, theta2, self.band)
        else:
            fast = arrays["ok"] & (ticks >= arrays["guard_until"]) & (
                arrays["stat"] > self.threshold)
        return fast & (ticks >= self._hold_until)

    def _level_runs(self, arrays, theta1, over_baseline) -> np.ndarray:
        """Per tick: how long the level has been above its fault-free value's margin."""
        with np.errstate(invalid="ignore"):
            above = (self.level_over(theta1, over_baseline) > 1.0) & (
                arrays["ticks"] >= self._hold_until)
        return _run_lengths(above, self._level_above)

    def _first_event(self, arrays, theta1, theta2, over) -> int | None:
        """Index of the first tick that raises an event, or None."""
        level_hits = np.flatnonzero(self._level_runs(arrays, theta1, over)
                                    >= self.level_samples)
        first_level = int(level_hits[0]) if level_hits.size else None
        if self.state == "calibrating":
            active = np.flatnonzero(arrays["ticks"] >= self._hold_until)
            need = self.calibration_samples - len(self._calibration)
            first = int(active[need - 1]) if active.size >= need else None
        else:
            hits = np.flatnonzero(_run_lengths(self._quiet_condition(arrays, theta1, theta2),
                                               self._above)
                                  >= self.settings.persistence_samples)
            first = int(hits[0]) if hits.size else None
        return min((i for i in (first, first_level) if i is not None), default=None)

    def _commit_quiet(self, arrays, theta1, theta2, over) -> None:
        runs = self._level_runs(arrays, theta1, over)
        if runs.size:
            self._level_above = int(runs[-1])
        if self.state == "calibrating":
            sel = np.flatnonzero(arrays["ticks"] >= self._hold_until)
            self._calibration.extend(zip(theta1[sel].tolist(), theta2[sel].tolist()))
            return
        fast = self._quiet_condition(arrays, theta1, theta2)
        if fast.size:
            self._above = int(_run_lengths(fast, self._above)[-1])


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
            # little of it in θ, whose regressors describe sliding), and what raised the
            # episode is gone: the residual test's innovation against the frozen pre-fault
            # reference (a level episode's reference may hold the fault: the level alone)
            normal = (over < 0.5 and (self.level or frozen_stat <= det.threshold)
                      and _moves_freely(det.residual_test.reference_sums))
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
        det._calibration = []
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


def _outside_band(theta1, theta2, band):
    """θ outside the calibrated band (floats or arrays; NaN θ is never outside)."""
    if band is None:
        return np.zeros(np.shape(theta1), dtype=bool) if np.ndim(theta1) else False
    lo1, hi1 = band["theta1"]
    lo2, hi2 = band["theta2"]
    return (theta1 < lo1) | (theta1 > hi1) | (theta2 < lo2) | (theta2 > hi2)


def _run_lengths(cond: np.ndarray, carry: int) -> np.ndarray:
    """Length of the run of True ending at every index (a run at index 0 continues carry)."""
    n = cond.size
    idx = np.arange(n)
    last_false = np.maximum.accumulate(np.where(~cond, idx, -1))
    run = idx - last_false
    head = last_false < 0
    run[head] += carry
    return np.where(cond, run, 0)
