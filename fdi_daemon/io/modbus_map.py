"""The Modbus register map of the rig's DAQ device (and of the fake device in hil_sim).

Byte order within a 16-bit register is always big endian (Modbus). 32-bit values take two
registers; their *word order* is explicit everywhere: ``"big"`` = high word first
(AB CD), ``"little"`` = low word first (CD AB). Addresses are offsets from a base
(``input_base`` / ``holding_base``, default 0, protocol addresses as sent on the wire).

Input registers (function code 4), read-only::

    offset  regs  field             type   meaning
         0     2  sample_counter    u32    samples produced since device start (wraps)
         2     1  fs_hz             u16    sampling rate, Hz
         3     1  status            u16    bit0 running, bit1 accel saturated (newest),
                                           bit2 fault injected (simulated device only)
         4     1  fifo_depth        u16    K, slots in the FIFO
         5     1  fifo_valid        u16    slots holding a sample, min(counter, K)
         6     1  map_version       u16    1
         7     1  words_per_sample  u16    8
         8     2  v_in_scale        f32    value in V = register value x scale
        10     2  accel_scale       f32    value in m/s² = register value x scale
        12     2  position_scale    f32    value in m = register value x scale
        14     2  reserved          -      0
        16    8K  FIFO              slot j (0 = newest) at 16 + 8 j:
                                           seq u32, v_in f32, accel f32, position f32

Slot j holds the sample with ``seq = sample_counter - 1 - j``; every slot carries its own
seq, so a reader can check what it got. Header plus the 13 newest slots fit one read
(120 <= 125 registers), so a poller at >= 20 Hz needs one request per poll; a slower one
reads deeper slots and loses nothing while it is less than K samples behind.
A NaN position means "no position sensor". Sample time is ``seq / fs_hz``.

Holding registers (function codes 3, 6, 16), fault control of the *simulated* device::

    offset  regs  field             type   meaning (nominal value)
         0     2  bearing_supply    f32    air-bearing supply fraction (1.0 = friction-free)
         2     2  accel_bias        f32    accelerometer bias, m/s² (0.0)
         4     2  valve_gain        f32    servo-valve gain factor (1.0)
         6     2  supply_pressure   f32    supply pressure fraction (1.0)
         8     2  accel_dropout     f32    1.0 = accelerometer reads 0, broken cable (0.0)
        10     2  accel_saturation  f32    accelerometer range, fraction of nominal (1.0)

The names and nominal values are those of ``hil_sim.rig`` (``Rig.set_bearing_supply``,
``Rig.set_fault``); a test keeps them equal.

Write both words of a value in one function-16 request; the device applies a value when
a write completes and reads back what it applied.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

from pymodbus.client.mixin import ModbusClientMixin

WordOrder = Literal["big", "little"]

# pymodbus's own conversion (byte order big endian within a register, word order as given)
_DATATYPE = ModbusClientMixin.DATATYPE
_to_registers = ModbusClientMixin.convert_to_registers
_from_registers = ModbusClientMixin.convert_from_registers

MAP_VERSION = 1
HEADER_REGS = 16
WORDS_PER_SAMPLE = 8
MAX_READ_REGS = 125  # Modbus limit for one read of registers
SLOTS_PER_READ = MAX_READ_REGS // WORDS_PER_SAMPLE  # 15 slots in a FIFO-only read
SLOTS_IN_FIRST_READ = (MAX_READ_REGS - HEADER_REGS) // WORDS_PER_SAMPLE  # 13

STATUS_RUNNING = 0x01
STATUS_SATURATED = 0x02
STATUS_FAULT_INJECTED = 0x04

#: fault-control holding registers: name -> (offset, nominal value)
FAULT_REGISTERS: dict[str, tuple[int, float]] = {
    "bearing_supply": (0, 1.0),
    "accel_bias": (2, 0.0),
    "valve_gain": (4, 1.0),
    "supply_pressure": (6, 1.0),
    "accel_dropout": (8, 0.0),
    "accel_saturation": (10, 1.0),
}
FAULT_REGS = 12


def _check_order(word_order: str) -> None:
    if word_order not in ("big", "little"):
        raise ValueError(f"word order {word_order!r} is not 'big' or 'little'")


def _check_pair(words: Sequence[int]) -> None:
    if len(words) != 2:
        raise ValueError(f"a 32-bit value takes 2 registers, got {len(words)}")


def encode_u32(value: int, word_order: WordOrder) -> list[int]:
    """Two registers of an unsigned 32-bit value (taken modulo 2**32)."""
    _check_order(word_order)
    return _to_registers(int(value) & 0xFFFFFFFF, _DATATYPE.UINT32, word_order)


def decode_u32(words: Sequence[int], word_order: WordOrder) -> int:
    _check_order(word_order)
    _check_pair(words)
    value = _from_registers(list(words), _DATATYPE.UINT32, word_order)
    assert isinstance(value, int)  # one UINT32: an int
    return value


def encode_f32(value: float, word_order: WordOrder) -> list[int]:
    """Two registers of an IEEE-754 float32 (big-endian bytes within each register)."""
    _check_order(word_order)
    return _to_registers(float(value), _DATATYPE.FLOAT32, word_order)


def decode_f32(words: Sequence[int], word_order: WordOrder) -> float:
    _check_order(word_order)
    _check_pair(words)
    value = _from_registers(list(words), _DATATYPE.FLOAT32, word_order)
    assert isinstance(value, float)  # one FLOAT32: a float
    return value


@dataclass(frozen=True)
class Header:
    """The decoded input-register header."""

    sample_counter: int
    fs_hz: int
    status: int
    fifo_depth: int
    fifo_valid: int
    map_version: int
    words_per_sample: int
    v_in_scale: float
    accel_scale: float
    position_scale: float


@dataclass(frozen=True)
class SlotSample:
    """One FIFO slot, values already multiplied by the scales (seq is the raw u32)."""

    seq: int
    v_in: float
    accel: float
    position: float


def encode_header(h: Header, word_order: WordOrder) -> list[int]:
    return (
        encode_u32(h.sample_counter, word_order)
        + [h.fs_hz, h.status, h.fifo_depth, h.fifo_valid, h.map_version, h.words_per_sample]
        + encode_f32(h.v_in_scale, word_order)
        + encode_f32(h.accel_scale, word_order)
        + encode_f32(h.position_scale, word_order)
        + [0, 0]
    )


def decode_header(regs: Sequence[int], word_order: WordOrder) -> Header:
    if len(regs) < HEADER_REGS:
        raise ValueError(f"header needs {HEADER_REGS} registers, got {len(regs)}")
    return Header(
        decode_u32(regs[0:2], word_order),
        regs[2],
        regs[3],
        regs[4],
        regs[5],
        regs[6],
        regs[7],
        decode_f32(regs[8:10], word_order),
        decode_f32(regs[10:12], word_order),
        decode_f32(regs[12:14], word_order),
    )


def encode_slot(
    seq: int, v_in: float, accel: float, position: float, word_order: WordOrder
) -> list[int]:
    """Eight registers of one FIFO slot (raw register values, before scaling)."""
    return encode_u32(seq, word_order) + _to_registers(
        [float(v_in), float(accel), float(position)], _DATATYPE.FLOAT32, word_order
    )


def decode_slots(
    regs: Sequence[int], word_order: WordOrder, scales: tuple[float, float, float] = (1.0, 1.0, 1.0)
) -> list[SlotSample]:
    """Decode consecutive 8-register slots (newest first, as stored)."""
    if len(regs) % WORDS_PER_SAMPLE:
        raise ValueError(f"slot block of {len(regs)} registers is not a multiple of 8")
    out = []
    _check_order(word_order)
    for i in range(0, len(regs), WORDS_PER_SAMPLE):
        r = list(regs[i : i + WORDS_PER_SAMPLE])
        floats = _from_registers(r[2:8], _DATATYPE.FLOAT32, word_order)
        assert isinstance(floats, list)  # three FLOAT32: a list
        v_in, accel, position = floats
        out.append(
            SlotSample(
                decode_u32(r[0:2], word_order),
                v_in * scales[0],
                accel * scales[1],
                position * scales[2],
            )
        )
    return out


def slot_address(slot: int) -> int:
    """Offset of FIFO slot ``slot`` (0 = newest) from the input base."""
    return HEADER_REGS + WORDS_PER_SAMPLE * slot


def encode_faults(values: dict[str, float], word_order: WordOrder) -> list[int]:
    """The 12 fault-control registers; missing names take their nominal value."""
    unknown = set(values) - set(FAULT_REGISTERS)
    if unknown:
        raise ValueError(f"unknown fault register(s): {', '.join(sorted(unknown))}")
    regs = [0] * FAULT_REGS
    for name, (offset, nominal) in FAULT_REGISTERS.items():
        regs[offset : offset + 2] = encode_f32(values.get(name, nominal), word_order)
    return regs


def decode_faults(regs: Sequence[int], word_order: WordOrder) -> dict[str, float]:
    if len(regs) < FAULT_REGS:
        raise ValueError(f"fault block needs {FAULT_REGS} registers, got {len(regs)}")
    return {
        name: decode_f32(regs[off : off + 2], word_order)
        for name, (off, _) in FAULT_REGISTERS.items()
    }


def nominal_faults() -> dict[str, float]:
    return {name: nominal for name, (_, nominal) in FAULT_REGISTERS.items()}
