"""Replay link: a recording file delivered as if it came from the rig.

``realtime=True`` paces samples on the monotonic clock by their recorded time (divided by
``speed``); ``realtime=False`` delivers them as fast as they are read, at most
``chunk_samples`` per ``read``. ``seq`` is the recording's ``seq`` column when present (its
gaps and duplicates are delivered as recorded, for the service to report), else the row
index. With ``loop`` the file starts over and ``seq`` and ``t`` keep counting; without it,
``finished`` turns True after the last sample and ``read`` returns [] from then on.
A file that cannot be read, or (with ``fs_hz``) is sampled at another rate than the
monitor's, raises ``RecordingError`` (a user mistake) from ``open``.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from fdi_daemon.errors import RecordingError
from fdi_daemon.io.links.base import Link
from fdi_daemon.io.recordings import read_recording, same_rate
from fdi_daemon.io.sample import Sample


class ReplayLink(Link):
    kind = "replay"

    def __init__(
        self,
        path: str | Path,
        realtime: bool = True,
        speed: float = 1.0,
        loop: bool = False,
        chunk_samples: int = 256,
        fs_hz: float | None = None,
    ) -> None:
        if not speed > 0:
            raise ValueError("speed must be > 0")
        self.path = Path(path)
        self.realtime = realtime
        self.speed = float(speed)
        self.loop = loop
        self.chunk_samples = int(chunk_samples)
        self.fs_hz = fs_hz
        self.finished = False
        self._cols: tuple[np.ndarray, ...] | None = None
        self._pos = 0
        self._pass = 0
        self._span_s = 0.0
        self._span_seq = 0
        self._t0_wall: float | None = None
        self._samples = 0

    def describe(self) -> str:
        pace = f"{self.speed:g}x real time" if self.realtime else "as fast as possible"
        return f"replay {self.path} ({pace})"

    def open(self) -> None:
        rec = read_recording(self.path, strict=False)
        if self.fs_hz is not None and not same_rate(rec.fs, self.fs_hz):
            # as `fdi replay`: run at the model's rate, its times would be wrong throughout
            raise RecordingError(
                f"{self.path}: sampled at {rec.fs:g} Hz but the model is for {self.fs_hz:g} Hz"
            )
        n = len(rec)
        seq = rec.columns.get("seq")
        seq = np.arange(n, dtype=np.int64) if seq is None else seq.astype(np.int64)
        position = rec.columns.get("position", np.full(n, math.nan))
        self._cols = (
            seq,
            rec.t.astype(float),
            rec.v_in.astype(float),
            rec.accel.astype(float),
            np.asarray(position, dtype=float),
        )
        dt = 1.0 / rec.fs
        self._span_s = float(rec.t[-1] - rec.t[0]) + dt
        self._span_seq = int(seq[-1] - seq[0]) + 1
        self._pos = 0
        self._pass = 0
        self._t0_wall = None
        self.finished = False

    def read(self, timeout_s: float) -> list[Sample]:
        assert self._cols is not None, "open() first"
        seq, t, v_in, accel, position = self._cols
        n = len(t)
        if self.finished:
            time.sleep(max(0.0, timeout_s))
            return []
        if self._pos >= n:
            self._pos = 0
            self._pass += 1
        if self.realtime:
            now = time.monotonic()
            if self._t0_wall is None:
                self._t0_wall = now
            elapsed = (now - self._t0_wall) * self.speed - self._pass * self._span_s
            stop = int(np.searchsorted(t - t[0], elapsed, side="right"))
            if stop <= self._pos:
                due_in = ((t[self._pos] - t[0]) + self._pass * self._span_s) / self.speed - (
                    now - self._t0_wall
                )
                time.sleep(max(0.0, min(timeout_s, due_in)))
                return []
        else:
            stop = min(n, self._pos + self.chunk_samples)
        lo, self._pos = self._pos, stop
        dseq = self._pass * self._span_seq
        dt = self._pass * self._span_s
        out = [
            Sample(
                int(seq[i]) + dseq,
                float(t[i]) + dt,
                float(v_in[i]),
                float(accel[i]),
                float(position[i]),
            )
            for i in range(lo, stop)
        ]
        if self._pos >= n and not self.loop:
            self.finished = True
        self._samples += len(out)
        return out

    def close(self) -> None:
        self._cols = None

    def counters(self) -> dict[str, int]:
        return {"samples": self._samples, "passes": self._pass + int(self.finished)}
