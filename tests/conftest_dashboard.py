"""Prepared status snapshots (TEAM.md "Status snapshot" schema) for the dashboard tests."""

from __future__ import annotations

import json
import os
import shlex
import shutil
import socket
import subprocess
import threading
import time
import uuid
from pathlib import Path
from typing import Any

import numpy as np
from rich.console import Console

TMUX = shutil.which("tmux")
STATES = (
    "starting",
    "calibrating",
    "monitoring",
    "fault_detected",
    "friction_isolated",
    "other_fault",
)


def make_snapshot(
    state: str = "monitoring",
    *,
    theta: tuple[float, float] = (0.0123, -0.0456),
    history_s: float = 30.0,
    history_points: int = 300,
    t_now: float = 130.0,
    band: dict | None | str = "default",
    n_alarms: int = 2,
    gamma_f: float = 2.4,
    wall_time: float = 1_780_000_000.0,
    seed: int = 0,
) -> dict[str, Any]:
    """A full snapshot; history is noise around θ (or empty when history_points is 0)."""
    rng = np.random.default_rng(seed)
    t = np.linspace(t_now - history_s, t_now, history_points)
    th1 = theta[0] + 0.01 * rng.standard_normal(history_points)
    th2 = theta[1] + 0.01 * rng.standard_normal(history_points)
    if band == "default":
        band = {"theta1": [-0.05, 0.05], "theta2": [-0.08, 0.08]}
    alarms = [
        {
            "t": 100.0 + i * 0.5,
            "kind": ("fault_detected", "friction_isolated", "cleared")[i % 3],
            "theta1": 0.5 + i,
            "theta2": 1.25 + i,
        }
        for i in range(n_alarms)
    ]
    return {
        "time": wall_time,
        "t": t_now,
        "state": state,
        "link": {
            "kind": "sim",
            "connected": True,
            "rate_hz": 256.0,
            "samples": 33280,
            "gaps": 3,
            "crc_errors": 7,
            "bad_samples": 0,
            "tick_latency_us": {"p50": 42.0, "p99": 317.0},
            "deadline_misses": 5,
        },
        "monitor": {
            "state": state,
            "theta1": theta[0],
            "theta2": theta[1],
            "friction_level": 0.25,
            "band": band,
            "signature": [1.0, gamma_f],
            "residual_rms": 0.0321,
            "statistic": 1.5,
            "threshold": 10.0,
            "history": {"t": t.tolist(), "theta1": th1.tolist(), "theta2": th2.tolist()},
        },
        "alarms": alarms,
        "model": {
            "path": "configs/sim/model.yaml",
            "provenance": {
                "tool": "fdi signature",
                "source": "friction_run.csv",
                "gamma_f": gamma_f,
            },
        },
    }


def screen_text(renderable, width: int = 80, height: int = 24) -> str:
    """What a `width` x `height` terminal shows for `renderable`, as plain text."""
    console = Console(
        record=True,
        width=width,
        height=height,
        color_system=None,
        force_terminal=False,
        legacy_windows=False,
    )
    console.print(renderable)
    return console.export_text()


class ScriptedStatusServer:
    """A status socket in a thread, speaking the daemon's protocol (a line on connect, then
    one per request line). Answers walk through `snapshots` (the last one repeats), with
    ``time`` set to now so that the client never sees them stale; `raw` replaces every
    answer with those bytes."""

    def __init__(
        self,
        path: str | Path,
        snapshots: list[dict[str, Any]] | None = None,
        raw: bytes | None = None,
    ):
        self.path = str(path)
        self.snapshots = snapshots or [{"state": "starting"}]
        self.raw = raw
        self.served = 0
        self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        self._sock.bind(self.path)
        self._sock.listen(8)
        self._sock.settimeout(0.05)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._serve, daemon=True)

    def __enter__(self) -> ScriptedStatusServer:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2.0)
        self._sock.close()
        if os.path.exists(self.path):
            os.unlink(self.path)

    def _answer(self) -> bytes:
        if self.raw is not None:
            return self.raw
        snapshot = dict(self.snapshots[min(self.served, len(self.snapshots) - 1)])
        snapshot["time"] = time.time()
        self.served += 1
        return json.dumps(snapshot).encode() + b"\n"

    def _serve(self) -> None:
        while not self._stop.is_set():
            try:
                conn, _ = self._sock.accept()
            except (TimeoutError, OSError):
                continue
            with conn:
                conn.settimeout(0.05)
                try:
                    conn.sendall(self._answer())
                    while not self._stop.is_set():
                        try:
                            chunk = conn.recv(4096)
                        except TimeoutError:
                            continue
                        if not chunk:
                            break
                        for _ in range(chunk.count(b"\n")):
                            conn.sendall(self._answer())
                except OSError:
                    pass


class TmuxScreen:
    """A detached tmux session of `width` x `height` running `command` (in `cwd`); the
    pane stays after the command ends (`pane_dead`)."""

    def __init__(
        self, command: list[str], width: int = 100, height: int = 30, cwd: str | Path | None = None
    ):
        self.server = f"fdi-test-{uuid.uuid4().hex[:8]}"
        self._tmux(
            "-f",
            "/dev/null",
            "new-session",
            "-d",
            "-s",
            "dash",
            "-x",
            str(width),
            "-y",
            str(height),
            *(["-c", str(cwd)] if cwd else []),
            " ".join(shlex.quote(part) for part in command),
            ";",
            "set-option",
            "-t",
            "dash",
            "remain-on-exit",
            "on",
        )

    def _tmux(self, *args: str, check: bool = True) -> str:
        # COLUMNS/LINES (set under pytest) would override the pane's real size
        env = {k: v for k, v in os.environ.items() if k not in ("COLUMNS", "LINES", "TMUX")}
        return subprocess.run(
            [TMUX, "-L", self.server, *args],
            capture_output=True,
            text=True,
            check=check,
            timeout=10,
            env=env,
        ).stdout

    def text(self, history_lines: int = 0) -> str:
        """The screen (and that many lines scrolled off above it)."""
        return self._tmux("capture-pane", "-p", "-S", str(-history_lines), "-t", "dash")

    def wait_for(self, needle: str, timeout_s: float = 20.0) -> str:
        deadline = time.monotonic() + timeout_s
        screen = ""
        while time.monotonic() < deadline:
            screen = self.text()
            if needle in screen:
                return screen
            time.sleep(0.1)
        raise AssertionError(f"{needle!r} not on screen after {timeout_s} s:\n{screen}")

    def keys(self, *keys: str) -> None:
        self._tmux("send-keys", "-t", "dash", *keys)

    def hang_up(self) -> None:
        """Close the terminal (`tmux kill-session`): SIGHUP, then EOF and EIO on the pty."""
        self._tmux("kill-session", "-t", "dash")

    def pane_dead(self) -> bool:
        return self._tmux("display-message", "-p", "-t", "dash", "#{pane_dead}").strip() == "1"

    def wait_until_dead(self, timeout_s: float = 10.0) -> bool:
        """True once the command in the pane has ended (False after `timeout_s`)."""
        deadline = time.monotonic() + timeout_s
        while not self.pane_dead():
            if time.monotonic() > deadline:
                return False
            time.sleep(0.1)
        return True

    def close(self) -> None:
        self._tmux("kill-server", check=False)
