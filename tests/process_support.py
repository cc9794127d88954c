"""An `fdi` command as a subprocess, and the processes it starts (psutil)."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import psutil

REPO = Path(__file__).resolve().parents[1]


#: ``python -m fdi_daemon ARGV`` with SIGINT and SIGQUIT at their defaults, as a terminal
#: starts a foreground job: a test run started in the background (``cmd &`` in a script,
#: as CI may) ignores both, every process it starts inherits that, and Python then leaves
#: Ctrl-C ignored (the fleet's Ctrl-C test ran to the end with exit 0)
_AS_FOREGROUND_JOB = (
    "import os, signal, sys\n"
    "signal.signal(signal.SIGINT, signal.SIG_DFL)\n"
    "signal.signal(signal.SIGQUIT, signal.SIG_DFL)\n"
    "os.execv(sys.executable, [sys.executable, '-m', 'fdi_daemon', *sys.argv[1:]])"
)


def start_fdi(*args: str, cwd: Path | None = None) -> subprocess.Popen:
    """``python -m fdi_daemon ARGS`` of this checkout in a session of its own (a signal
    reaches what it is sent to, not the test), as a terminal's foreground job (Ctrl-C not
    ignored, whatever the test run ignores), stdout and stderr piped as text."""
    return subprocess.Popen(
        [sys.executable, "-c", _AS_FOREGROUND_JOB, *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=cwd,
        start_new_session=True,
        env={**os.environ, "PYTHONPATH": str(REPO)},
    )


def wait_for_children(
    proc: subprocess.Popen, count: int, timeout_s: float = 120.0, command: str = ""
) -> set[psutil.Process]:
    """The processes started under ``proc`` (at any depth) once ``count`` have been seen;
    with ``command``, only those whose command line contains it (a short-lived helper such
    as the ``uname -p`` behind `platform.processor` is then not counted)."""
    parent = psutil.Process(proc.pid)
    seen: set[psutil.Process] = set()
    deadline = time.monotonic() + timeout_s
    while proc.poll() is None and time.monotonic() < deadline and len(seen) < count:
        for child in parent.children(recursive=True):
            try:
                if command in " ".join(child.cmdline()):
                    seen.add(child)
            except psutil.NoSuchProcess:
                pass
        time.sleep(0.05)
    assert len(seen) >= count, f"only {len(seen)} of {count} processes started"
    return seen


def wait_for_child_reading(
    proc: subprocess.Popen, suffix: str, timeout_s: float = 300.0
) -> set[psutil.Process]:
    """The processes under ``proc`` once one of them has a file ending in ``suffix`` open
    (a fleet's worker replays a recording: the command is past its start-up)."""
    parent = psutil.Process(proc.pid)
    seen: set[psutil.Process] = set()
    deadline = time.monotonic() + timeout_s
    while proc.poll() is None and time.monotonic() < deadline:
        for child in parent.children(recursive=True):
            seen.add(child)
            try:
                if any(f.path.endswith(suffix) for f in child.open_files()):
                    return seen
            except (psutil.NoSuchProcess, psutil.AccessDenied):
                pass
        time.sleep(0.05)
    raise AssertionError(f"no process under {proc.pid} opened a {suffix} file")


def survivors(processes) -> list[int]:
    """The pids of ``processes`` still running a second from now (zombies are gone)."""
    time.sleep(1)
    return [p.pid for p in processes if p.is_running() and p.status() != psutil.STATUS_ZOMBIE]
