"""Modbus conformance of the daemon's status register server, with real clients on 127.0.0.1.

pymodbus's client and, where installed, mbpoll (Debian's independent Modbus master, the tool
that found these defects): device id 255 (Modbus TCP "addressed directly") is answered like
the configured id, other ids get exception 11, and function codes 1 and 2 (coils, discrete
inputs) get exception 1 (illegal function) instead of register 0's bits; a register write
(function codes 6, 16) to a read-only register gets exception 2 (illegal data address), the
answer masters expect for a read-only register of a supported function.
"""

import shutil
import struct
import subprocess

import pytest
from pymodbus.client import ModbusTcpClient

from fdi_daemon.service.sinks import (
    STATUS_REGISTER_COUNT,
    ModbusStatusServer,
    StatusBoard,
    decode_status,
    encode_status,
    status_values,
)

SNAPSHOT = {
    "state": "fault_detected",
    "t": 21.25,
    "monitor": {"theta1": 0.75, "theta2": -2.5},
    "link": {"connected": True, "samples": 70000},
}
ILLEGAL_FUNCTION, ILLEGAL_ADDRESS, ILLEGAL_VALUE, GATEWAY_NO_RESPONSE = 1, 2, 3, 11


@pytest.fixture
def server():
    board = StatusBoard()
    board.publish(SNAPSHOT)
    srv = ModbusStatusServer(board, host="127.0.0.1", port=0, device_id=1)
    yield srv
    srv.close()


@pytest.fixture
def client(server):
    c = ModbusTcpClient("127.0.0.1", port=server.port, timeout=5, retries=0)
    assert c.connect()
    yield c
    c.close()


@pytest.mark.parametrize("device_id", [1, 255])
def test_configured_id_and_255_read_the_same_registers(client, device_id):
    for read in (client.read_input_registers, client.read_holding_registers):
        rr = read(0, count=STATUS_REGISTER_COUNT, device_id=device_id)
        assert not rr.isError(), rr
        values = decode_status(rr.registers)
        assert values["state"] == 3 and values["theta1"] == 0.75 and values["samples"] == 70000


@pytest.mark.parametrize("device_id", [0, 2, 9, 247])
def test_other_ids_get_gateway_target_failed(client, device_id):
    rr = client.read_input_registers(0, count=1, device_id=device_id)
    assert rr.isError() and rr.exception_code == GATEWAY_NO_RESPONSE


@pytest.mark.parametrize("device_id", [1, 255])
@pytest.mark.parametrize("address", [0, 44, 1000])
def test_coils_and_discrete_inputs_are_an_illegal_function(client, device_id, address):
    # before: both answered with the bits of the register at `address`
    for read in (client.read_coils, client.read_discrete_inputs):
        rr = read(address, count=8, device_id=device_id)
        assert rr.isError() and rr.exception_code == ILLEGAL_FUNCTION, (read, rr)
    # the server stays usable after a refusal
    assert client.read_input_registers(1, count=1, device_id=device_id).registers == [3]


def test_writes_stay_refused(client):
    """Without alarm requests every register is read-only: exception 2; coils: exception 1."""
    for device_id in (1, 255):
        for address in (1, 51):
            rr = client.write_register(address, 0, device_id=device_id)
            assert rr.isError() and rr.exception_code == ILLEGAL_ADDRESS, (address, rr)
        rr = client.write_registers(51, [1], device_id=device_id)
        assert rr.isError() and rr.exception_code == ILLEGAL_ADDRESS
        rr = client.write_coil(0, True, device_id=device_id)
        assert rr.isError() and rr.exception_code == ILLEGAL_FUNCTION


def test_words_are_high_word_first_big_endian_bytes():
    """The documented layout, from struct (an independent packing), word for word."""
    regs = encode_status(
        status_values({**SNAPSHOT, "t": 123456.789, "link": {"samples": 0x12345678}}, 7)
    )
    assert regs[17:21] == list(struct.unpack(">4H", struct.pack(">d", 123456.789)))
    assert regs[5:7] == list(struct.unpack(">2H", struct.pack(">f", 0.75)))
    assert regs[7:9] == [0xC020, 0x0000]  # -2.5f
    assert regs[21:23] == [0x1234, 0x5678]
    assert regs[3] == 7


def _mbpoll(port: int, *args: str, write: tuple[str, ...] = ()) -> subprocess.CompletedProcess:
    """mbpoll once against the server (``write``: the values to write, after the host)."""
    return subprocess.run(
        ["mbpoll", "-m", "tcp", "-p", str(port), "-0", "-1", "-o", "3", *args, "127.0.0.1", *write],
        capture_output=True,
        text=True,
        timeout=30,
    )


def _values(stdout: str) -> dict[int, str]:
    """mbpoll's ``[ref]: <tab>value`` lines."""
    out = {}
    for line in stdout.splitlines():
        if line.startswith("[") and "]:" in line:
            ref, _, value = line.partition("]:")
            out[int(ref[1:])] = value.strip()
    return out


@pytest.mark.skipif(shutil.which("mbpoll") is None, reason="mbpoll is not installed")
def test_mbpoll_reads_with_device_id_255_and_is_refused_bits(server):
    regs = _mbpoll(server.port, "-a", "255", "-t", "3", "-r", "0", "-c", "5")
    assert regs.returncode == 0, regs.stderr
    expected = encode_status(status_values(SNAPSHOT, 0))[:5]  # map version, state, ...
    values = _values(regs.stdout)
    assert [values[i] for i in (0, 1, 2, 4)] == [str(expected[i]) for i in (0, 1, 2, 4)]
    assert values[1] == "3"  # fault_detected
    theta = _mbpoll(server.port, "-a", "255", "-t", "3:float", "-B", "-r", "5", "-c", "2")
    assert theta.returncode == 0 and _values(theta.stdout) == {5: "0.75", 7: "-2.5"}
    samples = _mbpoll(server.port, "-a", "255", "-t", "4:int", "-B", "-r", "21", "-c", "1")
    assert samples.returncode == 0 and _values(samples.stdout) == {21: "70000"}
    for table, name in (("0", "coil"), ("1", "discrete input")):
        refused = _mbpoll(server.port, "-a", "255", "-t", table, "-r", "0", "-c", "1")
        assert refused.returncode != 0 and "Illegal function" in refused.stderr, name
    other = _mbpoll(server.port, "-a", "9", "-t", "3", "-r", "0", "-c", "1")
    assert other.returncode != 0 and "Target device failed to respond" in other.stderr
    for address in ("1", "51"):  # holding register writes (function 6) to read-only registers
        write = _mbpoll(server.port, "-a", "255", "-t", "4", "-r", address, write=("1",))
        assert write.returncode != 0 and "Illegal data address" in write.stderr, write.stderr


def test_coil_writes_never_reach_the_alarm_command_register():
    """A coil write at address 51 is not 'write 1 = acknowledge' (only 6 and 16 write)."""
    calls = []
    board = StatusBoard()
    board.publish(SNAPSHOT)
    srv = ModbusStatusServer(
        board,
        host="127.0.0.1",
        port=0,
        device_id=1,
        requests=lambda request: calls.append(request) or {"ok": True},
    )
    c = ModbusTcpClient("127.0.0.1", port=srv.port, timeout=5, retries=0)
    try:
        assert c.connect()
        for device_id in (1, 255):
            rr = c.write_coil(51, True, device_id=device_id)
            assert rr.isError() and rr.exception_code == ILLEGAL_FUNCTION
            rr = c.write_coils(51, [True], device_id=device_id)
            assert rr.isError() and rr.exception_code == ILLEGAL_FUNCTION
        for address, values in ((0, [2]), (4, [1]), (50, [1]), (51, [1, 5]), (52, [0, 0])):
            rr = c.write_registers(address, values, device_id=1)  # read-only, or two at once
            assert rr.isError() and rr.exception_code == ILLEGAL_ADDRESS, (address, rr)
            if len(values) == 1:
                rr = c.write_register(address, values[0], device_id=255)
                assert rr.isError() and rr.exception_code == ILLEGAL_ADDRESS, (address, rr)
        rr = c.write_register(51, 7, device_id=1)  # a command register, an unknown command
        assert rr.isError() and rr.exception_code == ILLEGAL_VALUE
        assert calls == []
        assert not c.write_register(51, 1, device_id=255).isError()  # function 6 does
        assert [r["request"] for r in calls] == ["acknowledge"]
    finally:
        c.close()
        srv.close()
