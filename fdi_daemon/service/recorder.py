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

The archive (``archive_format="parquet"``, the default; ``"csv"`` keeps the CSV files): the
CSV being written is the journal, durable row by row; a closed one is converted to Parquet
(`fdi_daemon.io.recordings`: zstd, seq int64, float32 where lossless, the metadata as
key-value metadata) on a background thread, read back and compared, then deleted. A CSV left
by a recorder that was killed (SIGKILL, power loss) is converted when the next recorder
starts: its rows are all kept, a torn last row is dropped with a warning naming it, and a
file that cannot be read stays as it is with an error in the log, never silently dropped.
"""

from __future__ import annotations

import logging
import math
import os
import time
from concurrent.futures import ThreadPoolExecutor
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from fdi_daemon.errors import RecordingError
from fdi_daemon.io.recordings import (
    csv_header_lines,
    format_csv_rows,
    read_recording,
    write_recording,
)
from fdi_daemon.io.sample import Sample

log = logging.getLogger("fdi.recorder")

COLUMNS = ("seq", "t", "v_in", "accel", "position")
PREFIX = "rec-"
#: archive formats: the CSV journal converted to Parquet when closed, or kept as CSV
ARCHIVE_FORMATS = ("parquet", "csv")


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
        archive_format: str = "parquet",
    ) -> None:
        if not 0 < fsync_period_s <= 1.0:
            raise ValueError("fsync_period_s must be in (0, 1]")
        if archive_format not in ARCHIVE_FORMATS:
            raise ValueError(f"archive_format must be one of {', '.join(ARCHIVE_FORMATS)}")
        self.archive_format = archive_format
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
        self._converter: ThreadPoolExecutor | None = None
        if archive_format == "parquet":
            self._converter = ThreadPoolExecutor(1, thread_name_prefix="fdi-archive")
            for left in sorted(self.directory.glob(f"{PREFIX}*.csv")):  # a killed recorder's
                self._convert_later(left)

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
        """Close the file being written and wait for its conversion to the archive."""
        self._close_file()
        if self._converter is not None:
            self._converter.shutdown(wait=True)
            self._converter = None

    def _convert_later(self, path: Path) -> None:
        assert self._converter is not None
        self._converter.submit(archive_csv, path)

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
        if self._converter is not None:  # after the conversions queued before it
            self._converter.submit(self._prune)
        else:
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
        if self._converter is not None and self._path is not None:
            self._convert_later(self._path)

    def _prune(self) -> None:
        """Delete all but the newest ``keep_files`` recordings; a recording is its name
        without the suffix, so a file being archived (.csv and .parquet at once) counts once."""
        if self.keep_files <= 0:
            return
        names = sorted(
            {
                p.name.rsplit(".", 1)[0]  # the time stamp in the name has a dot too
                for p in self.directory.glob(f"{PREFIX}*")
                if p.name.endswith((".csv", ".parquet"))
            }
        )
        for old in names[: -self.keep_files]:
            for path in (self.directory / f"{old}.csv", self.directory / f"{old}.parquet"):
                try:
                    path.unlink()
                    log.info("deleted old recording %s (keep_files=%d)", path, self.keep_files)
                except FileNotFoundError:
                    pass
                except OSError as exc:
                    log.error("cannot delete old recording %s: %s", path, exc)


def archive_csv(path: Path) -> Path | None:
    """Convert a closed CSV recording to ``.parquet`` beside it, check that the Parquet
    file reads back to the same samples, and delete the CSV; returns the Parquet path.
    A CSV that cannot be read or converted is kept, with an error in the log (None)."""
    target = path.with_suffix(".parquet")
    try:
        rec = read_recording(path, strict=False)
        write_recording(target, rec)
        back = read_recording(target, strict=False)
        same = all(np.array_equal(back[k], v, equal_nan=True) for k, v in rec.columns.items())
        if not same or back.meta != rec.meta:
            raise RecordingError(f"{target}: does not read back to the samples of {path.name}")
    except RecordingError as exc:
        log.error("recording kept as CSV, not archived: %s", exc)
        return None
    path.unlink()
    log.info("archived %s as %s (%d samples)", path.name, target.name, len(rec))
    return target
