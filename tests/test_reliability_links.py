"""Reliability under link faults: the daemon's own chain (ReconnectingLink -> ServiceLoop ->
Monitor) against devices that disconnect, corrupt bytes, cut frames, stall and flood.

Serial faults are injected by a test-side device (`reliability_support.PtyDevice`): frames
of a fault-free simulated recording built with the project's `encode_frame`, bytes
corrupted at chosen positions, so the exact counts the decoder and the service must report
are known in advance. Modbus disconnects use the fake device (`hil_sim.devices`) stopped
and restarted on the same address. Every test checks: no exception, every injected loss
shows in the events (``data_gap`` ``missing_samples``, ``link_lost``/``link_restored``),
nothing else is lost, and no alarm is raised on fault-free data.
"""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest
from reliability_support import PtyDevice, corrupt_bytes, fault_free, frames_of, service_loop

from fdi_daemon.io.links.base import ReconnectingLink, make_link
from fdi_daemon.io.links.serial_link import SerialLink
from fdi_daemon.io.serial_frames import FRAME_SIZE, SYNC, VERSION

CI_CYCLES = 10
SOAK_CYCLES = 100


def pump(loop, until, timeout_s: float = 30.0, what: str = "") -> None:
    """Iterate the service loop until ``until()`` holds (fail after ``timeout_s``)."""
    end = time.monotonic() + timeout_s
    while not until():
        assert time.monotonic() < end, f"timed out waiting for {what}"
        loop.iterate()


def drain(loop, seconds: float = 0.3) -> None:
    """Keep iterating for a while: anything late would show up here."""
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        loop.iterate()


def writer(dev: PtyDevice, data: bytes, seed: int) -> threading.Thread:
    """Write ``data`` in random pieces (1..97 bytes: frames arrive cut anywhere)."""
    rng = np.random.default_rng(seed)

    def body() -> None:
        pos = 0
        while pos < len(data):
            n = int(rng.integers(1, 98))
            dev.write(data[pos : pos + n])
            pos += n
            if rng.random() < 0.02:
                time.sleep(0.001)  # let the reader see a partial frame now and then

    thread = threading.Thread(target=body, daemon=True)
    thread.start()
    return thread


def serial_link(path: str, stall_timeout_s: float | None = None) -> ReconnectingLink:
    return ReconnectingLink(
        lambda: SerialLink(path),
        backoff_initial_s=0.02,
        backoff_max_s=0.2,
        stall_timeout_s=stall_timeout_s,
    )


def stream_through_pty(tmp_path, data: bytes, delivered: int, seed: int):
    """Write ``data`` to a pty device in random pieces, run the service loop on a serial
    link until ``delivered`` samples are through (and a while longer); returns the closed
    (link, loop, out) for their counters and events."""
    dev = PtyDevice(tmp_path)
    link = serial_link(dev.path)
    link.open()
    loop, out = service_loop(link)
    thread = writer(dev, data, seed=seed)
    pump(loop, lambda: loop.samples >= delivered, 120.0, f"{delivered} samples")
    thread.join(10)
    drain(loop)
    link.close()
    dev.close()
    return link, loop, out


def runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """(start, length) of each run of True."""
    edges = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(
        zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - np.flatnonzero(edges == 1))
    )


@pytest.mark.parametrize("rate", [1e-4, 1e-3, 1e-2])
def test_corrupted_bytes_are_counted_exactly_and_raise_no_alarm(tmp_path, rate):
    rec = fault_free(60.0)
    clean = frames_of(rec)
    assert not any(SYNC + bytes([VERSION]) in f[1:] for f in clean)  # exact counts possible
    frames, hit = corrupt_bytes(clean, rate, seed=int(1 / rate))
    frames[-256:], hit[-256:] = clean[-256:], False  # the stream ends clean (gap reported)
    assert hit.sum() > 0
    expected_crc = sum(f[:3] == SYNC + bytes([VERSION]) for f, h in zip(frames, hit) if h)

    delivered = len(frames) - int(hit.sum())
    link, loop, out = stream_through_pty(tmp_path, b"".join(frames), delivered, seed=1)

    counters = link.counters()
    gap_runs = runs(hit)
    assert loop.samples == delivered and counters["frames"] == delivered
    assert counters["crc_errors"] == expected_crc
    assert counters["bytes_dropped"] == FRAME_SIZE * int(hit.sum())
    assert counters["resyncs"] == len(gap_runs)
    gaps = out.of("data_gap")
    assert [g["missing_samples"] for g in gaps] == [n for _, n in gap_runs]
    assert [g["t"] for g in gaps] == [float(rec.t[s + n]) for s, n in gap_runs]
    assert out.of("link_lost") == [] and out.of("bad_sample") == []
    assert out.alarms() == []
    if rate <= 1e-4:  # few enough gaps for the monitor to calibrate: it really watched
        assert "calibrated" in out.kinds()


def test_truncated_frames_and_a_garbage_flood_lose_only_those_frames(tmp_path):
    rec = fault_free(30.0)
    frames = frames_of(rec)
    rng = np.random.default_rng(5)
    cut = np.zeros(len(frames), dtype=bool)
    cut[rng.choice(np.arange(100, len(frames) - 300), 40, replace=False)] = True
    bursts = sum(1 for k in range(len(frames)) if k % 512 == 300)
    garbage = rng.integers(0, 256, 30_000 * bursts, dtype=np.uint8)
    garbage[garbage == SYNC[0]] = 0  # garbage without a sync byte: dropped byte for byte
    garbage = garbage.tobytes()
    pieces, flooded = [], 0
    for k, frame in enumerate(frames):
        if k % 512 == 300:  # a 30 kB burst between two frames, ten times
            pieces.append(garbage[flooded : flooded + 30_000])
            flooded += 30_000
        pieces.append(frame[: FRAME_SIZE // 2] if cut[k] else frame)
    delivered = len(frames) - int(cut.sum())
    link, loop, out = stream_through_pty(tmp_path, b"".join(pieces), delivered, seed=2)

    counters = link.counters()
    assert flooded == len(garbage) >= 300_000
    assert loop.samples == counters["frames"] == delivered
    assert counters["crc_errors"] == int(cut.sum())  # a half frame fails its CRC once
    assert counters["bytes_dropped"] == flooded + int(cut.sum()) * FRAME_SIZE // 2
    assert sum(g["missing_samples"] for g in out.of("data_gap")) == int(cut.sum())
    assert out.alarms() == []


def test_a_flooding_device_loses_nothing(tmp_path):
    """60 s of frames written as fast as the pty takes them (far above 256 Hz)."""
    rec = fault_free(60.0)
    dev = PtyDevice(tmp_path)
    link = serial_link(dev.path)
    link.open()
    loop, out = service_loop(link)
    thread = threading.Thread(target=dev.write, args=(b"".join(frames_of(rec)),), daemon=True)
    thread.start()
    pump(loop, lambda: loop.samples >= len(rec), 120.0, "the flood")
    thread.join(10)
    drain(loop)
    link.close()
    dev.close()
    assert loop.samples == len(rec) and loop.gaps == 0 and loop.duplicates == 0
    assert link.counters()["crc_errors"] == 0 and link.counters()["bytes_dropped"] == 0
    assert out.kinds() == ["calibrated"]


def test_a_stalling_device_short_and_long(tmp_path):
    """A stall shorter than the stall timeout is a data gap of exactly the frames not sent;
    a longer one is also a lost and restored link; nothing else is lost."""
    rec = fault_free(30.0)
    frames = frames_of(rec)
    dev = PtyDevice(tmp_path)
    link = serial_link(dev.path, stall_timeout_s=0.5)
    link.open()
    loop, out = service_loop(link)
    sent = 0

    def send(first: int, count: int) -> None:
        nonlocal sent
        thread = writer(dev, b"".join(frames[first : first + count]), seed=first)
        sent += count
        pump(loop, lambda: loop.samples >= sent, 30.0, "the frames sent")
        thread.join(10)

    send(0, 2000)
    time.sleep(0.2)  # short stall: 0.2 s silence, 77 frames never sent
    send(2077, 2000)
    drain(loop, 0.1)
    assert out.of("link_lost") == []
    time.sleep(0.8)  # long stall (> 0.5 s): the link is declared lost and reopened ...
    pump(
        loop,
        lambda: len(out.of("link_lost")) == 1 and link.connected,
        10.0,
        "link_lost and the port reopened",
    )  # (opening a port flushes its input)
    send(4577, 2000)  # ... and restored when samples flow again
    drain(loop)
    link.close()
    dev.close()
    assert [e["kind"] for e in out.events if e["kind"] in ("link_lost", "link_restored")] == [
        "link_lost",
        "link_restored",
    ]
    assert [g["missing_samples"] for g in out.of("data_gap")] == [77, 500]
    assert loop.samples == 6000 and out.alarms() == []


def serial_disconnect_cycles(tmp_path, cycles: int) -> None:
    rec = fault_free(max(30.0, cycles * 1.2 + 5.0))
    frames = frames_of(rec)
    dev = PtyDevice(tmp_path)
    link = serial_link(dev.path)
    link.open()
    loop, out = service_loop(link)
    pos = sent = 0
    per_cycle, skipped = 200, 56
    for cycle in range(cycles):
        thread = writer(dev, b"".join(frames[pos : pos + per_cycle]), seed=cycle)
        pos += per_cycle
        sent += per_cycle
        pump(loop, lambda: loop.samples >= sent, 30.0, f"cycle {cycle}: samples")
        thread.join(10)
        assert len(out.of("link_restored")) == cycle  # restored once samples flowed
        dev.disconnect()
        pump(loop, lambda: len(out.of("link_lost")) == cycle + 1, 30.0, f"cycle {cycle}: lost")
        dev.connect()
        pos += skipped  # the device kept sampling while disconnected
        pump(loop, lambda: link.connected, 30.0, f"cycle {cycle}: port reopened")
    thread = writer(dev, b"".join(frames[pos : pos + per_cycle]), seed=cycles)
    sent += per_cycle
    pump(loop, lambda: loop.samples >= sent, 30.0, "the last samples")
    thread.join(10)
    drain(loop)
    link.close()
    dev.close()
    assert out.kinds().count("link_lost") == out.kinds().count("link_restored") == cycles
    assert [g["missing_samples"] for g in out.of("data_gap")] == [skipped] * cycles
    assert loop.samples == sent and link.counters()["crc_errors"] == 0
    assert out.alarms() == []


def modbus_disconnect_cycles(tmp_path, transport: str, cycles: int) -> None:
    """Stop the fake device and start a new one on the same address, ``cycles`` times."""
    from hil_sim.devices import SimulatedDevice, realtime_rig

    rtu_path = str(tmp_path / "rtu")

    def device(seed: int, port: int = 0):
        dev = SimulatedDevice(
            transport,
            realtime_rig(seed=seed),
            port=port,
            link_path=rtu_path if transport == "modbus-rtu" else None,
        )
        return dev, dev.start()

    dev, config = device(0)
    link = ReconnectingLink(
        lambda: make_link({**config, "timeout_s": 0.3}),
        backoff_initial_s=0.02,
        backoff_max_s=0.2,
        stall_timeout_s=1.0,
    )
    link.open()
    loop, out = service_loop(link)
    try:
        for cycle in range(cycles):
            # > RESTART_STEP_SAMPLES samples per device, so its restart is seen as one
            target = loop.samples + 300
            pump(loop, lambda: loop.samples >= target, 30.0, f"cycle {cycle}: samples")
            dev.stop()
            pump(loop, lambda: len(out.of("link_lost")) == cycle + 1, 30.0, f"cycle {cycle}: lost")
            dev, _ = device(cycle + 1, config.get("port", 0) if transport == "modbus-tcp" else 0)
            pump(
                loop,
                lambda: len(out.of("link_restored")) == cycle + 1,
                30.0,
                f"cycle {cycle}: restored",
            )
        target = loop.samples + 300
        pump(loop, lambda: loop.samples >= target, 30.0, "samples after the last restore")
    finally:
        dev.stop()
        link.close()
    kinds = out.kinds()
    assert kinds.count("link_lost") == kinds.count("link_restored") == cycles
    restarts = [g for g in out.of("data_gap") if g.get("reason") == "counter_restart"]
    assert len(restarts) == cycles and loop.restarts == cycles
    assert out.of("bad_sample") == []  # no sample of a new device taken for a duplicate
    # within one device's life nothing is lost: no other gap
    assert len(out.of("data_gap")) == cycles
    assert out.alarms() == []


def test_serial_disconnect_reconnect_cycles(tmp_path):
    serial_disconnect_cycles(tmp_path, CI_CYCLES)


@pytest.mark.slow
@pytest.mark.parametrize("transport", ["modbus-tcp", "modbus-rtu"])
def test_modbus_disconnect_reconnect_cycles(tmp_path, transport):
    modbus_disconnect_cycles(tmp_path, transport, CI_CYCLES)


@pytest.mark.soak
def test_serial_disconnect_reconnect_cycles_soak(tmp_path):
    serial_disconnect_cycles(tmp_path, SOAK_CYCLES)


@pytest.mark.soak
@pytest.mark.parametrize("transport", ["modbus-tcp", "modbus-rtu"])
def test_modbus_disconnect_reconnect_cycles_soak(tmp_path, transport):
    modbus_disconnect_cycles(tmp_path, transport, SOAK_CYCLES)
