"""Alarm requests on the status socket and the Modbus command registers (real sockets, a real
pymodbus client), and the event log reopened after logrotate renamed it."""

from __future__ import annotations

import json
import socket

import pytest

from fdi_daemon.alarms.lifecycle import AlarmSettings
from fdi_daemon.service.alarm_keeper import AlarmKeeper
from fdi_daemon.service.sinks import (
    COMMAND_REGISTERS,
    STATUS_REGISTER_COUNT,
    EventLog,
    ModbusStatusServer,
    StatusBoard,
    StatusSocketServer,
    decode_status,
)


def raised_keeper(allow_remote: bool) -> AlarmKeeper:
    keeper = AlarmKeeper(AlarmSettings(), "m", allow_remote=allow_remote)
    keeper.detector_event({"t": 1.0, "kind": "fault_detected"})
    return keeper


def ask(path, *lines: bytes) -> list[dict]:
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as sock:
        sock.settimeout(5)
        sock.connect(str(path))
        sock.sendall(b"".join(line + b"\n" for line in lines))
        sock.shutdown(socket.SHUT_WR)
        data = b""
        while chunk := sock.recv(65536):
            data += chunk
    return [json.loads(line) for line in data.splitlines()]


def test_status_socket_requests(tmp_path):
    keeper = raised_keeper(allow_remote=True)
    board = StatusBoard()
    board.publish({"state": "monitoring", "t": 3.0})
    server = StatusSocketServer(tmp_path / "s.sock", board, requests=keeper.handle)
    try:
        greeting, snapshot, ack, again, shelve, bad, junk = ask(
            tmp_path / "s.sock",
            b"",
            b'{"request": "acknowledge"}',
            b'{"request": "acknowledge"}',
            b'{"request": "shelve", "duration_s": 600}',
            b'{"request": "reboot"}',
            b'{"no": 1',
        )
    finally:
        server.close()
    assert greeting["t"] == snapshot["t"] == 3.0
    assert ack["ok"] and ack["alarm"]["state"] == "acknowledged"
    assert not again["ok"] and "nothing to acknowledge" in again["error"]
    assert shelve["ok"] and shelve["alarm"]["state_code"] == 4
    assert not bad["ok"] and "unknown request" in bad["error"]
    assert not junk["ok"] and "JSON object" in junk["error"]
    assert [e["kind"] for e in keeper.take_pending()] == ["alarm_acknowledged", "alarm_shelved"]


def test_status_socket_requests_refused_unless_enabled(tmp_path):
    keeper = raised_keeper(allow_remote=False)
    server = StatusSocketServer(tmp_path / "s.sock", StatusBoard(), requests=keeper.handle)
    try:
        _, answer = ask(tmp_path / "s.sock", b'{"request": "acknowledge"}')
    finally:
        server.close()
    assert not answer["ok"] and "allow_remote_acknowledge" in answer["error"]
    assert keeper.lifecycle.state == "unacknowledged"


@pytest.mark.parametrize("allow", [True, False])
def test_modbus_command_registers(allow):
    from pymodbus.client import ModbusTcpClient

    keeper = raised_keeper(allow_remote=allow)
    board = StatusBoard()
    server = ModbusStatusServer(board, port=0, requests=keeper.handle if allow else None)
    client = ModbusTcpClient("127.0.0.1", port=server.port, timeout=5)
    try:
        assert client.connect()
        ack = client.write_register(COMMAND_REGISTERS["alarm_command"], 1, device_id=1)
        if not allow:
            assert ack.isError() and ack.exception_code == 2  # read-only: illegal data address
            assert keeper.lifecycle.state == "unacknowledged"
            return
        assert not ack.isError(), ack
        assert keeper.lifecycle.state == "acknowledged"
        again = client.write_register(COMMAND_REGISTERS["alarm_command"], 1, device_id=1)
        assert again.isError() and again.exception_code == 3  # nothing to acknowledge
        shelve = client.write_register(COMMAND_REGISTERS["shelve_minutes"], 90, device_id=1)
        assert not shelve.isError()
        board.publish({"state": "monitoring", "time": keeper._clock(), "alarm": keeper.summary()})
        values = decode_status(
            client.read_input_registers(0, count=STATUS_REGISTER_COUNT, device_id=1).registers
        )
        assert values["alarm_state"] == 4 and values["alarm_id"] == 1
        assert values["shelve_minutes"] == 90 and values["alarm_active"] == 0
        too_long = client.write_register(COMMAND_REGISTERS["shelve_minutes"], 60000, device_id=1)
        assert too_long.isError() and too_long.exception_code == 3
        assert client.write_register(1, 0, device_id=1).isError()  # others stay read-only
        assert (
            client.write_register(COMMAND_REGISTERS["alarm_command"], 2, device_id=1).isError()
            is False
        )  # unshelve
        assert not keeper.lifecycle.shelved(keeper._clock())
    finally:
        client.close()
        server.close()


def test_event_log_follows_a_rename_by_logrotate(tmp_path):
    path = tmp_path / "events.jsonl"
    log = EventLog(path)
    log.write({"t": 1.0, "kind": "calibrated"})
    path.rename(tmp_path / "events.jsonl.1")  # logrotate's default (create) mode
    log.write({"t": 2.0, "kind": "fault_detected"})
    path.unlink()  # or someone deletes it
    log.write({"t": 3.0, "kind": "cleared"})
    log.close()
    assert [json.loads(x)["t"] for x in (tmp_path / "events.jsonl.1").read_text().splitlines()] == [
        1.0
    ]
    assert [json.loads(x)["t"] for x in path.read_text().splitlines()] == [3.0]
    assert log.reopened == 2
