"""Recordings: read and write the recording contract of DESIGN.md.

A recording is a set of equally long 1-D columns. Required: ``t`` (s), ``v_in`` (V),
``accel`` (m/s²); optional ``position`` (m) and ``seq`` (sample counter); any other column
(the simulator's ground truth, for example) is kept and ignored by the monitor.
Metadata are string key/value pairs (``fs``, ``scenario``, ``seed`` ...).

Formats, chosen by file name:
- ``.csv`` / ``.csv.gz``: header row, ``# key: value`` comment lines for metadata;
- ``.npz``: one array per column, metadata as JSON in ``__meta__``;
- ``.mat`` (MATLAB v5): one variable per column, metadata as JSON in ``meta_json``;
- ``.parquet`` (pyarrow, zstd): one column per column, metadata as the file's key-value
  metadata; ``seq`` as int64, a float column as float32 where that is lossless
  (`parquet_column_type`), else float64.

Sampling is checked on read: a gap, a duplicate or time going backwards (in ``seq`` where
present, else in ``t``) is reported, never papered over. ``read_recording(strict=True)``
refuses such a file with a one-line error; ``strict=False`` returns it with the findings
in ``Recording.sampling`` so that replay can turn them into ``data_gap`` events.
"""

from __future__ import annotations

import contextlib
import gzip
import io
import json
import logging
import math
import warnings
import zipfile
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import numpy as np

from fdi_daemon.errors import RecordingError
from fdi_daemon.io.outputs import replaced_atomically

log = logging.getLogger("fdi.recordings")

REQUIRED_COLUMNS = ("t", "v_in", "accel")

#: file endings of the recording formats, and as the error messages name them
SUFFIXES = (".csv", ".csv.gz", ".npz", ".mat", ".parquet")
FORMATS_TEXT = ".csv, .csv.gz, .npz, .mat or .parquet"

#: relative tolerance on a sample interval before it counts as irregular
DT_TOLERANCE = 0.25
#: relative tolerance between a recording's sampling rate and a model's
FS_TOLERANCE = 1e-3


@dataclass(frozen=True)
class SamplingIssue:
    """One irregularity in the sampling: ``kind`` is "gap", "duplicate" or "backwards"."""

    kind: str
    index: int  # index of the first sample after the irregularity
    t: float
    missing_samples: int = 0  # for gaps: samples that should have been there

    def describe(self) -> str:
        if self.kind == "gap":
            return f"gap of {self.missing_samples} sample(s) before t={self.t:.6g} s (row {self.index})"
        if self.kind == "duplicate":
            return f"duplicate sample at t={self.t:.6g} s (row {self.index})"
        return f"time goes backwards at t={self.t:.6g} s (row {self.index})"


@dataclass
class SamplingReport:
    """Result of the uniform-sampling check."""

    fs_hz: float
    issues: list[SamplingIssue] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.issues

    def summary(self, limit: int = 3) -> str:
        counts: dict[str, int] = {}
        for issue in self.issues:
            counts[issue.kind] = counts.get(issue.kind, 0) + 1
        head = ", ".join(f"{n} {k}{'s' if n > 1 else ''}" for k, n in counts.items())
        first = "; ".join(i.describe() for i in self.issues[:limit])
        more = f"; ... {len(self.issues) - limit} more" if len(self.issues) > limit else ""
        return f"{head}: {first}{more}"


@dataclass
class Recording:
    """Columns of equal length plus string metadata."""

    columns: dict[str, np.ndarray]
    meta: dict[str, str] = field(default_factory=dict)
    sampling: SamplingReport | None = None

    def __post_init__(self) -> None:
        lengths = {name: len(col) for name, col in self.columns.items()}
        if len(set(lengths.values())) > 1:
            raise RecordingError(f"columns differ in length: {lengths}")

    def __len__(self) -> int:
        return len(self.columns["t"])

    def __getitem__(self, name: str) -> np.ndarray:
        try:
            return self.columns[name]
        except KeyError:
            raise RecordingError(
                f"no column {name!r} (columns: {', '.join(self.columns)})"
            ) from None

    @property
    def t(self) -> np.ndarray:
        return self.columns["t"]

    @property
    def v_in(self) -> np.ndarray:
        return self.columns["v_in"]

    @property
    def accel(self) -> np.ndarray:
        return self.columns["accel"]

    @property
    def fs(self) -> float:
        """Sampling rate in Hz: the ``fs`` metadata if present, else from the median step."""
        if "fs" in self.meta:
            return float(self.meta["fs"])
        return nominal_fs_hz(self.t, self.columns.get("seq"))

    def samples(self, part: slice) -> Recording:
        """The samples of ``part``, a slice of sample indices (views of the columns)."""
        return Recording({k: v[part] for k, v in self.columns.items()}, dict(self.meta))

    def window(self, t0: float, t1: float) -> Recording:
        """The samples with t0 <= t < t1 (times in s)."""
        keep = (self.t >= t0) & (self.t < t1)
        if not keep.any():
            raise RecordingError(
                f"window {t0:g}:{t1:g} s holds no samples "
                f"(recording spans {self.t[0]:g} to {self.t[-1]:g} s)"
            )
        return Recording({k: v[keep] for k, v in self.columns.items()}, dict(self.meta))


def nominal_fs_hz(t: np.ndarray, seq: np.ndarray | None = None) -> float:
    """Sampling rate in Hz: the time per sample counter step over all regular steps (within
    half a step of the median: a gap is a whole step longer, a duplicate a whole step
    shorter). Summed over the whole span, the rounding of times printed with few decimals
    cancels (t at 4 decimals: 256.41 Hz from one step, 256.000 Hz from the span)."""
    if len(t) < 2:
        raise RecordingError("a recording needs at least 2 samples to know its sampling rate")
    dt = np.diff(t)
    counts = np.ones_like(dt) if seq is None else np.diff(seq).astype(float)
    ok = (counts > 0) & (dt > 0)
    if not ok.any():
        raise RecordingError("time column never increases: cannot tell the sampling rate")
    dt, counts = dt[ok], counts[ok]
    per_count = dt / counts
    regular = np.abs(per_count / np.median(per_count) - 1.0) <= 0.5
    return float(counts[regular].sum() / dt[regular].sum())


def same_rate(fs_a_hz: float, fs_b_hz: float) -> bool:
    """Two sampling rates are the same within ``FS_TOLERANCE`` (a recording's rate is
    estimated from its time column)."""
    return abs(fs_a_hz - fs_b_hz) <= FS_TOLERANCE * fs_b_hz


#: largest magnitude an offline fit takes: sums of squares of up to 10⁸ samples stay finite
MAX_FIT_VALUE = 1e150


def fit_column(rec: Recording, name: str, path: str | Path) -> np.ndarray:
    """Column ``name`` for the offline fits (identify, signature, baseline, diagnose): every
    value finite and at most MAX_FIT_VALUE in magnitude, else RecordingError naming the
    file, the column and the first bad row."""
    values = np.asarray(rec[name], dtype=float)
    bad = np.flatnonzero(~np.isfinite(values))
    if bad.size:
        raise RecordingError(
            f"{path}: column {name} is not finite at row {int(bad[0])} ({bad.size} bad value(s))"
        )
    huge = np.flatnonzero(np.abs(values) > MAX_FIT_VALUE)
    if huge.size:
        row = int(huge[0])
        raise RecordingError(
            f"{path}: column {name} holds {values[row]:.3g} at row {row}: "
            f"values beyond {MAX_FIT_VALUE:.0e} cannot be fitted "
            "(check the column's unit)"
        )
    return values


def check_sampling(
    t: np.ndarray, seq: np.ndarray | None = None, fs_hz: float | None = None
) -> SamplingReport:
    """Find gaps, duplicates and backward steps in ``seq`` (preferred) or ``t``."""
    fs = fs_hz if fs_hz is not None else nominal_fs_hz(t, seq)
    issues: list[SamplingIssue] = []
    if seq is not None:
        steps: np.ndarray = np.diff(seq.astype(np.int64))
        for i in np.flatnonzero(steps != 1):
            step = int(steps[i])
            kind = "gap" if step > 1 else ("duplicate" if step == 0 else "backwards")
            issues.append(
                SamplingIssue(kind, int(i + 1), float(t[i + 1]), step - 1 if step > 1 else 0)
            )
        return SamplingReport(fs, issues)
    steps = np.diff(t) * fs  # in samples
    bad = np.flatnonzero(np.abs(steps - 1.0) > DT_TOLERANCE)
    for i in bad:
        size = float(steps[i])
        if size > 1.0 + DT_TOLERANCE:
            issues.append(
                SamplingIssue("gap", int(i + 1), float(t[i + 1]), max(1, int(round(size)) - 1))
            )
        elif size < -DT_TOLERANCE:
            issues.append(SamplingIssue("backwards", int(i + 1), float(t[i + 1])))
        else:  # a step of less than 0.75 samples: the same sample again, or a clock slip
            issues.append(SamplingIssue("duplicate", int(i + 1), float(t[i + 1])))
    return SamplingReport(fs, issues)


# ----------------------------------------------------------------------------- reading


def read_recording(
    path: str | Path,
    strict: bool = True,
    required: tuple[str, ...] = REQUIRED_COLUMNS,
    columns: Mapping[str, str] | None = None,
    fs_hz: float | None = None,
) -> Recording:
    """Read a recording in any supported format and check its sampling.

    strict: refuse gaps, duplicates and backward time with a RecordingError; otherwise
    return them in ``Recording.sampling``. columns: fdi name -> the file's column name
    (``--columns``, `fdi_daemon.io.columns`); the file's columns are renamed on read.
    fs_hz: the sample rate (Hz) of a recording without a time column (benchmark data often
    have none): t = k / fs_hz is made; a recording with one must agree with it.
    """
    path = Path(path)
    if not path.exists():
        raise RecordingError(f"{path}: no such file")
    if path.is_dir():
        raise RecordingError(f"{path}: is a directory, not a recording")
    name = path.name.lower()
    try:
        if name.endswith(".csv") or name.endswith(".csv.gz"):
            columns_read, meta = _read_csv(path)
        elif name.endswith(".npz"):
            columns_read, meta = _read_npz(path)
        elif name.endswith(".mat"):
            columns_read, meta = _read_mat(path)
        elif name.endswith(".parquet"):
            columns_read, meta = _read_parquet(path)
        else:
            raise RecordingError(f"{path}: unknown recording format (use {FORMATS_TEXT})")
    except RecordingError:
        raise
    except (
        OSError,
        EOFError,
        ValueError,
        KeyError,
        TypeError,
        UnicodeDecodeError,
        NotImplementedError,
        zipfile.BadZipFile,
    ) as exc:
        raise RecordingError(f"{path}: cannot read recording: {_one_line(exc)}") from None

    data = (
        _renamed(columns_read, mapping, path) if (mapping := dict(columns or {})) else columns_read
    )
    if fs_hz is not None and "t" not in data and data:
        n = len(next(iter(data.values())))
        data = {"t": np.arange(n) / fs_hz, **data}
    missing = [c for c in required if c not in data]
    if missing:
        raise RecordingError(
            f"{path}: missing column(s) {', '.join(missing)} "
            f"(found: {', '.join(data) or 'none'}; map other names with "
            f"--columns {','.join(f'{c}=COLUMN' for c in missing)})"
        )
    if "t" in data and not np.all(np.isfinite(data["t"])):
        bad = int(np.flatnonzero(~np.isfinite(data["t"]))[0])
        raise RecordingError(f"{path}: time column t is not finite at row {bad}")
    try:
        rec = Recording(data, meta)
    except RecordingError as exc:  # the message names no file
        raise RecordingError(f"{path}: {exc}") from None
    if len(rec) < 2:
        raise RecordingError(f"{path}: holds {len(rec)} sample(s); at least 2 are needed")
    fs_meta = _meta_fs(meta, path)
    try:
        rec.sampling = check_sampling(rec.t, data.get("seq"), fs_meta)
    except RecordingError as exc:  # no rate to be found: the message names no file
        raise RecordingError(f"{path}: {exc}") from None
    if strict and not rec.sampling.ok:
        raise RecordingError(f"{path}: irregular sampling, {rec.sampling.summary()}")
    if fs_hz is not None and not same_rate(rec.fs, fs_hz):
        raise RecordingError(
            f"{path}: sampled at {rec.fs:g} Hz by its time column, not {fs_hz:g} Hz"
        )
    return rec


def _renamed(
    found: dict[str, np.ndarray], mapping: Mapping[str, str], path: Path
) -> dict[str, np.ndarray]:
    """The file's columns with ``mapping`` (fdi name -> file column) applied."""
    absent = [f"{name}={col}" for name, col in mapping.items() if col not in found]
    if absent:
        raise RecordingError(
            f"{path}: --columns {', '.join(absent)}: no such column "
            f"(found: {', '.join(found) or 'none'})"
        )
    sources = set(mapping.values())
    out = {name: col for name, col in found.items() if name not in sources and name not in mapping}
    out.update({name: found[col] for name, col in mapping.items()})
    return out


def _meta_fs(meta: dict[str, str], path: Path) -> float | None:
    if "fs" not in meta:
        return None
    try:
        fs = float(meta["fs"])
    except ValueError:
        raise RecordingError(f"{path}: metadata fs={meta['fs']!r} is not a number") from None
    if not (math.isfinite(fs) and fs > 0):
        raise RecordingError(f"{path}: metadata fs={meta['fs']!r} must be a positive number")
    return fs


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split()) or type(exc).__name__


def _open_text(path: Path) -> IO[str]:
    # utf-8-sig: a spreadsheet's CSV starts with a byte order mark, which was read as part
    # of the first column's name ("missing column t (found: \ufefft, ...)")
    if path.name.lower().endswith(".gz"):
        return gzip.open(path, "rt", encoding="utf-8-sig", newline="")
    return open(path, encoding="utf-8-sig", newline="")


#: a CSV at least this large is parsed by pyarrow's multi-threaded reader where pyarrow is
#: installed (below it, importing pyarrow.csv costs more than it saves)
ARROW_CSV_MIN_BYTES = 1 << 20

#: line ends of str.splitlines other than \n (the NumPy reader splits on them too)
_OTHER_LINE_ENDS = ("\r", "\x0b", "\x0c", "\x1c", "\x1d", "\x1e", "\x85", "\u2028", "\u2029")


def _read_csv(path: Path) -> tuple[dict[str, np.ndarray], dict[str, str]]:
    """A CSV recording: through pyarrow's CSV reader when the file is large and plain
    (`_read_csv_arrow`), else, and for anything it does not take, NumPy's reader with its
    findings and messages (`_read_csv_numpy`); both give the same arrays and metadata."""
    if path.stat().st_size >= ARROW_CSV_MIN_BYTES:
        found = _read_csv_arrow(path)
        if found is not None:
            return found
    return _read_csv_numpy(path)


def _read_csv_arrow(path: Path) -> tuple[dict[str, np.ndarray], dict[str, str]] | None:
    """A plain CSV recording through pyarrow (multi-threaded): comment lines (metadata)
    and the header as `_read_csv_numpy` reads them, then a body of numbers only. None
    when pyarrow is missing or the file is not plain (a comment or a quote in the body,
    other line ends than \n and \r\n, a malformed or torn line, an empty field ...):
    the NumPy reader then reads it, or reports what is wrong, as before."""
    try:
        import pyarrow as pa
        import pyarrow.csv as pacsv
    except ImportError:
        return None
    if path.name.lower().endswith(".gz"):
        with gzip.open(path, "rb") as fh:
            data = fh.read()
    else:
        data = path.read_bytes()
    if data.startswith(b"\xef\xbb\xbf"):
        data = data[3:]
    meta: dict[str, str] = {}
    pos = 0
    header: list[str] | None = None
    while pos < len(data):
        end = data.find(b"\n", pos)
        end = len(data) if end < 0 else end
        try:
            line = data[pos:end].decode("utf-8")
        except UnicodeDecodeError:
            return None
        pos = end + 1
        line = line[:-1] if line.endswith("\r") else line
        if any(c in line for c in _OTHER_LINE_ENDS):
            return None
        stripped = line.strip()
        if not stripped:
            continue
        if stripped.startswith("#"):
            key, sep, value = stripped[1:].partition(":")
            if sep and key.strip():
                meta[key.strip()] = value.strip()
            continue
        delimiter = _delimiter(stripped)
        header = [h.strip().strip('"').strip() for h in stripped.split(delimiter)]
        break
    if header is None or len(set(header)) != len(header) or any(not h for h in header):
        return None
    body = data[pos:]
    if not body.strip() or b"#" in body or b'"' in body or b"\r" in body.replace(b"\r\n", b""):
        return None
    try:
        table = pacsv.read_csv(
            pa.py_buffer(body),
            read_options=pacsv.ReadOptions(column_names=header, use_threads=True),
            parse_options=pacsv.ParseOptions(delimiter=delimiter, quote_char=False),
            convert_options=pacsv.ConvertOptions(
                column_types={name: pa.float64() for name in header},
                null_values=[],
                strings_can_be_null=False,
            ),
        )
    except (pa.ArrowException, ValueError):
        return None
    columns = {name: table.column(name).to_numpy() for name in header}
    if "seq" in columns:
        columns["seq"] = _as_counter(columns["seq"], path)
    return columns, meta


def _read_csv_numpy(path: Path) -> tuple[dict[str, np.ndarray], dict[str, str]]:
    meta: dict[str, str] = {}
    header: list[str] | None = None
    header_line = 0
    with _open_text(path) as fh:
        text = fh.read()
    lines = text.splitlines()
    body_start = len(lines)
    for number, line in enumerate(lines, start=1):
        stripped = line.strip()
        if not stripped:
            continue
        if stripped.startswith("#"):
            key, sep, value = stripped[1:].partition(":")
            if sep and key.strip() and header is None:
                meta[key.strip()] = value.strip()
            continue
        delimiter = _delimiter(stripped)
        header = [h.strip().strip('"').strip() for h in stripped.split(delimiter)]
        header_line = number
        body_start = number
        break
    if header is None:
        raise RecordingError(f"{path}: no header row (expected e.g. 't,v_in,accel')")
    if len(set(header)) != len(header) or any(not h for h in header):
        raise RecordingError(f"{path}: header row {header_line} has empty or repeated names")
    body = "\n".join(lines[body_start:])
    ncol = len(header)
    if not any(line.strip() and not line.lstrip().startswith("#") for line in lines[body_start:]):
        return {name: np.empty(0) for name in header}, meta
    data = _parse_csv_body(body, delimiter, ncol)
    if data is None:
        number, problem = _locate_bad_csv_line(path, lines, body_start, ncol, delimiter)
        torn = number == len(lines) and not text.endswith(("\n", "\r"))
        if not torn:
            raise RecordingError(problem)
        # a writer stopped mid-row: a malformed last line without its line end
        log.warning("%s; dropped as a torn last line (the rows before it are read)", problem)
        data = _parse_csv_body("\n".join(lines[body_start : number - 1]), delimiter, ncol)
        if data is None:
            raise RecordingError(problem)
    columns = {name: np.ascontiguousarray(data[:, j]) for j, name in enumerate(header)}
    if "seq" in columns:
        columns["seq"] = _as_counter(columns["seq"], path)
    return columns, meta


def _parse_csv_body(body: str, delimiter: str, ncol: int) -> np.ndarray | None:
    """The rows of a CSV body as a (rows, ncol) array; None when a line is malformed."""
    try:
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # "input contained no data"
            data = np.loadtxt(
                io.StringIO(body), delimiter=delimiter, comments="#", ndmin=2, dtype=np.float64
            )
    except ValueError:
        return None
    return data if data.shape[1] == ncol or data.size == 0 else None


def _delimiter(header: str) -> str:
    """The CSV's field separator, from its header row: a comma, else a semicolon or a tab
    (as spreadsheets and other tools write them; numbers still need a decimal point)."""
    for candidate in (",", ";", "\t"):
        if candidate in header:
            return candidate
    return ","


def _locate_bad_csv_line(
    path: Path, lines: list[str], start: int, ncol: int, delimiter: str
) -> tuple[int, str]:
    """The number (from 1) of the first malformed body line and what is wrong with it."""
    for number in range(start + 1, len(lines) + 1):
        line = lines[number - 1].strip()
        if not line or line.startswith("#"):
            continue
        cells = line.split(delimiter)
        if len(cells) != ncol:
            return number, f"{path}: line {number} has {len(cells)} field(s), the header has {ncol}"
        for cell in cells:
            try:
                float(cell)
            except ValueError:
                return number, f"{path}: line {number}: {cell.strip()!r} is not a number"
    return 0, f"{path}: malformed CSV body"


#: largest sample counter accepted (2**53: every whole number up to it is exact in float64)
MAX_SEQ = 2**53


def _as_counter(seq: np.ndarray, path: Path) -> np.ndarray:
    if (
        not np.all(np.isfinite(seq))
        or np.any(np.abs(seq) > MAX_SEQ)
        or np.any(seq != np.round(seq))
    ):
        raise RecordingError(f"{path}: column seq must hold whole numbers below 2**53")
    return seq.astype(np.int64)


def _read_npz(path: Path) -> tuple[dict[str, np.ndarray], dict[str, str]]:
    if not zipfile.is_zipfile(path):  # else numpy takes it for a pickle and suggests loading it
        raise RecordingError(
            f"{path}: cannot read recording: not an .npz file (a zip archive "
            f"of arrays, one per column): damaged, cut short or of another kind"
        )
    with open(path, "rb") as fh, np.load(fh, allow_pickle=False) as data:
        meta = _meta_object(str(data["__meta__"])) if "__meta__" in data.files else {}
        columns = {}
        for name in data.files:
            if name == "__meta__":
                continue
            columns[name] = _column(np.asarray(data[name]), name, path)
    return columns, meta


def _read_mat(path: Path) -> tuple[dict[str, np.ndarray], dict[str, str]]:
    from scipy.io import loadmat
    from scipy.io.matlab import MatReadError

    try:
        data = loadmat(str(path), squeeze_me=True, chars_as_strings=True)
    except MatReadError as exc:
        raise RecordingError(f"{path}: not a MATLAB v5 file: {_one_line(exc)}") from None
    meta: dict[str, str] = {}
    columns = {}
    for name, value in data.items():
        if name.startswith("__"):
            continue
        if name == "meta_json":
            meta = _meta_object(str(value))
            continue
        arr = np.asarray(value)
        if arr.dtype.kind in "biuf" and arr.ndim == 1:
            columns[name] = _column(arr, name, path)
    return columns, meta


def _pyarrow_parquet(path: Path) -> Any:  # the pyarrow.parquet module
    try:
        import pyarrow.parquet as pq
    except ImportError:
        raise RecordingError(
            f"{path}: Parquet recordings need pyarrow: pip install pyarrow"
        ) from None
    return pq


#: key-value metadata pyarrow and pandas write themselves (not the recording's)
_FOREIGN_META = (b"ARROW:schema", b"pandas")


def _read_parquet(path: Path) -> tuple[dict[str, np.ndarray], dict[str, str]]:
    """Every numeric column, read by columns; the file's own key-value metadata."""
    pq = _pyarrow_parquet(path)
    table = pq.read_table(path)
    raw = table.schema.metadata or {}
    meta = {k.decode(): v.decode() for k, v in raw.items() if k not in _FOREIGN_META}
    columns = {}
    for name in table.column_names:
        values = table.column(name).to_numpy(zero_copy_only=False)
        columns[name] = _column(np.asarray(values), name, path)
    return columns, meta


#: the columns the monitor reads; a streamed recording reads only these (by column)
MONITOR_COLUMNS = ("seq", "t", "v_in", "accel", "position")


@dataclass
class RecordingStream:
    """A Parquet recording read piece by piece (`open_stream`): memory stays flat on a
    day-long file. ``pieces()`` yields `Recording`s (one per row group) with
    the monitor's columns (fdi names), checked as `read_recording` checks them."""

    path: Path
    meta: dict[str, str]
    fs: float
    rows: int
    sources: dict[str, str]  # fdi name -> the file's column

    def pieces(self) -> Iterator[Recording]:
        """The recording in order, one Parquet row group at a time (the recorder writes
        `PARQUET_ROW_GROUP` rows per group; memory follows the file's row-group size).
        Row groups, not ``iter_batches``: pyarrow 26 kept some 10 bytes per sample
        allocated over a day's batches, against a flat 104 MiB read by row groups."""
        pq = _pyarrow_parquet(self.path)
        names = {source: name for name, source in self.sources.items()}
        offset = 0
        try:
            with pq.ParquetFile(self.path, pre_buffer=False) as file:
                for group in range(file.metadata.num_row_groups):
                    batch = file.read_row_group(group, columns=list(names), use_threads=False)
                    columns = {
                        names[col]: _column(
                            np.asarray(batch.column(col).to_numpy(zero_copy_only=False)),
                            names[col],
                            self.path,
                        )
                        for col in batch.schema.names
                    }
                    t = columns["t"]
                    if not np.all(np.isfinite(t)):
                        bad = offset + int(np.flatnonzero(~np.isfinite(t))[0])
                        raise RecordingError(
                            f"{self.path}: time column t is not finite at row {bad}"
                        )
                    offset += len(t)
                    yield Recording(columns, dict(self.meta))
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise RecordingError(f"{self.path}: cannot read recording: {_one_line(exc)}") from None


def open_stream(
    path: str | Path,
    columns: Mapping[str, str] | None = None,
    required: tuple[str, ...] = REQUIRED_COLUMNS,
) -> RecordingStream | None:
    """A `RecordingStream` of a Parquet recording that names its rate (``fs`` in its
    metadata), holds at least 2 samples and the ``required`` columns; None for any other
    file, and for one that is not that (`read_recording` of the whole file then gives its
    findings and errors, word for word). ``columns``: as `read_recording`'s."""
    path = Path(path)
    if not path.name.lower().endswith(".parquet") or not path.is_file():
        return None
    try:
        pq = _pyarrow_parquet(path)
        with pq.ParquetFile(path) as file:
            raw = file.schema_arrow.metadata or {}
            found = list(file.schema_arrow.names)
            rows = int(file.metadata.num_rows)
    except (RecordingError, OSError, ValueError, KeyError, TypeError):
        return None
    meta = {k.decode(): v.decode() for k, v in raw.items() if k not in _FOREIGN_META}
    try:
        fs = _meta_fs(meta, path)
        # each column's number through the renaming: fdi name -> the file's column
        numbers = {name: np.array([k]) for k, name in enumerate(found)}
        renamed = _renamed(numbers, dict(columns or {}), path)
        sources = {name: found[int(k[0])] for name, k in renamed.items()}
    except RecordingError:
        return None
    if fs is None or rows < 2 or any(c not in sources for c in required):
        return None
    wanted = {name: str(col) for name, col in sources.items() if name in MONITOR_COLUMNS}
    return RecordingStream(path, meta, fs, rows, wanted)


def parquet_column_type(name: str, values: np.ndarray) -> str:
    """The Parquet type of a column, lossless for what it holds: ``seq`` int64; a float
    column float32 when every value is exactly a float32 (a sensor resolving at most 24
    significant bits, as its ADC counts scaled by a power of two), else float64. Time
    in seconds is float64 unless exact (1/256 s steps are)."""
    if name == "seq":
        return "int64"
    as32 = values.astype(np.float32)
    with np.errstate(over="ignore", invalid="ignore"):
        exact = np.array_equal(as32.astype(np.float64), values, equal_nan=True)
    return "float32" if exact else "float64"


#: rows per Parquet row group (about 4 min at 256 Hz): the unit a torn file keeps
PARQUET_ROW_GROUP = 65_536


def _write_parquet(path: Path, columns: dict[str, np.ndarray], meta: dict[str, str]) -> None:
    import pyarrow as pa

    pq = _pyarrow_parquet(path)
    arrays = {}
    for name, col in columns.items():
        col = np.asarray(col)
        kind = parquet_column_type(name, col.astype(np.float64))
        arrays[name] = pa.array(col.astype(np.int64 if kind == "int64" else kind))
    table = pa.table(arrays).replace_schema_metadata(
        {k.encode(): v.encode() for k, v in meta.items()}
    )
    pq.write_table(
        table,
        path,
        compression="zstd",
        row_group_size=PARQUET_ROW_GROUP,
        **parquet_encodings(list(arrays)),
    )


def parquet_encodings(names: list[str]) -> dict[str, Any]:
    """Lossless Parquet encodings per column (`pyarrow.parquet.write_table` arguments):
    the ``seq`` counter as deltas (DELTA_BINARY_PACKED: an hour's 921 600 counters in
    10 kB instead of 2.7 MB through a dictionary), the time column ``t`` (steps of 1/fs)
    split by bytes (BYTE_STREAM_SPLIT: 0.08 instead of 4.3 MB), every other column
    through a dictionary (a sensor's quantized readings repeat a few thousand values;
    pyarrow falls back to plain where the dictionary grows too large). An hour of the
    simulated rig as the recorder archives it: 10.8 -> 4.0 MB (`fdi bench`)."""
    encodings = {"seq": "DELTA_BINARY_PACKED", "t": "BYTE_STREAM_SPLIT"}
    return {
        "use_dictionary": [name for name in names if name not in encodings],
        "column_encoding": {name: enc for name, enc in encodings.items() if name in names},
    }


def _meta_object(text: str) -> dict[str, str]:
    """Metadata stored as JSON text: it must be an object of key/value pairs."""
    meta = json.loads(text)
    if not isinstance(meta, dict):
        raise ValueError(f"metadata must be a JSON object, not {type(meta).__name__}")
    return {str(k): str(v) for k, v in meta.items()}


def _column(arr: np.ndarray, name: str, path: Path) -> np.ndarray:
    if arr.ndim != 1 or arr.dtype.kind not in "biuf":
        raise RecordingError(f"{path}: variable {name!r} is not a 1-D numeric array")
    if name == "seq":
        return _as_counter(arr.astype(np.float64), path)
    return arr.astype(np.float64)


# ----------------------------------------------------------------------------- writing


def check_format(path: str | Path) -> None:
    """A RecordingError unless the file's ending names a recording format."""
    if not Path(path).name.lower().endswith(SUFFIXES):
        raise RecordingError(f"{path}: unknown recording format (use {FORMATS_TEXT})")


def write_recording(path: str | Path, rec: Recording) -> Path:
    """Write ``rec`` in the format named by the file's ending; returns the path.

    The file appears whole or not at all (an error or Ctrl-C while writing leaves no
    truncated recording, and the file there before intact); a path that cannot be written
    is a RecordingError."""
    path = Path(path)
    name = path.name.lower()
    if path.parent and not path.parent.exists():
        raise RecordingError(f"{path}: directory {path.parent} does not exist")
    check_format(path)
    meta = {str(k): str(v) for k, v in rec.meta.items()}
    try:
        with replaced_atomically(path) as target:
            if name.endswith(".npz"):
                np.savez_compressed(
                    target,
                    __meta__=np.array(json.dumps(meta)),
                    **rec.columns,  # type: ignore[arg-type]  # numpy's stub: **kwds as allow_pickle
                )
            elif name.endswith(".mat"):
                from scipy.io import savemat

                savemat(
                    str(target),
                    {**rec.columns, "meta_json": json.dumps(meta)},
                    do_compression=True,
                    oned_as="column",
                )
            elif name.endswith(".parquet"):
                _write_parquet(target, rec.columns, meta)
            else:
                _write_csv(target, rec.columns, meta, path.name)
    except OSError as exc:
        raise RecordingError(f"{path}: cannot write the recording: {exc.strerror or exc}") from None
    return path


def csv_header_lines(names: list[str], meta: dict[str, str]) -> str:
    """The metadata comments and header row that open a CSV recording."""
    for key, value in meta.items():
        if "\n" in key or "\n" in value or ":" in key:
            raise RecordingError(f"metadata {key!r} cannot be written as a CSV comment")
    head = "".join(f"# {k}: {v}\n" for k, v in meta.items())
    return head + ",".join(names) + "\n"


def format_csv_rows(columns: dict[str, np.ndarray]) -> str:
    """CSV rows for the columns: counters as integers, the rest with 10 significant digits."""
    names = list(columns)
    fmt = ",".join("%d" if n == "seq" else ("%.9f" if n == "t" else "%.10g") for n in names)
    matrix = np.column_stack([columns[n] for n in names]) if names else np.empty((0, 0))
    buf = io.StringIO()
    np.savetxt(buf, matrix, fmt=fmt, delimiter=",")
    return buf.getvalue()


#: characters written per call: Ctrl-C is handled between calls, and compressing an hour's
#: CSV in one call kept it waiting some 20 s
WRITE_CHUNK = 1 << 20


def _write_csv(path: Path, columns: dict[str, np.ndarray], meta: dict[str, str], name: str) -> None:
    """The CSV text into ``path`` (gzip-compressed for a .gz ending); ``name``: the file's
    final name, which a .gz header holds (not that of the temporary file written)."""
    text = csv_header_lines(list(columns), meta) + format_csv_rows(columns)
    with contextlib.ExitStack() as stack:
        fh: io.BufferedWriter | gzip.GzipFile = stack.enter_context(open(path, "wb"))
        if path.name.lower().endswith(".gz"):
            fh = stack.enter_context(gzip.GzipFile(filename=name, mode="wb", fileobj=fh))
        out = stack.enter_context(io.TextIOWrapper(fh, encoding="utf-8", newline=""))
        for start in range(0, len(text), WRITE_CHUNK):
            out.write(text[start : start + WRITE_CHUNK])
