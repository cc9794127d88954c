"""The recording contract: formats round-trip, sampling checks, clear errors."""

import gzip
import io
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from fdi_daemon.errors import RecordingError
from fdi_daemon.io.recordings import (
    Recording,
    check_sampling,
    nominal_fs_hz,
    parquet_column_type,
    read_recording,
    write_recording,
)

FS = 256.0


def make_recording(n=512, seed=3, with_seq=True):
    rng = np.random.default_rng(seed)
    cols = {
        "t": np.arange(n) / FS,
        "v_in": rng.uniform(-1.5, 1.5, n),
        "accel": rng.normal(0.0, 2.0, n),
        "position": rng.normal(0.0, 0.01, n),
        "friction_force": rng.normal(0.0, 1.0, n),
    }
    if with_seq:
        cols["seq"] = np.arange(1000, 1000 + n, dtype=np.int64)
    return Recording(cols, {"fs": "256", "scenario": "unit test"})


@pytest.mark.parametrize("suffix", [".csv", ".csv.gz", ".npz", ".mat", ".parquet"])
def test_round_trip_every_format(tmp_path, suffix):
    rec = make_recording()
    path = write_recording(tmp_path / f"rec{suffix}", rec)
    back = read_recording(path)
    assert set(back.columns) == set(rec.columns)
    assert back.meta["scenario"] == "unit test"
    assert back.fs == FS
    for name, col in rec.columns.items():
        # CSV keeps 10 significant digits (9 decimals for t); binary formats are exact
        if suffix.startswith(".csv"):
            np.testing.assert_allclose(back[name], col, rtol=1e-9, atol=1e-9)
        else:
            np.testing.assert_array_equal(back[name], col)
    assert back["seq"].dtype == np.int64
    assert back.sampling.ok


def test_csv_is_plain_text_with_metadata_comments(tmp_path):
    path = write_recording(tmp_path / "rec.csv", make_recording(n=4))
    lines = path.read_text().splitlines()
    assert lines[0] == "# fs: 256"
    assert lines[2].startswith("t,v_in,accel")
    assert len(lines) == 3 + 4


def test_gz_is_really_gzip(tmp_path):
    """... whose header names the file (`gunzip -N`), not the temporary one it was written as."""
    path = write_recording(tmp_path / "rec.csv.gz", make_recording(n=8))
    with gzip.open(path, "rt") as fh:
        assert fh.readline().startswith("# fs:")
    header = path.read_bytes()
    assert header[3] & 0x08  # FNAME: a zero-terminated name follows the 10-byte header
    assert header[10 : header.index(b"\0", 10)] == b"rec.csv"


def test_nan_samples_are_kept_not_refused(tmp_path):
    rec = make_recording(n=64)
    rec.columns["accel"][10] = np.nan
    back = read_recording(write_recording(tmp_path / "rec.csv", rec))
    assert np.isnan(back.accel[10]) and np.isfinite(back.accel[11])


def test_gap_in_seq_is_reported_with_its_size(tmp_path):
    rec = make_recording(n=100)
    keep = np.r_[0:40, 45:100]  # 5 samples lost
    gapped = Recording({k: v[keep] for k, v in rec.columns.items()}, rec.meta)
    path = write_recording(tmp_path / "rec.csv", gapped)
    with pytest.raises(RecordingError, match=r"gap of 5 sample\(s\)"):
        read_recording(path)
    report = read_recording(path, strict=False).sampling
    assert [(i.kind, i.index, i.missing_samples) for i in report.issues] == [("gap", 40, 5)]


def test_gap_and_duplicate_in_time_without_seq():
    t = np.arange(50) / FS
    t = np.r_[t[:20], t[20], t[20:30], t[33:]]  # a duplicate at row 21, 3 lost before row 31
    report = check_sampling(t, None, FS)
    kinds = [(i.kind, i.index) for i in report.issues]
    assert ("duplicate", 21) in kinds
    gaps = [i for i in report.issues if i.kind == "gap"]
    assert len(gaps) == 1 and gaps[0].missing_samples == 3


def test_time_going_backwards_is_reported():
    t = np.arange(20) / FS
    t[12] = t[5]
    kinds = {i.kind for i in check_sampling(t, None, FS).issues}
    assert "backwards" in kinds


def test_fs_is_estimated_from_median_step_when_metadata_missing():
    t = np.arange(300) / 100.0
    assert nominal_fs_hz(t) == pytest.approx(100.0)


@pytest.mark.parametrize("decimals,start_s", [(4, 0.0), (3, 0.0), (6, 100.0), (4, 3600.0)])
def test_times_printed_with_few_decimals_give_the_rate_and_no_issue(decimals, start_s):
    """Another tool's CSV may print t with few decimals: one step of a 256 Hz file at 4
    decimals is 0.0039 s (256.4 Hz); over the span the rounding cancels."""
    t = np.round(start_s + np.arange(1536) / 256.0, decimals)
    assert nominal_fs_hz(t) == pytest.approx(256.0, rel=1e-4)
    assert check_sampling(t).ok
    with_gap = np.delete(t, np.arange(700, 710))  # 10 samples missing
    report = check_sampling(with_gap)
    assert [(i.kind, i.index, i.missing_samples) for i in report.issues] == [("gap", 700, 10)]
    assert report.fs_hz == pytest.approx(256.0, rel=1e-4)


@pytest.mark.parametrize(
    "header,sep",
    [
        ('"t","v_in","accel"', ","),
        ("t, v_in, accel", ", "),
        ("t;v_in;accel", ";"),
        ("t\tv_in\taccel", "\t"),
    ],
)
def test_csv_dialects_of_other_tools_are_read(tmp_path, header, sep):
    """Quoted names (R's write.csv), spaces after commas, semicolons, tabs."""
    t = np.arange(8) / FS
    rows = [sep.join(f"{x:.8f}" for x in (ti, 0.5 * ti, -ti)) for ti in t]
    path = tmp_path / "other.csv"
    path.write_text("\n".join([header, *rows]) + "\n")
    rec = read_recording(path)
    np.testing.assert_allclose(rec.t, t, atol=1e-8)
    np.testing.assert_allclose(rec.accel, -t, atol=1e-8)


@pytest.mark.parametrize(
    "body, message",
    [
        ("t,v_in,accel\n0,1,2\n0.1,x,3\n", r"line 3: 'x' is not a number"),
        ("t,v_in,accel\n0,1,2\n0.1,2\n", r"line 3 has 2 field\(s\), the header has 3"),
        ("# only comments\n", r"no header row"),
        ("t,v_in\n0,1\n1,2\n", r"missing column\(s\) accel"),
        ("t,v_in,accel\n0,1,2\n", r"at least 2 are needed"),
        ("t,t,accel\n0,1,2\n", r"empty or repeated names"),
        ("# fs: fast\nt,v_in,accel\n0,1,2\n1,1,2\n", r"fs='fast' is not a number"),
        ("t,v_in,accel\n0,1,2\nnan,1,2\n", r"time column t is not finite at row 1"),
        ("t;v_in;accel\n0,0;1,0;2,0\n0,1;1,0;2,0\n", r"line 2: '0,0' is not a number"),
    ],
)
def test_malformed_csv_gives_one_clear_line(tmp_path, body, message):
    path = tmp_path / "bad.csv"
    path.write_text(body)
    with pytest.raises(RecordingError, match=message) as info:
        read_recording(path)
    assert "\n" not in str(info.value)


def test_unreadable_inputs(tmp_path):
    with pytest.raises(RecordingError, match="no such file"):
        read_recording(tmp_path / "missing.csv")
    with pytest.raises(RecordingError, match="unknown recording format"):
        (tmp_path / "x.txt").write_text("t\n")
        read_recording(tmp_path / "x.txt")
    (tmp_path / "bad.npz").write_bytes(b"not a zip")
    with pytest.raises(RecordingError, match="cannot read recording"):
        read_recording(tmp_path / "bad.npz")
    (tmp_path / "bad.csv.gz").write_bytes(b"not gzip")
    with pytest.raises(RecordingError, match="cannot read recording"):
        read_recording(tmp_path / "bad.csv.gz")


def test_window_selects_half_open_interval():
    rec = make_recording(n=512)
    win = rec.window(0.5, 1.0)
    assert win.t[0] == pytest.approx(0.5) and win.t[-1] < 1.0
    assert len(win) == 128
    with pytest.raises(RecordingError, match="holds no samples"):
        rec.window(10.0, 11.0)


def test_writing_into_missing_directory_is_a_user_error(tmp_path):
    with pytest.raises(RecordingError, match="does not exist"):
        write_recording(tmp_path / "nope" / "r.csv", make_recording(n=4))


def test_reading_a_large_csv_is_not_pathological(tmp_path):
    """One simulated hour at 256 Hz must be readable (size check, not a timing assertion)."""
    rec = make_recording(n=921_600, with_seq=True)
    path = write_recording(tmp_path / "hour.npz", rec)
    assert len(read_recording(path)) == 921_600


def test_cli_never_shows_a_traceback_for_a_bad_subcommand():
    proc = subprocess.run(
        [sys.executable, "-m", "fdi_daemon", "no-such-command"], capture_output=True, text=True
    )
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr


def _npz_bytes() -> bytes:
    buf = io.BytesIO()
    np.savez(buf, t=np.arange(500) / FS, v_in=np.zeros(500), accel=np.zeros(500))
    return buf.getvalue()


def _npz_with_meta(path, meta_text):
    np.savez(
        path, t=np.arange(5) / FS, v_in=np.zeros(5), accel=np.zeros(5), __meta__=np.array(meta_text)
    )


@pytest.mark.parametrize(
    "name, write, message",
    [
        ("bad.npz", lambda p: p.write_bytes(b"PK\x03\x04 not really a zip"), "not an .npz file"),
        # numpy took these for a pickle and suggested allow_pickle=True
        ("noise.npz", lambda p: p.write_bytes(bytes(range(256)) * 8), "not an .npz file"),
        ("cut.npz", lambda p: p.write_bytes(_npz_bytes()[:300]), "not an .npz file"),
        ("empty.mat", lambda p: p.write_bytes(b""), "not a MATLAB v5 file"),
        ("zeros.mat", lambda p: p.write_bytes(bytes(200)), "not a MATLAB v5 file"),
        ("list.npz", lambda p: _npz_with_meta(p, "[1, 2]"), "must be a JSON object"),
        ("null.npz", lambda p: _npz_with_meta(p, "null"), "must be a JSON object"),
        (
            "seq.csv",
            lambda p: p.write_text("t,v_in,accel,seq\n0,0,0,0\n0.00390625,0,0,1e300\n"),
            "whole numbers below 2",
        ),
    ],
)
def test_corrupt_binary_files_and_absurd_counters_are_clear_errors(tmp_path, name, write, message):
    path = tmp_path / name
    write(path)
    with pytest.raises(RecordingError, match=message):
        read_recording(path)


def test_a_spreadsheet_csv_with_a_byte_order_mark_is_read(tmp_path):
    """The mark was read into the first name: "missing column(s) t (found: \ufefft, ...)"."""
    path = tmp_path / "excel.csv"
    path.write_bytes(b"\xef\xbb\xbft,v_in,accel\r\n0,1,2\r\n0.00390625,1,2\r\n")
    assert list(read_recording(path).columns) == ["t", "v_in", "accel"]


@pytest.mark.parametrize(
    "write, message",
    [
        (
            lambda p: np.savez(p, t=np.arange(5) / FS, v_in=np.zeros(4), accel=np.zeros(5)),
            "columns differ in length",
        ),
        (lambda p: p.write_text("t,v_in,accel\n0,0,0\n0,0,0\n0,0,0\n"), "never increases"),
    ],
)
def test_errors_found_after_reading_name_the_file(tmp_path, write, message):
    path = tmp_path / ("r.npz" if "length" in message else "r.csv")
    write(path)
    with pytest.raises(RecordingError, match=message) as info:
        read_recording(path)
    assert str(info.value).startswith(f"{path}: ")


def test_writing_onto_a_directory_is_a_recording_error(tmp_path):
    (tmp_path / "r.csv").mkdir()  # it was an IsADirectoryError traceback from `fdi sim record`
    with pytest.raises(RecordingError, match="cannot write the recording"):
        write_recording(tmp_path / "r.csv", make_recording(n=4))


@pytest.mark.parametrize("suffix", [".csv", ".csv.gz", ".npz", ".mat"])
def test_an_interrupted_write_leaves_the_old_file_and_no_partial_one(tmp_path, monkeypatch, suffix):
    """Ctrl-C while a long recording was written left a truncated file under its name."""
    import fdi_daemon.io.recordings as recordings

    path = write_recording(tmp_path / f"r{suffix}", make_recording(n=4))
    before = path.read_bytes()

    def cut(target, *args, **kwargs):
        Path(target).write_bytes(b"half a file")
        raise KeyboardInterrupt

    monkeypatch.setattr(recordings, "_write_csv", cut)
    monkeypatch.setattr(recordings.np, "savez_compressed", cut)
    monkeypatch.setattr("scipy.io.savemat", cut)
    with pytest.raises(KeyboardInterrupt):
        write_recording(path, make_recording(n=8))
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == [path.name]


@pytest.mark.parametrize("torn", ["0.0117,1.5", "0.0117,1.5,", "0.01", "0.0117,1.5,2e"])
def test_a_torn_last_line_is_dropped_with_a_warning_naming_it(tmp_path, caplog, torn):
    """A writer stopped mid-row leaves a malformed last line without its line end."""
    rows = "".join(f"{k / FS:.6f},{k % 3},{k % 5}\n" for k in range(3))
    path = tmp_path / "torn.csv"
    path.write_text("# fs: 256\nt,v_in,accel\n" + rows + torn)
    rec = read_recording(path)
    assert len(rec) == 3
    np.testing.assert_array_equal(rec.v_in, [0, 1, 2])
    assert "line 6" in caplog.text and "torn last line" in caplog.text


@pytest.mark.parametrize(
    "body",
    [
        "t,v_in,accel\n0,1,2\n0.0039,1\n0.0078,1,2\n0.0117,1,2\n",  # torn inside
        "t,v_in,accel\n0,1,2\n0.0039,1,2\n0.0078,1\n",  # malformed, yet ended
    ],
)
def test_a_torn_line_elsewhere_is_still_an_error(tmp_path, body):
    path = tmp_path / "torn.csv"
    path.write_text(body)
    with pytest.raises(RecordingError, match=r"line \d has 2 field"):
        read_recording(path)


def _with_gap_and_duplicate(rec: Recording) -> Recording:
    """``rec`` without samples 100-102 and with sample 300 twice."""
    keep = np.r_[np.arange(100), np.arange(103, 300), 300, np.arange(300, len(rec))]
    return Recording({k: v[keep] for k, v in rec.columns.items()}, dict(rec.meta))


@pytest.mark.parametrize("suffix", [".csv", ".csv.gz", ".npz", ".mat"])
def test_every_format_to_parquet_keeps_samples_gaps_duplicates_and_metadata(tmp_path, suffix):
    source = write_recording(tmp_path / f"rec{suffix}", _with_gap_and_duplicate(make_recording()))
    first = read_recording(source, strict=False)
    parquet = write_recording(tmp_path / "rec.parquet", first)
    back = read_recording(parquet, strict=False)
    assert back.meta == first.meta
    assert list(back.columns) == list(first.columns)
    for name, col in first.columns.items():
        np.testing.assert_array_equal(back[name], col)
    assert back.sampling.issues == first.sampling.issues
    assert [i.kind for i in back.sampling.issues] == ["gap", "duplicate"]
    assert back.sampling.issues[0].missing_samples == 3


def test_parquet_stores_float32_only_where_lossless(tmp_path):
    """The rule: a float column is float32 when every value is exactly a float32 (ADC counts
    times a power of two), else float64; seq is int64; the round trip is exact either way."""
    import pyarrow.parquet as pq

    n = 1024
    rng = np.random.default_rng(45)
    counts = rng.integers(-32768, 32768, n)
    rec = Recording(
        {
            "seq": np.arange(n, dtype=np.int64),
            "t": np.arange(n) / FS,  # 1/256 s steps: exact in float32 up to 2**24 / 256 s
            "v_in": counts * 2.0**-13,  # a 16-bit ADC, 8 V full scale: float32
            "accel": rng.normal(0.0, 2.0, n),  # full float64 precision: float64
        },
        {"fs": "256", "units": "t=s v_in=V accel=m/s^2", "model_sha256": "ab" * 32},
    )
    path = write_recording(tmp_path / "rec.parquet", rec)
    schema = pq.read_schema(path)
    types = {name: str(schema.field(name).type) for name in schema.names}
    assert types == {"seq": "int64", "t": "float", "v_in": "float", "accel": "double"}
    assert parquet_column_type("accel", np.float32(rng.normal(size=8)).astype(float)) == "float32"
    assert pq.ParquetFile(path).metadata.row_group(0).column(0).compression == "ZSTD"
    back = read_recording(path)
    for name, col in rec.columns.items():
        np.testing.assert_array_equal(back[name], col)
    assert back.meta == rec.meta


def test_a_torn_parquet_file_is_a_clear_error(tmp_path):
    path = write_recording(tmp_path / "rec.parquet", make_recording())
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(RecordingError, match="rec.parquet: cannot read recording") as info:
        read_recording(path)
    assert "\n" not in str(info.value)
