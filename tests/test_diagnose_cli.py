"""`fdi diagnose` end to end: report contract, augmented model, plot, bad input."""

from __future__ import annotations

import json

import numpy as np
import pytest

from fdi_daemon.cli import main
from fdi_daemon.diagnose import workflow
from fdi_daemon.diagnose.augment import AugmentedPlant
from fdi_daemon.io.model_file import FdiModel, load_model, save_model
from fdi_daemon.io.recordings import Recording, write_recording
from tests.diagnose_cases import FS, nominal_model, recording


@pytest.fixture(autouse=True)
def shared_diagnoses(diagnosis, monkeypatch):
    """`fdi diagnose` diagnoses through the shared `diagnosis` (conftest_diagnose.py): the
    same recording and model read twice (a rerun against the augmented model, whose plant
    is the nominal one; a --columns mapping; a recording with and without its time column)
    are diagnosed once, and the reports compared hold that one diagnosis."""
    monkeypatch.setattr(
        workflow, "run_diagnose", lambda *args, progress=None, **kwargs: diagnosis(*args, **kwargs)
    )


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("diag")
    b, a = nominal_model()
    save_model(
        d / "nominal.yaml", FdiModel(fs=FS, plant_b=b, plant_a=a, provenance={"source": "test"})
    )
    write_recording(d / "coulomb.csv", recording("coulomb_friction"))
    write_recording(d / "clean.npz", recording(None))
    return d


@pytest.mark.slow  # diagnoses
def test_report_model_and_plot(files, capsys):
    out = files / "out"
    out.mkdir(exist_ok=True)
    rc = main(
        [
            "diagnose",
            str(files / "coulomb.csv"),
            "--model",
            str(files / "nominal.yaml"),
            "--json",
            str(out / "r.json"),
            "--plot",
            str(out / "p.png"),
            "-o",
            str(out / "aug.yaml"),
        ]
    )
    assert rc == 0
    assert "coulomb_friction" in capsys.readouterr().out
    report = json.loads((out / "r.json").read_text())
    for key in ("effect", "gap_before", "gap_after", "gap_metric", "ranking", "params", "regions"):
        assert key in report
    assert report["effect"] == "coulomb_friction"
    assert report["gap_metric"] == "nrmse"
    assert report["gap_after"] <= 0.5 * report["gap_before"]
    assert {"effect", "gap_after", "score"} <= set(report["ranking"][0])
    assert {r["kind"] for r in report["regions"]} == {"time", "state", "frequency"}
    assert (out / "p.png").stat().st_size > 10_000
    model = load_model(out / "aug.yaml")
    assert model.provenance["source"] == "test"
    assert "coulomb_friction" in [i["name"] for i in model.extra["effects"]["items"]]
    rec = recording("coulomb_friction")
    test = slice(int(round(len(rec.t) * 2 / 3)), None)
    nominal = AugmentedPlant.from_model(load_model(files / "nominal.yaml"))
    e_before = rec.accel - nominal.run(rec.v_in)
    e_after = rec.accel - AugmentedPlant.from_model(model).run(rec.v_in)
    assert np.std(e_after[test]) < 0.5 * np.std(e_before[test])
    # diagnosing against the augmented model starts from its plant again, and says so
    assert main(["diagnose", str(files / "coulomb.csv"), "--model", str(out / "aug.yaml")]) == 0
    err = capsys.readouterr().err
    assert "holds effects (coulomb_friction) from an earlier diagnosis" in err


@pytest.mark.slow  # diagnoses
def test_fit_linear_velocity_output_and_no_effect(files, capsys):
    rc = main(
        [
            "diagnose",
            str(files / "clean.npz"),
            "--fit-linear",
            "--output-kind",
            "velocity",
            "--json",
            str(files / "v.json"),
            "-o",
            str(files / "v.yaml"),
        ]
    )
    assert rc == 0
    assert "no significant missing effect" in capsys.readouterr().out
    report = json.loads((files / "v.json").read_text())
    assert report["effect"] is None and report["params"] == {}
    model = load_model(files / "v.yaml")
    assert model.extra["effects"]["output_kind"] == "velocity"


def _bad(args, capsys):
    rc = main(["diagnose", *args])
    err = capsys.readouterr().err.strip()
    assert rc == 2
    assert len(err.splitlines()) == 1, err
    return err


def test_bad_input_is_one_line_and_exit_2(files, tmp_path, capsys):
    model = str(files / "nominal.yaml")
    assert "no such file" in _bad([str(tmp_path / "none.csv"), "--model", model], capsys)
    assert "missing column(s) torque " in _bad(
        [str(files / "coulomb.csv"), "--model", model, "--output", "torque"], capsys
    )
    assert "missing column(s) u " in _bad(
        [str(files / "coulomb.csv"), "--model", model, "--input", "u"], capsys
    )
    save_model(
        tmp_path / "m128.yaml",
        FdiModel(fs=128.0, plant_b=np.array([0.0, 1.0]), plant_a=np.array([1.0, -0.5])),
    )
    assert "fs" in _bad(
        [str(files / "coulomb.csv"), "--model", str(tmp_path / "m128.yaml")], capsys
    )
    rec = recording("coulomb_friction")
    cols = {k: v.copy() for k, v in rec.columns.items()}
    cols["accel"][100] = np.nan
    write_recording(tmp_path / "nan.csv", Recording(cols, dict(rec.meta)))
    assert "not finite" in _bad([str(tmp_path / "nan.csv"), "--fit-linear"], capsys)
    short = Recording({k: v[:100] for k, v in rec.columns.items()}, dict(rec.meta))
    write_recording(tmp_path / "short.csv", short)
    assert "samples" in _bad([str(tmp_path / "short.csv"), "--fit-linear"], capsys)
    flat = {k: v.copy() for k, v in rec.columns.items()}
    flat["v_in"][:] = 0.0
    write_recording(tmp_path / "flat.csv", Recording(flat, dict(rec.meta)))
    assert "constant" in _bad([str(tmp_path / "flat.csv"), "--fit-linear"], capsys)
    keep = np.ones(len(rec.t), bool)
    keep[500:510] = False
    write_recording(
        tmp_path / "gap.csv",
        Recording({k: v[keep] for k, v in rec.columns.items()}, dict(rec.meta)),
    )
    assert "irregular sampling" in _bad([str(tmp_path / "gap.csv"), "--fit-linear"], capsys)
    (tmp_path / "broken.yaml").write_text("fs: [\n")
    assert "YAML" in _bad(
        [str(files / "coulomb.csv"), "--model", str(tmp_path / "broken.yaml")], capsys
    )
    assert "does not exist" in _bad(
        [
            str(files / "coulomb.csv"),
            "--model",
            model,
            "--json",
            str(tmp_path / "missing_dir" / "r.json"),
        ],
        capsys,
    )
    # the report overwrote the recording; a plot's unknown ending was a traceback at the end
    rec_before = (files / "coulomb.csv").read_bytes()
    assert "is also an input" in _bad(
        [str(files / "coulomb.csv"), "--model", model, "--json", str(files / "coulomb.csv")], capsys
    )
    assert "is also an input" in _bad(
        [str(files / "coulomb.csv"), "--model", model, "-o", str(files / "coulomb.csv")], capsys
    )
    assert (files / "coulomb.csv").read_bytes() == rec_before
    assert "cannot write a plot as .foo" in _bad(
        [str(files / "coulomb.csv"), "--model", model, "--plot", str(tmp_path / "x.foo")], capsys
    )


@pytest.mark.slow  # diagnoses
def test_any_column_names(tmp_path, capsys):
    # a closed-loop stage recorded by another tool: no v_in, no accel
    from tests.diagnose_cases import stage_recording

    rec = stage_recording()
    path = tmp_path / "stage.csv"
    write_recording(
        path, Recording({"t": rec.t, "force": rec["force"], "vel": rec["vel"]}, dict(rec.meta))
    )
    rc = main(
        [
            "diagnose",
            str(path),
            "--fit-linear",
            "--input",
            "force",
            "--output",
            "vel",
            "--output-kind",
            "velocity",
            "--json",
            str(tmp_path / "a.json"),
        ]
    )
    assert rc == 0
    out = capsys.readouterr().out
    assert "coulomb_friction" in out and "inverse_dynamics" in out
    report = json.loads((tmp_path / "a.json").read_text())
    for key in (
        "form",
        "form_reason",
        "noise_floor",
        "gap_before_to_floor",
        "dead_time",
        "linear_check",
        "held_by_later",
        "force_balance",
    ):
        assert key in report
    # the shared --columns mapping gives the same answer
    rc = main(
        [
            "diagnose",
            str(path),
            "--fit-linear",
            "--columns",
            "v_in=force,velocity=vel",
            "--output-kind",
            "velocity",
            "--json",
            str(tmp_path / "b.json"),
        ]
    )
    assert rc == 0
    again = json.loads((tmp_path / "b.json").read_text())
    assert again["effect"] == report["effect"]
    assert again["gap_after"] == pytest.approx(report["gap_after"], rel=1e-12)
    # the inverse-dynamics form cannot be simulated: -o says so in one line
    assert "inverse-dynamics" in _bad(
        [
            str(path),
            "--fit-linear",
            "--input",
            "force",
            "--output",
            "vel",
            "--output-kind",
            "velocity",
            "-o",
            str(tmp_path / "m.yaml"),
        ],
        capsys,
    )
    with pytest.raises(SystemExit) as exc:  # argparse rejects a malformed mapping
        main(["diagnose", str(path), "--fit-linear", "--columns", "v_in"])
    assert exc.value.code == 2
    assert "--columns" in capsys.readouterr().err


@pytest.mark.slow  # diagnoses
def test_a_recording_without_a_time_column_takes_its_rate_from_fs(tmp_path, capsys):
    # benchmark data (the Silverbox's V1, V2) have no time column: --fs gives the rate
    from tests.diagnose_cases import duffing_recording

    rec = duffing_recording(3e5)
    bare = tmp_path / "bare.csv"
    np.savetxt(
        bare,
        np.column_stack([rec.v_in, rec["position"]]),
        delimiter=",",
        header="V1,V2",
        comments="",
        fmt="%.10g",
    )  # the digits `write_recording` keeps
    args = ["--fit-linear", "--input", "V1", "--output", "V2", "--output-kind", "position"]
    assert "missing column(s) t" in _bad([str(bare)] + args, capsys)
    rc = main(["diagnose", str(bare), *args, "--fs", str(FS), "--json", str(tmp_path / "a.json")])
    assert rc == 0
    timed = tmp_path / "timed.csv"
    write_recording(
        timed, Recording({"t": rec.t, "V1": rec.v_in, "V2": rec["position"]}, dict(rec.meta))
    )
    rc = main(["diagnose", str(timed), *args, "--json", str(tmp_path / "b.json")])
    assert rc == 0
    bare_report = json.loads((tmp_path / "a.json").read_text())
    assert bare_report["effect"] == "cubic_stiffness"
    assert bare_report["gap_after"] == pytest.approx(
        json.loads((tmp_path / "b.json").read_text())["gap_after"], rel=1e-9
    )
    # a time column and a rate that disagree: one line, no traceback
    assert "not 100 Hz" in _bad([str(timed)] + args + ["--fs", "100"], capsys)
    assert "--fs must be a positive" in _bad([str(bare)] + args + ["--fs", "0"], capsys)


def test_every_missing_column_is_named_at_once(tmp_path, capsys):
    """It named only t where the input and the output were missing too."""
    other = tmp_path / "other.csv"
    other.write_text("time,u,y\n" + "".join(f"{k / 100},{k % 7},{k % 5}\n" for k in range(400)))
    err = _bad([str(other), "--fit-linear"], capsys)
    assert "missing column(s) t, v_in, accel " in err
    assert "--columns t=COLUMN,v_in=COLUMN,accel=COLUMN" in err
