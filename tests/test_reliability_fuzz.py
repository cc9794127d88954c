"""Bad files and configs, fuzzed (hypothesis, derandomized, bounded examples).

Recordings (CSV text, npz), rig configs, model files and serial byte streams are generated
or mutated at random and handed to the CLI exactly as a user would (`fdi_daemon.cli.main`),
plus a few as a subprocess. The contract (DESIGN.md, TEAM.md): a bad input is one clear
line on stderr and exit code 2; a good one exits 0; never a traceback (any exception
escaping `main` fails the test), never a hang (an alarm signal bounds every call).
"""

from __future__ import annotations

import contextlib
import copy
import io
import json
import logging
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from reliability_support import fault_free, model_path
from test_io_serial_frames import feed_in_cuts

from fdi_daemon.cli import main
from fdi_daemon.io.recordings import write_recording
from fdi_daemon.io.serial_frames import Frame, FrameDecoder, encode_frame

CALL_TIMEOUT_S = 60

FUZZ = settings(
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[
        HealthCheck.function_scoped_fixture,
        HealthCheck.too_slow,
        HealthCheck.data_too_large,
    ],
)


def fuzz(examples: int) -> settings:
    return settings(FUZZ, max_examples=examples)


class Hang(Exception):
    pass


def _on_alarm(signum, frame):
    raise Hang(f"a CLI call took more than {CALL_TIMEOUT_S} s")


def run_cli(argv: list[str]) -> tuple[int, str, str]:
    """``main(argv)`` with stdout/stderr captured; (exit code, stdout, stderr).

    Exceptions are not caught: one escaping ``main`` is a traceback the user would see.
    """
    out, err = io.StringIO(), io.StringIO()
    root = logging.getLogger()
    handlers, level = list(root.handlers), root.level  # `fdi run` sets up logging
    previous = signal.signal(signal.SIGALRM, _on_alarm)
    signal.alarm(CALL_TIMEOUT_S)
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                code = main(argv)
            except SystemExit as exc:  # argparse's own usage errors
                code = exc.code if isinstance(exc.code, int) else 1
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)
        root.handlers[:] = handlers
        root.setLevel(level)
    return code, out.getvalue(), err.getvalue()


def check_clear(code: int, err: str, command: str) -> None:
    """Exit 0, or exit 2 with one ``fdi <command>: error: ...`` line."""
    assert code in (0, 2), (code, err)
    assert "Traceback" not in err
    if code == 2:
        lines = [line for line in err.splitlines() if line.strip()]
        errors = [line for line in lines if line.startswith(f"fdi {command}: error: ")]
        assert len(errors) == 1 and len(errors[0]) < 2000, err


# ----------------------------------------------------------------------------- recordings

NUMBER_TOKENS = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True, width=64).map(repr),
    st.integers(-(10**30), 10**30).map(str),
    st.sampled_from(
        [
            "",
            " ",
            "nan",
            "inf",
            "-inf",
            "1e999",
            "abc",
            "0x10",
            "1,2",
            "--1",
            "\t",
            "1.5.2",
            "NaN",
            "+3",
            "١٢",
        ]
    ),
)
COLUMN_NAMES = st.sampled_from(
    ["t", "v_in", "accel", "position", "seq", "x", "", "t ", "T", "accel", "ünïcode"]
)


@st.composite
def csv_texts(draw) -> str:
    lines = []
    for _ in range(draw(st.integers(0, 3))):
        key = draw(st.sampled_from(["fs", "seed", "", "fs ", "x"]))
        value = draw(st.one_of(NUMBER_TOKENS, st.text(max_size=8)))
        lines.append(f"# {key}: {value}")
    header = draw(st.lists(COLUMN_NAMES, min_size=0, max_size=6))
    if draw(st.booleans()):
        header = ["t", "v_in", "accel"] + header
    lines.append(",".join(header))
    ncol = max(1, len(header))
    regular = draw(st.booleans())
    for i in range(draw(st.integers(0, 40))):
        if regular and draw(st.integers(0, 9)) > 0:
            row = [repr(i / 256.0)] + [
                repr(float(draw(st.integers(-5, 5)))) for _ in range(ncol - 1)
            ]
            if "seq" in header:
                row[header.index("seq")] = str(i)
        else:
            row = draw(st.lists(NUMBER_TOKENS, min_size=0, max_size=ncol + 2))
        lines.append(",".join(row))
    if draw(st.booleans()):
        lines.insert(draw(st.integers(0, len(lines))), draw(st.text(max_size=30)))
    return "\n".join(lines)


@pytest.fixture(scope="module")
def model_file() -> str:
    return str(model_path())


@fuzz(60)
@given(text=csv_texts())
def test_fuzzed_csv_recordings(tmp_path, model_file, text):
    path = tmp_path / "rec.csv"
    path.write_text(text, encoding="utf-8")
    code, _, err = run_cli(["replay", str(path), "--model", model_file])
    check_clear(code, err, "replay")


@fuzz(40)
@given(
    data=st.binary(max_size=400),
    suffix=st.sampled_from([".csv", ".csv.gz", ".npz", ".mat", ".txt"]),
)
def test_random_bytes_as_a_recording(tmp_path, model_file, data, suffix):
    path = tmp_path / f"rec{suffix}"
    path.write_bytes(data)
    code, _, err = run_cli(["replay", str(path), "--model", model_file])
    check_clear(code, err, "replay")
    assert code == 2 or suffix in (".csv", ".csv.gz")  # random bytes are no npz/mat


def _write_npz(path: Path, meta: str | None = None, **columns) -> None:
    base = {"t": np.arange(5) / 256.0, "v_in": np.zeros(5), "accel": np.zeros(5)}
    base.update(columns)
    if meta is not None:
        base["__meta__"] = np.array(meta)
    np.savez(path, **base)


#: files that once escaped `read_recording` as a traceback (found by this fuzzing, fixed in
#: fdi_daemon/io/recordings.py): kept as regression cases
KNOWN_BAD_RECORDINGS = {
    # name: (writer, what used to escape)
    "npz-not-a-zip": (
        lambda p: p.write_bytes(b"PK\x03\x04 not really a zip"),
        "zipfile.BadZipFile from np.load (_read_npz)",
    ),
    "mat-empty": (lambda p: p.write_bytes(b""), "scipy MatReadError from loadmat (_read_mat)"),
    "mat-zeros": (
        lambda p: p.write_bytes(bytes(200)),
        "scipy MatReadError from loadmat (_read_mat)",
    ),
    "npz-meta-list": (
        lambda p: _write_npz(p, "[1, 2]"),
        "AttributeError: meta.items() on a JSON list (_read_npz)",
    ),
    "npz-meta-null": (
        lambda p: _write_npz(p, "null"),
        "AttributeError: meta.items() on JSON null (_read_npz)",
    ),
    "csv-seq-1e300": (
        lambda p: p.write_text(
            "t,v_in,accel,seq\n0,0,0,0\n0.00390625,0,0,1e300\n0.0078125,0,0,2\n"
        ),
        "RuntimeWarning 'invalid value encountered in cast' in _as_counter: "
        "the file is accepted with a garbage seq",
    ),
}


@pytest.mark.parametrize("name", sorted(KNOWN_BAD_RECORDINGS))
def test_known_bad_recordings_are_clear_errors(tmp_path, model_file, name):
    writer, _ = KNOWN_BAD_RECORDINGS[name]
    suffix = ".csv" if name.startswith("csv") else "." + name.split("-")[0]
    path = tmp_path / f"rec{suffix}"
    writer(path)
    code, _, err = run_cli(["replay", str(path), "--model", model_file])
    assert code == 2
    check_clear(code, err, "replay")


ARRAYS = st.one_of(
    st.lists(st.floats(allow_nan=True, allow_infinity=True), max_size=30).map(np.array),
    st.lists(st.integers(-(2**62), 2**62), max_size=30).map(lambda v: np.array(v, np.int64)),
    st.lists(st.booleans(), max_size=5).map(np.array),
    st.text(max_size=10).map(np.array),
    st.floats(allow_nan=True).map(np.array),
    st.integers(1, 5).map(lambda n: np.zeros((n, 2))),
    st.just(np.arange(40) / 256.0),
    st.just(np.arange(40)),
)
META = st.one_of(
    st.dictionaries(
        st.sampled_from(["fs", "seed", "x"]),
        st.one_of(st.text(max_size=6), st.floats(allow_nan=False), st.integers()),
    ).map(json.dumps),
    st.sampled_from(
        [
            "[1, 2]",
            "null",
            "3",
            '"fs"',
            "{",
            "",
            '{"fs": "abc"}',
            '{"fs": -256}',
            '{"fs": 256}',
            '{"fs": 0}',
        ]
    ),
)


@fuzz(60)
@given(
    arrays=st.dictionaries(
        st.sampled_from(["t", "v_in", "accel", "seq", "position", "other"]), ARRAYS, max_size=6
    ),
    meta=st.none() | META,
)
def test_fuzzed_npz_recordings(tmp_path, model_file, arrays, meta):
    path = tmp_path / "rec.npz"
    payload = dict(arrays)
    if meta is not None:
        payload["__meta__"] = np.array(meta)
    np.savez(path, **payload)
    code, _, err = run_cli(["replay", str(path), "--model", model_file])
    check_clear(code, err, "replay")


# ----------------------------------------------------------------------------- model files

VALUES = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-10, 10**6),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=6),
    st.lists(st.floats(-3, 3), max_size=6),
    st.lists(st.one_of(st.floats(), st.text(max_size=2)), max_size=4),
    st.dictionaries(st.text(max_size=4), st.integers(), max_size=2),
)


def _paths(node, prefix=()):
    """Every key path of a nested mapping/list."""
    out = []
    if isinstance(node, dict):
        for k, v in node.items():
            out.append(prefix + (k,))
            out.extend(_paths(v, prefix + (k,)))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            out.append(prefix + (i,))
            out.extend(_paths(v, prefix + (i,)))
    return out


@st.composite
def mutated(draw, base: dict, extra_keys: list[str], values=VALUES):
    """``base`` with 1-3 mutations: a value replaced, a key deleted, or a key added."""
    doc = copy.deepcopy(base)
    for _ in range(draw(st.integers(1, 3))):
        paths = _paths(doc)
        if not paths:
            break
        path = draw(st.sampled_from(paths))
        parent = doc
        for key in path[:-1]:
            parent = parent[key]
        action = draw(st.sampled_from(["replace", "replace", "delete", "add"]))
        if action == "replace":
            parent[path[-1]] = draw(values)
        elif action == "delete":
            del parent[path[-1]]
        elif isinstance(parent, dict):
            parent[draw(st.sampled_from(extra_keys))] = draw(values)
        else:
            parent.append(draw(values))
    return doc


def _model_dict() -> dict:
    return yaml.safe_load(Path(model_path()).read_text())


@pytest.fixture(scope="module")
def short_recording(tmp_path_factory) -> str:
    path = tmp_path_factory.mktemp("fuzz") / "short.npz"
    write_recording(path, fault_free(4.0))
    return str(path)


UNSTABLE = {"plant": {"a": [1.0, -2.5, 1.6]}, "fault_filter": {"f": [1.0, -1.0]}}


@fuzz(50)
@given(data=st.data())
def test_fuzzed_model_files(tmp_path, short_recording, data):
    base = _model_dict()
    base.setdefault("detector", {"window_s": 1.0, "threshold": 20.0})
    doc = data.draw(
        mutated(
            base,
            [
                "fs",
                "plant",
                "b",
                "a",
                "nk",
                "window_s",
                "method",
                "accel_limit_mps2",
                "bogus",
                "highpass_hz",
            ],
        )
    )
    if data.draw(st.booleans()):  # also try unstable filters now and then
        section = data.draw(st.sampled_from(sorted(UNSTABLE)))
        if isinstance(doc.get(section), dict):
            doc[section].update(UNSTABLE[section])
    path = tmp_path / "model.yaml"
    path.write_text(yaml.safe_dump(doc))
    code, _, err = run_cli(["replay", short_recording, "--model", str(path)])
    check_clear(code, err, "replay")


@fuzz(20)
@given(text=st.text(max_size=200))
def test_random_text_as_a_model_file(tmp_path, short_recording, text):
    path = tmp_path / "model.yaml"
    path.write_text(text, encoding="utf-8")
    code, _, err = run_cli(["replay", short_recording, "--model", str(path)])
    check_clear(code, err, "replay")
    assert code == 2


# ----------------------------------------------------------------------------- rig configs

SAFE_TEXT = st.text("abcxyz019_-.", min_size=0, max_size=8)  # no '/': outputs stay in tmp


@fuzz(30)
@given(data=st.data())
def test_fuzzed_rig_configs(tmp_path, short_recording, data):
    """``fdi run --config`` on mutated configs (a replay link, flat out: a valid config
    finishes the 4 s file quickly; --duration bounds everything else)."""
    base = {
        "link": {"kind": "replay", "path": short_recording, "realtime": False},
        "model": {"path": str(model_path())},
        "sinks": {
            "event_log": "events.jsonl",
            "stdout": False,
            "status_socket": None,
            "modbus_status": {"enabled": False, "port": 0},
        },
        "recorder": {"enabled": False, "dir": "rec", "rotate_seconds": 600},
        "service": {"state_dir": str(tmp_path / "state"), "deadline_s": 0.05},
    }
    doc = data.draw(
        mutated(
            base,
            ["kind", "bogus", "port", "enabled", "fs", "realtime"],
            st.one_of(VALUES, SAFE_TEXT),
        )
    )
    for section in ("service",):  # outputs never leave tmp_path
        if isinstance(doc.get(section), dict) and "state_dir" in doc[section]:
            doc[section]["state_dir"] = str(tmp_path / "state")
    path = tmp_path / "rig.yaml"
    path.write_text(yaml.safe_dump(doc))
    with contextlib.chdir(tmp_path):
        code, _, err = run_cli(["run", "--config", str(path), "--duration", "2"])
    check_clear(code, err, "run")


# ----------------------------------------------------------------------------- serial frames


@fuzz(80)
@given(
    garbage=st.lists(st.binary(max_size=60), min_size=1, max_size=12),
    cuts=st.lists(st.integers(1, 50), min_size=1, max_size=20),
)
def test_frames_survive_random_bytes_between_them(garbage, cuts):
    """Every frame sent whole is decoded, in order, whatever bytes lie between frames and
    however the stream is cut; no frame is invented."""
    frames = [
        encode_frame(Frame(1000 + i, 0.25 * i, -0.5 * i, 0.001 * i)) for i in range(len(garbage))
    ]
    wire = b"".join(g + f for g, f in zip(garbage, frames)) + encode_frame(Frame(9999, 0, 0))
    decoder = FrameDecoder()
    got = feed_in_cuts(decoder, wire, cuts)
    seqs = [s.seq for s in got]
    assert seqs[: len(frames)] == list(range(1000, 1000 + len(frames)))
    assert len(seqs) == len(frames) + 1 and got[-1].seq == 9999
    counters = decoder.counters()
    assert counters["frames"] == len(frames) + 1
    assert counters["bytes_dropped"] == sum(map(len, garbage))


# ----------------------------------------------------------------------------- subprocess


def _bad_inputs(tmp_path: Path) -> list[tuple[list[str], str]]:
    model = str(model_path())
    csv = tmp_path / "bad.csv"
    csv.write_text("# fs: 256\nt,v_in,accel\n0,1,2\n0.00390625,abc,3\n")
    npz = tmp_path / "bad.npz"
    npz.write_bytes(b"PK\x03\x04 not really a zip")
    bad_model = tmp_path / "bad_model.yaml"
    bad_model.write_text("fs: 256\nplant: {b: [0, 1], a: [2, 1]}\n")
    good = tmp_path / "good.npz"
    write_recording(good, fault_free(4.0))
    config = tmp_path / "rig.yaml"
    config.write_text(f"link: {{kind: serial}}\nmodel: {{path: {model}}}\n")
    return [
        (["replay", str(csv), "--model", model], "replay"),
        (["replay", str(npz), "--model", model], "replay"),
        (["replay", str(good), "--model", str(bad_model)], "replay"),
        (["run", "--config", str(config)], "run"),
        (["identify", str(csv), "-o", str(tmp_path / "m.yaml")], "identify"),
    ]


def test_bad_inputs_as_a_subprocess_are_one_line_and_exit_2(tmp_path):
    for argv, command in _bad_inputs(tmp_path):
        proc = subprocess.run(
            [sys.executable, "-m", "fdi_daemon", *argv],
            capture_output=True,
            text=True,
            timeout=120,
            cwd=tmp_path,
        )
        assert proc.returncode == 2, (argv, proc.stderr)
        assert "Traceback" not in proc.stderr
        lines = [line for line in proc.stderr.splitlines() if line.strip()]
        assert len(lines) == 1 and lines[0].startswith(f"fdi {command}: error: "), proc.stderr
