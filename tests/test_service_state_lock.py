"""One daemon per state folder: a second `fdi run` is refused naming the holder; the lock
goes with the holder on any exit (SIGKILL included); a restart names the alarm it inherits."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from alarm_state_support import seed_open_alarm
from process_support import start_fdi

from fdi_daemon.service.state_lock import LOCK_NAME


def wait_for_line(proc: subprocess.Popen, text: str, timeout_s: float = 240.0) -> list[str]:
    """The stdout lines of ``proc`` up to the first containing ``text``."""
    lines: list[str] = []
    deadline = time.monotonic() + timeout_s
    assert proc.stdout is not None
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if not line:
            break
        lines.append(line)
        if text in line:
            return lines
    raise AssertionError(f"{text!r} not seen; stdout {''.join(lines)}; rc {proc.poll()}")


def second_run(state: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "fdi_daemon", "run", "--state-dir", str(state), "--duration", "1"],
        capture_output=True,
        text=True,
        timeout=120,
    )


def test_a_second_daemon_is_refused_naming_the_holder_and_sigkill_frees_the_folder(tmp_path):
    state = tmp_path / "state"
    first = start_fdi("run", "--state-dir", str(state))
    try:
        wait_for_line(first, "  state   ")
        refused = second_run(state)
        assert refused.returncode == 2, refused.stderr
        lines = refused.stderr.strip().splitlines()
        assert len(lines) == 1 and "Traceback" not in refused.stderr, refused.stderr
        assert f"state folder {state} is in use by another fdi daemon (pid {first.pid}" in lines[0]
        assert f"command fdi run --state-dir {state})" in lines[0]
        holder = json.loads((state / LOCK_NAME).read_text())
        assert holder["pid"] == first.pid
        os.kill(first.pid, signal.SIGKILL)  # no clean-up at all: the kernel drops the flock
        first.wait(timeout=30)
    finally:
        if first.poll() is None:
            first.kill()
            first.wait()
        first.stdout.close()
        first.stderr.close()
    after = second_run(state)
    assert after.returncode == 0, after.stderr[-2000:]
    assert "events of this run: " in after.stdout


def test_a_restart_names_the_alarm_it_inherits_and_counts_its_own_events(tmp_path):
    state = tmp_path / "state"
    started = seed_open_alarm(state)
    result = second_run(state)
    assert result.returncode == 0, result.stderr[-2000:]
    since = time.strftime("%Y-%m-%d %H:%M:%S %z", time.localtime(started))
    assert (
        f"  alarm carried over from an earlier run: #1 P1 unacknowledged since {since}"
        in result.stdout
    )
    summary = result.stdout.strip().splitlines()[-1]
    this_run = summary.split("events of this run: ")[1].split(";")[0]
    assert "alarm_raised" not in this_run and "calibrated 7" not in this_run, summary
    assert "alarm_raised 1" in summary.split("kept across restarts): ")[1]
