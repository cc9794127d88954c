"""Serial frame codec and incremental decoder: whole, split, byte-by-byte, corrupted, flooded."""

import math
import struct

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fdi_daemon.io.serial_frames import (
    FLAG_ACCEL_INVALID,
    FLAG_SATURATED,
    FRAME_SIZE,
    SYNC,
    Frame,
    FrameDecoder,
    crc16_ccitt,
    decode_frame,
    encode_frame,
)


def crc16_ccitt_bitwise(data: bytes) -> int:
    """Reference CRC-16/CCITT-FALSE, bit by bit from its definition."""
    crc = 0xFFFF
    for byte in data:
        crc ^= byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) if crc & 0x8000 else (crc << 1)
            crc &= 0xFFFF
    return crc


def make_frames(n, seq0=0, seed=0):
    rng = np.random.default_rng(seed)
    frames = [
        Frame(
            seq0 + i,
            float(np.float32(rng.normal())),
            float(np.float32(rng.normal() * 3)),
            float(np.float32(rng.normal() * 1e-3)),
        )
        for i in range(n)
    ]
    return frames, b"".join(encode_frame(f) for f in frames)


def feed_in_cuts(decoder, wire, cuts):
    """Feed ``wire`` to ``decoder`` in pieces of the sizes in ``cuts`` (repeated); the
    samples it decodes."""
    out, pos, k = [], 0, 0
    while pos < len(wire):
        step = cuts[k % len(cuts)]
        out += decoder.feed(wire[pos : pos + step])
        pos += step
        k += 1
    return out


def test_crc_matches_the_catalogue_check_value_and_a_bitwise_reference():
    assert crc16_ccitt(b"123456789") == 0x29B1
    rng = np.random.default_rng(1)
    for _ in range(50):
        data = rng.integers(0, 256, int(rng.integers(0, 40)), dtype=np.uint8).tobytes()
        assert crc16_ccitt(data) == crc16_ccitt_bitwise(data)


def test_frame_layout_is_little_endian_as_documented():
    raw = encode_frame(Frame(0x01020304, 1.5, -2.25, 0.125, FLAG_SATURATED))
    assert len(raw) == FRAME_SIZE == 22
    assert raw[:2] == SYNC and raw[2] == 1
    assert raw[4:8] == bytes([4, 3, 2, 1])
    assert struct.unpack("<fff", raw[8:20]) == (1.5, -2.25, 0.125)
    assert struct.unpack("<H", raw[20:22])[0] == crc16_ccitt_bitwise(raw[2:20])
    back = decode_frame(raw)
    assert (back.seq, back.v_in, back.accel, back.position) == (0x01020304, 1.5, -2.25, 0.125)
    assert back.flags & FLAG_SATURATED


def test_decode_frame_names_what_is_wrong():
    raw = bytearray(encode_frame(Frame(7, 0.0, 0.0)))
    with pytest.raises(ValueError, match="22 bytes"):
        decode_frame(bytes(raw[:-1]))
    raw[10] ^= 0x40
    with pytest.raises(ValueError, match="CRC"):
        decode_frame(bytes(raw))


def test_whole_halves_and_byte_by_byte_give_the_same_samples():
    frames, wire = make_frames(40)
    whole = FrameDecoder(256.0).feed(wire)
    dec = FrameDecoder(256.0)
    halves = []
    for i in range(0, len(wire), FRAME_SIZE // 2):
        halves += dec.feed(wire[i : i + FRAME_SIZE // 2])
    dec = FrameDecoder(256.0)
    bytewise = [s for b in wire for s in dec.feed(bytes([b]))]
    assert whole == halves == bytewise
    assert [s.seq for s in whole] == list(range(40))
    assert [s.accel for s in whole] == [f.accel for f in frames]
    assert [s.t for s in whole] == [i / 256.0 for i in range(40)]
    assert dec.counters() == {
        "frames": 40,
        "crc_errors": 0,
        "resyncs": 0,
        "bytes_dropped": 0,
        "saturated_frames": 0,
    }


@given(st.lists(st.integers(1, 60), min_size=1, max_size=40))
@settings(max_examples=60, deadline=None)
def test_any_split_gives_the_same_samples(cuts):
    _, wire = make_frames(30, seed=3)
    dec = FrameDecoder()
    out = feed_in_cuts(dec, wire, cuts)
    assert [s.seq for s in out] == list(range(30))
    assert dec.pending_bytes == 0


def test_corrupted_frames_are_rejected_and_counted_exactly():
    frames, wire = make_frames(200, seed=5)
    bad = bytearray(wire)
    corrupted = [3, 50, 51, 120, 199]
    rng = np.random.default_rng(7)
    for i in corrupted:
        bad[i * FRAME_SIZE + int(rng.integers(4, 20))] ^= 0x5A
    dec = FrameDecoder()
    out = []
    for i in range(0, len(bad), 7):
        out += dec.feed(bytes(bad[i : i + 7]))
    assert [s.seq for s in out] == [i for i in range(200) if i not in corrupted]
    c = dec.counters()
    assert c["crc_errors"] == len(corrupted)
    assert c["bytes_dropped"] == FRAME_SIZE * len(corrupted)
    assert c["resyncs"] == 4  # frames 50 and 51 form one run of dropped bytes


def test_a_corrupted_sync_byte_drops_that_frame_without_a_crc_error():
    _, wire = make_frames(10)
    bad = bytearray(wire)
    bad[4 * FRAME_SIZE] = 0x00
    dec = FrameDecoder()
    out = dec.feed(bytes(bad))
    assert [s.seq for s in out] == [0, 1, 2, 3, 5, 6, 7, 8, 9]
    assert dec.counters()["crc_errors"] == 0
    assert dec.counters()["bytes_dropped"] == FRAME_SIZE


def test_truncated_frames_count_one_crc_error_each():
    _, wire = make_frames(10)
    parts = [wire[i * FRAME_SIZE : (i + 1) * FRAME_SIZE] for i in range(10)]
    parts[2] = parts[2][:11]
    parts[6] = parts[6][:5]
    dec = FrameDecoder()
    out = dec.feed(b"".join(parts))
    assert [s.seq for s in out] == [0, 1, 3, 4, 5, 7, 8, 9]
    assert dec.counters()["crc_errors"] == 2
    assert dec.counters()["bytes_dropped"] == 11 + 5


def test_garbage_flood_is_dropped_byte_for_byte():
    rng = np.random.default_rng(11)
    garbage = rng.integers(0, 256, 50_000, dtype=np.uint8)
    garbage[garbage == 0xA5] = 0  # no false frame starts
    _, before = make_frames(5)
    _, after = make_frames(5, seq0=5)
    dec = FrameDecoder()
    out = dec.feed(before)
    for i in range(0, len(garbage), 4096):
        out += dec.feed(garbage[i : i + 4096].tobytes())
        assert dec.pending_bytes <= FRAME_SIZE
    out += dec.feed(after)
    assert [s.seq for s in out] == list(range(10))
    assert dec.counters()["bytes_dropped"] == len(garbage)
    assert dec.counters()["resyncs"] == 1


@given(st.binary(max_size=600))
@settings(max_examples=200, deadline=None)
def test_random_bytes_never_crash_and_every_byte_is_accounted_for(data):
    dec = FrameDecoder()
    out = dec.feed(data)
    c = dec.counters()
    assert c["frames"] == len(out)
    assert c["bytes_dropped"] + FRAME_SIZE * c["frames"] + dec.pending_bytes == len(data)


def test_seq_wraps_at_2_32_and_is_unwrapped():
    frames = [Frame((2**32 - 2 + i) % 2**32, 0.0, 0.0) for i in range(4)]
    dec = FrameDecoder()
    out = dec.feed(b"".join(encode_frame(f) for f in frames))
    assert [s.seq for s in out] == [2**32 - 2, 2**32 - 1, 2**32, 2**32 + 1]


def test_flags_turn_into_nan_accel_and_missing_position():
    dec = FrameDecoder()
    out = dec.feed(encode_frame(Frame(1, 0.5, 3.0, math.nan, FLAG_ACCEL_INVALID)))
    assert math.isnan(out[0].accel) and math.isnan(out[0].position)
    assert out[0].v_in == 0.5
