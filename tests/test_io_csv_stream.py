"""A plain CSV recording streamed piece by piece (`fdi_daemon.io.csv_stream`) gives the
columns of the whole file and replays to the same events; a file that is not plain is
read whole, and a line found malformed further on stops the stream with the NumPy
reader's message."""

from __future__ import annotations

import gzip

import numpy as np
import pytest
from conftest_detect import MODEL, scenario_recording

from fdi_daemon.errors import RecordingError
from fdi_daemon.fleet.replay_one import replay_recording
from fdi_daemon.io import csv_stream, recordings
from fdi_daemon.io.csv_stream import CsvRecordingStream
from fdi_daemon.io.recordings import Recording, open_stream, read_recording, write_recording

pytest.importorskip("pyarrow")


@pytest.fixture
def small_blocks(monkeypatch):
    """Every CSV streamed (no size floor), in blocks of 4 KiB: many pieces, cut anywhere."""
    monkeypatch.setattr(recordings, "ARROW_CSV_MIN_BYTES", 0)
    monkeypatch.setattr(csv_stream, "BLOCK_BYTES", 4096)


def _text(seconds: float = 4.0, seed: int = 3) -> str:
    rec = scenario_recording("test_case_2", seed=seed, duration_s=seconds)
    cols = {"seq": np.arange(len(rec)), **{k: rec[k] for k in ("t", "v_in", "accel")}}
    cols["accel"] = np.array(cols["accel"], dtype=float)
    cols["accel"][100:110] = np.nan  # bad samples cross the pieces as they are
    header = "# fs: 256\n# device: rig 9\nseq,t,v_in,accel,truth\n"
    rows = "".join(
        f"{k},{t:.9f},{v:.10g},{a:.10g},0\n"
        for k, t, v, a in zip(cols["seq"], cols["t"], cols["v_in"], cols["accel"])
    )
    return header + rows


@pytest.mark.parametrize("kind", ["plain", "crlf", "gzip", "bom"])
def test_a_plain_csv_streams_to_the_whole_files_columns(tmp_path, small_blocks, kind):
    text = _text()
    if kind == "crlf":
        text = text.replace("\n", "\r\n")
    if kind == "bom":
        text = "\ufeff" + text
    path = tmp_path / ("rec.csv.gz" if kind == "gzip" else "rec.csv")
    data = text.encode()
    path.write_bytes(gzip.compress(data) if kind == "gzip" else data)
    stream = open_stream(path)
    assert isinstance(stream, CsvRecordingStream)
    whole = read_recording(path, strict=False)
    assert stream.rows == len(whole) and stream.fs == 256.0
    assert stream.meta == whole.meta == {"fs": "256", "device": "rig 9"}
    pieces = list(stream.pieces())
    assert len(pieces) > 10
    assert all(set(p.columns) == {"seq", "t", "v_in", "accel"} for p in pieces)  # not truth
    for name in ("seq", "t", "v_in", "accel"):
        joined = np.concatenate([p[name] for p in pieces])
        np.testing.assert_array_equal(joined, whole[name])
        assert joined.dtype == whole[name].dtype


def test_a_streamed_csv_replays_as_the_whole_file(tmp_path, small_blocks):
    path = tmp_path / "rec.csv"
    path.write_text(_text(seconds=8.0))
    assert open_stream(path) is not None
    whole = replay_recording(path, MODEL)
    streamed = replay_recording(path, MODEL, stream=True)
    assert whole.events, "the scenario's fault must give events to compare"
    assert streamed.events == whole.events
    assert streamed.summary == whole.summary


@pytest.mark.parametrize(
    "change",
    [
        pytest.param(lambda t: t.replace("\n50,", "\n# a note\n50,"), id="comment in the body"),
        pytest.param(lambda t: t.replace("\n50,", '\n"50",'), id="quote"),
        pytest.param(lambda t: t.replace("\n50,", "\n\n50,"), id="blank line"),
        pytest.param(lambda t: t.replace("\n50,", "\n 50,"), id="line starting with a blank"),
        pytest.param(lambda t: t.replace("\n50,", "\r50,"), id="lone carriage return"),
        pytest.param(lambda t: t[:-9], id="torn last line"),
        pytest.param(lambda t: t.replace("# fs: 256\n", ""), id="no rate"),
        pytest.param(lambda t: t.replace("v_in", "u"), id="missing column"),
        pytest.param(lambda t: t.replace("\n3,", "\n3,x,"), id="malformed first rows"),
    ],
)
def test_a_csv_that_is_not_plain_is_read_whole(tmp_path, small_blocks, change):
    path = tmp_path / "rec.csv"
    path.write_text(change(_text()))
    assert open_stream(path) is None


def test_a_csv_below_the_size_floor_is_read_whole(tmp_path):
    path = tmp_path / "rec.csv"
    path.write_text(_text())
    assert path.stat().st_size < recordings.ARROW_CSV_MIN_BYTES
    assert open_stream(path) is None


def test_a_line_malformed_further_on_stops_with_the_numpy_readers_message(tmp_path, small_blocks):
    text = _text(seconds=8.0)
    lines = text.split("\n")
    bad = 1900  # past the first rows tried when the stream opens (64 KiB, ~1400 rows)
    lines[bad] = lines[bad].rsplit(",", 2)[0]  # two fields short
    path = tmp_path / "rec.csv"
    path.write_text("\n".join(lines))
    stream = open_stream(path)
    assert stream is not None
    with pytest.raises(RecordingError) as streamed:
        list(stream.pieces())
    with pytest.raises(RecordingError) as whole:
        read_recording(path)
    assert str(streamed.value) == str(whole.value)
    assert f"line {bad + 1} has 3 field(s), the header has 5" in str(streamed.value)


def test_the_recorders_csv_streams(tmp_path, small_blocks):
    """What the recorder writes (`write_recording`'s CSV) is plain."""
    rec = scenario_recording("test_case_1", seed=2, duration_s=2.0)
    path = write_recording(tmp_path / "r.csv", Recording(rec.columns, {"fs": "256"}))
    stream = open_stream(path)
    assert stream is not None and stream.rows == len(rec)
