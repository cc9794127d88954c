"""The daemon end to end, as separate processes: latency, CPU share, resident memory.

Everything runs as a user would run it: the fake device is ``fdi sim serve`` (its own
process), the daemon is ``fdi run --config`` (its own process, recorder and event log on).

End-to-end latency, per event: from the moment the sample that raised the event left the
fake device to the moment the event's line is in the event log.
- "left the device": the device's due time of that sample, ``tick0 + seq / fs`` on the
  machine-wide monotonic clock (the device reports ``tick0_monotonic_s``; it publishes or
  writes each sample at that time or a fraction of a millisecond later, so the figure is
  an upper bound by that much). ``seq = round(event.t * fs)``: the monitor stamps each
  event with the time of the sample that raised it.
- "written": this process watches the event log (a stat every 0.5 ms) and takes the
  monotonic time at which the line became visible to a reader (write(2) done; the fsync
  of alarm lines is not included). The polling adds up to ~0.6 ms.
Events: the faults are real: the air-bearing supply is cut (friction) and restored, in
cycles, through the device's control channel; each cycle gives ``fault_detected``,
``friction_isolated`` and ``cleared``. On the serial device, short stalls (0.1 s, below
the stall timeout) add ``data_gap`` events, raised by the first sample after the stall.
Over Modbus TCP the latency includes the poll interval (10 ms).

CPU share: utime + stime of the daemon process (/proc/<pid>/stat) over a window of steady
monitoring at 256 Hz, divided by the wall time of the window (100 % = one core).

Resident memory after a simulated hour: the daemon with the in-process simulated rig as a
link delivered as fast as it computes (``link: {kind: sim, realtime: false}``, the
changing operation of configs/scenarios/fault_free_hour.yaml) goes through its per-tick
path (Monitor.step, sinks, recorder) for 921 600 samples; VmRSS and VmHWM are read from
/proc/<pid>/status once monitoring starts and once the sample time reaches one hour.
"""

from __future__ import annotations

import json
import os
import queue
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import yaml

#: events raised by one sample (link events and bad_sample runs are stamped otherwise)
SAMPLE_EVENTS = (
    "calibrated",
    "fault_detected",
    "friction_isolated",
    "other_fault",
    "cleared",
    "data_gap",
)
HOUR_S = 3600.0
STARTUP_TIMEOUT_S = 180.0


def default_model_path() -> Path:
    """The model of the embedded default config (the simulated rig's ready model)."""
    from fdi_daemon.service.config import load_config

    return load_config(None).model_path


def _fdi(*args: str, **kwargs) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "fdi_daemon", *args], **kwargs)


def _stop(proc: subprocess.Popen | None) -> None:
    if proc is None or proc.poll() is not None:
        return
    proc.send_signal(signal.SIGTERM)
    try:
        proc.wait(30)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait(10)


class Device:
    """``fdi sim serve`` as a subprocess, driven through its JSON-lines control channel."""

    def __init__(self, transport: str, seed: int = 1) -> None:
        how = ["--modbus-tcp", "127.0.0.1:0"] if transport == "modbus-tcp" else ["--serial"]
        self.proc = _fdi(
            "sim",
            "serve",
            *how,
            "--seed",
            str(seed),
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        try:
            self._connect(transport, how)
        except BaseException:  # a SIGTERM or Ctrl-C while it starts: stop it too
            _stop(self.proc)
            raise

    def _connect(self, transport: str, how: list[str]) -> None:
        """Read where the device serves and its clock (its first stdout line and status)."""
        self._lines: queue.Queue[str] = queue.Queue()
        threading.Thread(target=self._read_lines, daemon=True).start()
        self.where = self._line(60.0).strip()
        if not self.where:
            raise RuntimeError(f"fdi sim serve {' '.join(how)} did not start")
        # a status request right after the address line can come before the device's first
        # tick and kill its control thread (reported to the links engineer): wait a moment
        time.sleep(0.5)
        status = self.command({"status": True})["status"]
        self.tick0 = float(status["tick0_monotonic_s"])
        self.fs_hz = float(status["fs_hz"])
        if transport == "modbus-tcp":
            host, port = self.where.rsplit(":", 1)
            self.link = {
                "kind": "modbus-tcp",
                "host": host,
                "port": int(port),
                "poll_interval_s": 0.01,
            }
        else:
            self.link = {"kind": "serial", "port": self.where}

    def _read_lines(self) -> None:
        assert self.proc.stdout is not None  # started with stdout=PIPE
        for line in self.proc.stdout:
            self._lines.put(line)
        self._lines.put("")

    def _line(self, timeout_s: float) -> str:
        try:
            return self._lines.get(timeout=timeout_s)
        except queue.Empty:
            raise RuntimeError(f"fdi sim serve did not answer within {timeout_s:g} s") from None

    def command(self, cmd: dict) -> dict:
        assert self.proc.stdin is not None  # started with stdin=PIPE
        self.proc.stdin.write(json.dumps(cmd) + "\n")
        self.proc.stdin.flush()
        answer = json.loads(self._line(10.0) or "{}")
        if not answer.get("ok"):
            raise RuntimeError(f"device refused {cmd}: {answer}")
        return answer

    def sent_at(self, t: float) -> float:
        """Monotonic time at which the sample of sample time ``t`` was due on the device."""
        return self.tick0 + round(t * self.fs_hz) / self.fs_hz

    def stop(self) -> None:
        _stop(self.proc)


class Daemon:
    """``fdi run --config`` as a subprocess with its state under ``state_dir``."""

    def __init__(self, link: dict, model: Path, state_dir: Path, recorder: bool = True) -> None:
        self.state_dir = state_dir
        config = {
            "link": {
                **link,
                "reconnect": {
                    "backoff_initial_s": 0.1,
                    "backoff_max_s": 1.0,
                    "stall_timeout_s": 3.0,
                },
            }
            if link["kind"] not in ("sim", "replay")
            else link,
            "model": {"path": str(model)},
            "sinks": {
                "event_log": "events.jsonl",
                "stdout": False,
                "status_socket": "status.sock",
                "modbus_status": {"enabled": False},
            },
            "recorder": {"enabled": recorder, "dir": "recordings", "rotate_seconds": 3600},
            "service": {"state_dir": str(state_dir)},
        }
        path = state_dir / "rig.yaml"
        path.write_text(yaml.safe_dump(config))
        self.stderr = open(state_dir / "daemon.stderr", "w")
        self.proc = _fdi(
            "run",
            "--config",
            str(path),
            stdout=subprocess.DEVNULL,
            stderr=self.stderr,
            cwd=state_dir,
        )
        self.events_path = state_dir / "events.jsonl"

    def snapshot(self) -> dict | None:
        from fdi_daemon.dashboard.client import DaemonUnreachable, fetch_snapshot

        try:
            return fetch_snapshot(self.state_dir / "status.sock", timeout_s=5.0)
        except DaemonUnreachable:
            return None

    def wait_for(self, predicate, timeout_s: float, what: str) -> dict:
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            if self.proc.poll() is not None:
                raise RuntimeError(
                    f"the daemon exited while waiting for {what}: "
                    f"{(self.state_dir / 'daemon.stderr').read_text()[-2000:]}"
                )
            snap = self.snapshot()
            if snap is not None and predicate(snap):
                return snap
            time.sleep(0.1)
        raise RuntimeError(f"timed out waiting for {what}")

    def cpu_s(self) -> float:
        """utime + stime of the daemon so far (s)."""
        with open(f"/proc/{self.proc.pid}/stat") as fh:
            fields = fh.read().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")

    def memory_mib(self) -> dict[str, float]:
        """VmRSS and VmHWM of the daemon (MiB)."""
        out = {}
        with open(f"/proc/{self.proc.pid}/status") as fh:
            for line in fh:
                key, _, value = line.partition(":")
                if key in ("VmRSS", "VmHWM"):
                    out[key] = int(value.split()[0]) / 1024.0
        return out

    def stop(self) -> None:
        _stop(self.proc)
        self.stderr.close()


class EventWatcher:
    """Notes the monotonic time at which each new event-log line becomes visible."""

    def __init__(self, path: Path, poll_s: float = 0.0005) -> None:
        self.path = path
        self.poll_s = poll_s
        self.seen: list[tuple[float, dict]] = []
        self._offset = path.stat().st_size if path.exists() else 0
        self._partial = b""
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                size = os.stat(self.path).st_size
            except FileNotFoundError:
                size = 0
            if size > self._offset:
                now = time.monotonic()
                with open(self.path, "rb") as fh:
                    fh.seek(self._offset)
                    data = fh.read(size - self._offset)
                self._offset += len(data)
                *lines, self._partial = (self._partial + data).split(b"\n")
                self.seen.extend((now, json.loads(line)) for line in lines if line.strip())
            time.sleep(self.poll_s)

    def kinds(self) -> list[str]:
        return [e["kind"] for _, e in self.seen]

    def count(self, *kinds: str) -> int:
        return sum(k in kinds for k in self.kinds())

    def wait(self, kinds: tuple[str, ...], count: int, timeout_s: float) -> None:
        """Until ``count`` events of any of ``kinds`` were seen."""
        end = time.monotonic() + timeout_s
        while self.count(*kinds) < count:
            if time.monotonic() > end:
                raise RuntimeError(
                    f"timed out waiting for {' or '.join(kinds)} #{count}; "
                    f"events seen: {self.kinds()}"
                )
            time.sleep(0.01)

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(5)


def _percentiles(values_ms: list[float]) -> dict:
    arr = np.asarray(values_ms, dtype=float)
    if arr.size == 0:
        return {"p50": None, "p99": None, "max": None, "events": 0}
    return {
        "p50": float(np.percentile(arr, 50)),
        "p99": float(np.percentile(arr, 99)),
        "max": float(arr.max()),
        "events": int(arr.size),
    }


def measure_link(
    transport: str, model: Path, fault_cycles: int, stalls: int, cpu_window_s: float, work_dir: Path
) -> dict:
    """Latency and CPU share of the daemon on one transport (see the module docstring)."""
    state = work_dir / transport
    state.mkdir()
    device = Device(transport)
    daemon = watcher = None
    try:
        daemon = Daemon(device.link, model, state)
        daemon.wait_for(lambda s: s.get("state") == "monitoring", STARTUP_TIMEOUT_S, "monitoring")
        first = daemon.snapshot()
        cpu0, wall0 = daemon.cpu_s(), time.monotonic()
        time.sleep(cpu_window_s)
        cpu1, wall1 = daemon.cpu_s(), time.monotonic()
        last = daemon.snapshot()
        if first is None or last is None:
            raise RuntimeError("the daemon's status socket stopped answering")
        cpu = {
            "percent_of_one_core": 100.0 * (cpu1 - cpu0) / (wall1 - wall0),
            "window_s": wall1 - wall0,
            "samples_in_window": last["link"]["samples"] - first["link"]["samples"],
        }

        watcher = EventWatcher(daemon.events_path)
        for cycle in range(1, fault_cycles + 1):
            device.command({"set": {"bearing_supply": 0.35}})
            watcher.wait(("friction_isolated", "other_fault"), cycle, 30.0)
            time.sleep(0.3)
            device.command({"set": {"bearing_supply": 1.0}})
            watcher.wait(("cleared",), cycle, 30.0)
            time.sleep(0.5)
        for _ in range(stalls if transport == "serial" else 0):
            before = watcher.count("data_gap")
            device.command({"inject": "stall", "seconds": 0.1})
            watcher.wait(("data_gap",), before + 1, 10.0)
            time.sleep(0.3)
        time.sleep(0.2)
        watcher.stop()
        latency = [
            (e["kind"], 1e3 * (seen - device.sent_at(e["t"])))
            for seen, e in watcher.seen
            if e["kind"] in SAMPLE_EVENTS and isinstance(e.get("t"), (int, float))
        ]
        final = daemon.snapshot() or {}
    finally:
        if watcher is not None:
            watcher.stop()
        if daemon is not None:
            daemon.stop()
        device.stop()
    by_kind = {
        kind: _percentiles([ms for k, ms in latency if k == kind])
        for kind in dict.fromkeys(k for k, _ in latency)
    }
    return {
        "latency_ms": _percentiles([ms for _, ms in latency]),
        "by_kind": by_kind,
        "cpu": cpu,
        "deadline_misses": final.get("link", {}).get("deadline_misses"),
        "samples": final.get("link", {}).get("samples"),
        "lateness_us": final.get("link", {}).get("lateness_us"),
        "other_fault_events": watcher.kinds().count("other_fault"),
    }


def measure_memory(model: Path, simulated_s: float, work_dir: Path) -> dict:
    """Resident memory of the daemon after ``simulated_s`` of samples (see the docstring)."""
    state = work_dir / "memory"
    state.mkdir()
    scenario = (
        Path(__file__).resolve().parents[2] / "configs" / "scenarios" / "fault_free_hour.yaml"
    )
    link = {
        "kind": "sim",
        "realtime": False,
        "seed": 3,
        "scenario": str(scenario) if scenario.exists() else None,
    }
    daemon = Daemon(link, model, state)
    try:
        start = daemon.wait_for(
            lambda s: s.get("state") == "monitoring", STARTUP_TIMEOUT_S, "monitoring"
        )
        at_start = {**daemon.memory_mib(), "t": start["t"]}
        wall0 = time.monotonic()
        end = daemon.wait_for(
            lambda s: (s.get("t") or 0) >= simulated_s,
            max(600.0, simulated_s),
            f"{simulated_s:g} s of samples",
        )
        wall = time.monotonic() - wall0
        after = {**daemon.memory_mib(), "t": end["t"]}
        samples = end["link"]["samples"]
    finally:
        daemon.stop()
    return {
        "simulated_s": simulated_s,
        "samples": samples,
        "at_monitoring_mib": at_start,
        "after_mib": after,
        "growth_mib": after["VmRSS"] - at_start["VmRSS"],
        "wall_s": wall,
        "scenario": link["scenario"] or "device default",
    }


def bench_e2e(quick: bool = False, model: str | Path | None = None) -> dict:
    """End-to-end figures of the daemon; ``quick``: fewer events, 10 simulated minutes."""
    model = (Path(model) if model is not None else default_model_path()).resolve()
    if not model.exists():
        return {"skipped": f"no model file at {model}"}
    cycles, stalls, window = (3, 10, 5.0) if quick else (15, 40, 20.0)
    with tempfile.TemporaryDirectory(prefix="fdi-bench-e2e-") as tmp:
        work = Path(tmp)
        out = {"model": str(model), "quick": quick}
        for transport in ("modbus-tcp", "serial"):
            out[transport] = measure_link(transport, model, cycles, stalls, window, work)
        out["memory"] = measure_memory(model, 600.0 if quick else HOUR_S, work)
    return out


def e2e_table(e2e: dict):
    """A rich table of the figures (for `fdi bench`)."""
    from rich.table import Table

    table = Table(title="daemon end to end (fdi sim serve -> fdi run -> event log)")
    table.add_column("measure")
    table.add_column("value", justify="right")
    if "skipped" in e2e:
        table.add_row("skipped", e2e["skipped"])
        return table
    for transport in ("modbus-tcp", "serial"):
        r = e2e[transport]
        lat = r["latency_ms"]
        if lat["events"]:
            table.add_row(
                f"{transport}: sample -> event written p50 / p99 (ms)",
                f"{lat['p50']:.1f} / {lat['p99']:.1f}  ({lat['events']} events)",
            )
        table.add_row(
            f"{transport}: daemon CPU at 256 Hz (% of one core)",
            f"{r['cpu']['percent_of_one_core']:.1f}",
        )
    mem = e2e["memory"]
    table.add_row(
        f"resident memory after {mem['simulated_s'] / 60:g} simulated min (MiB)",
        f"{mem['after_mib']['VmRSS']:.0f} (at start {mem['at_monitoring_mib']['VmRSS']:.0f},"
        f" peak {mem['after_mib']['VmHWM']:.0f})",
    )
    return table
