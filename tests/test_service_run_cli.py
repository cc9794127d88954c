"""`fdi run` on the command line: user mistakes give one line and exit code 2."""

import subprocess
import sys

import pytest


def fdi(*args, cwd=None):
    return subprocess.run(
        [sys.executable, "-m", "fdi_daemon", *args],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=cwd,
    )


@pytest.mark.parametrize(
    "text, expected",
    [
        (
            "link: {kind: modbus-tcp}\nmodel: {path: m.yaml}\nsinks: {stdot: true}\n",
            "sinks.stdot: unknown key",
        ),
        ("link: {kind: modbus-tcp, prot: 5}\nmodel: {path: m.yaml}\n", "link.prot: unknown key"),
        ("link: {kind: modbus-tcp}\nmodel: {path: missing-model.yaml}\n", "no such model file"),
        ("link: {kind: modbus-tcp}\n", "model.path is required"),
    ],
)
def test_config_mistakes_are_one_line_and_exit_2(tmp_path, text, expected):
    config = tmp_path / "rig.yaml"
    config.write_text(text)
    result = fdi("run", "--config", str(config), cwd=tmp_path)
    assert result.returncode == 2, result.stderr
    assert expected in result.stderr
    assert "Traceback" not in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1, result.stderr


def test_missing_config_and_bad_duration(tmp_path):
    result = fdi("run", "--config", str(tmp_path / "nope.yaml"))
    assert result.returncode == 2 and "no such config file" in result.stderr
    result = fdi("run", "--duration", "-1")
    assert result.returncode == 2 and "--duration" in result.stderr


def test_a_state_dir_that_is_a_file_is_one_line_naming_it(tmp_path):
    """It logged a state-file ERROR, then 'cannot open an output: [Errno 17] File exists',
    blaming the config."""
    config = tmp_path / "rig.yaml"
    config.write_text("link: {kind: replay, path: missing.csv}\nmodel: {path: m.yaml}\n")
    (tmp_path / "state").write_text("a file")
    result = fdi("run", "--config", str(config), "--state-dir", str(tmp_path / "state"))
    assert result.returncode == 2, result.stderr
    assert result.stderr.strip().splitlines() == [
        f"fdi run: error: state directory {tmp_path / 'state'} (--state-dir or "
        f"service.state_dir) is a file, not a directory"
    ]
    assert (tmp_path / "state").read_text() == "a file"


@pytest.mark.parametrize("state_dir_option", [False, True])
def test_outputs_go_to_the_xdg_state_dir_or_state_dir_never_the_working_directory(
    tmp_path, monkeypatch, state_dir_option
):
    monkeypatch.delenv("STATE_DIRECTORY", raising=False)
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path / "xdg"))
    work = tmp_path / "repo"
    work.mkdir()
    expected = tmp_path / "mine" if state_dir_option else tmp_path / "xdg" / "fdi"
    extra = ["--state-dir", str(expected)] if state_dir_option else []
    result = fdi("run", "--duration", "2", *extra, cwd=work)
    assert result.returncode == 0, result.stderr[-2000:]
    assert list(work.iterdir()) == []  # nothing written where the user happened to be
    assert f"  state   {expected}/" in result.stdout  # says where it went
    assert (expected / "events.jsonl").exists() and (expected / "recordings").is_dir()


def test_a_replayed_recording_at_another_rate_than_the_model_is_one_line(tmp_path):
    """The replay link ran a 128 Hz file through the 256 Hz model as if it were 256 Hz."""
    from pathlib import Path

    import numpy as np

    from fdi_daemon.io.recordings import Recording, write_recording

    model = Path(__file__).resolve().parents[1] / "configs" / "model_sim_rig.yaml"
    n = 512
    rec = write_recording(
        tmp_path / "slow.csv",
        Recording(
            {"t": np.arange(n) / 128.0, "v_in": np.zeros(n), "accel": np.zeros(n)}, {"fs": "128"}
        ),
    )
    config = tmp_path / "rig.yaml"
    config.write_text(
        f"link: {{kind: replay, path: {rec}, realtime: false}}\nmodel: {{path: {model}}}\n"
    )
    result = fdi("run", "--config", str(config), "--state-dir", str(tmp_path / "state"))
    assert result.returncode == 2, result.stderr[-2000:]
    assert result.stderr.strip().splitlines()[-1] == (
        f"fdi run: error: {rec}: sampled at 128 Hz but the model is for 256 Hz"
    )
    assert "Traceback" not in result.stderr
