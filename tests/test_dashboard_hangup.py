"""`fdi run --dashboard` in a real terminal (tmux) that goes away: the daemon must end.

Closing the terminal (an ssh drop, `tmux kill-session`) hangs up the controlling terminal:
SIGHUP, then EIO on every write to it and EOF on reads. With the dashboard on that terminal
the daemon has nobody to show anything to and must stop cleanly (summary written, status
socket closed) instead of reloading on SIGHUP and drawing to a dead terminal forever.
"""

from __future__ import annotations

import os
import signal
import sys
import time
from pathlib import Path

import pytest
from conftest_dashboard import TMUX, TmuxScreen

from fdi_daemon.service.config import load_config

DEFAULT = load_config()

pytestmark = [
    pytest.mark.usefixtures("compiled_kernel_cache"),
    pytest.mark.skipif(TMUX is None, reason="tmux is not installed"),
    pytest.mark.skipif(
        not DEFAULT.model_path.exists(),
        reason=f"{DEFAULT.model_path.name} is not in fdi_daemon/data",
    ),
]


def fdi_pids(marker: str) -> list[int]:
    """`python -m fdi_daemon ...` processes with `marker` among their arguments."""
    pids = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            argv = (entry / "cmdline").read_bytes().decode().split("\0")
        except OSError:
            continue
        if argv[1:3] == ["-m", "fdi_daemon"] and marker in argv:
            pids.append(int(entry.name))
    return pids


def alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


@pytest.mark.parametrize("hangup", ["kill-session", "SIGHUP"])
def test_run_dashboard_ends_cleanly_when_its_terminal_hangs_up(tmp_path, hangup):
    """kill-session: the whole terminal goes (SIGHUP, EOF, EIO); SIGHUP alone: the signal
    without the rest (plain `fdi run` takes it as reload)."""
    state = tmp_path / "state"
    screen = TmuxScreen(
        [sys.executable, "-m", "fdi_daemon", "run", "--dashboard", "--state-dir", str(state)],
        80,
        24,
        cwd=tmp_path,
    )
    pids = []
    try:
        screen.wait_for("MONITORING", timeout_s=60.0)
        pids = fdi_pids(str(state))
        assert len(pids) == 1, pids
        assert (state / "status.sock").exists()
        if hangup == "SIGHUP":
            os.kill(pids[0], signal.SIGHUP)
        else:
            screen.hang_up()
        deadline = time.monotonic() + 30.0  # generous: it never ended before the fix
        while alive(pids[0]) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not alive(pids[0]), "fdi run --dashboard outlived its terminal"
        held = (state / "dashboard-output.log").read_text()
        assert "fdi run: " in held and " samples, " in held  # the summary line
        assert held.count("CALIBRATED") == 1  # a hangup is not a reload here
        assert not (state / "status.sock").exists()  # the socket was closed and removed
    finally:
        for pid in pids:
            if alive(pid):
                os.kill(pid, signal.SIGKILL)
        screen.close()
