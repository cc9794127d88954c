"""Shared helpers of the reliability suite (tests/test_reliability_*.py).

- `model_path()`: a model file of the simulated rig: ``configs/model_sim_rig.yaml`` when it
  exists with a fault filter, else the monitor tests' identified model (`conftest_detect.sim_rig_model`) saved
  once per session;
- `fault_free(seconds, seed)`: a fault-free simulated recording (the device's default
  excitation, the paper's 1.4 V 8 Hz sine), cached;
- `PtyDevice`: a test-side serial device: a pty whose master this test writes, with a stable
  symlink, frames built with the project's own `encode_frame`, and disconnects on demand;
- `Collector`: the ``Outputs`` of a `ServiceLoop` that keeps everything in lists;
- `write_config()`: a rig config for ``fdi run --config``.
"""

from __future__ import annotations

import contextlib
import functools
import os
import tempfile
import tty
from pathlib import Path

import numpy as np
import yaml

REPO = Path(__file__).resolve().parents[1]
SHIPPED_MODEL = REPO / "configs" / "model_sim_rig.yaml"
FS_HZ = 256.0
ALARMS = ("fault_detected", "friction_isolated", "other_fault")


@functools.cache
def _session_dir() -> Path:
    return Path(tempfile.mkdtemp(prefix="fdi-reliability-"))


def _complete(path: Path) -> bool:
    """A model file that loads and has its friction signature."""
    from fdi_daemon.errors import UserError
    from fdi_daemon.io.model_file import load_model

    try:
        return load_model(path).fault_filter is not None
    except (UserError, OSError):
        return False


@functools.cache
def model_path() -> Path:
    """Model file of the simulated rig (see the module docstring)."""
    if SHIPPED_MODEL.exists() and _complete(SHIPPED_MODEL):
        return SHIPPED_MODEL
    from conftest_detect import sim_rig_model

    from fdi_daemon.io.model_file import save_model

    path = _session_dir() / "model_sim_rig.yaml"
    save_model(path, sim_rig_model())
    return path


def load_test_model(**changes):
    """A fresh FdiModel from `model_path()`, with some fields replaced."""
    from fdi_daemon.io.model_file import load_model

    model = load_model(model_path())
    for key, value in changes.items():
        setattr(model, key, value)
    return model


@functools.cache
def fault_free(seconds: float, seed: int = 3):
    """Fault-free recording of the device's default scenario (1.4 V, 8 Hz sine)."""
    from hil_sim.devices.realtime import DEFAULT_SCENARIO
    from hil_sim.scenarios import scenario_from_dict, simulate

    scenario = scenario_from_dict({**DEFAULT_SCENARIO, "duration_s": float(seconds)})
    return simulate(scenario, seed=seed)


def frames_of(rec, first: int = 0, count: int | None = None, seq_offset: int = 0) -> list[bytes]:
    """Encoded serial frames of recording rows [first, first + count)."""
    from fdi_daemon.io.serial_frames import Frame, encode_frame

    stop = len(rec) if count is None else first + count
    seq = rec.columns["seq"]
    return [
        encode_frame(
            Frame(
                int(seq[i]) + seq_offset,
                float(rec.v_in[i]),
                float(rec.accel[i]),
                float(rec["position"][i]),
            )
        )
        for i in range(first, stop)
    ]


class PtyDevice:
    """A pty written by the test: ``write(bytes)``, ``disconnect()``, ``connect()``.

    ``path`` is a symlink that always points at the current pty's slave side, so a
    reconnecting serial link finds the new pty after a disconnect (like a udev name).
    """

    def __init__(self, directory: Path) -> None:
        self.path = str(Path(directory) / "tty-fdi-test")
        self._master = self._slave = -1
        self.connect()

    def connect(self) -> None:
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)
        tmp = f"{self.path}.tmp"
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        os.symlink(os.ttyname(self._slave), tmp)
        os.replace(tmp, self.path)

    def write(self, data: bytes) -> None:
        view = memoryview(data)
        while view:
            n = os.write(self._master, view)  # blocking: a full pty waits for the reader
            view = view[n:]

    def disconnect(self) -> None:
        """Close both sides: the reader's next read fails (EIO), like a pulled adapter."""
        for fd in (self._master, self._slave):
            if fd >= 0:
                with contextlib.suppress(OSError):
                    os.close(fd)
        self._master = self._slave = -1
        with contextlib.suppress(FileNotFoundError):
            os.unlink(self.path)

    close = disconnect


class Collector:
    """``Outputs`` of a `ServiceLoop`: events, samples received, last status, in memory."""

    def __init__(self) -> None:
        self.events: list[dict] = []
        self.received = 0  # samples handed to the recorder lane
        self.last_status: dict | None = None

    def event(self, event: dict) -> None:
        self.events.append(event)

    def samples(self, samples) -> None:
        self.received += len(samples)

    def status(self, snapshot: dict) -> None:
        self.last_status = snapshot

    def dropped(self) -> int:
        return 0

    def kinds(self) -> list[str]:
        return [e["kind"] for e in self.events]

    def of(self, kind: str) -> list[dict]:
        return [e for e in self.events if e["kind"] == kind]

    def alarms(self) -> list[dict]:
        return [e for e in self.events if e["kind"] in ALARMS]


def service_loop(link, model=None, deadline_s: float = 10.0):
    """A `ServiceLoop` over ``link`` with a real `Monitor` (compiled before it serves, as the
    daemon does: a cold numba cache must not make the first tick miss a test's timeout) and a
    `Collector`."""
    from fdi_daemon.detect.monitor import Monitor
    from fdi_daemon.service.loop import ServiceLoop

    model = model or load_test_model()
    out = Collector()
    monitor = Monitor(model)
    monitor.warm_up()
    loop = ServiceLoop(
        link,
        monitor,
        out,
        fs_hz=model.fs,
        deadline_s=deadline_s,
        read_timeout_s=0.02,
        status_period_s=3600.0,
    )
    return loop, out


def write_config(
    path: Path,
    link: dict,
    state_dir: Path,
    *,
    recorder: bool = True,
    stall_timeout_s: float | None = 1.0,
    status_socket: bool = True,
) -> Path:
    """A rig config for ``fdi run --config`` with outputs under ``state_dir``."""
    link = dict(link)
    if link.get("kind") not in ("replay", "sim"):
        link["reconnect"] = {
            "backoff_initial_s": 0.1,
            "backoff_max_s": 1.0,
            "stall_timeout_s": stall_timeout_s,
        }
    config = {
        "link": link,
        "model": {"path": str(model_path())},
        "sinks": {
            "event_log": "events.jsonl",
            "stdout": True,
            "status_socket": "status.sock" if status_socket else None,
            "modbus_status": {"enabled": False},
        },
        "recorder": {
            "enabled": recorder,
            "dir": "recordings",
            "rotate_seconds": 600,
            "fsync_period_s": 1.0,
        },
        "service": {"state_dir": str(state_dir)},
    }
    path.write_text(yaml.safe_dump(config))
    return path


def corrupt_bytes(frames: list[bytes], rate: float, seed: int) -> tuple[list[bytes], np.ndarray]:
    """Flip chosen bytes of the frames, each byte with probability ``rate``.

    The XOR value of each corrupted byte is drawn until the corrupted frame contains no
    false frame start (sync + version) after its first byte, so what the decoder must do
    is exactly determined. Returns (frames, boolean mask of corrupted frames).
    """
    from fdi_daemon.io.serial_frames import SYNC, VERSION

    rng = np.random.default_rng(seed)
    start = SYNC + bytes([VERSION])
    out = list(frames)
    hit = np.zeros(len(frames), dtype=bool)
    wire = rng.random((len(frames), len(frames[0]))) < rate
    for k in np.flatnonzero(wire.any(axis=1)):
        while True:
            bad = bytearray(frames[k])
            for i in np.flatnonzero(wire[k]):
                bad[i] ^= int(rng.integers(1, 256))
            if start not in bytes(bad[1:]):
                break
        out[k] = bytes(bad)
        hit[k] = True
    return out, hit


def continuous_fault_free_hours(hours: int, seed: int):
    """Yield ``hours`` consecutive hours of one uninterrupted fault-free simulated run.

    One `Rig` runs throughout (its state, noise and t/seq continue across hours); each hour
    plays a fresh random program of configs/scenarios/fault_free_hour.yaml (random sines,
    multisines and chirps) with that scenario's drift of supply pressure, temperature and
    bearing supply, updated every second as `hil_sim.scenarios.simulate` does. Yields
    recordings with t, v_in, accel, seq.
    """
    from fdi_daemon.io.recordings import Recording
    from hil_sim.excitation import build_program
    from hil_sim.rig import Rig
    from hil_sim.scenarios import load_scenario

    scenario = load_scenario(REPO / "configs" / "scenarios" / "fault_free_hour.yaml")
    fs = scenario.rig.fs_hz
    per_hour = int(round(3600.0 * fs))
    step = int(round(fs))
    rig = Rig(scenario.rig, seed=seed)
    rig.set_centring(scenario.centring_gain_v_per_m)
    setters = {
        "supply_pressure": rig.set_supply_drift,
        "temperature_k": rig.set_temperature,
        "bearing_supply": rig.set_bearing_supply,
    }
    for hour in range(hours):
        program = build_program(
            scenario.excitation, fs, per_hour, np.random.default_rng([seed, hour, 0x5EED])
        )
        parts = []
        for start in range(0, per_hour, step):
            for name, prof in scenario.drift.items():
                setters[name](float(np.interp(start / fs, prof["times_s"], prof["values"])))
            parts.append(rig.run(program[start : start + step]))
        cols = {k: np.concatenate([p[k] for p in parts]) for k in ("t", "v_in", "accel", "seq")}
        cols["seq"] = cols["seq"].astype(np.int64)
        yield Recording(cols, {"fs": f"{fs:g}", "hour": str(hour), "seed": str(seed)})
