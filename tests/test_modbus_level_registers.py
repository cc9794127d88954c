"""The current friction level (registers 9-10) and the baseline (45-46) over Modbus TCP.

The snapshot is made the daemon's way (the monitor's level, the alarm section from
`AlarmKeeper.summary()` after a status refresh) and read back with a real pymodbus client on
127.0.0.1, decoded with pymodbus's own FLOAT32 conversion (high word first).
"""

import math

import pytest
from pymodbus.client import ModbusTcpClient

from fdi_daemon.alarms.lifecycle import AlarmSettings
from fdi_daemon.service.alarm_keeper import AlarmKeeper
from fdi_daemon.service.sinks import ModbusStatusServer, StatusBoard

LEVEL_REGISTER, BASELINE_REGISTER = 9, 45


def snapshot(level: float, baseline: float | None) -> dict:
    keeper = AlarmKeeper(AlarmSettings(), "model", clock=lambda: 1_790_000_000.0)
    monitor = {"state": "monitoring", "friction_level": level, "baseline_level": baseline}
    keeper.status({"t": 5.0, "monitor": monitor})
    return {
        "state": "monitoring",
        "t": 5.0,
        "time": 1_790_000_000.0,
        "monitor": monitor,
        "link": {"connected": True, "samples": 1280},
        "alarm": keeper.summary(),
    }


def read_floats(board: StatusBoard) -> tuple[float, float]:
    server = ModbusStatusServer(board, host="127.0.0.1", port=0, device_id=1)
    client = ModbusTcpClient("127.0.0.1", port=server.port, timeout=5, retries=0)
    try:
        assert client.connect()
        values = []
        for address in (LEVEL_REGISTER, BASELINE_REGISTER):
            rr = client.read_input_registers(address, count=2, device_id=1)
            assert not rr.isError(), rr
            values.append(client.convert_from_registers(rr.registers, client.DATATYPE.FLOAT32))
        return values[0], values[1]
    finally:
        client.close()
        server.close()


@pytest.mark.parametrize("level", [0.5625, 1.375])
def test_level_and_baseline_registers_carry_the_snapshot(level):
    board = StatusBoard()
    board.publish(snapshot(level, 0.125))
    assert read_floats(board) == (level, 0.125)


def test_without_a_baseline_the_register_is_nan_and_the_level_still_there():
    board = StatusBoard()
    board.publish(snapshot(0.25, None))
    level, baseline = read_floats(board)
    assert level == 0.25 and math.isnan(baseline)
