"""Sinks: event log, stdout lines, worker queue, status socket, Modbus status registers."""

import io
import json
import math
import os
import socket
import stat
import threading
from pathlib import Path

import pytest

from fdi_daemon.dashboard.client import fetch_snapshot
from fdi_daemon.service.sinks import (
    STATUS_REGISTER_COUNT,
    STATUS_REGISTERS,
    EventLog,
    ModbusStatusServer,
    StatusBoard,
    StatusSocketServer,
    StdoutLog,
    Worker,
    decode_status,
    encode_status,
    format_event,
    status_values,
)

ROOT = Path(__file__).resolve().parents[1]


def test_event_log_appends_strict_json_and_fsyncs_alarms(tmp_path, monkeypatch):
    synced = []
    real_fsync = os.fsync
    monkeypatch.setattr(os, "fsync", lambda fd: (synced.append(fd), real_fsync(fd)))
    path = tmp_path / "ev" / "events.jsonl"
    log = EventLog(path, fsync_period_s=1000.0)
    log.write({"t": 1.0, "kind": "calibrated", "theta1": 0.1, "theta2": math.nan})
    assert synced == []
    log.write({"t": 2.0, "kind": "fault_detected", "theta1": 0.5, "theta2": 0.01})
    assert len(synced) == 1
    log.close()
    log = EventLog(path)  # reopen: append, never truncate
    log.write({"t": 3.0, "kind": "cleared"})
    log.close()
    lines = [json.loads(line) for line in path.read_text().splitlines()]
    assert [e["kind"] for e in lines] == ["calibrated", "fault_detected", "cleared"]
    assert lines[0]["theta2"] is None  # NaN is not JSON


def test_stdout_lines_with_and_without_journald_priorities():
    out = io.StringIO()
    StdoutLog(out, priorities=True).write(
        {"t": 20.5, "kind": "fault_detected", "theta1": 0.25, "theta2": -0.5}
    )
    StdoutLog(out, priorities=False).write({"t": 21.0, "kind": "calibrated"})
    first, second = out.getvalue().splitlines()
    assert first.startswith("<4>") and "FAULT DETECTED" in first and "θ1=+0.25" in first
    assert second.lstrip().startswith("t=") and "CALIBRATED" in second
    assert "missing=3" in format_event({"t": 1.0, "kind": "data_gap", "missing": 3})
    lost = format_event({"t": None, "kind": "link_lost", "reason": "refused", "time": 1e9})
    assert "LINK LOST" in lost and "reason=refused" in lost and "time=" not in lost
    isolated = format_event(
        {"t": 20.5, "kind": "friction_isolated", "friction_level": None, "coulomb_change": 1.6}
    )  # the level is not measured yet
    assert "friction_level" not in isolated and "coulomb_change=1.6" in isolated


def test_worker_drops_non_critical_items_but_never_alarms():
    gate = threading.Event()
    handled = []

    def handler(item):
        gate.wait(10)
        handled.append(item)

    worker = Worker("test", handler, maxsize=3)
    results = [worker.put(("status", i)) for i in range(10)]
    for i in range(5):
        assert worker.put(("alarm", i), critical=True)
    gate.set()
    worker.close()
    assert worker.dropped == results.count(False) >= 6
    assert [x for x in handled if x[0] == "alarm"] == [("alarm", i) for i in range(5)]
    assert len(handled) == 15 - worker.dropped


def test_worker_survives_a_failing_handler(caplog):
    calls = []

    def handler(item):
        calls.append(item)
        if item == 1:
            raise OSError("disk full")

    worker = Worker("flaky", handler, maxsize=10)
    for i in range(3):
        worker.put(i)
    worker.close()
    assert calls == [0, 1, 2] and worker.errors == 1
    assert "disk full" in caplog.text


def test_status_socket_serves_json_lines(tmp_path):
    board = StatusBoard()
    board.publish({"time": 1.0, "state": "monitoring", "t": 5.0, "monitor": {"theta1": math.inf}})
    path = tmp_path / "run" / "status.sock"
    server = StatusSocketServer(path, board)
    try:
        assert stat.S_IMODE(os.stat(path).st_mode) == 0o660
        snap = fetch_snapshot(path)
        assert snap["state"] == "monitoring" and snap["monitor"]["theta1"] is None
        # one line on connect, one more per request line; closed when the client is
        with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as sock:
            sock.settimeout(5)
            sock.connect(str(path))
            sock.sendall(b"status\n\n")
            sock.shutdown(socket.SHUT_WR)
            data = b""
            while chunk := sock.recv(65536):
                data += chunk
        lines = data.splitlines()
        assert len(lines) == 3 and json.loads(lines[2])["t"] == 5.0
    finally:
        server.close()
    assert not path.exists()


def test_status_register_encoding_round_trips():
    snapshot = {
        "state": "friction_isolated",
        "t": 123456.789,
        "link": {
            "connected": True,
            "samples": 70000,
            "gaps": 2,
            "crc_errors": 5,
            "tick_latency_us": {"p50": 20.0, "p99": 180.4},
        },
        "monitor": {"theta1": 0.125, "theta2": -2.5, "friction_level": None},
        "counters": {"fault_detected": 1, "friction_isolated": 1},
        "uptime_s": 99.9,
    }
    values = decode_status(encode_status(status_values(snapshot, 7)))
    assert values["state"] == 4 and values["alarm_active"] == 1 and values["heartbeat"] == 7
    assert values["theta1"] == 0.125 and values["theta2"] == -2.5
    assert math.isnan(values["friction_level"])
    assert values["t"] == 123456.789 and values["samples"] == 70000
    assert values["tick_latency_p99_us"] == 180 and values["uptime_s"] == 99
    assert values["crc_errors"] == 5 and values["friction_isolated_count"] == 1


def test_register_map_is_contiguous_and_documented():
    sizes = {"u16": 1, "u32": 2, "f32": 2, "f64": 4}
    address = 0
    doc = (ROOT / "docs" / "status_registers.md").read_text()
    for name, first, kind, _ in STATUS_REGISTERS:
        assert first == address, name
        address += sizes[kind]
        assert f"| {first} " in doc and f"`{name}`" in doc, name
    assert address == STATUS_REGISTER_COUNT


def test_modbus_status_server_with_a_real_client():
    from pymodbus.client import ModbusTcpClient

    board = StatusBoard()
    board.publish(
        {
            "state": "fault_detected",
            "t": 21.25,
            "monitor": {"theta1": 0.75},
            "link": {"connected": True, "samples": 5440},
        }
    )
    server = ModbusStatusServer(board, host="127.0.0.1", port=0, device_id=1)
    client = ModbusTcpClient("127.0.0.1", port=server.port, timeout=5)
    try:
        assert client.connect()
        rr = client.read_holding_registers(0, count=STATUS_REGISTER_COUNT, device_id=1)
        assert not rr.isError()
        values = decode_status(rr.registers)
        assert values["state"] == 3 and values["theta1"] == 0.75 and values["t"] == 21.25
        first_heartbeat = values["heartbeat"]
        board.publish({"state": "friction_isolated", "t": 21.5})
        ir = client.read_input_registers(1, count=3, device_id=1)
        assert ir.registers[0] == 4 and ir.registers[2] == (first_heartbeat + 1) & 0xFFFF
        theta = client.read_holding_registers(5, count=2, device_id=1)
        assert math.isnan(client.convert_from_registers(theta.registers, client.DATATYPE.FLOAT32))
        assert client.write_register(1, 0, device_id=1).isError()  # read-only
        assert client.read_holding_registers(0, count=1, device_id=9).isError()
    finally:
        client.close()
        server.close()


def test_a_file_where_the_status_socket_goes_is_named_and_kept(tmp_path):
    """A regular file at the socket's path was reported as "Address already in use"."""
    path = tmp_path / "status.sock"
    path.write_text("notes")
    with pytest.raises(FileExistsError, match="a file of that name is there, not a socket"):
        StatusSocketServer(path, StatusBoard())
    assert path.read_text() == "notes"
