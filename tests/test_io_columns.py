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
    rows = "".join(
        f"{a:.6f},{b:.6f},{c:.6f},{d}\n" for a, b, c, d in zip(t, np.sin(t), np.cos(t), range(300))
    )
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


@pytest.mark.parametrize(
    "spec, message",
    [
        ("t", "is not NAME=COLUMN"),
        ("t=", "is not NAME=COLUMN"),
        ("t=a,t=b", "t is mapped twice"),
        ("t=a,v_in=a", "'a' is mapped to more than one name"),
    ],
)
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


def renamed(path, out, header: str):
    """The same recording with the header of another tool."""
    lines = path.read_text().splitlines(keepends=True)
    first = next(i for i, line in enumerate(lines) if not line.startswith("#"))
    lines[first] = header + "\n"
    out.write_text("".join(lines))
    return out


def test_identify_signature_and_replay_read_another_tools_columns(tmp_path, capsys):
    """One option, the same result as with fdi's own names, for every command on the way
    from a chirp to a replayed fault."""
    import json

    from conftest_ident import FS, OE_B, OE_F, plant_recording
    from scipy import signal

    from fdi_daemon.cli import main
    from fdi_daemon.core.velocity import VelocityEstimator
    from fdi_daemon.io.model_file import load_model
    from fdi_daemon.io.recordings import Recording, write_recording

    mapping = ["--columns", "t=time,v_in=u,accel=y"]
    chirp = plant_recording(tmp_path / "chirp.csv", 1024, seed=1)
    other_chirp = renamed(chirp, tmp_path / "chirp_other.csv", "time,u,y")
    for rec, extra, out in ((chirp, [], "own.yaml"), (other_chirp, mapping, "other.yaml")):
        assert main(["identify", str(rec), "-o", str(tmp_path / out), *extra]) == 0
    own, other = load_model(tmp_path / "own.yaml"), load_model(tmp_path / "other.yaml")
    np.testing.assert_array_equal(own.plant_b, other.plant_b)
    np.testing.assert_array_equal(own.plant_a, other.plant_a)

    t = np.arange(1536) / FS
    v_in = 1.4 * np.sin(2 * np.pi * 8 * t) + 0.5 * np.sin(2 * np.pi * 3 * t)
    accel = signal.lfilter(own.plant_b, own.plant_a, v_in)
    velocity = VelocityEstimator(FS).run(accel)
    friction = np.where(t > 2.0, np.sign(velocity) + 1.5 * velocity, 0.0)
    accel = accel + signal.lfilter(OE_B, OE_F, friction)
    fault = tmp_path / "fault.csv"
    write_recording(fault, Recording({"t": t, "v_in": v_in, "accel": accel}, {"fs": "256"}))
    other_fault = renamed(fault, tmp_path / "fault_other.csv", "time,u,y")
    summaries = []
    for rec, extra, tag in ((fault, [], "own"), (other_fault, mapping, "other")):
        model = tmp_path / f"{tag}_sig.yaml"
        assert (
            main(
                [
                    "signature",
                    str(rec),
                    "--model",
                    str(tmp_path / f"{tag}.yaml"),
                    "--fault-window",
                    "2.5:6",
                    "-o",
                    str(model),
                    "--gamma-grid",
                    "0:10:0.5",
                    *extra,
                ]
            )
            == 0
        )
        summary = tmp_path / f"{tag}.json"
        assert (
            main(["replay", str(rec), "--model", str(model), "--summary", str(summary), *extra])
            == 0
        )
        summaries.append(json.loads(summary.read_text()))
    assert (
        load_model(tmp_path / "own_sig.yaml").fault_filter.gamma_f
        == load_model(tmp_path / "other_sig.yaml").fault_filter.gamma_f
    )
    assert summaries[0] == summaries[1] and summaries[0]["samples"] == 1536
    capsys.readouterr()
    assert main(["replay", str(other_fault), "--model", str(tmp_path / "own_sig.yaml")]) == 2
    assert "--columns" in capsys.readouterr().err  # without the option: the way around
