"""SIGTERM to an fdi command (a user's `kill`, `timeout`, a service manager) stops it as
Ctrl-C does: the processes it started are stopped, one line says so, exit 143."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import psutil

from fdi_daemon.cli import main

REPO = Path(__file__).resolve().parents[1]


def test_sigterm_stops_the_command_and_the_processes_it_started(tmp_path):
    # `fdi bench` runs a simulated device and a daemon as subprocesses for its end-to-end
    # part; Python's default for SIGTERM ended the bench at once and left both running
    proc = subprocess.Popen([sys.executable, "-m", "fdi_daemon", "bench", "--quick"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            cwd=tmp_path, start_new_session=True,
                            env={**os.environ, "PYTHONPATH": str(REPO)})
    parent = psutil.Process(proc.pid)
    seen: set[psutil.Process] = set()
    deadline = time.monotonic() + 120
    while proc.poll() is None and time.monotonic() < deadline and len(seen) < 2:
        seen.update(parent.children(recursive=True))
        time.sleep(0.2)
    assert len(seen) >= 2, "the bench never started its device and daemon"
    proc.send_signal(signal.SIGTERM)  # the bench itself, not its process group
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 128 + signal.SIGTERM, (proc.returncode, err)
    assert "Traceback" not in err, err
    assert err.strip().splitlines()[-1] == "fdi bench: terminated"
    time.sleep(1)
    assert [p.pid for p in seen if p.is_running() and p.status() != psutil.STATUS_ZOMBIE] == []


def test_a_command_leaves_the_sigterm_handler_as_it_found_it(tmp_path, capsys):
    before = signal.getsignal(signal.SIGTERM)
    assert main(["replay", str(tmp_path / "missing.csv"), "--model",
                 str(tmp_path / "missing.yaml")]) != 0
    assert signal.getsignal(signal.SIGTERM) is before
