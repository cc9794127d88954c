"""A Parquet recording streamed piece by piece (`open_stream`, `fdi replay` and
`fdi fleet-replay` on a day-long file) replays to the events and summary of the whole
file read at once; a file the stream cannot take falls back to `read_recording` and its
errors, word for word."""

from __future__ import annotations

import numpy as np
import pytest
from conftest_detect import MODEL, scenario_recording

from fdi_daemon.errors import RecordingError
from fdi_daemon.fleet.replay_one import replay_recording
from fdi_daemon.io import recordings
from fdi_daemon.io.recordings import Recording, open_stream, read_recording, write_recording

pytest.importorskip("pyarrow")


def _defective(rec: Recording) -> Recording:
    """``rec`` with seq, a run of bad samples, a gap, samples going back, a duplicate."""
    n = len(rec)
    cols = {k: np.array(v, dtype=float) for k, v in rec.columns.items()}
    cols["seq"] = np.arange(n)
    cols["accel"][300:400] = np.nan
    order = list(range(n))
    del order[600:620]
    b = order.index(900)
    order[b:b] = list(range(890, 900))
    order.insert(order.index(1200), 1199)
    return Recording({k: v[order] for k, v in cols.items()}, {**rec.meta, "fs": "256"})


@pytest.mark.parametrize("defects", [False, True])
def test_a_streamed_parquet_replays_as_the_whole_file(tmp_path, monkeypatch, defects):
    rec = scenario_recording("test_case_2", seed=1)
    rec = _defective(rec) if defects else Recording(rec.columns, {**rec.meta, "fs": "256"})
    monkeypatch.setattr(recordings, "PARQUET_ROW_GROUP", 97)  # many pieces, cut anywhere
    path = write_recording(tmp_path / "rig.parquet", rec)
    stream = open_stream(path)
    assert stream is not None and stream.rows == len(rec)
    assert sum(len(p) for p in stream.pieces()) == len(rec)
    seen = []
    whole = replay_recording(path, MODEL)
    streamed = replay_recording(path, MODEL, stream=True, progress=lambda d, n: seen.append(d))
    assert streamed.recording is None and whole.recording is not None
    assert len(seen) > 10 and seen[-1] == len(rec)
    assert whole.events, "the scenario's fault must give events to compare"
    assert streamed.events == whole.events
    assert streamed.summary == whole.summary
    for name in ("t", "theta1", "friction_level", "state"):
        np.testing.assert_array_equal(getattr(streamed.trace, name), getattr(whole.trace, name))


def test_the_stream_renames_columns_and_reads_only_the_monitors(tmp_path):
    rec = scenario_recording("test_case_1", seed=2, duration_s=2.0)
    cols = {("a_meas" if k == "accel" else k): v for k, v in rec.columns.items()}
    path = write_recording(tmp_path / "r.parquet", Recording(cols, {"fs": "256"}))
    stream = open_stream(path, {"accel": "a_meas"})
    assert stream is not None
    piece = next(stream.pieces())
    assert set(piece.columns) <= set(recordings.MONITOR_COLUMNS)
    np.testing.assert_array_equal(
        piece["accel"], read_recording(path, columns={"accel": "a_meas"})["accel"][: len(piece)]
    )


def test_files_the_stream_cannot_take_fall_back_to_read_recording(tmp_path):
    rec = scenario_recording("test_case_1", seed=2, duration_s=1.0)
    no_fs = write_recording(tmp_path / "no_fs.parquet", Recording(rec.columns, {}))
    assert open_stream(no_fs) is None  # the rate needs the whole time column
    no_accel = write_recording(
        tmp_path / "no_accel.parquet",
        Recording({k: v for k, v in rec.columns.items() if k != "accel"}, {"fs": "256"}),
    )
    assert open_stream(no_accel) is None
    with pytest.raises(RecordingError, match="missing column"):
        replay_recording(no_accel, MODEL, stream=True)
    assert open_stream(tmp_path / "rec.csv") is None
    damaged = tmp_path / "damaged.parquet"
    damaged.write_bytes(b"PAR1 not really")
    assert open_stream(damaged) is None
    with pytest.raises(RecordingError, match="cannot read recording"):
        replay_recording(damaged, MODEL, stream=True)


def test_a_time_column_not_finite_is_named_by_its_row_in_the_file(tmp_path, monkeypatch):
    rec = scenario_recording("test_case_1", seed=2, duration_s=2.0)
    cols = {k: np.array(v, dtype=float) for k, v in rec.columns.items()}
    cols["t"][400] = np.nan
    monkeypatch.setattr(recordings, "PARQUET_ROW_GROUP", 128)
    path = write_recording(tmp_path / "r.parquet", Recording(cols, {"fs": "256"}))
    with pytest.raises(RecordingError) as whole:
        read_recording(path, strict=False)
    with pytest.raises(RecordingError) as streamed:
        replay_recording(path, MODEL, stream=True)
    assert (
        str(streamed.value) == str(whole.value) == f"{path}: time column t is not finite at row 400"
    )
