"""The raw-data recorder: rotating CSV files in the recording contract.

Each file is a recording `fdi replay` reads: ``# key: value`` metadata (``fs``, link,
start time), the header ``seq,t,v_in,accel,position`` and one row per sample, written with
`fdi_daemon.io.recordings.format_csv_rows` (the same formatting as every CSV recording).

Durability: every batch of samples is handed to the kernel (``os.write`` of whole rows) as
soon as it arrives, so a SIGKILL of the daemon loses only the samples still in its queues
(milliseconds); the file is fsynced at least every ``fsync_period_s`` (≤ 1 s), so a power
loss loses at most that much. A file is never rewritten, only appended and rotated:
after ``rotate_seconds`` of sample time, ``rotate_bytes``, or when the device's counter
restarts (seq going backwards: the device was reset). ``keep_files > 0`` deletes the
oldest recordings beyond that many.
"""

from __future__ import annotations

import logging
import math
import os
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from fdi_daemon.io.recordings import csv_header_lines, format_csv_rows
from fdi_daemon.io.sample import Sample

log = logging.getLogger("fdi.recorder")

COLUMNS = ("seq", "t", "v_in", "accel", "position")
PREFIX = "rec-"


class Recorder:
    """Append samples to rotating CSV recordings under ``directory``."""

    def __init__(
        self,
        directory: str | Path,
        fs_hz: float,
        rotate_seconds: float = 3600.0,
        rotate_bytes: int = 200_000_000,
        fsync_period_s: float = 1.0,
        keep_files: int = 0,
        meta: dict[str, str] | None = None,
    ) -> None:
        if not 0 < fsync_period_s <= 1.0:
            raise ValueError("fsync_period_s must be in (0, 1]")
        self.directory = Path(directory)
        self.directory.mkdir(parents=True, exist_ok=True)
        self.fs_hz = fs_hz
        self.rotate_seconds = rotate_seconds
        self.rotate_bytes = rotate_bytes
        self.fsync_period_s = fsync_period_s
        self.keep_files = keep_files
        self.meta = dict(meta or {})
        self.files_written: list[Path] = []
        self.samples_written = 0
        self._fd: int | None = None
        self._path: Path | None = None
        self._file_t0 = math.nan
        self._file_bytes = 0
        self._last_seq: int | None = None
        self._last_fsync = time.monotonic()

    @property
    def path(self) -> Path | None:
        """The file being written."""
        return self._path

    def append(self, samples: list[Sample]) -> None:
        """Write the samples (whole rows, straight to the kernel); rotate and fsync as due."""
        start = 0
        for i, s in enumerate(samples):
            if self._fd is not None and self._needs_rotation(s):
                self._write(samples[start:i])
                self._close_file()
                start = i
            if self._fd is None:
                self._open_file(s)
            self._last_seq = s.seq
        self._write(samples[start:])
        self.sync_if_due()

    def sync_if_due(self) -> None:
        """fsync when the last one is ``fsync_period_s`` old (call it when idle too)."""
        if self._fd is not None and time.monotonic() - self._last_fsync >= self.fsync_period_s:
            os.fsync(self._fd)
            self._last_fsync = time.monotonic()

    def close(self) -> None:
        self._close_file()

    def _needs_rotation(self, s: Sample) -> bool:
        return (
            s.t - self._file_t0 >= self.rotate_seconds
            or self._file_bytes >= self.rotate_bytes
            or (self._last_seq is not None and s.seq <= self._last_seq)
        )

    def _open_file(self, first: Sample) -> None:
        stamp = datetime.now(timezone.utc).strftime("%Y%m%dT%H%M%S.%fZ")
        path = self.directory / f"{PREFIX}{stamp}-seq{first.seq}.csv"
        meta = {
            "fs": f"{self.fs_hz:g}",
            "source": "fdi run recorder",
            "started_utc": stamp,
            **self.meta,
        }
        self._fd = os.open(
            path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_APPEND | os.O_CLOEXEC, 0o640
        )
        self._path = path
        self._file_t0 = first.t
        self._file_bytes = 0
        self._last_seq = None
        self._write_bytes(csv_header_lines(list(COLUMNS), meta).encode())
        self.files_written.append(path)
        log.info("recording to %s", path)
        self._prune()

    def _write(self, samples: list[Sample]) -> None:
        if not samples:
            return
        columns = {
            "seq": np.fromiter((s.seq for s in samples), np.int64, len(samples)),
            "t": np.fromiter((s.t for s in samples), float, len(samples)),
            "v_in": np.fromiter((s.v_in for s in samples), float, len(samples)),
            "accel": np.fromiter((s.accel for s in samples), float, len(samples)),
            "position": np.fromiter((s.position for s in samples), float, len(samples)),
        }
        self._write_bytes(format_csv_rows(columns).encode())
        self.samples_written += len(samples)

    def _write_bytes(self, data: bytes) -> None:
        assert self._fd is not None
        view = memoryview(data)
        while view:
            n = os.write(self._fd, view)
            view = view[n:]
        self._file_bytes += len(data)

    def _close_file(self) -> None:
        if self._fd is None:
            return
        os.fsync(self._fd)
        os.close(self._fd)
        self._fd = None
        self._last_fsync = time.monotonic()

    def _prune(self) -> None:
        if self.keep_files <= 0:
            return
        files = sorted(self.directory.glob(f"{PREFIX}*.csv"))
        for old in files[: -self.keep_files]:
            try:
                old.unlink()
                log.info("deleted old recording %s (keep_files=%d)", old, self.keep_files)
            except OSError as exc:
                log.error("cannot delete old recording %s: %s", old, exc)
