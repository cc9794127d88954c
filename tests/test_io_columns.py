"""`--columns`: a recording from another tool, read under fdi's names."""

import argparse

import numpy as np
import pytest

from fdi_daemon.errors import RecordingError, UserError
from fdi_daemon.io.columns import add_columns_option, parse_columns
from fdi_daemon.io.recordings import read_recording


@pytest.fixture
def other_tool_csv(tmp_path):
    t = np.arange(300) / 256.0
    path = tmp_path / "other.csv"
    rows = "".join(f"{a:.6f},{b:.6f},{c:.6f},{d}\n"
                   for a, b, c, d in zip(t, np.sin(t), np.cos(t), range(300)))
    path.write_text("time,u,y,extra\n" + rows)
    return path, t


def test_mapped_columns_read_under_fdi_names(other_tool_csv):
    path, t = other_tool_csv
    rec = read_recording(path, columns=parse_columns("t=time, v_in=u ,accel=y"))
    assert set(rec.columns) == {"t", "v_in", "accel", "extra"}
    np.testing.assert_allclose(rec.t, np.round(t, 6))
    np.testing.assert_allclose(rec.accel, np.round(np.cos(t), 6))
    assert rec.fs == pytest.approx(256.0, rel=1e-4)


def test_without_mapping_the_error_names_the_option(other_tool_csv):
    path, _ = other_tool_csv
    with pytest.raises(RecordingError, match=r"missing column\(s\) t, v_in, accel.*--columns t="):
        read_recording(path)


def test_a_mapping_to_an_absent_column_is_one_clear_error(other_tool_csv):
    path, _ = other_tool_csv
    with pytest.raises(RecordingError, match=r"--columns v_in=volts: no such column \(found: time"):
        read_recording(path, columns={"t": "time", "v_in": "volts", "accel": "y"})


@pytest.mark.parametrize("spec, message", [
    ("t", "is not NAME=COLUMN"),
    ("t=", "is not NAME=COLUMN"),
    ("t=a,t=b", "t is mapped twice"),
    ("t=a,v_in=a", "'a' is mapped to more than one name"),
])
def test_malformed_specs_are_refused(spec, message):
    with pytest.raises(UserError, match=message):
        parse_columns(spec)


def test_the_option_parses_into_a_mapping_and_refuses_bad_specs(capsys):
    parser = argparse.ArgumentParser()
    add_columns_option(parser)
    assert parser.parse_args([]).columns == {}
    assert parser.parse_args(["--columns", "accel=y"]).columns == {"accel": "y"}
    with pytest.raises(SystemExit) as exc:
        parser.parse_args(["--columns", "accel"])
    assert exc.value.code == 2
    assert "is not NAME=COLUMN" in capsys.readouterr().err
