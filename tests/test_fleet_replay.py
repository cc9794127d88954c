"""`fdi fleet-replay`: many recordings on a Dask LocalCluster give the rows of single replays.

The fleet: 50 short recordings of the simulated rig (6 s or less; friction faults, a small
fault, fault-free, gaps, .npz, a wrong rate, malformed files), two rigs with their own
models routed by a model map. Every row must be what `fdi replay --summary` says about that
file on its own (or the error line it prints), whatever worker ran it.
"""

import csv
import json
import os
import socket
from pathlib import Path

import numpy as np
import psutil
import pytest
import yaml
from conftest_detect import MODEL, scenario_recording
from process_support import start_fdi, survivors, wait_for_child_reading, wait_for_children

from fdi_daemon.cli import main
from fdi_daemon.errors import ConfigError, UserError
from fdi_daemon.fleet.inputs import ModelMap, find_recordings
from fdi_daemon.fleet.replay_one import ROW_COLUMNS, model_sha256, replay_row, summary_row
from fdi_daemon.io.recordings import Recording, write_recording

pytest.importorskip("dask.distributed")


def _variant(rec: Recording, kind: str) -> Recording:
    cols = {k: np.asarray(v) for k, v in rec.columns.items()}
    if kind == "gap":  # 5 samples lost at 2 s
        keep = np.ones(len(rec), dtype=bool)
        keep[512:517] = False
        cols = {k: v[keep] for k, v in cols.items()}
    elif kind == "short":  # the first 2.5 s: before the fault
        cols = {k: v[:640] for k, v in cols.items()}
    return Recording(cols, dict(rec.meta))


def _write_fleet(root: Path) -> tuple[list[str], Path]:
    """50 recordings in root/recs, two models and a model map; returns (files, map)."""
    recs = root / "recs"
    recs.mkdir()
    base = yaml.safe_load(MODEL.read_text())
    (root / "models").mkdir()
    (root / "models" / "rig_a.yaml").write_text(yaml.safe_dump(base))
    # rig B: the same plant with a shorter window, so the map's routing shows in the rows
    (root / "models" / "rig_b.yaml").write_text(
        yaml.safe_dump({**base, "detector": {**(base.get("detector") or {}), "window_s": 0.5}})
    )
    model_map = root / "map.yaml"
    model_map.write_text(
        'rig-b-03.csv: models/rig_a.yaml\n"rig-a-*": models/rig_a.yaml\n'
        '"rig-b-*": models/rig_b.yaml\n'
    )
    files = []
    plans = [("test_case_2", kind) for kind in ("full", "gap", "short")] * 6 + [
        ("test_case_1", kind) for kind in ("full", "short")
    ] * 4  # 26 per rig
    for rig in ("a", "b"):
        for i, (scenario, kind) in enumerate(plans[:23]):
            rec = _variant(scenario_recording(scenario, seed=i % 5), kind)
            suffix = ".npz" if i % 7 == 6 else ".csv"
            files.append(str(write_recording(recs / f"rig-{rig}-{i:02d}{suffix}", rec)))
    # malformed: a missing column, a broken npz, the wrong rate, no model for it
    (recs / "rig-a-90.csv").write_text("# fs: 256\nt,v_in\n0,1\n0.00390625,1\n")
    (recs / "rig-b-91.npz").write_bytes(b"PK\x03\x04 this is no zip archive")
    fast = scenario_recording("test_case_2", seed=0)
    write_recording(
        recs / "rig-a-92.csv",
        Recording(
            {k: np.asarray(v)[:600] for k, v in fast.columns.items()}, dict(fast.meta, fs="512")
        ),
    )
    write_recording(recs / "other-93.csv", _variant(fast, "short"))
    files += [
        str(recs / n) for n in ("rig-a-90.csv", "rig-b-91.npz", "rig-a-92.csv", "other-93.csv")
    ]
    assert len(files) == 50
    return sorted(files), model_map


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    root = tmp_path_factory.mktemp("fleet")
    files, model_map = _write_fleet(root)
    return root, files, model_map


def _single_replay_row(file: str, model: str | None, tmp: Path, capsys) -> dict:
    """What one `fdi replay --summary` run says about a file, as a row."""
    if model is None:
        return summary_row(file, None, error="no model: the model map has no pattern for this file")
    out = tmp / (Path(file).name + ".summary.json")
    code = main(["replay", file, "--model", model, "--summary", str(out)])
    captured = capsys.readouterr()
    digest = model_sha256(model)
    if code != 0:
        assert code == 2 and captured.err.startswith("fdi replay: error: ")
        error = captured.err.strip()[len("fdi replay: error: ") :]
        return summary_row(file, model, error=error, model_sha256=digest)
    return summary_row(file, model, json.loads(out.read_text()), model_sha256=digest)


def _read_csv_rows(path: Path) -> list[dict]:
    """The CSV table with its values typed back (empty cell = None)."""
    ints = {
        "samples",
        "alarm_episodes",
        "alarms",
        "alarm_peak_priority",
        "gaps",
        "missing_samples",
        "bad_samples",
    }
    floats = {"fs", "first_detection_t", "isolated_t", "friction_level_final"}
    rows = []
    with open(path, newline="") as fh:
        for raw in csv.DictReader(fh):
            row = {}
            for key, value in raw.items():
                if value == "":
                    row[key] = None
                elif key in ints:
                    row[key] = int(value)
                elif key in floats:
                    row[key] = float(value)
                else:
                    row[key] = value
            rows.append(row)
    return rows


@pytest.mark.slow
def test_fifty_recordings_on_two_workers_equal_fifty_single_replays(fleet, tmp_path, capsys):
    root, files, model_map = fleet
    out = tmp_path / "results.csv"
    assert (
        main(
            [
                "fleet-replay",
                str(root / "recs"),
                "--model-map",
                str(model_map),
                "--workers",
                "2",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    assert "50 recording(s)" in capsys.readouterr().out
    rows = _read_csv_rows(out)
    assert [r["file"] for r in rows] == files
    assert list(rows[0]) == list(ROW_COLUMNS)

    models = ModelMap.load(model_map)
    expected = [_single_replay_row(f, models.model_for(f), tmp_path, capsys) for f in files]
    for row, want in zip(rows, expected):
        assert row == want, row["file"]

    by_name = {Path(r["file"]).name: r for r in rows}
    errors = sorted(name for name, r in by_name.items() if r["error"])
    assert errors == ["other-93.csv", "rig-a-90.csv", "rig-a-92.csv", "rig-b-91.npz"]
    assert "512 Hz" in by_name["rig-a-92.csv"]["error"]
    # the fleet has what it was built with: friction found on rig A, gaps counted, and the
    # map's exact name routes rig-b-03 to rig A's model
    assert by_name["rig-a-00.csv"]["classification"] == "friction"
    assert by_name["rig-a-01.csv"]["gaps"] == 1 and by_name["rig-a-01.csv"]["missing_samples"] == 5
    assert by_name["rig-a-02.csv"]["alarm_episodes"] == 0  # before the fault
    a, b = by_name["rig-a-00.csv"], by_name["rig-b-00.csv"]  # the same recording
    assert b["model"].endswith("rig_b.yaml") and a["model"].endswith("rig_a.yaml")
    assert b["friction_level_final"] != a["friction_level_final"]
    assert by_name["rig-b-03.csv"]["model"].endswith("rig_a.yaml")
    assert (
        by_name["rig-b-03.csv"]["friction_level_final"]
        == by_name["rig-a-03.csv"]["friction_level_final"]
    )


@pytest.mark.slow
def test_local_cluster_listens_on_loopback_only_and_parquet_holds_the_rows(fleet, tmp_path):
    pa = pytest.importorskip("pyarrow.parquet")
    from fdi_daemon.fleet.cluster import dask_client, replay_fleet

    root, files, model_map = fleet
    models = ModelMap.load(model_map)
    jobs = [(f, models.model_for(f)) for f in files[:4]]
    seen = []
    with dask_client(None, 1) as client:
        info = client.scheduler_info()
        addresses = [info["address"], *info["workers"]]
        addresses += [w["nanny"] for w in info["workers"].values() if w.get("nanny")]
        assert addresses and all(a.startswith("tcp://127.0.0.1:") for a in addresses), addresses
        # every listening socket of this process and the worker processes (the scheduler's
        # HTTP endpoint too, which Dask starts even without a dashboard) is on loopback
        me = psutil.Process()
        listening = [
            c.laddr
            for p in (me, *me.children(recursive=True))
            for c in p.net_connections(kind="inet")
            if c.status == psutil.CONN_LISTEN
        ]
        assert len(listening) >= 3 and {a.ip for a in listening} == {"127.0.0.1"}, listening
        rows = replay_fleet(jobs, client, on_row=seen.append)
    assert len(seen) == 4 and rows == [replay_row(f, m) for f, m in jobs]
    from fdi_daemon.fleet.table import write_table

    write_table(tmp_path / "r.parquet", rows)
    assert pa.read_table(tmp_path / "r.parquet").to_pylist() == rows


@pytest.mark.slow
def test_a_local_cluster_leaves_this_processs_environment_as_it_was(monkeypatch):
    """The nannies set OPENBLAS_NUM_THREADS=1 (and more) for their workers in this process;
    left there, every later subprocess of a test worker ran its BLAS on one thread."""
    from fdi_daemon.fleet.cluster import dask_client

    for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MALLOC_TRIM_THRESHOLD_"):
        monkeypatch.delenv(name, raising=False)
    before = dict(os.environ)
    with dask_client(None, 1) as client:
        in_worker = client.run(lambda: os.environ.get("OPENBLAS_NUM_THREADS"))
        assert list(in_worker.values()) == ["1"]  # the workers keep their one BLAS thread
        assert dict(os.environ) == before
    assert dict(os.environ) == before


def test_a_bad_file_is_a_row_never_an_exception(tmp_path):
    bad = tmp_path / "x.csv"
    bad.write_text("not a recording at all\n\x00\x01")
    row = replay_row(str(bad), str(MODEL))
    assert row["error"] and row["samples"] is None and row["file"] == str(bad)
    row = replay_row(str(bad), str(tmp_path / "no-model.yaml"))
    assert "no-model.yaml" in row["error"]
    assert replay_row(str(bad), None)["error"].startswith("no model")


def test_model_map_exact_names_first_then_patterns_in_order(tmp_path):
    (tmp_path / "m").mkdir()
    for name in ("a.yaml", "b.yaml", "c.yaml"):
        (tmp_path / "m" / name).write_text("fs: 256\n")
    path = tmp_path / "map.yaml"
    path.write_text(
        '"rig-1*": m/a.yaml\nrig-12-x.csv: m/b.yaml\n"line/*/rig-2?.csv": m/c.yaml\n'
        '"rig-*": m/c.yaml\n'
    )
    mm = ModelMap.load(path)
    m = tmp_path / "m"
    assert mm.model_for("/data/rig-12-x.csv") == str(m / "b.yaml")  # exact name wins
    assert mm.model_for("/data/rig-13-x.csv") == str(m / "a.yaml")  # first pattern
    assert mm.model_for("/d/line/7/rig-21.csv") == str(m / "c.yaml")
    assert mm.model_for("/d/rig-21.csv") == str(m / "c.yaml")  # via "rig-*"
    assert mm.model_for("/d/other.csv") is None


@pytest.mark.parametrize(
    "text, message",
    [
        ("- a\n- b\n", "mapping"),
        ('"*": missing.yaml\n', "does not exist"),
        ('"*": 3\n', "expected a pattern and a model file"),
        ("", "mapping"),
    ],
)
def test_bad_model_maps_are_config_errors(tmp_path, text, message):
    path = tmp_path / "map.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=message):
        ModelMap.load(path)


def test_finding_recordings(tmp_path):
    for name in ("b.csv", "a.npz", "c.csv.gz", "d.mat", "notes.txt"):
        (tmp_path / name).write_text("")
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "e.csv").write_text("")
    names = [Path(p).name for p in find_recordings(str(tmp_path))]
    assert names == ["a.npz", "b.csv", "c.csv.gz", "d.mat"]
    assert [Path(p).name for p in find_recordings(f"{tmp_path}/**/*.csv")] == ["b.csv", "e.csv"]
    with pytest.raises(UserError, match="no recordings"):
        find_recordings(f"{tmp_path}/*.parquet")
    with pytest.raises(UserError, match="no such"):
        find_recordings(str(tmp_path / "absent"))


@pytest.mark.parametrize(
    "extra, message",
    [
        (["--workers", "2", "--scheduler", "tcp://127.0.0.1:1"], "--workers sizes the local"),
        (["--workers", "0"], "at least 1"),
        (["--out", "r.xlsx"], ".csv or .parquet"),
        (["--out", "RECS/rig-a-00.csv"], "is also an input"),  # the table replaced a recording
    ],
)
def test_user_mistakes_exit_2_with_one_line(fleet, capsys, extra, message):
    root, _, model_map = fleet
    extra = [arg.replace("RECS", str(root / "recs")) for arg in extra]
    code = main(["fleet-replay", str(root / "recs"), "--model-map", str(model_map), *extra])
    err = capsys.readouterr().err
    assert code == 2 and message in err and err.count("\n") == 1, err


@pytest.mark.slow  # waits out the client's 10 s connect timeout
def test_an_unreachable_scheduler_is_one_line(fleet, capsys):
    root, _, _ = fleet
    with socket.socket() as s:  # a port where nothing listens
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    code = main(
        [
            "fleet-replay",
            str(root / "recs" / "rig-a-00.csv"),
            "--model",
            str(MODEL),
            "--scheduler",
            f"tcp://127.0.0.1:{port}",
        ]
    )
    err = capsys.readouterr().err
    assert code == 2 and "cannot reach the Dask scheduler" in err and err.count("\n") == 1, err


def test_parquet_without_pyarrow_names_the_extra(tmp_path, monkeypatch):
    import sys

    from fdi_daemon.fleet.table import write_table

    monkeypatch.setitem(sys.modules, "pyarrow", None)
    with pytest.raises(UserError, match=r"fdi\[fleet\]"):
        write_table(tmp_path / "r.parquet", [summary_row("f.csv", None, error="x")])


@pytest.mark.slow
def test_a_scheduler_address_runs_on_that_cluster(fleet, tmp_path):
    """--scheduler: the work goes to a running cluster (here one on 127.0.0.1)."""
    from dask.distributed import LocalCluster

    root, files, model_map = fleet
    out = tmp_path / "r.csv"
    with LocalCluster(
        n_workers=1, threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address=None
    ) as cluster:
        assert (
            main(
                [
                    "fleet-replay",
                    f"{root}/recs/rig-a-0*.csv",
                    "--model-map",
                    str(model_map),
                    "--scheduler",
                    cluster.scheduler_address,
                    "--out",
                    str(out),
                ]
            )
            == 0
        )
        assert "replay_row" in cluster.scheduler.task_prefixes  # the tasks ran there
    rows = _read_csv_rows(out)
    models = ModelMap.load(model_map)
    wanted = [f for f in files if Path(f).match("rig-a-0*.csv")]
    assert rows == [replay_row(f, models.model_for(f)) for f in wanted]


def test_without_dask_the_error_names_the_extra(monkeypatch):
    import sys

    from fdi_daemon.fleet.cluster import dask_client

    monkeypatch.setitem(sys.modules, "dask.distributed", None)
    with pytest.raises(UserError, match=r"fdi\[fleet\]"):
        with dask_client(None, 1):
            pass


#: a worker that dies on a file, in a process of its own: the test suite's own state
#: (signal handlers, threads, other clusters) must not decide whether the Nanny sees the
#: death, and a cluster that never answers fails the test instead of hanging the suite
_DIES = """
import json, sys
from fdi_daemon.fleet.cluster import dask_client, replay_fleet
from fleet_support import replay_or_die
if __name__ == "__main__":  # the worker processes are spawned: they import this file
    jobs = json.loads(sys.argv[1])
    with dask_client(None, 1) as client:
        print(json.dumps(replay_fleet([tuple(j) for j in jobs], client, task=replay_or_die)))
"""


@pytest.mark.slow
def test_a_worker_that_dies_on_a_file_is_that_files_row(fleet, tmp_path):
    import subprocess
    import sys

    root, files, _ = fleet
    killer = tmp_path / "rig-a-kill.csv"
    killer.write_text(Path(files[1]).read_text())
    jobs = [(files[1], str(MODEL)), (str(killer), str(MODEL)), (files[2], str(MODEL))]
    tests = Path(__file__).resolve().parent
    script = tmp_path / "dies.py"
    script.write_text(_DIES)
    done = subprocess.run(
        [sys.executable, str(script), json.dumps(jobs)],
        cwd=tests,
        env={**__import__("os").environ, "PYTHONPATH": f"{tests}:{tests.parent}"},
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    rows = json.loads(done.stdout.strip().splitlines()[-1])
    assert rows[0] == replay_row(files[1], str(MODEL))
    assert rows[2] == replay_row(files[2], str(MODEL))
    assert rows[1]["file"] == str(killer) and rows[1]["samples"] is None
    error = rows[1]["error"]
    assert error.startswith("worker failed: KilledWorker") and "\n" not in error


def test_ctrl_c_stops_the_fleet_with_one_line_and_no_worker_left(long_fleet, tmp_path):
    """Ctrl-C reaches the whole foreground process group: each Dask worker process printed
    a KeyboardInterrupt traceback while `fdi fleet-replay` itself stopped cleanly.

    Ctrl-C is pressed once, when a worker has a recording open (while the cluster starts,
    the fleet ignores SIGINT so that its workers inherit that). The fleet runs as a
    terminal's foreground job (`start_fdi`): a test run started in the background ignores
    SIGINT, and the fleet inherited that and replayed every file (exit 0).
    """
    import os
    import signal

    proc = _start_fleet(long_fleet, tmp_path)
    seen = wait_for_child_reading(proc, ".parquet")
    ignored = _ignored_signals(proc.pid)
    os.killpg(proc.pid, signal.SIGINT)
    out, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, (proc.returncode, err, out, ignored)
    assert "Traceback" not in err and "KeyboardInterrupt" not in err, err
    assert err.strip().splitlines() == ["fdi fleet-replay: interrupted"]
    assert survivors(seen) == []


def _ignored_signals(pid: int) -> str:
    """The signals process ``pid`` ignores (/proc's SigIgn mask, bit n − 1 for signal n)."""
    with open(f"/proc/{pid}/status") as status:
        return next(line.split()[1] for line in status if line.startswith("SigIgn"))


def test_sigterm_stops_the_fleet_with_one_line_and_no_worker_left(long_fleet, tmp_path):
    """`kill` of `fdi fleet-replay` (its own pid, not the group) stops its workers too."""
    import signal

    proc = _start_fleet(long_fleet, tmp_path)
    seen = wait_for_children(proc, 2, timeout_s=60.0)
    proc.send_signal(signal.SIGTERM)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 128 + signal.SIGTERM, (proc.returncode, err)
    assert err.strip().splitlines() == ["fdi fleet-replay: terminated"]
    assert survivors(seen) == []


@pytest.fixture(scope="module")
def long_fleet(tmp_path_factory):
    """40 links to one 2 h Parquet recording: seconds of replay on 2 workers, so a signal
    sent once a worker reads lands while they work (the fleet's 50 short files can all be
    done before the test's signal arrives)."""
    pytest.importorskip("pyarrow")
    root = tmp_path_factory.mktemp("long_fleet")
    rec = scenario_recording("test_case_2", seed=0)
    n = 2 * 3600 * 256
    reps = -(-n // len(rec))
    cols = {k: np.tile(np.asarray(rec[k]), reps)[:n] for k in ("v_in", "accel")}
    cols.update(seq=np.arange(n), t=np.arange(n) / 256.0)
    first = write_recording(root / "rig-000.parquet", Recording(cols, {"fs": "256"}))
    for k in range(1, 40):
        os.link(first, root / f"rig-{k:03d}.parquet")
    return root


def _start_fleet(root, tmp_path):
    return start_fdi(
        "fleet-replay",
        str(root),
        "--model",
        str(MODEL),
        "--workers",
        "2",
        "--out",
        str(tmp_path / "rows.csv"),
    )


def test_rows_name_the_fdi_version_and_the_models_hash(tmp_path):
    import hashlib

    from fdi_daemon import __version__

    rec = write_recording(tmp_path / "r.csv", scenario_recording("test_case_1", duration_s=2.0))
    row = replay_row(str(rec), str(MODEL))
    assert row["error"] is None and row["fdi_version"] == __version__
    assert row["model_sha256"] == hashlib.sha256(MODEL.read_bytes()).hexdigest()


def test_relative_paths_reach_the_workers_absolute_and_all_failing_exits_1(
    tmp_path, monkeypatch, capsys
):
    """With --scheduler, workers resolve paths in their own folder: the jobs carry absolute
    paths. A run in which every file fails exits 1; piped output keeps whole names."""
    pa = pytest.importorskip("pyarrow.parquet")
    monkeypatch.chdir(tmp_path)
    (tmp_path / "recs").mkdir()
    (tmp_path / "m.yaml").write_bytes(MODEL.read_bytes())
    long_name = "rig-with-a-name-far-longer-than-any-terminal-column-" + "x" * 60 + ".csv"
    rec = scenario_recording("test_case_1", duration_s=2.0)
    write_recording(tmp_path / "recs" / long_name, rec)
    out = "r.parquet"
    code = main(["fleet-replay", "recs", "--model", "m.yaml", "--workers", "1", "--out", out])
    assert code == 0
    table = pa.read_table(out)
    (row,) = table.to_pylist()
    assert row["error"] is None, row["error"]
    assert row["file"] == str(tmp_path / "recs" / long_name)
    assert row["model"] == str(tmp_path / "m.yaml")
    assert table.schema.metadata[b"fdi_version"]
    assert "M samples/s" in capsys.readouterr().out
    assert main(["fleet-replay", "recs", "--model", "m.yaml", "--workers", "1", "--progress"]) == 0
    assert long_name in capsys.readouterr().out  # captured: not a terminal
    (tmp_path / "recs" / "bad.csv").write_text("t,v_in\n0,1\n")
    (tmp_path / "recs" / long_name).write_text("t,v_in\n0,1\n")
    assert main(["fleet-replay", "recs", "--model", "m.yaml", "--workers", "1"]) == 1
    assert "2 recording(s): 0 with alarms, 2 with errors" in capsys.readouterr().out


def test_a_worker_loads_each_version_of_a_model_once(tmp_path):
    """Per-worker caching: the same model file gives the same loaded model to every file;
    a changed file (size or modification time) is loaded again."""
    import os

    from fdi_daemon.fleet.replay_one import cached_model, warm_worker

    model = tmp_path / "m.yaml"
    model.write_bytes(MODEL.read_bytes())
    first = cached_model(str(model))
    assert cached_model(str(model)) is first
    model.write_bytes(MODEL.read_bytes() + b"\n# changed\n")
    os.utime(model, ns=(1, 1))
    again = cached_model(str(model))
    assert again is not first and again.fs == first.fs
    assert warm_worker() is True
