"""`fdi dashboard` in a real terminal (tmux), read back from the screen.

The daemon side here is a scripted status-socket server speaking the daemon's protocol: it
is absent at first, then walks starting -> calibrating -> monitoring -> fault detected ->
friction isolated, goes away and comes back. The daemon-backed run is in
test_dashboard_e2e.py.
"""

from __future__ import annotations

import re
import sys
import time
from pathlib import Path

import pytest
from conftest_dashboard import TMUX, ScriptedStatusServer, TmuxScreen, make_snapshot

pytestmark = pytest.mark.skipif(TMUX is None, reason="tmux is not installed")


def dashboard_command(socket_path) -> list[str]:
    return [sys.executable, "-m", "fdi_daemon", "dashboard", "--connect", str(socket_path)]


@pytest.fixture
def sock_path(tmp_path):
    return tmp_path / "status.sock"


def scripted_run() -> list[dict]:
    states = (
        ["starting"] * 3
        + ["calibrating"] * 8
        + ["monitoring"] * 8
        + ["fault_detected"] * 8
        + ["friction_isolated"]
    )
    theta = {
        "starting": (float("nan"),) * 2,
        "calibrating": (float("nan"),) * 2,
        "monitoring": (0.01, -0.02),
        "fault_detected": (0.4, 0.9),
        "friction_isolated": (0.97, 2.35),
    }
    snapshots = []
    for i, state in enumerate(states):
        snap = make_snapshot(
            state,
            theta=theta[state],
            t_now=30.0 + 0.1 * i,
            n_alarms=0 if state in ("starting", "calibrating", "monitoring") else 2,
        )
        snapshots.append(snap)
    return snapshots


def test_dashboard_in_tmux_follows_daemon_to_the_fault_and_quits_on_q(sock_path):
    screen = TmuxScreen(dashboard_command(sock_path))
    try:
        screen.wait_for("daemon not reachable, retrying")
        with ScriptedStatusServer(sock_path, scripted_run()):
            screen.wait_for("CALIBRATING")
            text = screen.wait_for("FRICTION ISOLATED")
            assert re.search(r"θ1 Coulomb +\+0\.97 ", text)
            assert re.search(r"θ2 viscous +\+2\.35 ", text)
            assert "friction_isolated" in text and "fault_detected" in text
            assert "not reachable" not in text
        text = screen.wait_for("daemon not reachable, retrying")
        assert "FRICTION ISOLATED" in text and "last known" in text
        with ScriptedStatusServer(sock_path, [make_snapshot("monitoring")]):
            text = screen.wait_for("MONITORING")
            deadline = time.monotonic() + 10
            while "not reachable" in text and time.monotonic() < deadline:
                text = screen.text()
            assert "not reachable" not in text
            screen.keys("q")
            assert screen.wait_until_dead()
    finally:
        screen.close()


@pytest.mark.slow
def test_realtime_replay_with_dashboard_in_tmux(tmp_path):
    """`fdi replay --realtime --dashboard`: the in-process view of a paced replay."""
    from fdi_daemon.io.recordings import write_recording
    from fdi_daemon.service.config import load_config
    from hil_sim.scenarios import load_scenario, simulate

    model = load_config().model_path
    if not model.exists():
        pytest.skip(f"{model.name} is not in fdi_daemon/data")
    scenario = load_scenario(
        Path(__file__).parents[1] / "configs" / "scenarios" / "test_case_2.yaml"
    )
    write_recording(tmp_path / "rec.csv", simulate(scenario, seed=0))
    screen = TmuxScreen(
        [
            sys.executable,
            "-m",
            "fdi_daemon",
            "replay",
            "rec.csv",
            "--model",
            str(model),
            "--realtime",
            "--dashboard",
        ],
        100,
        30,
        cwd=tmp_path,
    )
    try:
        text = screen.wait_for("finished, press q to quit", timeout_s=40.0)
        assert "FRICTION ISOLATED" in text and "replay" in text
        assert re.search(r"samples +(\d+)/\1 ", text)  # every sample replayed
        screen.keys("q")
        assert screen.wait_until_dead()
        assert "classification friction" in screen.text(history_lines=50)
    finally:
        screen.close()
