"""`fdi replay`: files written, summary contract, user mistakes give exit code 2."""

import json

import numpy as np
import pytest
from conftest_detect import scenario_recording, sim_rig_model

from fdi_daemon.cli import main
from fdi_daemon.detect.events import read_events
from fdi_daemon.detect.pipeline import Pipeline
from fdi_daemon.io.model_file import load_model, save_model
from fdi_daemon.io.recordings import Recording, write_recording


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    root = tmp_path_factory.mktemp("replay")
    model = save_model(root / "model.yaml", sim_rig_model())
    rec = write_recording(root / "tc2.csv", scenario_recording("test_case_2"))
    return root, model, rec


def test_a_csv_of_another_tool_with_rounded_times_replays(files, tmp_path):
    """Times printed with 4 decimals, no seq, CRLF line ends and an extra column, as another
    tool may write them: the rate comes out as 256 Hz and the events are those of the
    original file."""
    root, model, rec = files
    src = scenario_recording("test_case_2")
    lines = ["t,v_in,accel,truth"] + [
        f"{t:.4f},{v:.6f},{a:.6f},0" for t, v, a in zip(src.t, src.v_in, src.accel)
    ]
    other = tmp_path / "other.csv"
    other.write_bytes("\r\n".join(lines).encode() + b"\r\n")
    for path, name in ((rec, "ev_own.jsonl"), (other, "ev_other.jsonl")):
        assert (
            main(["replay", str(path), "--model", str(model), "--events", str(tmp_path / name)])
            == 0
        )
    kinds = [
        [e["kind"] for e in read_events(tmp_path / name)]
        for name in ("ev_own.jsonl", "ev_other.jsonl")
    ]
    assert (
        kinds[0]
        == kinds[1]
        == ["calibrated", "fault_detected", "alarm_raised", "friction_isolated"]
    )


def test_replay_writes_events_summary_and_plot(files, capsys):
    root, model, rec = files
    code = main(
        [
            "replay",
            str(rec),
            "--model",
            str(model),
            "--events",
            str(root / "ev.jsonl"),
            "--summary",
            str(root / "sum.json"),
            "--plot",
            str(root / "fig.png"),
        ]
    )
    assert code == 0
    summary = json.loads((root / "sum.json").read_text())
    for key in (
        "samples",
        "fs",
        "first_detection_t",
        "isolated_t",
        "classification",
        "theta_final",
        "alarm_episodes",
    ):
        assert key in summary
    assert summary["samples"] == 1536 and summary["fs"] == 256.0
    assert summary["classification"] == "friction" and summary["alarm_episodes"] == 1
    assert 2.9 <= summary["first_detection_t"] <= summary["isolated_t"]
    events = read_events(root / "ev.jsonl")
    assert [e["kind"] for e in events] == [
        "calibrated",
        "fault_detected",
        "alarm_raised",
        "friction_isolated",
    ]
    assert summary["alarms"] == 1 and summary["alarm_peak_priority"] >= 1
    assert (root / "fig.png").stat().st_size > 10_000
    out = capsys.readouterr().out
    assert "classification friction" in out
    lines = out.splitlines()
    isolated = next(line for line in lines if "friction_isolated" in line)
    assert " θ1=" in isolated and " s/m" in isolated  # θ2 with its unit
    assert " friction_level=" in isolated  # beside θ, "- (not measured yet)" when None
    raised = next(line for line in lines if "alarm_raised" in line)
    assert "level=- (not measured yet)" in raised  # not the level from before the fault
    assert events[2]["level"] is None and "level_before" in events[2]
    assert (
        f"wrote events {root / 'ev.jsonl'} (4 lines); summary {root / 'sum.json'}; "
        f"plot {root / 'fig.png'}"
    ) in lines


def test_replay_of_a_recording_with_a_gap(files):
    root, model, _ = files
    rec = scenario_recording("test_case_2")
    keep = np.ones(len(rec), dtype=bool)
    keep[1000:1003] = False
    gappy = write_recording(
        root / "gap.csv", Recording({k: v[keep] for k, v in rec.columns.items()}, dict(rec.meta))
    )
    assert (
        main(["replay", str(gappy), "--model", str(model), "--events", str(root / "gap.jsonl")])
        == 0
    )
    gaps = [e for e in read_events(root / "gap.jsonl") if e["kind"] == "data_gap"]
    assert [g["missing_samples"] for g in gaps] == [3]


def test_realtime_replay_uses_the_per_tick_path(files):
    root, model, _ = files
    rec = scenario_recording("test_case_2")
    short = write_recording(
        root / "short.csv", Recording({k: v[:300] for k, v in rec.columns.items()}, dict(rec.meta))
    )
    assert (
        main(
            [
                "replay",
                str(short),
                "--model",
                str(model),
                "--realtime",
                "--summary",
                str(root / "rt.json"),
            ]
        )
        == 0
    )
    assert json.loads((root / "rt.json").read_text())["samples"] == 300


@pytest.mark.parametrize("case", ["no_model", "bad_rec", "fs"])
def test_user_mistakes_exit_2(files, tmp_path, capsys, case):
    root, model, rec = files
    if case == "no_model":
        argv = ["replay", str(rec), "--model", str(tmp_path / "missing.yaml")]
    elif case == "bad_rec":
        bad = tmp_path / "bad.csv"
        bad.write_text("t,v_in\n0,1\n")
        argv = ["replay", str(bad), "--model", str(model)]
    else:
        other = scenario_recording("test_case_2")
        meta = dict(other.meta, fs="512")
        path = write_recording(tmp_path / "fs.csv", Recording(dict(other.columns), meta))
        argv = ["replay", str(path), "--model", str(model)]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("fdi replay: error:") and err.count("\n") == 1


def test_summary_line_is_one_line_in_an_80_column_terminal(files, tmp_path, monkeypatch):
    """It wrapped mid-sentence with a trailing space ("first detection 2.9180 s, ⏎
    classification friction"): each line the replay prints stays whole, whatever the
    terminal's width; the terminal, not the program, wraps it."""
    import subprocess
    import sys

    root, model, rec = files
    env = {**__import__("os").environ, "COLUMNS": "80", "TERM": "xterm"}
    result = subprocess.run(
        [sys.executable, "-m", "fdi_daemon", "replay", str(rec), "--model", str(model)],
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
    )
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    assert all(line == line.rstrip() for line in lines), lines
    summary = [line for line in lines if " samples at " in line]
    assert len(summary) == 1 and summary[0].endswith("classification friction"), lines
    assert "first detection 2.9" in summary[0] and len(summary[0]) > 80


def _trace_rows(path):
    import csv

    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    return rows[0], rows[1:]


@pytest.mark.parametrize("every", [1, 4])
def test_trace_csv_and_npz_hold_every_nth_sample_with_the_events_states(
    files, tmp_path, every, capsys
):
    """--trace: the header, one row per N samples, θ as the detector reports it, and the
    state named, switching where the events say it does."""
    root, model, rec = files
    csv_path, npz_path = tmp_path / "trace.csv", tmp_path / "trace.npz"
    events_path = tmp_path / "ev.jsonl"
    for path in (csv_path, npz_path):
        argv = [
            "replay",
            str(rec),
            "--model",
            str(model),
            "--trace",
            str(path),
            "--events",
            str(events_path),
        ]
        if every != 1:
            argv += ["--trace-every", str(every)]
        assert main(argv) == 0
    said = [line for line in capsys.readouterr().out.splitlines() if line.startswith("wrote ")]
    assert said and all(f"every {every} sample" in line for line in said), said
    header, rows = _trace_rows(csv_path)
    assert header == ["t", "theta1", "theta2", "friction_level", "statistic", "state"]
    src = scenario_recording("test_case_2")
    assert len(rows) == -(-len(src) // every)
    t = np.array([float(r[0]) for r in rows])
    np.testing.assert_allclose(t, src.t[::every], atol=1e-9)
    theta1 = np.array([float(r[1]) for r in rows])
    level = np.array([float(r[3]) for r in rows])
    states = np.array([r[5] for r in rows])
    events = {e["kind"]: e["t"] for e in read_events(events_path)}
    assert set(states[t < events["calibrated"]]) <= {"starting", "calibrating"}
    assert set(states[(t > events["calibrated"]) & (t < events["fault_detected"])]) == {
        "monitoring"
    }
    assert set(states[t >= events["friction_isolated"]]) == {"friction_isolated"}
    # after isolation θ is the fit the event reports, not NaN, and the reported level (the
    # median of the trusted windows' levels since the detection) follows the window's level
    after = t >= events["friction_isolated"]
    late = t >= events["fault_detected"] + 1.0  # the first pick: one window after detection
    assert np.all(np.isfinite(theta1[after])) and np.all(np.isfinite(level[late]))
    pipeline = Pipeline(load_model(model), 256)
    window_level = pipeline.levels(pipeline.run(src.v_in, src.accel))[::every]
    assert abs(np.median(level[late]) / np.median(window_level[late]) - 1) < 0.05
    npz = np.load(npz_path)
    assert set(npz.files) == set(header)
    np.testing.assert_allclose(npz["theta1"], theta1, rtol=1e-9, equal_nan=True)
    np.testing.assert_allclose(npz["friction_level"], level, rtol=1e-9, equal_nan=True)
    assert list(npz["state"]) == list(states)


def test_trace_of_the_realtime_path_and_bad_arguments(files, tmp_path, capsys):
    root, model, _ = files
    rec = scenario_recording("test_case_2")
    short = write_recording(
        tmp_path / "short.csv",
        Recording({k: v[:40] for k, v in rec.columns.items()}, dict(rec.meta)),
    )
    path = tmp_path / "rt.csv"
    assert (
        main(
            [
                "replay",
                str(short),
                "--model",
                str(model),
                "--realtime",
                "--trace",
                str(path),
                "--trace-every",
                "3",
            ]
        )
        == 0
    )
    assert len(_trace_rows(path)[1]) == 14
    assert (
        main(
            [
                "replay",
                str(short),
                "--model",
                str(model),
                "--trace",
                str(path),
                "--trace-every",
                "0",
            ]
        )
        == 2
    )
    assert (
        main(
            [
                "replay",
                str(short),
                "--model",
                str(model),
                "--trace",
                str(tmp_path / "no" / "dir.csv"),
            ]
        )
        == 2
    )
    assert main(["replay", str(short), "--model", str(model), "--trace-every", "4"]) == 2
    err = capsys.readouterr().err
    assert "--trace-every thins the trace file: it needs --trace FILE" in err
    assert "--trace-every must be" in err and "directory" in err and "does not exist" in err


@pytest.mark.parametrize(
    "option, target, fragment",
    [
        ("--trace", "rec", "is also an input"),  # it replaced the recording with the trace
        ("--events", "rec", "is also an input"),
        ("--summary", "model", "is also an input"),
        (
            "--plot",
            "out.txt",
            "cannot write a plot as .txt",
        ),  # a matplotlib traceback after the run
        ("--summary", "events", "name the same file"),
        ("--events", "no/dir.jsonl", "does not exist"),
    ],
)
def test_outputs_that_cannot_be_written_or_would_destroy_an_input(
    files, tmp_path, capsys, option, target, fragment
):
    """Refused before the replay, with one line; the inputs stay as they were and nothing is
    written."""
    root, model, rec = files
    before = {rec: rec.read_bytes(), model: model.read_bytes()}
    events = tmp_path / "ev.jsonl"
    path = {"rec": rec, "model": model, "events": events}.get(target, tmp_path / target)
    argv = ["replay", str(rec), "--model", str(model), option, str(path)]
    if option != "--events":
        argv += ["--events", str(events)]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"fdi replay: error: {option}") and err.count("\n") == 1
    assert fragment in err
    assert {p: p.read_bytes() for p in before} == before
    assert not events.exists() and list(tmp_path.iterdir()) == []


def test_ctrl_c_in_a_paced_replay_keeps_what_was_replayed(files, tmp_path, capsys, monkeypatch):
    """Ctrl-C in `--realtime` lost every event already shown: no --events, --summary or
    --trace was written. Now the replay stops there, the outputs hold the part replayed,
    and the exit code is 130 with one line on stderr."""
    import time

    root, model, rec = files
    calls = 0

    def sleep(seconds):  # the pacing sleeps once per sample: Ctrl-C at the 1000th
        nonlocal calls
        calls += 1
        if calls == 1000:
            raise KeyboardInterrupt

    monkeypatch.setattr(time, "sleep", sleep)
    out = {name: tmp_path / name for name in ("ev.jsonl", "sum.json", "trace.csv")}
    assert (
        main(
            [
                "replay",
                str(rec),
                "--model",
                str(model),
                "--realtime",
                "--events",
                str(out["ev.jsonl"]),
                "--summary",
                str(out["sum.json"]),
                "--trace",
                str(out["trace.csv"]),
            ]
        )
        == 130
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("fdi replay: interrupted at t = ")
    summary = json.loads(out["sum.json"].read_text())
    assert 900 <= summary["samples"] < 1536
    assert summary["interrupted_at_t"] == pytest.approx(summary["samples"] / 256.0, abs=0.01)
    kinds = [e["kind"] for e in read_events(out["ev.jsonl"])]
    assert kinds[:2] == ["calibrated", "fault_detected"]  # the fault comes at 2.9 s
    assert len(_trace_rows(out["trace.csv"])[1]) == summary["samples"]
