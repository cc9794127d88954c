"""The status-socket client against real Unix socket servers (the daemon's and a scripted one)."""

from __future__ import annotations

import math
import time

import pytest
from conftest_dashboard import ScriptedStatusServer, make_snapshot

from fdi_daemon.dashboard.client import (
    DaemonUnreachable,
    SocketProvider,
    StatusConnection,
    fetch_snapshot,
)


class FakeClock:
    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


@pytest.fixture
def sock_path(tmp_path):
    return tmp_path / "status.sock"


def test_reads_the_daemons_status_socket_on_one_connection(sock_path):
    sinks = pytest.importorskip("fdi_daemon.service.sinks")
    board = sinks.StatusBoard()
    server = sinks.StatusSocketServer(sock_path, board)
    try:
        first = make_snapshot("calibrating", theta=(math.nan, 0.5))
        first["time"] = time.time()
        board.publish(first)
        provider = SocketProvider(sock_path)
        frame = provider()
        assert frame.notice is None
        assert frame.snapshot["state"] == "calibrating"
        assert frame.snapshot["monitor"]["theta1"] is None  # NaN travels as null
        assert frame.snapshot["monitor"]["theta2"] == 0.5
        second = make_snapshot("friction_isolated", theta=(0.97, 2.3))
        second["time"] = time.time()
        board.publish(second)
        frame = provider()
        assert frame.snapshot["state"] == "friction_isolated"
        assert frame.snapshot["monitor"]["theta1"] == 0.97
        assert server.requests == 2  # the second frame asked on the same connection
        provider.close()
    finally:
        server.close()


def test_fetch_snapshot_from_scripted_server(sock_path):
    with ScriptedStatusServer(sock_path, [make_snapshot("monitoring")]) as server:
        snapshot = fetch_snapshot(sock_path)
        assert snapshot["state"] == "monitoring"
        with StatusConnection(sock_path) as connection:
            states = [connection.request()["state"] for _ in range(3)]
        assert states == ["monitoring"] * 3
        assert server.served == 4


def test_absent_socket_is_a_notice_not_an_error(sock_path):
    provider = SocketProvider(sock_path)
    frame = provider()
    assert frame.snapshot is None
    assert frame.notice.startswith("daemon not reachable, retrying")
    assert str(sock_path) in frame.notice
    with pytest.raises(DaemonUnreachable, match="no socket"):
        fetch_snapshot(sock_path)


def test_stale_socket_file_is_refused(sock_path):
    import socket

    stale = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    stale.bind(str(sock_path))
    stale.close()  # the file stays, nobody listens
    with pytest.raises(DaemonUnreachable, match="nothing listening"):
        fetch_snapshot(sock_path)


def test_garbage_answer_is_reported(sock_path):
    with ScriptedStatusServer(sock_path, raw=b"hello\n"):
        frame = SocketProvider(sock_path)()
    assert "not a JSON snapshot" in frame.notice


def test_keeps_last_snapshot_while_away_and_reconnects_when_back(sock_path):
    clock = FakeClock()
    provider = SocketProvider(sock_path, monotonic=clock, retry_initial_s=0.2, retry_max_s=0.8)
    with ScriptedStatusServer(sock_path, [make_snapshot("monitoring")]):
        assert provider().notice is None
    frame = provider()  # the daemon went away
    assert frame.notice.startswith("daemon not reachable, retrying")
    assert frame.snapshot["state"] == "monitoring"
    delays = [round(provider._next_try - clock.now, 3)]
    for _ in range(3):
        clock.now = provider._next_try - 1e-3
        attempts_before = provider._next_try
        provider()  # too early: no new attempt
        assert provider._next_try == attempts_before
        clock.now = provider._next_try
        provider()
        delays.append(round(provider._next_try - clock.now, 3))
    assert delays == [0.2, 0.4, 0.8, 0.8]
    with ScriptedStatusServer(sock_path, [make_snapshot("friction_isolated")]):
        assert provider().notice is not None  # still waiting for the retry delay
        clock.now += 1.0
        frame = provider()
        assert frame.notice is None and frame.snapshot["state"] == "friction_isolated"
    provider.close()


def test_stalled_daemon_is_reported_except_while_starting(sock_path):
    wall = FakeClock()
    wall.now = time.time() + 10.0  # every answer looks 10 s old
    with ScriptedStatusServer(sock_path, [make_snapshot("monitoring")]):
        frame = SocketProvider(sock_path, wall_clock=wall)()
    assert "snapshot 10 s old" in frame.notice
    with ScriptedStatusServer(sock_path, [{"state": "starting"}]):
        frame = SocketProvider(sock_path, wall_clock=wall)()
    assert frame.notice is None
