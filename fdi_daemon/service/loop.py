"""The daemon's sample loop: link -> monitor -> sinks, paced by the device's counter.

One iteration: ``link.read(read_timeout_s)`` returns whatever arrived; every sample goes
through ``Monitor.step``; events go to the sink worker (critical lane: never dropped),
sample batches to the recorder worker and status snapshots to the sink worker (both
non-critical: dropped and counted when their queue is full). The loop itself never
touches a file or a socket, so a slow sink can not block it.

Timing (monotonic clock only):
- tick latency: from the moment the link delivered a sample to the end of its
  ``Monitor.step`` (waiting behind earlier samples of the same batch included);
- lateness: end of the step minus the sample's due time. Due times come from the device's
  sample counter: ``seq / fs + offset``, where offset is the smallest ``arrival - seq/fs``
  seen over the last ~10 s (the fastest delivery; a windowed minimum follows clock drift
  between device and host). A tick later than ``deadline_s`` is a deadline miss; a miss whose
  sample already *arrived* later than ``deadline_s`` is also a late arrival (the device or
  the link was late, not the daemon). A miss is logged, at most once per
  `MISS_LOG_PERIOD_S`, with both figures.
Both go into log-spaced histograms (p50/p99 in the status snapshot).

Alarms. With an `AlarmKeeper` (``alarms=``), every detector event and every status
refresh also feed the alarm lifecycle; its events go out like the monitor's (critical
lane), followed by the state to persist (``outputs.alarm_state``); a finished trend minute
goes to ``outputs.trend``. Acknowledge/shelve requests answered by the servers are emitted
from here too (`AlarmKeeper.take_pending`). ``event_counts`` continue the counts of the
previous run (the state file) or of the loop before a reload.

Watchdog. ``WATCHDOG=1`` every ``watchdog_period_s`` for as long as the loop iterates,
samples or not: it means "the process and its loop are alive". A link that delivers
nothing is a status (``link.connected``) and a ``link_lost`` / ``link_restored`` pair,
never a restart by systemd.

Sequence check. Gaps and duplicates are the monitor's to handle (`Monitor.step` sees
``seq``: a jump forward gives a ``data_gap`` event and restarts its estimator, a repeat or
small step back is a ``bad_sample`` and skipped); the loop counts them for the status. A step
back by more than `RESTART_STEP_SAMPLES` is a restarted device: the loop then renumbers
the samples it hands to the monitor so that they continue the monitor's count after a
one-sample jump, which restarts the estimator like any gap, and marks that ``data_gap``
event with ``reason: counter_restart`` and ``missing_samples: null`` (the number lost is
unknown). The recorder and the status keep the device's own numbers.
"""

from __future__ import annotations

import collections
import dataclasses
import logging
import math
import threading
import time
from collections.abc import Callable
from typing import Any, Protocol

from fdi_daemon.alarms.lifecycle import DETECTOR_FAULT_KINDS, DETECTOR_INPUTS
from fdi_daemon.io.sample import Sample

log = logging.getLogger("fdi.loop")

#: a step back by more than this many samples is a device restart, not a duplicate
RESTART_STEP_SAMPLES = 256
#: a deadline miss is logged at most this often (s); the counters count every one
MISS_LOG_PERIOD_S = 10.0


class LatencyHistogram:
    """Counts in log-spaced bins (20 per decade, 1 µs .. 100 s): percentiles within 12 %."""

    BINS_PER_DECADE = 20
    LOW_US = 1.0
    DECADES = 8

    def __init__(self) -> None:
        self.counts = [0] * (self.BINS_PER_DECADE * self.DECADES + 2)
        self.total = 0
        self.sum_us = 0.0
        self.max_us = 0.0

    def add(self, value_us: float) -> None:
        if value_us < self.LOW_US:
            index = 0
        else:
            index = 1 + int(math.log10(value_us / self.LOW_US) * self.BINS_PER_DECADE)
            index = min(index, len(self.counts) - 1)
        self.counts[index] += 1
        self.total += 1
        self.sum_us += value_us
        if value_us > self.max_us:
            self.max_us = value_us

    def upper_edge_us(self, index: int) -> float:
        return self.LOW_US * 10 ** (index / self.BINS_PER_DECADE)

    def percentile(self, q: float) -> float:
        """The upper edge of the bin holding the q-th percentile (NaN when empty)."""
        if self.total == 0:
            return math.nan
        rank = q / 100.0 * self.total
        seen = 0
        for index, count in enumerate(self.counts):
            seen += count
            if seen >= rank and count:
                return min(self.upper_edge_us(index), self.max_us)
        return self.max_us

    def summary(self) -> dict[str, float]:
        return {
            "p50": self.percentile(50),
            "p99": self.percentile(99),
            "max": self.max_us,
            "count": self.total,
        }


class WindowedMin:
    """Minimum of the values added over the last ``blocks`` blocks of ``block_s`` seconds."""

    def __init__(self, block_s: float = 1.0, blocks: int = 10) -> None:
        self.block_s = block_s
        self._blocks: collections.deque = collections.deque(maxlen=blocks)
        self._current_start = -math.inf
        self._current = math.inf

    def add(self, now: float, value: float) -> float:
        if now - self._current_start >= self.block_s:
            if math.isfinite(self._current):
                self._blocks.append(self._current)
            self._current_start = now
            self._current = value
        elif value < self._current:
            self._current = value
        return min(self._current, min(self._blocks, default=math.inf))

    def reset(self) -> None:
        self._blocks.clear()
        self._current_start = -math.inf
        self._current = math.inf


class MonitorLike(Protocol):
    def step(self, sample: Sample) -> list[dict]: ...
    def finish(self) -> list[dict]: ...
    def snapshot(self) -> dict: ...


class Outputs(Protocol):
    """Where the loop hands things (implemented by the daemon with sink workers)."""

    def event(self, event: dict) -> None: ...
    def samples(self, samples: list[Sample]) -> None: ...
    def status(self, snapshot: dict) -> None: ...
    def dropped(self) -> int: ...
    # only called when the loop has an AlarmKeeper:
    def alarm_state(self, state: dict) -> None: ...
    def trend(self, row: dict) -> None: ...


class ServiceLoop:
    """Read, check, monitor, hand over; count and time every tick."""

    def __init__(
        self,
        link: Any,
        monitor: MonitorLike,
        outputs: Outputs,
        *,
        fs_hz: float,
        deadline_s: float = 0.05,
        read_timeout_s: float = 0.05,
        status_period_s: float = 0.1,
        model_info: dict | None = None,
        notifier: Any = None,
        watchdog_period_s: float | None = None,
        alarms: Any = None,
        event_counts: dict[str, int] | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.link = link
        self.monitor = monitor
        self.outputs = outputs
        self.fs_hz = float(fs_hz)
        self.deadline_s = deadline_s
        self.read_timeout_s = read_timeout_s
        self.status_period_s = status_period_s
        self.model_info = model_info or {}
        self.notifier = notifier
        self.watchdog_period_s = watchdog_period_s
        self.alarms = alarms
        self._clock = clock
        self.started_mono = clock()
        self.tick_latency = LatencyHistogram()
        self.lateness = LatencyHistogram()
        self._offset_min = WindowedMin()
        self.samples = 0
        self.gaps = 0
        self.missing_samples = 0
        self.duplicates = 0
        self.bad_samples = 0
        self.restarts = 0
        self.deadline_misses = 0
        self.late_arrivals = 0
        self._next_miss_log = -math.inf
        self.event_counts: collections.Counter = collections.Counter(event_counts or {})
        self.recent_events: collections.deque = collections.deque(maxlen=20)
        self.last_t = math.nan
        self._last_seq: int | None = None
        self._seq_offset = 0  # added to device seq for the monitor after device restarts
        self._last_monitor_seq: int | None = None
        self._restart_pending = False
        self._last_sample_mono = -math.inf
        self._next_status = -math.inf
        self._last_watchdog = -math.inf
        self._rate_marks: collections.deque = collections.deque(maxlen=64)
        self._state = "starting"
        self._last_status_text = ""

    # ------------------------------------------------------------------ running
    def run(self, stop: threading.Event, duration_s: float | None = None) -> None:
        """Iterate until ``stop`` is set, the link is finished, or ``duration_s`` passed."""
        end = math.inf if duration_s is None else self._clock() + duration_s
        while not stop.is_set() and self._clock() < end:
            self.iterate()
            if getattr(self.link, "finished", False):
                log.info("the link has delivered everything (finished)")
                break
        for event in self.monitor.finish():  # e.g. a run of bad samples still open
            self._emit(event)
        self.publish_status(force=True)
        if self.alarms is not None:
            if (row := self.alarms.trend.flush()) is not None:  # the minute in progress
                self.outputs.trend(row)
            self.outputs.alarm_state(self.alarms.state(self.event_counts))

    def iterate(self) -> int:
        """One read and everything that follows; returns the number of samples handled."""
        batch = self.link.read(self.read_timeout_s)
        received = self._clock()
        for event in self.link.events():  # lost/restored happened before these samples
            self._emit(event)
        for sample in batch:
            self._handle(self._renumbered(sample), received)
        if self.alarms is not None:
            self._emit_alarm_events(self.alarms.take_pending())
        if batch:
            self.outputs.samples(batch)
            if self.alarms is not None and (row := self.alarms.samples(batch)) is not None:
                self._trend(row)
            self._last_sample_mono = self._clock()
            self._rate_marks.append((self._last_sample_mono, self.samples))
        now = self._clock()
        self._feed_watchdog(now)
        if now >= self._next_status:
            self.publish_status()
        return len(batch)

    # ------------------------------------------------------------------ per sample
    def _renumbered(self, sample: Sample) -> Sample:
        """The sample as the monitor sees it: device restarts continue its numbering."""
        last = self._last_seq
        if last is None or sample.seq > last:
            self._last_seq = sample.seq
        elif last - sample.seq > RESTART_STEP_SAMPLES:
            self.restarts += 1
            self._last_seq = sample.seq
            self._offset_min.reset()
            log.warning("device sample counter restarted (%d after %d)", sample.seq, last)
            if self._last_monitor_seq is not None:
                self._seq_offset = self._last_monitor_seq + 2 - sample.seq
                self._restart_pending = True
        else:
            self.duplicates += 1
        if self._seq_offset:
            sample = dataclasses.replace(sample, seq=sample.seq + self._seq_offset)
        if self._last_monitor_seq is None or sample.seq > self._last_monitor_seq:
            self._last_monitor_seq = sample.seq
        return sample

    def _handle(self, sample: Sample, received: float) -> None:
        events = self.monitor.step(sample)
        done = self._clock()
        for event in events:
            if event.get("kind") == "data_gap" and self._restart_pending:
                event.update(reason="counter_restart", missing_samples=None)
                self._restart_pending = False
            self._emit(event)
        self.samples += 1
        self.last_t = sample.t
        self.tick_latency.add((done - received) * 1e6)
        nominal = sample.seq / self.fs_hz
        offset = self._offset_min.add(received, received - nominal)
        due = nominal + offset
        late_s = done - due
        self.lateness.add(late_s * 1e6)
        if late_s > self.deadline_s:
            self.deadline_misses += 1
            arrived_late_s = received - due
            self.late_arrivals += arrived_late_s > self.deadline_s
            if done >= self._next_miss_log:
                self._next_miss_log = done + MISS_LOG_PERIOD_S
                log.warning(
                    "deadline miss: sample %d done %.1f ms after its due time, arrived "
                    "%.1f ms after it (misses %d, late arrivals %d)",
                    sample.seq,
                    late_s * 1e3,
                    arrived_late_s * 1e3,
                    self.deadline_misses,
                    self.late_arrivals,
                )

    def _emit(self, event: dict) -> None:
        kind = event.get("kind")
        if kind == "data_gap":
            self.gaps += 1
            self.missing_samples += int(event.get("missing_samples") or 0)
        elif kind == "bad_sample":
            self.bad_samples += int(event.get("count") or 1)
        self.event_counts[kind] += 1
        self.recent_events.append(event)
        self.outputs.event(event)
        if self.alarms is not None and kind in DETECTOR_INPUTS:
            self._emit_alarm_events(self.alarms.detector_event(event))

    def _emit_alarm_events(self, events: list[dict]) -> None:
        """Lifecycle events, then the state that includes them (critical lane)."""
        for event in events:
            self._emit(event)
        if events:
            self.outputs.alarm_state(self.alarms.state(self.event_counts))

    def _trend(self, row: dict) -> None:
        """A finished trend minute, and the state once a minute with it."""
        self.outputs.trend(row)
        self.outputs.alarm_state(self.alarms.state(self.event_counts))

    # ------------------------------------------------------------------ watchdog, status
    def _feed_watchdog(self, now: float) -> None:
        if self.notifier is None or not self.watchdog_period_s:
            return
        if now - self._last_watchdog >= self.watchdog_period_s:
            self.notifier.watchdog()
            self._last_watchdog = now

    def rate_hz(self) -> float:
        """Samples per second over the last ~2 s of deliveries."""
        now = self._clock()
        marks = [m for m in self._rate_marks if now - m[0] <= 2.0]
        if len(marks) < 2 or now - self._last_sample_mono > 1.0:
            return 0.0
        (t0, n0), (t1, n1) = marks[0], marks[-1]
        return (n1 - n0) / (t1 - t0) if t1 > t0 else 0.0

    def snapshot(self) -> dict[str, Any]:
        """The status snapshot (TEAM.md schema, plus counters the Modbus map needs)."""
        monitor = self.monitor.snapshot()
        state = monitor.get("state", "starting") if self.samples else "starting"
        counters = self.link.counters()
        latency = self.tick_latency.summary()
        lateness = self.lateness.summary()
        return {
            "time": time.time(),
            "t": self.last_t if self.samples else None,
            "state": state,
            "link": {
                "kind": self.link.kind,
                "where": self.link.describe(),
                "connected": bool(getattr(self.link, "connected", True)),
                "rate_hz": self.rate_hz(),
                "samples": self.samples,
                "gaps": self.gaps,
                "missing_samples": self.missing_samples,
                "duplicates": self.duplicates,
                "restarts": self.restarts,
                "crc_errors": int(counters.get("crc_errors", 0)),
                "bad_samples": int(counters.get("bad_samples", 0)) + self.bad_samples,
                "tick_latency_us": {
                    "p50": latency["p50"],
                    "p99": latency["p99"],
                    "max": latency["max"],
                },
                "lateness_us": {
                    "p50": lateness["p50"],
                    "p99": lateness["p99"],
                    "max": lateness["max"],
                },
                "deadline_misses": self.deadline_misses,
                "late_arrivals": self.late_arrivals,
                "deadline_s": self.deadline_s,
                "counters": counters,
            },
            "monitor": monitor,
            "alarms": list(self.recent_events),
            "model": self.model_info,
            "alarm": self.alarms.summary() if self.alarms is not None else None,
            "counters": dict(self.event_counts),
            "uptime_s": self._clock() - self.started_mono,
            "dropped_outputs": self.outputs.dropped(),
        }

    def publish_status(self, force: bool = False) -> None:
        now = self._clock()
        self._next_status = now + self.status_period_s
        snap = self.snapshot()
        if self.alarms is not None:
            events, row = self.alarms.status(snap)
            self._emit_alarm_events(events)
            if row is not None:
                self._trend(row)
        self.outputs.status(snap)
        if self.notifier is not None:
            text = self.status_text(snap)
            if force or snap["state"] != self._state or text != self._last_status_text:
                self.notifier.status(text)
                self._last_status_text = text
        self._state = snap["state"]

    @staticmethod
    def status_text(snap: dict[str, Any]) -> str:
        """The systemd STATUS= line: state, link, alarm count (changes rarely)."""
        link = snap["link"]
        alarms = sum(snap["counters"].get(k, 0) for k in DETECTOR_FAULT_KINDS)
        up = "up" if link["connected"] else "DOWN"
        return f"{snap['state']}; link {link['kind']} {up}; {alarms} alarm(s)"
