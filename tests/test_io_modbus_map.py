"""Modbus register map: explicit word order, checked against pymodbus's own conversion."""

import math

import numpy as np
import pytest
from pymodbus.client.mixin import ModbusClientMixin

from fdi_daemon.io import modbus_map as mm

DT = ModbusClientMixin.DATATYPE


@pytest.mark.parametrize("word_order", ["big", "little"])
def test_float32_and_u32_round_trip_and_agree_with_pymodbus(word_order):
    rng = np.random.default_rng(0)
    for value in [0.0, -1.5, 3.0e-7, 9.81, *rng.normal(size=50) * 100]:
        value = float(np.float32(value))
        regs = mm.encode_f32(value, word_order)
        assert mm.decode_f32(regs, word_order) == value
        assert ModbusClientMixin.convert_from_registers(regs, DT.FLOAT32, word_order) == value
        assert regs == ModbusClientMixin.convert_to_registers(value, DT.FLOAT32, word_order)
    for value in [0, 1, 65535, 65536, 2**32 - 1, *rng.integers(0, 2**32, 50)]:
        regs = mm.encode_u32(int(value), word_order)
        assert mm.decode_u32(regs, word_order) == value
        assert ModbusClientMixin.convert_from_registers(regs, DT.UINT32, word_order) == value


def test_word_order_is_what_the_map_says():
    # 1.0f = 0x3F800000: big = high word first, little = low word first
    assert mm.encode_f32(1.0, "big") == [0x3F80, 0x0000]
    assert mm.encode_f32(1.0, "little") == [0x0000, 0x3F80]
    assert mm.encode_u32(0x12345678, "big") == [0x1234, 0x5678]
    with pytest.raises(ValueError):
        mm.encode_f32(1.0, "middle")


@pytest.mark.parametrize("word_order", ["big", "little"])
def test_header_slots_and_faults_round_trip(word_order):
    h = mm.Header(
        123456789,
        256,
        mm.STATUS_RUNNING | mm.STATUS_SATURATED,
        64,
        64,
        mm.MAP_VERSION,
        mm.WORDS_PER_SAMPLE,
        1.0,
        9.80665,
        0.001,
    )
    regs = mm.encode_header(h, word_order)
    assert len(regs) == mm.HEADER_REGS
    back = mm.decode_header(regs, word_order)
    assert back.sample_counter == h.sample_counter and back.fifo_depth == 64
    assert math.isclose(back.accel_scale, 9.80665, rel_tol=1e-7)
    slots = mm.encode_slot(7, 1.25, -0.5, math.nan, word_order) + mm.encode_slot(
        6, 2.0, 4.0, 0.01, word_order
    )
    decoded = mm.decode_slots(slots, word_order, scales=(1.0, 2.0, 1000.0))
    assert [s.seq for s in decoded] == [7, 6]
    assert decoded[0].accel == -1.0 and math.isnan(decoded[0].position)
    assert math.isclose(decoded[1].position, 10.0, rel_tol=1e-6)
    faults = {"bearing_supply": 0.35, "accel_bias": -0.5}
    back_faults = mm.decode_faults(mm.encode_faults(faults, word_order), word_order)
    assert math.isclose(back_faults["bearing_supply"], 0.35, rel_tol=1e-7)
    assert back_faults["valve_gain"] == 1.0 and back_faults["accel_saturation"] == 1.0
    assert mm.decode_faults(mm.encode_faults({}, word_order), word_order) == mm.nominal_faults()


def test_first_read_fits_one_modbus_request():
    assert mm.slot_address(mm.SLOTS_IN_FIRST_READ) <= mm.MAX_READ_REGS
    assert mm.SLOTS_PER_READ * mm.WORDS_PER_SAMPLE <= mm.MAX_READ_REGS


def test_fault_registers_match_the_rig():
    from hil_sim.rig import FAULTS

    names = set(mm.FAULT_REGISTERS) - {"bearing_supply"}
    assert names == set(FAULTS)
    for name in names:
        assert mm.FAULT_REGISTERS[name][1] == FAULTS[name][1]
    offsets = sorted(off for off, _ in mm.FAULT_REGISTERS.values())
    assert offsets == list(range(0, mm.FAULT_REGS, 2))


@pytest.mark.parametrize(
    "word_order, expected",
    [
        ("big", [0x0000, 0x03E8, 0x3FA0, 0x0000, 0xC060, 0x0000, 0x3B03, 0x126F]),
        ("little", [0x03E8, 0x0000, 0x0000, 0x3FA0, 0x0000, 0xC060, 0x126F, 0x3B03]),
    ],
)
def test_slot_words_are_the_documented_example(word_order, expected):
    # docs/protocols.md: slot of seq 1000, v_in 1.25 V, accel -3.5 m/s², position 0.002 m
    assert mm.encode_slot(1000, 1.25, -3.5, 0.002, word_order) == expected
    (slot,) = mm.decode_slots(expected, word_order)
    assert (slot.seq, slot.v_in, slot.accel) == (1000, 1.25, -3.5)
    assert slot.position == float(np.float32(0.002))


def test_header_words_are_the_documented_example():
    h = mm.Header(
        1001, 256, mm.STATUS_RUNNING, 256, 256, mm.MAP_VERSION, mm.WORDS_PER_SAMPLE, 1.0, 1.0, 1.0
    )
    assert mm.encode_header(h, "big") == [
        0x0000,
        0x03E9,
        0x0100,
        0x0001,
        0x0100,
        0x0100,
        0x0001,
        0x0008,
        0x3F80,
        0x0000,
        0x3F80,
        0x0000,
        0x3F80,
        0x0000,
        0x0000,
        0x0000,
    ]


def test_a_value_needs_exactly_two_registers():
    with pytest.raises(ValueError):
        mm.decode_f32([0x3F80], "big")
    with pytest.raises(ValueError):
        mm.decode_u32([0, 1, 2], "little")
