"""The service loop with a scripted link and monitor: seq checks, timing, events, watchdog."""

import math
import threading

import pytest

from fdi_daemon.io.sample import Sample
from fdi_daemon.service.loop import LatencyHistogram, ServiceLoop, WindowedMin

FS = 256.0


class FakeClock:
    def __init__(self):
        self.now = 100.0

    def __call__(self):
        return self.now


class ScriptedLink:
    """Returns the scripted batches, one per read; the clock advances by `read_s` per read."""

    kind = "scripted"
    connected = True
    finished = False

    def __init__(self, batches, clock, read_s=8 / FS, events=None):
        self.batches = list(batches)
        self.clock = clock
        self.read_s = read_s
        self._events = list(events or [])

    def read(self, timeout_s):
        self.clock.now += self.read_s
        if not self.batches:
            self.finished = True
            return []
        return self.batches.pop(0)

    def events(self):
        out, self._events = self._events, []
        return out

    def counters(self):
        return {"samples": 0, "crc_errors": 3}

    def describe(self):
        return "scripted"


class StubMonitor:
    """The Monitor's contract for seq: gaps -> data_gap, repeats/backwards -> skipped."""

    def __init__(self, clock, step_s=20e-6, alarm_seq=None):
        self.clock = clock
        self.step_s = step_s
        self.alarm_seq = alarm_seq
        self.seen = []
        self.last = None

    def step(self, sample):
        self.clock.now += self.step_s
        events = []
        if self.last is not None:
            if sample.seq <= self.last:
                return [{"t": sample.t, "kind": "bad_sample", "count": 1, "reason": "duplicate"}]
            if sample.seq > self.last + 1:
                events.append(
                    {
                        "t": sample.t,
                        "kind": "data_gap",
                        "missing_samples": sample.seq - self.last - 1,
                    }
                )
        self.last = sample.seq
        self.seen.append(sample.seq)
        if sample.seq == self.alarm_seq:
            events.append({"t": sample.t, "kind": "fault_detected", "theta1": 1.0, "theta2": 0.1})
        return events

    def finish(self):
        return [{"t": self.last / FS, "kind": "bad_sample", "count": 2, "reason": "test"}]

    def snapshot(self):
        return {"state": "monitoring", "theta1": 0.0, "theta2": 0.0}


class Collect:
    def __init__(self):
        self.events, self.batches, self.snaps = [], [], []

    def event(self, e):
        self.events.append(e)

    def samples(self, s):
        self.batches.append(s)

    def status(self, s):
        self.snaps.append(s)

    def dropped(self):
        return 0


def batch(seqs):
    return [Sample(s, s / FS, 0.0, 0.0) for s in seqs]


def run(batches, monitor=None, clock=None, **kw):
    clock = clock or FakeClock()
    link = ScriptedLink(batches, clock, **{k: kw.pop(k) for k in ("read_s", "events") if k in kw})
    monitor = monitor or StubMonitor(clock)
    out = Collect()
    loop = ServiceLoop(link, monitor, out, fs_hz=FS, clock=clock, **kw)
    loop.run(threading.Event())
    return loop, monitor, out


def test_gaps_and_duplicates_are_the_monitors_and_counted():
    batches = [
        batch(range(0, 8)),
        batch(range(8, 12)) + batch(range(15, 16)),
        batch([15, 14]) + batch(range(16, 20)),
        batch(range(0, 4)),
    ]
    loop, monitor, out = run(batches)
    gaps = [e for e in out.events if e["kind"] == "data_gap"]
    assert [g["missing_samples"] for g in gaps] == [3]
    # 15, 14 repeat/step back; 0..3 after 19 is a small step back: duplicates, not a restart
    assert loop.gaps == 1 and loop.missing_samples == 3 and loop.duplicates == 6
    assert loop.restarts == 0 and loop.bad_samples == 6 + 2  # 2 from finish()
    assert monitor.seen == list(range(12)) + list(range(15, 20))
    assert [s.seq for b in out.batches for s in b] == [s.seq for b in batches for s in b]


def test_a_device_restart_continues_the_monitors_numbering_after_a_gap():
    batches = [batch(range(1000, 1010)), batch(range(0, 5))]
    loop, monitor, out = run(batches)
    assert loop.restarts == 1
    assert monitor.seen == list(range(1000, 1010)) + list(range(1011, 1016))
    (gap,) = [e for e in out.events if e["kind"] == "data_gap"]
    assert gap["reason"] == "counter_restart" and gap["missing_samples"] is None
    assert loop.gaps == 1 and loop.missing_samples == 0
    # the recorder keeps the device's numbers
    assert [s.seq for s in out.batches[-1]] == [0, 1, 2, 3, 4]


def test_events_counts_and_snapshot_schema():
    clock = FakeClock()
    batches = [batch(range(i, i + 8)) for i in range(0, 64, 8)]
    lost = {"t": None, "kind": "link_lost", "link": "scripted"}
    loop, monitor, out = run(
        batches, monitor=StubMonitor(clock, alarm_seq=40), clock=clock, events=[lost]
    )
    kinds = [e["kind"] for e in out.events]
    assert kinds == ["link_lost", "fault_detected", "bad_sample"]
    assert sum(len(b) for b in out.batches) == 64 == loop.samples
    snap = out.snaps[-1]
    assert snap["state"] == "monitoring" and snap["t"] == 63 / FS
    link = snap["link"]
    assert link["samples"] == 64 and link["crc_errors"] == 3 and link["gaps"] == 0
    assert set(link["tick_latency_us"]) >= {"p50", "p99"}
    assert snap["counters"] == {"link_lost": 1, "fault_detected": 1, "bad_sample": 1}
    assert [a["kind"] for a in snap["alarms"]] == kinds


def test_latency_and_deadline_are_paced_by_the_sample_counter():
    clock = FakeClock()
    # 8 samples per read, reads 8/FS apart: on time. Then the link stalls 0.2 s and
    # delivers a burst: those samples are late; the loop itself takes 20 µs per sample.
    batches = [batch(range(i, i + 8)) for i in range(0, 80, 8)]
    link = ScriptedLink(batches, clock)
    out = Collect()
    loop = ServiceLoop(
        link, StubMonitor(clock, step_s=20e-6), out, fs_hz=FS, clock=clock, deadline_s=0.05
    )
    for _ in range(5):
        loop.iterate()
    assert loop.deadline_misses == 0
    # latency: the k-th sample of a batch waits for the k-1 steps before it
    assert loop.tick_latency.percentile(50) == pytest.approx(20 * 4.5, rel=0.25)
    clock.now += 0.2  # stall
    link.batches = [batch(range(80, 140))]
    loop.iterate()
    assert loop.deadline_misses > 0
    assert loop.late_arrivals == loop.deadline_misses  # the link was late, not the loop
    # now the loop is slow (60 ms per sample) with samples arriving on time
    slow = ServiceLoop(
        ScriptedLink([batch(range(i, i + 8)) for i in range(0, 80, 8)], clock),
        StubMonitor(clock, step_s=0.06),
        Collect(),
        fs_hz=FS,
        clock=clock,
        deadline_s=0.05,
    )
    slow.iterate()
    assert slow.deadline_misses == 8 and slow.late_arrivals == 0
    assert slow.snapshot()["link"]["late_arrivals"] == 0


def test_histogram_percentiles_against_numpy():
    import numpy as np

    rng = np.random.default_rng(7)
    values = rng.lognormal(mean=4.0, sigma=1.0, size=5000)
    hist = LatencyHistogram()
    for v in values:
        hist.add(float(v))
    for q in (50, 99):
        exact = np.percentile(values, q)
        assert exact <= hist.percentile(q) <= exact * 10 ** (1 / 20) * 1.0001
    assert hist.max_us == values.max()
    assert math.isnan(LatencyHistogram().percentile(50))


def test_windowed_min_follows_the_last_blocks():
    wm = WindowedMin(block_s=1.0, blocks=3)
    assert wm.add(0.0, 5.0) == 5.0
    assert wm.add(0.5, 3.0) == 3.0
    assert wm.add(1.0, 4.0) == 3.0
    for t in (2.0, 3.0, 4.0):
        last = wm.add(t, 4.0)
    assert last == 4.0  # the block holding 3.0 has left the window


class Pinger:
    def __init__(self):
        self.pings = 0
        self.statuses = []

    def watchdog(self):
        self.pings += 1

    def status(self, text):
        self.statuses.append(text)


def test_watchdog_pings_while_the_loop_runs_with_or_without_samples():
    """The watchdog means "the loop is alive": a silent link does not stop the pings (the
    old loop pinged only while samples flowed, and systemd restarted a daemon whose field
    link was down)."""
    clock = FakeClock()
    batches = [batch(range(i, i + 8)) for i in range(0, 256, 8)] + [[]] * 40
    link = ScriptedLink(batches, clock, read_s=0.05)
    notifier = Pinger()
    loop = ServiceLoop(
        link,
        StubMonitor(clock),
        Collect(),
        fs_hz=FS,
        clock=clock,
        notifier=notifier,
        watchdog_period_s=0.2,
    )
    for _ in range(32):  # 1.6 s of flowing data
        loop.iterate()
    flowing = notifier.pings
    assert 6 <= flowing <= 9
    for _ in range(40):  # 2 s with nothing: a ping every 0.2 s all the same
        loop.iterate()
    assert 8 <= notifier.pings - flowing <= 11
    assert notifier.statuses and "monitoring" in notifier.statuses[-1]
