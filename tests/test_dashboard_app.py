"""The dashboard loop: providers, q to quit (through a real pty), running alongside work."""

from __future__ import annotations

import errno
import io
import os
import pty
import threading
import time

import pytest
from conftest_dashboard import make_snapshot
from rich.console import Console

from fdi_daemon.dashboard.app import (
    DashboardConsole,
    Frame,
    KeyReader,
    LatestSnapshot,
    run_alongside,
    run_dashboard,
)


def quiet_console() -> Console:
    return Console(file=io.StringIO(), width=80, height=24, force_terminal=False)


def test_latest_snapshot_hands_over_the_newest():
    box = LatestSnapshot()
    assert box() == Frame(None)
    box.publish(make_snapshot("monitoring"))
    box.publish(make_snapshot("fault_detected"), notice="replay")
    frame = box()
    assert frame.snapshot["state"] == "fault_detected" and frame.notice == "replay"


def test_loop_polls_the_provider_until_stopped():
    calls = []
    stop = threading.Event()

    def provider() -> Frame:
        calls.append(time.monotonic())
        if len(calls) == 5:
            stop.set()
        return Frame(make_snapshot())

    console = quiet_console()
    assert run_dashboard(provider, refresh_hz=50, console=console, stop=stop) == "stopped"
    assert len(calls) == 6  # five frames, then the final state once stopped
    assert "MONITORING" in console.file.getvalue()


def test_q_from_a_terminal_quits_and_restores_the_terminal():
    import termios

    master, slave = pty.openpty()
    try:
        with open(slave, "rb", buffering=0, closefd=False) as stream:
            before = termios.tcgetattr(slave)
            keys = KeyReader(stream)
            with keys:
                assert keys.interactive
                assert not termios.tcgetattr(slave)[3] & termios.ICANON
                os.write(master, b"q")
                assert (
                    run_dashboard(
                        lambda: Frame(None), refresh_hz=20, console=quiet_console(), keys=keys
                    )
                    == "quit"
                )
            assert termios.tcgetattr(slave) == before
    finally:
        os.close(master)
        os.close(slave)


def test_not_a_terminal_reads_no_keys():
    with KeyReader(io.StringIO()) as keys:
        assert not keys.interactive
        assert keys.wait(0.01) == ""


def test_run_alongside_returns_the_work_result_and_shows_its_snapshots():
    box = LatestSnapshot()
    console = quiet_console()

    def work() -> int:
        for state in ("calibrating", "monitoring", "friction_isolated"):
            box.publish(make_snapshot(state))
            time.sleep(0.15)
        return 3

    assert run_alongside(work, box, console=console, refresh_hz=20) == 3
    assert "FRICTION ISOLATED" in console.file.getvalue()


WORK_IN_A_TERMINAL = """
import logging, sys, time
sys.path.insert(0, {tests!r})
from conftest_dashboard import make_snapshot
from fdi_daemon.dashboard.app import LatestSnapshot, run_alongside
logging.basicConfig(level=logging.INFO, stream=sys.stderr)
box = LatestSnapshot()
def work():
    box.publish(make_snapshot("monitoring"))
    print("printed by work", flush=True)
    logging.info("logged by work")
    time.sleep(0.5)
    return 7
print("exit code", run_alongside(work, box))
"""


def test_output_of_work_waits_until_the_dashboard_has_left_the_screen(tmp_path):
    """In a real terminal (a pty), what `work` prints must not land on the dashboard."""
    import subprocess
    import sys
    from pathlib import Path

    script = tmp_path / "work.py"
    script.write_text(WORK_IN_A_TERMINAL.format(tests=str(Path(__file__).parent)))
    master, slave = pty.openpty()
    env = {k: v for k, v in os.environ.items() if k not in ("COLUMNS", "LINES")}
    process = subprocess.Popen(
        [sys.executable, str(script)],
        stdin=slave,
        stdout=slave,
        stderr=slave,
        env={**env, "TERM": "xterm"},
        close_fds=True,
    )
    os.close(slave)
    output = b""
    try:
        while True:
            try:
                chunk = os.read(master, 65536)
            except OSError:  # the child closed the pty
                break
            if not chunk:
                break
            output += chunk
        assert process.wait(timeout=30) == 0
    finally:
        os.close(master)
        if process.poll() is None:
            process.kill()
    text = output.decode("utf-8", errors="replace")
    leave_screen = text.rindex("\x1b[?1049l")  # the alternate screen is left here
    assert "MONITORING" in text[:leave_screen]
    for line in ("printed by work", "logged by work", "exit code 7"):
        assert text.index(line) > leave_screen, line


class DeadTerminal(io.StringIO):
    """A console file whose writes fail as on a terminal that hung up; counts the tries."""

    def __init__(self, err: int):
        super().__init__()
        self.err = err
        self.writes = 0

    def write(self, text: str) -> int:
        self.writes += 1
        raise OSError(self.err, os.strerror(self.err))


@pytest.mark.parametrize("err", [errno.EIO, errno.EPIPE])
def test_a_write_to_a_dead_terminal_ends_the_loop_instead_of_spinning(err):
    calls = []

    def provider() -> Frame:
        calls.append(1)
        return Frame(make_snapshot())

    dead = DeadTerminal(err)
    console = DashboardConsole(file=dead, width=80, height=24, force_terminal=True)
    assert (
        run_dashboard(provider, refresh_hz=50, console=console, keys=KeyReader(io.StringIO()))
        == "hangup"
    )
    assert len(calls) <= 1 and dead.writes <= 3  # at most one frame tried, no retry loop


def test_a_hung_up_terminal_ends_the_loop_and_restores_nothing_that_fails():
    master, slave = pty.openpty()
    with open(slave, "rb", buffering=0, closefd=False) as stream:
        with KeyReader(stream) as keys:
            os.close(master)  # the terminal emulator goes away: end of input on the slave
            started = time.monotonic()
            assert (
                run_dashboard(
                    lambda: Frame(None), refresh_hz=20, console=quiet_console(), keys=keys
                )
                == "hangup"
            )
            assert time.monotonic() - started < 30  # ended by itself (before: spun forever)
    os.close(slave)


def test_hangup_of_the_dashboards_terminal_stops_the_work():
    """q and a hangup both call request_stop; the work then returns."""
    stopped = threading.Event()

    def work() -> int:
        stopped.wait(30)
        return 0 if stopped.is_set() else 1

    dead = DeadTerminal(errno.EPIPE)
    console = DashboardConsole(file=dead, width=80, height=24, force_terminal=True)
    assert (
        run_alongside(
            work, lambda: Frame(make_snapshot()), request_stop=stopped.set, console=console
        )
        == 0
    )


def test_an_unwritable_place_for_the_held_output_is_one_clear_error(tmp_path, monkeypatch):
    """Only with a terminal on stdout is anything held; a pty stands in for it."""
    from fdi_daemon.dashboard.app import captured_output
    from fdi_daemon.errors import UserError

    master, slave = pty.openpty()
    blocker = tmp_path / "file"
    blocker.write_text("")
    try:
        with open(slave, "w", closefd=False) as fake_stdout:
            monkeypatch.setattr("sys.stdout", fake_stdout)
            with pytest.raises(UserError, match="cannot hold the output there"):
                with captured_output(keep=blocker / "held.log"):
                    pass
    finally:
        os.close(master)
        os.close(slave)
