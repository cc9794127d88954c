"""sd_notify over a real AF_UNIX datagram socket (path and abstract namespace)."""

import logging
import os
import socket

import pytest

from fdi_daemon.service.notify import Notifier, watchdog_period_s


def receive(sock):
    sock.settimeout(5.0)
    return sock.recv(4096).decode()


def test_messages_reach_a_path_socket(tmp_path, monkeypatch):
    path = str(tmp_path / "notify.sock")
    with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM) as server:
        server.bind(path)
        monkeypatch.setenv("NOTIFY_SOCKET", path)
        notifier = Notifier()
        assert notifier.enabled
        assert notifier.ready("monitoring")
        assert receive(server) == "READY=1\nSTATUS=monitoring"
        assert notifier.watchdog()
        assert receive(server) == "WATCHDOG=1"
        assert notifier.status("3 alarms")
        assert receive(server) == "STATUS=3 alarms"
        assert notifier.stopping()
        assert receive(server) == "STOPPING=1"
        assert notifier.sent == 4 and notifier.errors == 0
        notifier.close()


def test_messages_reach_an_abstract_socket():
    name = f"fdi-test-notify-{os.getpid()}"
    with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM) as server:
        server.bind(b"\0" + name.encode())
        notifier = Notifier("@" + name)
        assert notifier.ready()
        assert receive(server) == "READY=1"
        notifier.close()


def test_without_notify_socket_it_is_a_no_op(monkeypatch):
    monkeypatch.delenv("NOTIFY_SOCKET", raising=False)
    notifier = Notifier()
    assert not notifier.enabled
    assert notifier.ready() is False and notifier.errors == 0


def test_send_errors_are_logged_and_counted(tmp_path, caplog):
    notifier = Notifier(str(tmp_path / "nobody-listens.sock"))
    with caplog.at_level(logging.ERROR, logger="fdi.notify"):
        assert notifier.ready() is False
        assert notifier.watchdog() is False
    assert notifier.errors == 2
    errors = [r for r in caplog.records if r.levelno == logging.ERROR]
    assert len(errors) == 1 and "sd_notify" in errors[0].getMessage()
    notifier.close()


def test_relative_notify_socket_is_refused_loudly(caplog):
    with caplog.at_level(logging.ERROR, logger="fdi.notify"):
        notifier = Notifier("relative/path")
    assert not notifier.enabled
    assert "neither a path" in caplog.text


@pytest.mark.parametrize(
    "env, expected",
    [
        ({}, None),
        ({"WATCHDOG_USEC": "10000000"}, 5.0),
        ({"WATCHDOG_USEC": "10000000", "WATCHDOG_PID": "1"}, None),
        ({"WATCHDOG_USEC": "0"}, None),
        ({"WATCHDOG_USEC": "ten"}, None),
    ],
)
def test_watchdog_period(env, expected):
    assert watchdog_period_s(env) == expected
