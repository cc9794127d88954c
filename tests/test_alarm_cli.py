"""`fdi alarm list|ack|shelve|unshelve` against a running `fdi run` over its real status
socket: the answer on the terminal, who and why in the event log, refusals as one line."""

from __future__ import annotations

import argparse
import json
import signal
import subprocess
import sys
from datetime import datetime
from pathlib import Path

import pytest
from alarm_state_support import seed_open_alarm
from process_support import start_fdi
from test_service_state_lock import wait_for_line

from fdi_daemon.commands.alarm import duration_s
from fdi_daemon.service.config import default_config_path

DEFAULT = default_config_path()


def fdi_alarm(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "fdi_daemon", "alarm", *args],
        capture_output=True,
        text=True,
        timeout=60,
    )


def rig_config(tmp_path: Path, allow: bool) -> Path:
    """The embedded default without its fault, with remote requests allowed or not."""
    text = DEFAULT.read_text().replace(
        "  faults:\n    - {at_s: 20.0, bearing_supply: 0.35}\n", "  faults: []\n"
    )
    text = text.replace(
        "path: model_sim_rig.yaml", f"path: {DEFAULT.parent / 'model_sim_rig.yaml'}"
    )
    text += f"alarms: {{allow_remote_acknowledge: {'true' if allow else 'false'}}}\n"
    path = tmp_path / "rig.yaml"
    path.write_text(text)
    return path


@pytest.mark.parametrize(
    "text, seconds",
    [("90", 90.0), ("90s", 90.0), ("30m", 1800.0), ("8h", 28800.0), ("1d", 86400.0)],
)
def test_durations(text, seconds):
    assert duration_s(text) == seconds


@pytest.mark.parametrize("text", ["", "0", "-5m", "5x", "m"])
def test_bad_durations(text):
    with pytest.raises(argparse.ArgumentTypeError):
        duration_s(text)


def test_ack_shelve_unshelve_on_a_running_daemon(tmp_path):
    state = tmp_path / "state"
    seed_open_alarm(state)
    daemon = start_fdi(
        "run", "--config", str(rig_config(tmp_path, True)), "--state-dir", str(state)
    )
    where = ["--state-dir", str(state)]
    try:
        wait_for_line(daemon, "  status  ")
        listed = fdi_alarm("list", *where)
        assert listed.returncode == 0, listed.stderr
        assert listed.stdout.startswith("alarm #1: unacknowledged, P1"), listed.stdout
        ack = fdi_alarm("ack", *where, "--by", "alice", "--reason", "bearing supply checked")
        assert ack.returncode == 0, ack.stderr
        assert ack.stdout.startswith("acknowledged by alice; alarm #1: acknowledged"), ack.stdout
        again = fdi_alarm("ack", *where, "--by", "alice")
        assert again.returncode == 2
        assert again.stderr.strip().splitlines() == [
            "fdi alarm: error: ack refused: nothing to acknowledge (alarm state acknowledged)"
        ]
        shelve = fdi_alarm("shelve", *where, "--for", "30m", "--by", "bob", "--reason", "repair")
        assert shelve.returncode == 0, shelve.stderr
        assert "shelved until" in shelve.stdout
        assert fdi_alarm("unshelve", *where, "--by", "bob").returncode == 0
        no_duration = fdi_alarm("shelve", *where)
        assert no_duration.returncode == 2 and "--for DURATION" in no_duration.stderr
    finally:
        daemon.send_signal(signal.SIGTERM)
        out, err = daemon.communicate(timeout=60)
    assert daemon.returncode == 0, err[-2000:]
    events = [json.loads(line) for line in (state / "events.jsonl").read_text().splitlines()]
    by_kind = {e["kind"]: e for e in events if e["kind"].startswith("alarm_")}
    assert by_kind["alarm_acknowledged"]["by"] == "alice (status socket)"
    assert by_kind["alarm_acknowledged"]["why"] == "bearing supply checked"
    shelved = by_kind["alarm_shelved"]
    assert shelved["by"] == "bob (status socket)" and shelved["why"] == "repair"
    shelved_at = datetime.fromisoformat(shelved["time"]).timestamp()  # RFC 3339, ms
    assert abs(shelved["until"] - shelved_at - 1800.0) < 2e-3
    assert by_kind["alarm_unshelved"]["by"] == "bob (status socket)"
    assert "why" not in by_kind["alarm_unshelved"]


def test_refusals_are_one_line(tmp_path):
    state = tmp_path / "state"
    seed_open_alarm(state)
    nobody = fdi_alarm("ack", "--state-dir", str(state))
    assert nobody.returncode == 2
    assert nobody.stderr.strip().splitlines() == [
        f"fdi alarm: error: no daemon answers on the status socket {state / 'status.sock'} "
        f"(no socket at {state / 'status.sock'}); is `fdi run` running?"
    ]
    daemon = start_fdi(
        "run", "--config", str(rig_config(tmp_path, False)), "--state-dir", str(state)
    )
    try:
        wait_for_line(daemon, "  status  ")
        refused = fdi_alarm("ack", "--state-dir", str(state))
    finally:
        daemon.send_signal(signal.SIGTERM)
        daemon.communicate(timeout=60)
    assert refused.returncode == 2
    assert "alarms.allow_remote_acknowledge: false" in refused.stderr
    assert len(refused.stderr.strip().splitlines()) == 1
