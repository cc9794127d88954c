"""The binary serial frame of the streaming device, and an incremental decoder (no I/O).

One frame per 256 Hz sample, 22 bytes, every multi-byte field little endian::

    offset size  field
         0    2  sync        0xA5 0x5A
         2    1  version     1
         3    1  flags       bit0 accel saturated, bit1 accel invalid (dropout),
                             bit2 fault injected (simulated device only), bit3 position valid
         4    4  seq         u32 sample counter (wraps at 2**32; the decoder unwraps it)
         8    4  v_in        float32, V
        12    4  accel       float32, m/s²
        16    4  position    float32, m
        20    2  crc         CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection,
                             no final xor) over bytes 2..19, stored little endian

Sample time is ``seq / fs_hz`` (the device's own clock). A frame with the "accel invalid"
flag yields ``accel = NaN``; without "position valid", ``position = NaN``.

`FrameDecoder.feed(data)` accepts any split of the byte stream (whole frames, halves, single
bytes) and returns the decoded samples. After corruption it searches the next sync. Its
counters, exact for a test that corrupts isolated frames:
``frames`` decoded; ``crc_errors`` candidates (sync + version right) whose CRC failed, which
includes a frame cut short by the next one; ``resyncs`` times the decoder had to skip bytes
to find a frame again (one per contiguous run of skipped bytes); ``bytes_dropped`` bytes
that belonged to no valid frame.
"""

from __future__ import annotations

import binascii
import math
import struct
from dataclasses import dataclass

from fdi_daemon.io.links.base import SeqUnwrapper
from fdi_daemon.io.sample import Sample

SYNC = b"\xa5\x5a"
VERSION = 1
FRAME_SIZE = 22
_BODY = struct.Struct("<BBIfff")  # version, flags, seq, v_in, accel, position
_CRC = struct.Struct("<H")

FLAG_SATURATED = 0x01
FLAG_ACCEL_INVALID = 0x02
FLAG_FAULT_INJECTED = 0x04
FLAG_POSITION_VALID = 0x08


def crc16_ccitt(data: bytes) -> int:
    """CRC-16/CCITT-FALSE of ``data`` (check value of b"123456789" is 0x29B1)."""
    return binascii.crc_hqx(data, 0xFFFF)


@dataclass(frozen=True)
class Frame:
    """One frame's fields as sent (seq is the raw u32 counter)."""

    seq: int
    v_in: float
    accel: float
    position: float = math.nan
    flags: int = 0


def encode_frame(frame: Frame) -> bytes:
    """The 22 bytes of one frame; a NaN position clears the "position valid" flag."""
    flags = frame.flags & ~FLAG_POSITION_VALID
    position = frame.position
    if math.isfinite(position):
        flags |= FLAG_POSITION_VALID
    else:
        position = 0.0
    body = _BODY.pack(VERSION, flags, frame.seq & 0xFFFFFFFF, frame.v_in, frame.accel, position)
    return SYNC + body + _CRC.pack(crc16_ccitt(body))


def decode_frame(data: bytes) -> Frame:
    """Decode exactly one frame; raises ValueError naming what is wrong."""
    if len(data) != FRAME_SIZE:
        raise ValueError(f"a frame is {FRAME_SIZE} bytes, got {len(data)}")
    if data[:2] != SYNC:
        raise ValueError(f"bad sync bytes {data[:2].hex()}")
    body = data[2:20]
    (crc,) = _CRC.unpack_from(data, 20)
    if crc != crc16_ccitt(body):
        raise ValueError(f"CRC mismatch (sent {crc:#06x}, computed {crc16_ccitt(body):#06x})")
    version, flags, seq, v_in, accel, position = _BODY.unpack(body)
    if version != VERSION:
        raise ValueError(f"frame version {version}, expected {VERSION}")
    if not flags & FLAG_POSITION_VALID:
        position = math.nan
    return Frame(seq, v_in, accel, position, flags)


class FrameDecoder:
    """Incremental frame decoder: ``feed(bytes) -> list[Sample]``; keeps < 1 frame buffered."""

    def __init__(self, fs_hz: float = 256.0) -> None:
        self.fs_hz = float(fs_hz)
        self._buf = bytearray()
        self._unwrap = SeqUnwrapper(32)
        self._skipping = False  # inside a run of dropped bytes
        self.frames = 0
        self.crc_errors = 0
        self.resyncs = 0
        self.bytes_dropped = 0
        self.saturated = 0

    def counters(self) -> dict[str, int]:
        return {
            "frames": self.frames,
            "crc_errors": self.crc_errors,
            "resyncs": self.resyncs,
            "bytes_dropped": self.bytes_dropped,
            "saturated_frames": self.saturated,
        }

    @property
    def pending_bytes(self) -> int:
        return len(self._buf)

    def feed(self, data: bytes) -> list[Sample]:
        buf = self._buf
        buf += data
        out: list[Sample] = []
        pos = 0
        n = len(buf)
        while True:
            start = buf.find(SYNC, pos)
            if start < 0:
                # keep a trailing first sync byte: it may be the start of the next frame
                keep = 1 if n > pos and buf[n - 1] == SYNC[0] else 0
                self._drop(n - keep - pos)
                pos = n - keep
                break
            self._drop(start - pos)
            pos = start
            if n - pos < FRAME_SIZE:
                break  # wait for the rest of this frame
            if buf[pos + 2] != VERSION:
                self._drop(1)  # not a frame start after all
                pos += 1
                continue
            body = bytes(buf[pos + 2 : pos + 20])
            (crc,) = _CRC.unpack_from(buf, pos + 20)
            if crc != crc16_ccitt(body):
                self.crc_errors += 1
                self._drop(1)
                pos += 1
                continue
            out.append(self._sample(body))
            self._skipping = False
            pos += FRAME_SIZE
        del buf[:pos]
        return out

    def _drop(self, count: int) -> None:
        if count <= 0:
            return
        if not self._skipping:
            self.resyncs += 1
            self._skipping = True
        self.bytes_dropped += count

    def _sample(self, body: bytes) -> Sample:
        _, flags, seq_raw, v_in, accel, position = _BODY.unpack(body)
        self.frames += 1
        if flags & FLAG_SATURATED:
            self.saturated += 1
        if flags & FLAG_ACCEL_INVALID:
            accel = math.nan
        if not flags & FLAG_POSITION_VALID:
            position = math.nan
        seq = self._unwrap(seq_raw)
        return Sample(seq, seq / self.fs_hz, v_in, accel, position)
