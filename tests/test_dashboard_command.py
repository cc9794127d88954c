"""`fdi dashboard`: arguments, the default socket path, and a one-frame capture."""

from __future__ import annotations

from pathlib import Path

import pytest
from conftest_dashboard import ScriptedStatusServer, make_snapshot

from fdi_daemon.cli import main
from fdi_daemon.commands.dashboard import default_socket_path
from fdi_daemon.service import config as config_module


def test_default_socket_is_the_one_fdi_run_uses(tmp_path, monkeypatch):
    from fdi_daemon.service.config import load_config

    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("STATE_DIRECTORY", raising=False)
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path / "xdg"))
    config = load_config(None)
    expected = config.output_path(config.sinks["status_socket"])
    assert Path(default_socket_path(None)) == expected
    assert expected == tmp_path / "xdg" / "fdi" / "status.sock"
    monkeypatch.setenv("STATE_DIRECTORY", str(tmp_path / "state"))
    assert Path(default_socket_path(None)) == tmp_path / "state" / "status.sock"


def test_socket_from_a_config_and_a_disabled_socket(tmp_path, capsys, monkeypatch):
    rig = tmp_path / "rig.yaml"
    rig.write_text(
        "link: {kind: sim}\nmodel: {path: m.yaml}\n"
        f"service: {{state_dir: {tmp_path}}}\nsinks: {{status_socket: s.sock}}\n"
    )
    assert Path(default_socket_path(str(rig))) == tmp_path / "s.sock"
    config = config_module.load_config(rig)
    config.sinks["status_socket"] = None  # what `status_socket: null` means
    monkeypatch.setattr(config_module, "load_config", lambda path=None: config)
    assert main(["dashboard", "--config", str(rig)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "sinks.status_socket is null" in err


def test_once_prints_a_frame_of_the_requested_size(tmp_path, capsys):
    sock = tmp_path / "status.sock"
    with ScriptedStatusServer(sock, [make_snapshot("other_fault")]):
        assert (
            main(["dashboard", "--connect", str(sock), "--once", "--width", "90", "--height", "26"])
            == 0
        )
    lines = capsys.readouterr().out.rstrip("\n").split("\n")
    assert len(lines) == 26 and max(len(line) for line in lines) <= 90
    assert "OTHER FAULT" in lines[0]


def test_once_without_daemon_is_one_line_naming_the_socket(tmp_path, capsys):
    sock = tmp_path / "none.sock"
    assert main(["dashboard", "--connect", str(sock), "--once"]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.count("\n") == 1
    assert f"no daemon answers on the status socket {sock} (" in err


@pytest.mark.parametrize("rate", ["0.5", "fast", "100"])
def test_bad_refresh_rate_is_a_usage_error(rate, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["dashboard", "--refresh-hz", rate])
    assert exc.value.code == 2
    assert "--refresh-hz" in capsys.readouterr().err


def test_replay_dashboard_needs_realtime(tmp_path, capsys):
    assert (
        main(
            [
                "replay",
                str(tmp_path / "rec.csv"),
                "--model",
                str(tmp_path / "m.yaml"),
                "--dashboard",
            ]
        )
        == 2
    )
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--dashboard needs --realtime" in err
