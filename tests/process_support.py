"""An `fdi` command as a subprocess, and the processes it starts (psutil)."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from collections.abc import Callable
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
    seen = _children_until(
        proc,
        timeout_s,
        lambda child: command in " ".join(child.cmdline()),
        lambda s: len(s) >= count,
    )
    assert len(seen) >= count, f"only {len(seen)} of {count} processes started"
    return seen


def wait_for_child_reading(
    proc: subprocess.Popen, suffix: str, timeout_s: float = 300.0
) -> set[psutil.Process]:
    """The processes under ``proc`` once one of them has a file ending in ``suffix`` open
    (a fleet's worker replays a recording: the command is past its start-up)."""

    def reading(child: psutil.Process) -> bool:
        try:
            return any(f.path.endswith(suffix) for f in child.open_files())
        except (psutil.NoSuchProcess, psutil.AccessDenied):
            return False

    seen = _children_until(proc, timeout_s, lambda child: True, lambda s: any(map(reading, s)))
    if not any(map(reading, seen)):
        raise AssertionError(f"no process under {proc.pid} opened a {suffix} file")
    return seen


def _children_until(
    proc: subprocess.Popen,
    timeout_s: float,
    keep: Callable[[psutil.Process], bool],
    done: Callable[[set[psutil.Process]], bool],
) -> set[psutil.Process]:
    """The processes under ``proc`` (at any depth) for which ``keep`` holds, gathered in
    whole passes every 50 ms until ``done`` holds for them, ``proc`` ends or ``timeout_s``
    passes; a process that is gone (or not ours to read) meanwhile is left out."""
    parent = psutil.Process(proc.pid)
    seen: set[psutil.Process] = set()
    deadline = time.monotonic() + timeout_s
    while proc.poll() is None and time.monotonic() < deadline and not done(seen):
        for child in parent.children(recursive=True):
            try:
                if keep(child):
                    seen.add(child)
            except (psutil.NoSuchProcess, psutil.AccessDenied):
                pass
        time.sleep(0.05)
    return seen


def survivors(processes) -> list[int]:
    """The pids of ``processes`` still running a second from now (zombies are gone)."""
    time.sleep(1)
    return [p.pid for p in processes if p.is_running() and p.status() != psutil.STATUS_ZOMBIE]
