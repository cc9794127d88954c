"""Fake streaming DAQ: one binary frame (``fdi_daemon.io.serial_frames``) per rig sample,
written at 256 Hz to the master side of a pty; the client opens the slave path.

Link faults can be injected for tests (`inject`), each counted in `injected()` so a test
can check that the decoder counted exactly what was injected:

- ``corrupt``  (count frames): one payload byte of each of the next frames is changed;
  the receiver counts one CRC error per frame;
- ``truncate`` (count frames): only the first half of each of the next frames is sent;
  the receiver counts one CRC error and 11 dropped bytes per frame;
- ``garbage``  (count bytes): random bytes without any 0xA5 go out between frames, at most
  1024 per gap (a flood spreads over ticks); the receiver drops exactly ``garbage_bytes``
  (bursts the pty could not take count as ``garbage_dropped_bytes`` instead);
- ``stall``    (seconds): nothing is sent for that long while the rig keeps running;
  the frames of that time are lost (a jump in seq);
- ``noise``    (rate): from now on each byte of a frame has one random bit flipped with
  probability ``rate`` (0 stops it); ``noisy_frames`` counts the frames hit, each of which
  the receiver loses (CRC-16/CCITT detects every error of up to 3 bits in a frame, and a
  larger one with probability 1 - 2**-16).

Frames the pty cannot take (no reader for a long time) are dropped whole, never cut,
and counted as ``tx_dropped``; ``frames_sent`` counts frames handed to the pty.
"""

from __future__ import annotations

import contextlib
import os
import threading
import time
import tty

import numpy as np

from fdi_daemon.io.serial_frames import (
    FLAG_FAULT_INJECTED,
    FLAG_SATURATED,
    FRAME_SIZE,
    SYNC,
    VERSION,
    Frame,
    encode_frame,
)
from hil_sim.devices.realtime import DeviceSample, RealtimeRig

#: bytes kept waiting for a slow or absent reader (like a UART's transmit buffer, about
#: 0.7 s of frames) before whole frames or garbage bursts are dropped
MAX_PENDING_BYTES = 4096
#: most garbage bytes sent between two frames: a large flood is spread over many ticks
GARBAGE_PER_GAP = 1024


class SerialDevice:
    """The streaming device in a background thread; ``start()`` returns the slave path."""

    def __init__(self, rt: RealtimeRig, link_path: str | None = None, seed: int = 0) -> None:
        self.rt = rt
        self._link_path = link_path
        self._rng = np.random.default_rng(seed)
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._master = -1
        self._slave = -1
        self.path: str | None = None
        self._pending = bytearray()
        self._todo = {"corrupt": 0, "truncate": 0, "garbage": 0}
        self._stall_until = 0.0
        self._noise_rate = 0.0
        self._counts = {
            "frames_sent": 0,
            "corrupted_frames": 0,
            "truncated_frames": 0,
            "garbage_bytes": 0,
            "garbage_dropped_bytes": 0,
            "stalled_frames": 0,
            "noisy_frames": 0,
            "flipped_bytes": 0,
            "tx_dropped": 0,
        }

    # ------------------------------------------------------------------ public
    def start(self) -> str:
        if self._thread is not None:
            raise RuntimeError("device already started")
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)  # no echo or line editing before the client configures it
        os.set_blocking(self._master, False)
        self.path = os.ttyname(self._slave)
        if self._link_path:
            tmp = f"{self._link_path}.tmp{os.getpid()}"
            os.symlink(self.path, tmp)
            os.replace(tmp, self._link_path)
        self.rt.start()
        self._thread = threading.Thread(target=self._run, name="fake-serial-device", daemon=True)
        self._thread.start()
        return self.path

    def stop(self, timeout_s: float = 5.0) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout_s)
            self._thread = None
        for fd in (self._master, self._slave):
            if fd >= 0:
                with contextlib.suppress(OSError):
                    os.close(fd)
        self._master = self._slave = -1
        if self._link_path:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(self._link_path)

    def inject(self, kind: str, count: int = 0, seconds: float = 0.0, rate: float = 0.0) -> None:
        """Queue a link fault: corrupt/truncate ``count`` frames, ``count`` garbage bytes,
        a stall of ``seconds``, or byte noise at ``rate`` per byte."""
        with self._lock:
            if kind == "noise":
                if not 0.0 <= rate <= 1.0:
                    raise ValueError("noise rate must be in [0, 1]")
                self._noise_rate = float(rate)
            elif kind == "stall":
                if not seconds > 0:
                    raise ValueError("a stall needs seconds > 0")
                self._stall_until = time.monotonic() + float(seconds)
            elif kind in self._todo:
                if count < 0:
                    raise ValueError(f"{kind}: count must be >= 0")
                self._todo[kind] += int(count)
            else:
                raise ValueError(
                    f"unknown injection {kind!r} (corrupt, truncate, garbage, stall, noise)"
                )

    def injected(self) -> dict[str, int]:
        """What was sent and injected so far (counts of executed injections)."""
        with self._lock:
            return dict(self._counts)

    # ------------------------------------------------------------------ internals
    def _run(self) -> None:
        while not self._stop.is_set():
            delay = self.rt.next_tick_time - time.monotonic()
            if delay > 0:
                self._stop.wait(delay)
                continue
            samples = self.rt.advance()
            with self._lock:
                self._send(self._encode(samples))

    def _encode(self, samples: list[DeviceSample]) -> list[tuple[bytes, bool]]:
        """(bytes, is_frame) chunks to send for these samples, injections applied; garbage
        is counted when it is queued for sending (`_send`)."""
        if time.monotonic() < self._stall_until:
            self._counts["stalled_frames"] += len(samples)
            return []
        out = []
        for s in samples:
            flags = (FLAG_SATURATED if s.saturated else 0) | (
                FLAG_FAULT_INJECTED if s.fault_injected else 0
            )
            frame = encode_frame(Frame(s.seq, s.v_in, s.accel, s.position, flags))
            if self._todo["garbage"]:
                burst = min(self._todo["garbage"], GARBAGE_PER_GAP)
                out.append((self._garbage(burst), False))
                self._todo["garbage"] -= burst
            if self._todo["corrupt"]:
                frame = self._corrupt(frame)
                self._todo["corrupt"] -= 1
                self._counts["corrupted_frames"] += 1
            elif self._todo["truncate"]:
                frame = frame[: FRAME_SIZE // 2]
                self._todo["truncate"] -= 1
                self._counts["truncated_frames"] += 1
            elif self._noise_rate > 0.0:
                frame = self._noisy(frame)
            out.append((frame, True))
        return out

    def _garbage(self, n: int) -> bytes:
        data = self._rng.integers(0, 256, n, dtype=np.uint8)
        data[data == SYNC[0]] = 0x00  # no sync byte, so no false frame start
        return data.tobytes()

    def _corrupt(self, frame: bytes) -> bytes:
        """Change one payload byte so that no false frame start appears inside the frame."""
        while True:
            i = int(self._rng.integers(4, 20))
            bad = bytearray(frame)
            bad[i] ^= int(self._rng.integers(1, 256))
            if SYNC + bytes([VERSION]) not in bytes(bad[1:]):
                return bytes(bad)

    def _noisy(self, frame: bytes) -> bytes:
        hits = np.flatnonzero(self._rng.random(len(frame)) < self._noise_rate)
        if not len(hits):
            return frame
        bad = bytearray(frame)
        for i in hits:
            bad[i] ^= 1 << int(self._rng.integers(0, 8))
        self._counts["noisy_frames"] += 1
        self._counts["flipped_bytes"] += len(hits)
        return bytes(bad)

    def _send(self, wire: list[tuple[bytes, bool]]) -> None:
        for chunk, is_frame in wire:
            if len(self._pending) + len(chunk) > MAX_PENDING_BYTES:
                self._counts["tx_dropped" if is_frame else "garbage_dropped_bytes"] += (
                    1 if is_frame else len(chunk)
                )
                continue
            self._pending += chunk
            self._counts["frames_sent" if is_frame else "garbage_bytes"] += (
                1 if is_frame else len(chunk)
            )
        if not self._pending:
            return
        try:
            n = os.write(self._master, self._pending)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:  # pty gone: the device is shutting down
            self._pending.clear()
            return
        del self._pending[:n]
