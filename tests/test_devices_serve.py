"""`fdi sim serve` as a subprocess: where to connect, live fault control, clean stop."""

import json
import queue
import signal
import subprocess
import sys
import threading
import time

import pytest
from pymodbus.client import ModbusTcpClient

from fdi_daemon.io import modbus_map as mm
from fdi_daemon.io.links.base import make_link
from hil_sim.devices.realtime import realtime_rig
from hil_sim.devices.serve import SimulatedDevice


class Served:
    """`fdi sim serve ARGS` with its stdout lines in a queue and stdin for commands."""

    def __init__(self, *args):
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "fdi_daemon", "sim", "serve", *args],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        self.lines: queue.Queue[str] = queue.Queue()
        threading.Thread(target=self._pump, daemon=True).start()
        self.where = self.line(timeout_s=30.0)

    def _pump(self):
        for line in self.proc.stdout:
            self.lines.put(line.rstrip("\n"))

    def line(self, timeout_s=10.0):
        try:
            return self.lines.get(timeout=timeout_s)
        except queue.Empty:
            self.proc.kill()
            raise AssertionError(f"no output; stderr: {self.proc.stderr.read()}") from None

    def command(self, obj):
        self.proc.stdin.write(json.dumps(obj) + "\n")
        self.proc.stdin.flush()
        return json.loads(self.line())

    def stop(self, sig=signal.SIGTERM):
        self.proc.send_signal(sig)
        try:
            return self.proc.wait(timeout=20)
        finally:
            if self.proc.poll() is None:
                self.proc.kill()


def read_n(link, n, timeout_s=10.0):
    out = []
    end = time.monotonic() + timeout_s
    while len(out) < n and time.monotonic() < end:
        out += link.read(0.05)
    return out


def test_serve_serial_prints_the_pty_and_takes_commands():
    dev = Served("--serial", "--seed", "3")
    try:
        assert dev.where.startswith("/dev/")
        link = make_link({"kind": "serial", "port": dev.where})
        link.open()
        try:
            assert len(read_n(link, 20)) >= 20
            base = link.counters()["crc_errors"]
            assert dev.command({"inject": "corrupt", "count": 3}) == {"ok": True}
            reply = dev.command({"set": {"bearing_supply": 0.3}})
            assert reply["ok"] and reply["faults"]["bearing_supply"] == 0.3
            end = time.monotonic() + 10
            while dev.command({"status": True})["status"]["injected"]["corrupted_frames"] < 3:
                assert time.monotonic() < end
                link.read(0.05)
            read_n(link, 30)
            assert link.counters()["crc_errors"] - base == 3
            bad = dev.command({"set": {"warp_drive": 1}})
            assert bad["ok"] is False and "warp_drive" in bad["error"]
            assert dev.command({"frobnicate": 1})["ok"] is False
        finally:
            link.close()
    finally:
        assert dev.stop() == 0


def test_serve_modbus_tcp_on_a_free_port_with_fault_registers():
    dev = Served("--modbus-tcp", "127.0.0.1:0", "--word-order", "little")
    try:
        host, port = dev.where.rsplit(":", 1)
        assert host == "127.0.0.1" and int(port) > 0
        link = make_link(
            {"kind": "modbus-tcp", "host": host, "port": int(port), "word_order": "little"}
        )
        link.open()
        assert len(read_n(link, 30)) >= 30
        link.close()
        client = ModbusTcpClient(host, port=int(port))
        client.connect()
        client.write_registers(
            mm.FAULT_REGISTERS["bearing_supply"][0], mm.encode_f32(0.25, "little"), device_id=1
        )
        status = dev.command({"status": True})["status"]
        assert status["faults"]["bearing_supply"] == pytest.approx(0.25, rel=1e-7)
        # the device's tick clock is this machine's monotonic clock
        due = status["tick0_monotonic_s"] + status["seq"] / status["fs_hz"]
        assert abs(due - time.monotonic()) < 5.0
        client.close()
    finally:
        assert dev.stop() == 0


def test_serve_modbus_rtu_keeps_a_symlink_and_stops_on_sigint(tmp_path):
    link_path = tmp_path / "rtu.tty"
    dev = Served("--modbus-rtu", "--link", str(link_path), "--device-id", "5")
    try:
        assert dev.where == str(link_path) and link_path.is_symlink()
        link = make_link({"kind": "modbus-rtu", "port": dev.where, "device_id": 5})
        link.open()
        samples = read_n(link, 30)
        link.close()
        seqs = [s.seq for s in samples]
        assert seqs == list(range(seqs[0], seqs[0] + len(seqs)))
    finally:
        assert dev.stop(signal.SIGINT) == 0
    assert not link_path.exists()


def test_serve_rejects_a_bad_address_in_one_line():
    proc = subprocess.run(
        [sys.executable, "-m", "fdi_daemon", "sim", "serve", "--modbus-tcp", "localhost"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 2
    assert proc.stderr.count("\n") == 1 and "HOST:PORT" in proc.stderr


def test_serve_names_a_link_in_a_missing_directory(tmp_path):
    """It said "[Errno 2] No such file or directory: '/dev/pts/3' -> '.../link.tmp123'"."""
    link = tmp_path / "no" / "rig"
    proc = subprocess.run(
        [sys.executable, "-m", "fdi_daemon", "sim", "serve", "--serial", "--link", str(link)],
        capture_output=True,
        text=True,
        timeout=60,
        stdin=subprocess.DEVNULL,
    )
    assert proc.returncode == 2
    assert proc.stderr.splitlines() == [
        f"fdi sim: error: --link {link}: cannot write there: directory {link.parent} does not exist"
    ]


@pytest.mark.slow
def test_link_measurement_tool_reports_every_transport(tmp_path):
    from hil_sim.devices import measure

    out = tmp_path / "links.json"
    assert measure.main(["--seconds", "0.5", "--decoder-frames", "2000", "--json", str(out)]) == 0
    figures = json.loads(out.read_text())
    for kind in ("modbus-tcp", "modbus-rtu", "serial"):
        assert figures[kind]["samples_per_s"] > 0
        assert figures[kind]["latency_ms"]["p50"] <= figures[kind]["latency_ms"]["max"]
    assert figures["serial_decoder_frames_per_s"] > 0


@pytest.mark.parametrize("transport", ["modbus-tcp", "modbus-rtu"])
def test_status_is_valid_as_soon_as_start_returns(transport):
    """The device clock runs before start() returns: status() at once used to fail, and in
    `fdi sim serve` that killed the stdin control loop."""
    device = SimulatedDevice(transport, realtime_rig(seed=1))
    device.start()
    try:
        assert device.status()["tick0_monotonic_s"] > 0
    finally:
        device.stop()
