"""The monitor: samples in, events out; one object for the daemon (``step``) and replay (``run``).

Per sample: the link's checks (sequence, finite values, saturation), the signal chain
(`Pipeline`: x̂̈, residual, velocity, g1, g2, θ of eq. 17) and the `Detector`.

Bad samples. A sample whose ``v_in`` is not finite keeps the last good valve voltage; a
sample whose ``accel`` is not finite or at/above ``accel_limit_mps2`` (when the model sets
one) is replaced by the model's prediction x̂̈, so its residual is 0 (no evidence either
way) and the velocity estimator integrates a plausible value. A sample whose ``seq`` does
not advance (duplicate, going backwards) is dropped. Each run of bad samples gives one
``bad_sample`` event (at the first one's time, with ``count`` and ``reason``) when the run
ends or reaches one second.

Gaps. A ``seq`` jump (or, without ``seq``, a time step over 1.5 sample periods) gives a
``data_gap`` event with ``missing_samples``; every filter and window restarts and the
detector holds its decisions until its windows are full again (an ongoing alarm episode
and the calibrated band are kept).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from fdi_daemon.core.compiled import Arena, jit
from fdi_daemon.detect import kernel as K
from fdi_daemon.detect.baseline import Baseline
from fdi_daemon.detect.detector import STATES, Detector
from fdi_daemon.detect.events import make_event
from fdi_daemon.detect.history import History
from fdi_daemon.detect.pipeline import Pipeline
from fdi_daemon.detect.settings import DetectorSettings
from fdi_daemon.errors import ConfigError, UserError
from fdi_daemon.io.model_file import FdiModel
from fdi_daemon.io.outputs import finite_or_none
from fdi_daemon.io.recordings import Recording
from fdi_daemon.io.sample import Sample

__all__ = ["Monitor", "MonitorTrace"]

#: the arrays of a `MonitorTrace`, in order
TRACE_NAMES = (
    "t",
    "accel",
    "residual",
    "theta1",
    "theta2",
    "statistic",
    "state",
    "v_rms",
    "friction_level",
)
HISTORY_S = 30.0
HISTORY_POINTS = 300
_CHUNK = 16384


log = logging.getLogger("fdi.monitor")


@dataclass
class MonitorTrace:
    """Per-sample signals of a batch run (every ``every``-th sample)."""

    every: int
    t: np.ndarray
    accel: np.ndarray
    residual: np.ndarray
    theta1: np.ndarray
    theta2: np.ndarray
    statistic: np.ndarray
    state: np.ndarray  # int8 codes into detect.detector.STATES
    v_rms: np.ndarray  # the window's velocity RMS (m/s): the baseline's operating condition
    friction_level: np.ndarray  # the reported level (`detect.friction_level`)


class Monitor:
    """Friction FDI monitor of one rig (see the module docstring)."""

    def __init__(self, model: FdiModel) -> None:
        if model.fault_filter is None:
            raise ConfigError("the model has no fault_filter (G_e, γ_f): run `fdi signature` first")
        detector_map = dict(model.detector or {})
        self.accel_limit_mps2 = detector_map.pop("accel_limit_mps2", None)
        if self.accel_limit_mps2 is not None and (
            isinstance(self.accel_limit_mps2, bool)
            or not isinstance(self.accel_limit_mps2, (int, float))
            or not self.accel_limit_mps2 > 0
        ):
            raise ConfigError("detector.accel_limit_mps2 must be a positive number")
        check_stable(model.fault_filter.f, "fault_filter.f")
        check_stable(model.plant_a, "plant.a")
        self.model = model
        self.settings = DetectorSettings.from_mapping(detector_map)
        self.fs_hz = float(model.fs)
        gamma_f = model.fault_filter.gamma_f
        if gamma_f is None and self.settings.method == "band":
            raise ConfigError(
                "detector.method band tracks the signature (1, gamma_f), but the "
                "model's gamma_f is not identified (null): use method sequential "
                "or calibrate the signature again (docs/identification.md)"
            )
        self.gamma_f = float("nan") if gamma_f is None else float(gamma_f)
        self.baseline = None
        self.baseline_note = (
            "the model has no commissioning baseline: friction present "
            "when monitoring starts is not reported (run `fdi baseline`)"
        )
        if model.extra.get("baseline") is not None:
            if not isinstance(model.extra["baseline"], dict):
                raise ConfigError("model: baseline must be a mapping (from `fdi baseline`)")
            self.baseline = Baseline.from_mapping(model.extra["baseline"])
            self.baseline_note = ""
            self._margin = np.maximum(
                0.5 * self.settings.friction_min_level,
                self.settings.band_k * self.baseline.coulomb_sigma,
            )
        else:
            log.info(self.baseline_note)
        self.arena = Arena()
        bins = (
            None
            if self.baseline is None
            else (self.baseline.edges_mps, self.baseline.coulomb_median, self._margin)
        )
        self.detector = Detector(
            self.settings,
            self.fs_hz,
            self.gamma_f,
            baseline=self.baseline is not None,
            arena=self.arena,
            baseline_bins=bins,
            drift_reference=model.fault_filter.drift is not None,
        )
        self.pipeline = Pipeline(
            model,
            self.detector.window_samples,
            min_velocity_rms_mps=self.settings.min_velocity_rms_mps,
            arena=self.arena,
            trust_phase_deg=self.settings.velocity_trust_phase_deg,
            trust_share=self.settings.velocity_trust_share,
            band_fraction=self.settings.signature_band_fraction,
        )
        self.arena.i[self.detector.io + K.D_CHAIN] = self.pipeline.io
        self._io = self.detector.io
        self._history_every = max(1, int(math.ceil(HISTORY_S * self.fs_hz / HISTORY_POINTS)))
        self._history = History(HISTORY_POINTS)
        self._scratch: tuple[np.ndarray, ...] | None = None  # see `_outputs`
        self._samples = 0
        self._last_seq: int | None = None
        self._last_t = math.nan
        self._v_in = 0.0
        self._bad_run = 0
        self._bad_t = math.nan
        self._bad_reason = ""

    def warm_up(self) -> None:
        """Compile (or load from numba's cache) every kernel ``step`` and ``run`` call, on a
        copy of the state: the daemon calls it before it serves, so no tick pays for it."""
        f, ii = self.arena.f.copy(), self.arena.i.copy()
        K.monitor_tick(f, ii, self._io, 0.0, 0.0, math.nan, 0.0)
        one = np.zeros(1)
        K.monitor_run(
            f,
            ii,
            self._io,
            one,
            one,
            one,
            one,
            0,
            one.copy(),
            np.zeros(1, dtype=np.int8),
            *(one.copy() for _ in range(5)),
        )
        from fdi_daemon.detect.episode_kernel import episode_restart

        episode_restart(f, ii, self.detector.epi)

    # ------------------------------------------------------------------ per tick
    def step(self, sample: Sample) -> list[dict[str, Any]]:
        """One link tick; returns the events it raised (one compiled call, `monitor_tick`)."""
        seq = int(sample.seq)
        last = self._last_seq
        v_in = sample.v_in
        accel = sample.accel
        t = sample.t
        pl = self.pipeline
        if (
            last is not None
            and seq == last + 1
            and not self._bad_run
            and math.isfinite(v_in)
            and math.isfinite(accel)
            and math.isfinite(t)
            and self.accel_limit_mps2 is None
            and not pl.needs_position
            and not pl.external_plant
        ):
            # the usual tick: nothing to check further, nothing to replace
            self._last_seq = seq
            self._v_in = v_in
            self._last_t = t
            code = K.monitor_tick(
                self.arena.f, self.arena.i, self._io, float(v_in), float(accel), math.nan, 0.0
            )
            events = self.detector.decide(code, t) if code else []
            if self._samples % self._history_every == 0:
                self._history.append(t, self.detector.theta1, self.detector.theta2)
            self._samples += 1
            return events
        events = []  # typed by the fast path's `events` above
        if last is not None:
            if seq <= last:
                reason = "duplicate" if seq == last else "backwards"
                return self._bad(t, reason, events)
            if seq > last + 1:
                events.extend(self._flush_bad())
                events.append(self._gap(t, seq - last - 1))
        self._last_seq = seq
        reason = ""
        if not math.isfinite(v_in):
            v_in = self._v_in
            reason = "v_in not finite"
        if not math.isfinite(accel):
            accel = math.nan
            reason = reason or "accel not finite"
        elif self.accel_limit_mps2 is not None and abs(accel) >= self.accel_limit_mps2:
            accel = math.nan
            reason = reason or "accel saturated"
        if pl.needs_position and not math.isfinite(sample.position):
            reason = reason or "position not finite"  # the velocity holds the last position
        t = t if math.isfinite(t) else self._last_t + 1.0 / self.fs_hz
        if reason:
            self._bad(t, reason, events)
        elif self._bad_run:
            events.extend(self._flush_bad())
        self._v_in = v_in
        self._last_t = t
        xext = pl.plant.step(v_in) if pl.external_plant else 0.0
        code = K.monitor_tick(
            self.arena.f,
            self.arena.i,
            self._io,
            float(v_in),
            float(accel),
            float(sample.position),
            xext,
        )
        if code:
            events.extend(self.detector.decide(code, t))
        if self._samples % self._history_every == 0:
            self._history.append(t, self.detector.theta1, self.detector.theta2)
        self._samples += 1
        return events

    def _bad(self, t: float, reason: str, events: list[dict[str, Any]]) -> list[dict[str, Any]]:
        if not self._bad_run:
            self._bad_t = t
            self._bad_reason = reason
        self._bad_run += 1
        if self._bad_run >= int(self.fs_hz):
            events.extend(self._flush_bad())
        return events

    def _flush_bad(self) -> list[dict[str, Any]]:
        if not self._bad_run:
            return []
        ev = make_event(self._bad_t, "bad_sample", count=self._bad_run, reason=self._bad_reason)
        self._bad_run = 0
        return [ev]

    def _gap(self, t: float, missing: int) -> dict[str, Any]:
        self.pipeline.reset()
        self.detector.restart()
        return make_event(t, "data_gap", missing_samples=int(missing))

    def finish(self) -> list[dict[str, Any]]:
        """Events still pending at the end of a stream (an unfinished run of bad samples)."""
        return self._flush_bad()

    # ------------------------------------------------------------------ batch
    def run(
        self,
        rec: Recording,
        trace_every: int = 1,
        progress: Callable[[int, int], object] | None = None,
        final: bool = True,
    ) -> tuple[list[dict[str, Any]], MonitorTrace]:
        """Replay a recording through the batch path; same events as ``step`` per sample.

        trace_every: keep every n-th sample in the trace (1: all). progress(done, total) is
        called after every chunk. A recording in pieces (a file streamed chunk by chunk) is
        one ``run`` per piece with ``final=False`` but for the last: the events, trace rows
        and final state are those of one ``run`` over the whole (a run of bad samples
        across pieces stays one event; without ``seq``, the time step from the previous
        piece's last sample tells a gap).
        """
        t, v_in, accel, position, seq = self._columns(rec)
        n = t.size
        needs_position = self.pipeline.needs_position
        last: int | None = None  # the number of the sample before the chunk (no seq column)
        events: list[dict[str, Any]] = []
        parts: dict[str, list[np.ndarray]] = {k: [] for k in TRACE_NAMES}
        start = 0
        limit = math.inf if self.accel_limit_mps2 is None else float(self.accel_limit_mps2)
        # a piece that continues an earlier one, without seq: its first sample's number
        # comes from the time step after the previous piece's last sample (general path)
        resumed = seq is None and self._last_seq is not None and math.isfinite(self._last_t)
        while start < n:
            stop = min(n, start + _CHUNK)
            chunk = (
                t[start:stop],
                v_in[start:stop],
                accel[start:stop],
                position[start:stop] if needs_position else position[: stop - start],
            )
            # the number of the chunk's first sample if it follows on
            if seq is not None:
                first = int(seq[start])
            elif start > 0:
                assert last is not None  # set by the previous chunk
                first = last + 1
            else:
                first = 0 if self._last_seq is None else self._last_seq + 1
            follows = not (resumed and start == 0) and (
                self._last_seq is None or first == self._last_seq + 1
            )
            if (
                follows
                and not self._bad_run
                and _clean_chunk(
                    t,
                    v_in,
                    accel,
                    position,
                    needs_position,
                    start,
                    stop,
                    limit,
                    self.fs_hz,
                    _NO_SEQ if seq is None else seq,
                    start > 0,
                )
            ):
                # the usual chunk (one compiled pass says so): nothing to replace or split
                events.extend(self._run_good(*chunk, parts, trace_every))
                self._last_seq = last = first + stop - start - 1
            else:
                numbers, last = self._chunk_numbers(t, seq, start, stop, last, resumed)
                events.extend(self._run_chunk(*chunk, numbers, parts, trace_every))
            start = stop
            if progress is not None:
                progress(stop, n)
        if final:
            events.extend(self.finish())
        trace = MonitorTrace(
            every=trace_every,
            **{k: (np.concatenate(v) if v else np.empty(0)) for k, v in parts.items()},
        )
        return events, trace

    def baseline_level(self) -> float | None:
        """The commissioning baseline's fault-free level at the current operating condition
        (the bin of the window's velocity RMS); None without a baseline."""
        if self.baseline is None:
            return None
        return finite_or_none(self.baseline_levels(self.pipeline.v_rms))

    def baseline_levels(self, v_rms_mps: np.ndarray | float) -> Any:
        """`baseline_level` at each velocity RMS (m/s; array or scalar); NaN without one."""
        if self.baseline is None:
            return np.full(np.shape(v_rms_mps), np.nan)
        return self.baseline.level_median[self.baseline.bin_index(v_rms_mps)]

    def over_baseline(self, theta1: np.ndarray | float, v_rms: np.ndarray | float) -> Any:
        """(θ1 − baseline median)/margin of the bin of the window's velocity RMS; margin =
        max(friction_min_level/2, band_k·σ). Above 1: friction beyond the fault-free level."""
        assert self.baseline is not None  # called only with a baseline
        idx = self.baseline.bin_index(v_rms)
        return (theta1 - self.baseline.coulomb_median[idx]) / self._margin[idx]

    def position_column(self, rec: Recording) -> np.ndarray:
        """The recording's ``position`` (m) when the velocity fuses it, else NaN; a model
        whose velocity needs position and a recording without it: UserError."""
        n = len(rec.columns["t"])
        if not self.pipeline.needs_position:
            return np.full(n, np.nan)
        if "position" not in rec.columns:
            raise UserError(
                "the model's velocity fuses position (velocity.method "
                "position_observer) but the recording has no position column"
            )
        return np.asarray(rec.columns["position"], dtype=float)

    def _columns(
        self, rec: Recording
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
        """(t s, v_in V, accel m/s², position m, seq or None) of a recording as arrays; the
        position is NaN for a velocity that does not use it (one chunk's worth, reused)."""
        cols = rec.columns
        n = len(cols["t"])
        position = (
            self.position_column(rec)
            if self.pipeline.needs_position
            else np.full(min(n, _CHUNK), np.nan)
        )
        return (
            np.asarray(cols["t"], dtype=float),
            np.asarray(cols["v_in"], dtype=float),
            np.asarray(cols["accel"], dtype=float),
            position,
            np.asarray(cols["seq"], dtype=np.int64) if "seq" in cols else None,
        )

    def _chunk_numbers(
        self,
        t: np.ndarray,
        seq: np.ndarray | None,
        start: int,
        stop: int,
        last: int | None,
        resumed: bool,
    ) -> tuple[np.ndarray, int | None]:
        """(the sample numbers of t[start:stop], the number of its last sample, or ``last``
        as it was with a seq column): the recording's seq, else from the time steps, after
        the sample before the chunk or, for a piece that resumes an earlier one, after that
        piece's last sample."""
        if seq is not None:
            return seq[start:stop], last
        if resumed and start == 0:
            with_last = np.concatenate(([self._last_t], t[:stop]))
            numbers = self.sample_numbers(with_last, self._last_seq)[1:]
        else:
            lo = max(start - 1, 0)
            numbers = self.sample_numbers(t[lo:stop], last)[start - lo :]
        return numbers, int(numbers[-1])

    def sample_numbers(self, t: np.ndarray, base: int | None = None) -> np.ndarray:
        """Sample numbers from the time column (recordings without ``seq``); ``base``: the
        first sample's (default: the one after the last sample seen)."""
        if t.size == 0:
            return np.zeros(0, dtype=np.int64)
        with np.errstate(invalid="ignore"):
            steps = np.diff(t)
            steps *= self.fs_hz
            np.rint(steps, out=steps)
        if base is None:
            base = 0 if self._last_seq is None else self._last_seq + 1
        if (steps == 1.0).all():  # a regular time column (the usual case)
            return np.arange(base, base + t.size, dtype=np.int64)
        steps = np.where(np.isfinite(steps), steps, 1).astype(np.int64)
        return base + np.concatenate([[0], np.cumsum(steps)])

    def _run_chunk(
        self,
        t: np.ndarray,
        v_in: np.ndarray,
        accel: np.ndarray,
        position: np.ndarray,
        seq: np.ndarray,
        parts: dict[str, list[np.ndarray]],
        trace_every: int,
    ) -> list[dict[str, Any]]:
        events: list[dict[str, Any]] = []
        # split where seq does not advance by exactly one: gaps and dropped samples
        step = np.empty_like(seq)
        if seq.size:
            step[0] = seq[0] - self._last_seq if self._last_seq is not None else 1
            np.subtract(seq[1:], seq[:-1], out=step[1:])
        irregular = step != 1
        cuts = np.flatnonzero(irregular) if irregular.any() else np.zeros(0, dtype=np.intp)
        bounds = np.concatenate([[0], cuts, [seq.size]])
        for a, b in zip(bounds[:-1], bounds[1:]):
            if a == b:
                continue
            if step[a] != 1 and self._last_seq is not None:
                if seq[a] <= self._last_seq:
                    # duplicates / going backwards: drop them one at a time (rare); the
                    # samples after them in this run are traced like any other
                    for k in range(a, b):
                        ticks = self._samples
                        events.extend(
                            self.step(
                                Sample(
                                    int(seq[k]),
                                    float(t[k]),
                                    float(v_in[k]),
                                    float(accel[k]),
                                    float(position[k]),
                                )
                            )
                        )
                        if self._samples > ticks:
                            self._trace_one(parts, trace_every)
                    continue
                events.extend(self._flush_bad())
                events.append(self._gap(float(t[a]), int(seq[a] - self._last_seq - 1)))
            if step[a] != 1:
                self._last_seq = int(seq[a]) - 1
            events.extend(
                self._run_contiguous(
                    t[a:b], v_in[a:b], accel[a:b], position[a:b], parts, trace_every
                )
            )
            self._last_seq = int(seq[b - 1])
        return events

    def _run_contiguous(
        self,
        t: np.ndarray,
        v_in: np.ndarray,
        accel: np.ndarray,
        position: np.ndarray,
        parts: dict[str, list[np.ndarray]],
        trace_every: int,
    ) -> list[dict[str, Any]]:
        """Samples with consecutive seq: good runs batched, bad samples through ``step``."""
        events: list[dict[str, Any]] = []
        good = np.isfinite(v_in)
        good &= np.isfinite(accel)
        good &= np.isfinite(t)
        if self.pipeline.needs_position:
            good &= np.isfinite(position)
        if self.accel_limit_mps2 is not None:
            with np.errstate(invalid="ignore"):
                good &= np.abs(accel) < self.accel_limit_mps2
        bad = ~good
        edges = (
            np.flatnonzero(np.diff(bad.astype(np.int8))) + 1
            if not good.all()
            else np.zeros(0, dtype=np.intp)
        )
        bounds = np.concatenate([[0], edges, [len(t)]])
        for a, b in zip(bounds[:-1], bounds[1:]):
            if bad[a] or self._bad_run:
                # bad samples, and the good one that ends their run, go through step()
                last = b if bad[a] else a + 1
                for k in range(a, last):
                    seq = self._last_seq + 1 if self._last_seq is not None else 0
                    events.extend(
                        self.step(
                            Sample(
                                seq,
                                float(t[k]),
                                float(v_in[k]),
                                float(accel[k]),
                                float(position[k]),
                            )
                        )
                    )
                    self._trace_one(parts, trace_every)
                a = last
            if a < b:
                events.extend(
                    self._run_good(t[a:b], v_in[a:b], accel[a:b], position[a:b], parts, trace_every)
                )
        return events

    def _run_good(
        self,
        t: np.ndarray,
        v_in: np.ndarray,
        accel: np.ndarray,
        position: np.ndarray,
        parts: dict[str, list[np.ndarray]],
        trace_every: int,
    ) -> list[dict[str, Any]]:
        """Good samples with consecutive seq: `monitor_run` over the arrays, handing the
        ticks that need Python (events, episodes) to `Detector.decide` as ``step`` does."""
        pl = self.pipeline
        det = self.detector
        n = len(t)
        v_in = np.ascontiguousarray(v_in, dtype=float)
        accel = np.ascontiguousarray(accel, dtype=float)
        position = np.ascontiguousarray(position, dtype=float)
        xext = pl.external_xhat(v_in)
        stat, theta1, theta2, residual, v_rms, level, state = self._outputs(n, trace_every)
        f, ii, io = self.arena.f, self.arena.i, self._io
        events: list[dict[str, Any]] = []
        pos = 0
        while pos < n:
            pos = K.monitor_run(
                f,
                ii,
                io,
                v_in,
                accel,
                position,
                xext,
                pos,
                stat,
                state,
                theta1,
                theta2,
                residual,
                v_rms,
                level,
            )
            code = int(ii[io + K.D_CODE])
            if code:
                k = pos - 1
                events.extend(det.decide(code, float(t[k])))
                state[k] = STATES.index(det.state)
                theta1[k], theta2[k] = det.theta1, det.theta2
        every = self._history_every
        first = (-self._samples) % every
        self._history.extend(t[first::every], theta1[first::every], theta2[first::every])
        # every sample: the arrays themselves (new ones per chunk, `_outputs`); every n-th:
        # a copy (the arrays serve the next chunk)
        keep = slice((-self._samples) % trace_every, n, trace_every)
        for name, values in zip(
            TRACE_NAMES, (t, accel, residual, theta1, theta2, stat, state, v_rms, level)
        ):
            parts[name].append(values if trace_every == 1 else values[keep].copy())
        self._samples += n
        self._v_in = float(v_in[-1])
        self._last_t = float(t[-1])
        if self._last_seq is not None:
            self._last_seq += n
        else:
            self._last_seq = n - 1
        return events

    def _outputs(self, n: int, trace_every: int) -> tuple[np.ndarray, ...]:
        """`monitor_run`'s per-sample outputs for ``n`` samples (stat, θ1, θ2, residual,
        v_rms, level, state). A trace of every sample keeps them, so they are new; otherwise
        the same arrays serve every chunk (the trace copies the samples it keeps), and the
        memory stays in cache instead of being handed back and faulted in again."""
        if trace_every == 1 or n > _CHUNK:
            return (*(np.empty(n) for _ in range(6)), np.empty(n, dtype=np.int8))
        if self._scratch is None:
            self._scratch = (*(np.empty(_CHUNK) for _ in range(6)), np.empty(_CHUNK, dtype=np.int8))
        return tuple(a[:n] for a in self._scratch)

    def _trace_one(self, parts: dict[str, list[np.ndarray]], trace_every: int) -> None:
        if (self._samples - 1) % trace_every:
            return
        for name, value in zip(TRACE_NAMES, self.trace_row(self._last_t)):
            parts[name].append(np.array([value], dtype=np.int8 if name == "state" else float))

    def trace_row(self, t: float) -> tuple[float, ...]:
        """The newest tick's values in the order of TRACE_NAMES, its time given as ``t``."""
        pl, det = self.pipeline, self.detector
        return (
            t,
            pl.residual + pl.xhat,
            pl.residual,
            det.theta1,
            det.theta2,
            det.statistic,
            STATES.index(det.state),
            pl.v_rms,
            det.level.level,
        )

    # ------------------------------------------------------------------ status
    def snapshot(self) -> dict[str, Any]:
        """The ``monitor`` part of the status snapshot (TEAM.md schema)."""
        wls = self.pipeline.wls
        det = self.detector
        syy = wls.sums[5]
        count = wls.count
        hist = self._history.points().tolist()
        return {
            "state": det.state if self._samples else "starting",
            "theta1": finite_or_none(det.theta1),
            "theta2": finite_or_none(det.theta2),
            "friction_level": finite_or_none(det.level.level),
            "friction_level_spread": finite_or_none(det.level.spread),
            "baseline_level": self.baseline_level(),
            "band": det.band,
            "signature": [1.0, finite_or_none(self.gamma_f)],
            "residual_rms": finite_or_none(math.sqrt(syy / count)) if count and syy >= 0 else None,
            "statistic": finite_or_none(det.statistic),
            "threshold": float(det.threshold),
            "history": {
                "t": [h[0] for h in hist],
                "theta1": [finite_or_none(h[1]) for h in hist],
                "theta2": [finite_or_none(h[2]) for h in hist],
            },
        }


def check_stable(a: np.ndarray, name: str) -> None:
    """A monitor built on an unstable (or marginally stable) filter would drift: refuse it."""
    a = np.asarray(a, dtype=float)
    if a.size > 1:
        radius = float(np.max(np.abs(np.roots(a))))
        if not radius < 1.0:
            raise ConfigError(
                f"model {name} has a pole at |z| = {radius:.9g} (>= 1): the "
                f"filter is not stable; re-run the identification"
            )


_NO_SEQ = np.zeros(0, dtype=np.int64)


@jit
def _clean_chunk(
    t: np.ndarray,
    v_in: np.ndarray,
    accel: np.ndarray,
    position: np.ndarray,
    needs_position: bool,
    start: int,
    stop: int,
    accel_limit: float,
    fs_hz: float,
    seq: np.ndarray,
    after_previous: bool,
) -> bool:  # pragma: no cover - jit
    """Whether samples [start, stop) need none of `Monitor.run`'s checks: every value
    finite (position only when the velocity uses it), |accel| below the limit, and numbered
    on without a gap: ``seq`` advancing by one, or without ``seq`` (empty) time steps that
    round to one sample period (from the sample before ``start`` when ``after_previous``),
    as `Monitor.sample_numbers` counts them."""
    # no early exit: the loops vectorise; a chunk that is not clean is the rare one
    ok = True
    for k in range(start, stop):
        ok &= math.isfinite(t[k]) & math.isfinite(v_in[k]) & (abs(accel[k]) < accel_limit)
    if needs_position:
        for k in range(start, stop):
            ok &= math.isfinite(position[k])
    if seq.size:
        for k in range(start + 1, stop):
            ok &= seq[k] == seq[k - 1] + 1
    else:
        for k in range(start if after_previous else start + 1, stop):
            steps = (t[k] - t[k - 1]) * fs_hz
            ok &= (0.5 < steps) & (steps < 1.5)  # np.rint(steps) == 1
    return ok
