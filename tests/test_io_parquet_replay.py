"""Parquet recordings in use: `fdi convert` between formats, and a Parquet recording
replays to the same events and summary as the CSV it was converted from."""

from __future__ import annotations

import numpy as np
import pytest
from conftest_detect import MODEL, scenario_recording

from fdi_daemon.cli import main
from fdi_daemon.fleet.replay_one import replay_recording
from fdi_daemon.io.recordings import read_recording, write_recording

pytest.importorskip("pyarrow")


def test_a_parquet_recording_replays_to_the_same_events_as_its_csv(tmp_path, capsys):
    csv = write_recording(tmp_path / "rig.csv", scenario_recording("test_case_2", seed=1))
    parquet = tmp_path / "rig.parquet"
    assert main(["convert", str(csv), str(parquet)]) == 0
    assert "samples at 256 Hz" in capsys.readouterr().out
    from_csv = replay_recording(csv, MODEL)
    from_parquet = replay_recording(parquet, MODEL)
    assert from_csv.events, "the scenario's fault must give events to compare"
    assert from_parquet.events == from_csv.events
    assert from_parquet.summary == from_csv.summary


@pytest.mark.parametrize("suffix", [".csv.gz", ".npz", ".mat", ".csv"])
def test_convert_from_parquet_to_every_format_and_back(tmp_path, suffix, capsys):
    rec = scenario_recording("test_case_1", seed=2, duration_s=2.0)
    parquet = write_recording(tmp_path / "rec.parquet", rec)
    out = tmp_path / f"out{suffix}"
    assert main(["convert", str(parquet), str(out)]) == 0
    back = read_recording(out)
    for name, col in read_recording(parquet).columns.items():
        if suffix.startswith(".csv"):  # CSV keeps 10 significant digits
            np.testing.assert_allclose(back[name], col, rtol=1e-9, atol=1e-9)
        else:
            np.testing.assert_array_equal(back[name], col)


def test_convert_keeps_and_reports_a_gap(tmp_path, capsys):
    rec = scenario_recording("test_case_1", seed=3, duration_s=2.0)
    keep = np.ones(len(rec), dtype=bool)
    keep[100:104] = False
    gappy = type(rec)({k: v[keep] for k, v in rec.columns.items()}, dict(rec.meta))
    source = write_recording(tmp_path / "gap.csv", gappy)
    assert main(["convert", str(source), str(tmp_path / "gap.parquet")]) == 0
    assert "gap of 4 sample(s)" in capsys.readouterr().err
    back = read_recording(tmp_path / "gap.parquet", strict=False)
    assert [(i.kind, i.missing_samples) for i in back.sampling.issues] == [("gap", 4)]


@pytest.mark.parametrize(
    "args, message",
    [
        (["IN.csv", "out.xls"], "unknown recording format"),
        (["missing.csv", "out.parquet"], "no such file"),
    ],
)
def test_convert_mistakes_exit_2_with_one_line(tmp_path, monkeypatch, capsys, args, message):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "IN.csv").write_text("t,v_in,accel\n0,1,2\n0.00390625,1,2\n")
    assert main(["convert", *args]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and "\n" not in err
