"""One daemon per state folder: an advisory ``flock`` on ``<state_dir>/fdi.lock``.

`StateDirLock.acquire` takes the lock without waiting and writes who holds it (pid, start
time, command line) into the file; a second daemon on the same folder is refused with one
line naming that holder (`StateDirInUse`, exit 2). The kernel drops a ``flock`` when its
file descriptor closes, so the lock is released on any exit of the holder, SIGKILL and
crashes included; the file itself stays (it is rewritten by the next holder).
"""

from __future__ import annotations

import fcntl
import json
import os
import sys
import time
from pathlib import Path

from fdi_daemon.errors import UserError

__all__ = ["LOCK_NAME", "StateDirInUse", "StateDirLock"]

#: the lock file's name in the state folder
LOCK_NAME = "fdi.lock"


class StateDirInUse(UserError):
    """Another process holds the state folder's lock."""


def _holder_text(path: Path) -> str:
    """``pid N, started <local time>, command <...>`` from the lock file, as far as readable."""
    try:
        holder = json.loads(path.read_text() or "{}")
    except (OSError, ValueError):
        holder = {}
    if not isinstance(holder, dict) or "pid" not in holder:
        return "a process that has not written its name yet"
    started = holder.get("started_unix_s")
    when = (
        time.strftime("%Y-%m-%d %H:%M:%S %z", time.localtime(float(started)))
        if isinstance(started, (int, float))
        else "?"
    )
    return f"pid {holder['pid']}, started {when}, command {holder.get('command', '?')}"


class StateDirLock:
    """The exclusive lock of one state folder for the life of this process (or `release`)."""

    def __init__(self, state_dir: Path) -> None:
        self.path = Path(state_dir) / LOCK_NAME
        self._fd: int | None = None

    def acquire(self) -> None:
        """Take the lock or raise `StateDirInUse` naming the holder; creates the folder."""
        if self._fd is not None:
            return
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
        except OSError as exc:
            raise UserError(f"cannot open the state folder's lock {self.path}: {exc}") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise StateDirInUse(
                f"state folder {self.path.parent} is in use by another fdi daemon "
                f"({_holder_text(self.path)}); stop it or give this one --state-dir"
            ) from None
        holder = {
            "pid": os.getpid(),
            "started_unix_s": round(time.time(), 3),
            "command": " ".join(["fdi", *sys.argv[1:]]),
        }
        os.ftruncate(fd, 0)
        os.pwrite(fd, (json.dumps(holder) + "\n").encode(), 0)
        self._fd = fd

    def release(self) -> None:
        """Drop the lock (closing the descriptor); the file stays for the next holder."""
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None

    @property
    def held(self) -> bool:
        return self._fd is not None
