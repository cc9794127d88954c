"""Reading status snapshots from the daemon's status socket (Unix stream socket, JSON lines).

The protocol is the one of `fdi_daemon.service.sinks.StatusSocketServer`: on connect the
daemon sends one JSON line (the latest snapshot); every line the client sends afterwards is
answered with one more. `StatusConnection` keeps one connection open and asks with "\n", so a
dashboard at 10 Hz costs the daemon no new connection per frame. `SocketProvider` is the
dashboard's snapshot provider: it keeps the last good snapshot, turns an absent, refusing,
silent or stalled daemon into the notice "daemon not reachable, retrying (...)", and
reconnects with a capped, growing delay until the daemon answers again.
"""

from __future__ import annotations

import contextlib
import json
import math
import socket
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from fdi_daemon.dashboard.app import Frame
from fdi_daemon.dashboard.render import number

#: largest answer accepted (a snapshot is a few tens of kB)
MAX_SNAPSHOT_BYTES = 4 * 1024 * 1024
UNREACHABLE = "daemon not reachable, retrying"


class DaemonUnreachable(Exception):
    """The status socket gave no snapshot; the message says why, in a few words."""


class StatusConnection:
    """One open connection to the status socket; `request()` returns the next snapshot."""

    def __init__(self, path: str | Path, timeout_s: float = 0.5):
        self.path = Path(path)
        self.timeout_s = timeout_s
        self._sock: socket.socket | None = None
        self._buffer = b""

    def __enter__(self) -> StatusConnection:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        if self._sock is not None:
            self._sock.close()
        self._sock, self._buffer = None, b""

    def request(self) -> dict[str, Any]:
        """The daemon's latest snapshot; on any failure the connection is closed and
        `DaemonUnreachable` says why (the next call connects again)."""
        with self._failures():
            if self._sock is None:
                self._connect()  # the daemon greets a new client with a snapshot
            else:
                self._sock.sendall(b"\n")
            return _parse(self._read_line())

    def ask(self, request: dict[str, Any]) -> dict[str, Any]:
        """The daemon's answer to one ``{"request": ...}`` (acknowledge, shelve, unshelve);
        failures as in `request`."""
        with self._failures():
            if self._sock is None:
                self._connect()
                self._read_line()  # the greeting snapshot
            assert self._sock is not None
            self._sock.sendall(json.dumps(request).encode() + b"\n")
            return _parse(self._read_line())

    @contextlib.contextmanager
    def _failures(self) -> Iterator[None]:
        """Any failure inside: the connection closed and `DaemonUnreachable` saying why."""
        try:
            yield
        except DaemonUnreachable:
            self.close()
            raise
        except FileNotFoundError:
            self.close()
            raise DaemonUnreachable(f"no socket at {self.path}") from None
        except ConnectionRefusedError:
            self.close()
            raise DaemonUnreachable(f"nothing listening on {self.path}") from None
        except TimeoutError:
            self.close()
            raise DaemonUnreachable(f"no answer within {self.timeout_s:g} s") from None
        except OSError as exc:
            self.close()
            raise DaemonUnreachable(f"{self.path}: {exc.strerror or exc}") from None

    def _connect(self) -> None:
        sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            sock.settimeout(self.timeout_s)
            sock.connect(str(self.path))
        except BaseException:
            sock.close()
            raise
        self._sock = sock

    def _read_line(self) -> bytes:
        assert self._sock is not None
        while b"\n" not in self._buffer:
            if len(self._buffer) > MAX_SNAPSHOT_BYTES:
                raise DaemonUnreachable("answer too long for a snapshot")
            chunk = self._sock.recv(65536)
            if not chunk:
                raise DaemonUnreachable("daemon closed the connection")
            self._buffer += chunk
        line, self._buffer = self._buffer.split(b"\n", 1)
        return line


def _parse(line: bytes) -> dict[str, Any]:
    try:
        snapshot = json.loads(line)
    except (UnicodeDecodeError, json.JSONDecodeError):
        raise DaemonUnreachable("answer is not a JSON snapshot") from None
    if not isinstance(snapshot, dict):
        raise DaemonUnreachable("answer is not a JSON object")
    return snapshot


def fetch_snapshot(path: str | Path, timeout_s: float = 0.5) -> dict[str, Any]:
    """One snapshot from the status socket at `path` (connect, read, close)."""
    with StatusConnection(path, timeout_s) as connection:
        return connection.request()


class SocketProvider:
    """Snapshot provider over the status socket, for `run_dashboard`.

    A snapshot whose ``time`` is more than `stale_after_s` behind the wall clock counts as a
    stalled daemon (except while it is "starting": loading the model may take a while).
    After a failure the next attempt waits `retry_initial_s`, doubling up to `retry_max_s`;
    the first good answer resets the delay.
    """

    def __init__(
        self,
        path: str | Path,
        *,
        timeout_s: float = 0.5,
        stale_after_s: float = 3.0,
        retry_initial_s: float = 0.2,
        retry_max_s: float = 2.0,
        wall_clock: Callable[[], float] = time.time,
        monotonic: Callable[[], float] = time.monotonic,
    ):
        self.path = Path(path)
        self._connection = StatusConnection(path, timeout_s)
        self.stale_after_s = stale_after_s
        self.retry_initial_s = retry_initial_s
        self.retry_max_s = retry_max_s
        self._wall_clock = wall_clock
        self._monotonic = monotonic
        self._last: dict[str, Any] | None = None
        self._notice: str | None = None
        self.last_error: str | None = None
        """Why the last attempt failed (None after a good answer)."""
        self._retry_s = 0.0
        self._next_try = -math.inf

    def __call__(self) -> Frame:
        now = self._monotonic()
        if now < self._next_try:
            return Frame(self._last, self._notice)
        try:
            snapshot = self._connection.request()
        except DaemonUnreachable as exc:
            return self._failed(now, str(exc))
        self._last = snapshot
        age_s = self._wall_clock() - number(snapshot.get("time"))
        if age_s > self.stale_after_s and snapshot.get("state") != "starting":
            return self._failed(now, f"snapshot {age_s:.0f} s old")
        self._retry_s, self._next_try, self._notice = 0.0, -math.inf, None
        self.last_error = None
        return Frame(snapshot)

    def _failed(self, now: float, reason: str) -> Frame:
        self._retry_s = min(max(self._retry_s * 2, self.retry_initial_s), self.retry_max_s)
        self._next_try = now + self._retry_s
        self._notice = f"{UNREACHABLE} ({reason})"
        self.last_error = reason
        return Frame(self._last, self._notice)

    def ask(self, request: dict[str, Any]) -> dict[str, Any]:
        """The daemon's answer to an alarm request, on the connection the snapshots come
        through (`fdi_daemon.dashboard.operator`); raises `DaemonUnreachable`."""
        return self._connection.ask(request)

    def close(self) -> None:
        self._connection.close()
