"""A plain CSV recording read piece by piece (`open_csv_stream`): memory stays flat on a
day-long CSV as on a day-long Parquet file (`fdi_daemon.io.recordings.RecordingStream`).

pyarrow's streaming CSV reader parses the body block by block (``BLOCK_BYTES``), only the
monitor's columns. A file is streamed only where the whole-file readers would read it the
same way, which one pass over its bytes shows before the first piece: the header and
comment lines as `csv_preamble` reads them, a body of numbers only (no comment, quote,
blank line or line end other than \\n and \\r\\n) ending with a line end (a torn last line
is the NumPy reader's to report and drop), and first rows that parse. Anything else
is read whole (`read_recording`), with its findings and messages. A line that turns out
malformed further on stops the stream with the message the NumPy reader gives for it.
"""

from __future__ import annotations

import gzip
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any, cast

import numpy as np

from fdi_daemon.errors import RecordingError
from fdi_daemon.io.recordings import (
    Recording,
    RecordingStream,
    _one_line,
    _read_csv_numpy,
    csv_preamble,
    stream_columns,
)

#: bytes parsed per piece (about 70 s of the recorder's 5 columns at 256 Hz). pyarrow reads
#: blocks ahead: an hour's streamed replay peaked at 246 / 270 / 316 MiB with blocks of
#: 1 / 2 / 8 MiB (the whole file read at once: 668 MiB), in about the same time
BLOCK_BYTES = 1 << 20
#: the first bytes searched for the comment lines and the header, and parsed as a trial
PREAMBLE_BYTES = 1 << 16


def _open(path: Path) -> IO[bytes]:
    if path.name.lower().endswith(".gz"):
        return cast(IO[bytes], gzip.open(path, "rb"))
    return open(path, "rb")


def _plain_rows(data: bytes) -> int | None:
    """Line ends in ``data[1:]``, where ``data[0]`` is the byte before them (a line end at
    the body's start); None where ``data`` holds a comment, a quote, a lone \\r, a blank line
    or a line starting with a blank. Single bytes are found at memchr speed, the bytes after
    each line end by NumPy (a line starts with a number, above the blank 0x20; Python's
    search for two bytes ran at 250 MB/s, a regular expression at 14 MB/s)."""
    if b"#" in data or b'"' in data:
        return None
    if b"\r" in data and data.count(b"\r") != data.count(b"\r\n"):
        return None
    raw = np.frombuffer(data, dtype=np.uint8)
    line_end = raw == ord("\n")
    starts = raw[1:][line_end[:-1]]
    if starts.size and starts.min() <= ord(" "):
        return None
    return int(np.count_nonzero(line_end[1:]))


def _body_rows(path: Path, body_offset: int) -> int | None:
    """Rows of a plain body (its line ends), read once block by block; None where it is
    not plain or does not end with a line end."""
    rows = 0
    tail = b"\n"  # the byte before the block (the body starts a line)
    with _open(path) as fh:
        fh.seek(body_offset)
        while block := fh.read(BLOCK_BYTES):
            if block.endswith(b"\r"):  # its \n, if any, belongs to this block
                block += fh.read(1)
            found = _plain_rows(tail + block)
            if found is None:
                return None
            rows += found
            tail = block[-1:]
    return rows if tail == b"\n" else None


@dataclass
class CsvRecordingStream(RecordingStream):
    """`RecordingStream` of a plain CSV recording (`open_csv_stream`)."""

    header: list[str]
    delimiter: str
    body_offset: int  # bytes (of the decompressed text) before the first data row

    def pieces(self) -> Iterator[Recording]:
        """The recording in order, one block of about `BLOCK_BYTES` at a time."""
        offset = 0
        try:
            with _open(self.path) as fh:
                fh.seek(self.body_offset)
                for batch in self._reader(fh):
                    piece = self.piece(batch, offset)
                    offset += len(piece)
                    yield piece
        except (OSError, ValueError, KeyError, TypeError, EOFError) as exc:
            # pyarrow's parse errors are ValueErrors: the NumPy reader names the line
            try:
                _read_csv_numpy(self.path)
            except RecordingError as numpy_said:
                raise numpy_said from None
            raise RecordingError(f"{self.path}: cannot read recording: {_one_line(exc)}") from None

    def _reader(self, fh: IO[bytes], block_bytes: int | None = None) -> Any:
        """pyarrow's streaming reader of the body from ``fh`` (at the body), in blocks of
        ``block_bytes`` (default `BLOCK_BYTES`)."""
        import pyarrow as pa
        import pyarrow.csv as pacsv

        wanted = list(self.sources.values())
        return pacsv.open_csv(
            fh,
            read_options=pacsv.ReadOptions(
                column_names=self.header,
                block_size=block_bytes or BLOCK_BYTES,
                use_threads=True,
            ),
            parse_options=pacsv.ParseOptions(delimiter=self.delimiter, quote_char=False),
            convert_options=pacsv.ConvertOptions(
                include_columns=wanted,
                column_types={name: pa.float64() for name in wanted},
                null_values=[],
                strings_can_be_null=False,
            ),
        )


def open_csv_stream(
    path: Path, columns: Mapping[str, str] | None, required: tuple[str, ...]
) -> CsvRecordingStream | None:
    """A `CsvRecordingStream` of ``path`` (arguments as `recordings.open_stream`'s), or None
    where the file is read whole (see the module docstring)."""
    try:
        import pyarrow  # noqa: F401  (the stream's parser)
    except ImportError:
        return None
    try:
        with _open(path) as fh:
            preamble = csv_preamble(fh.read(PREAMBLE_BYTES), whole=False)
        if preamble is None:
            return None
        meta, header, delimiter, body_offset = preamble
        rows = _body_rows(path, body_offset)
    except (OSError, EOFError, ValueError):  # unreadable, a damaged .gz: read whole
        return None
    if rows is None:
        return None
    found = stream_columns(path, meta, header, rows, columns, required)
    if found is None:
        return None
    fs, wanted = found
    stream = CsvRecordingStream(path, meta, fs, rows, wanted, header, delimiter, body_offset)
    try:  # the first rows parse, or the whole-file readers judge the file
        with _open(path) as fh:
            fh.seek(body_offset)
            stream._reader(fh, PREAMBLE_BYTES).read_next_batch()
    except (OSError, ValueError, EOFError, StopIteration):
        return None
    return stream
