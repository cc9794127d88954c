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

pytestmark = [
    pytest.mark.usefixtures("compiled_kernel_cache"),
    pytest.mark.skipif(TMUX is None, reason="tmux is not installed"),
]


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


def test_alarm_keys_in_tmux_acknowledge_and_shelve_on_the_daemons_socket(sock_path):
    """The footer's keys on a real status socket server with the daemon's alarm keeper: who
    and why reach the event the daemon logs, the shelving its duration."""
    import threading

    from fdi_daemon.alarms.lifecycle import AlarmSettings
    from fdi_daemon.service.alarm_keeper import AlarmKeeper
    from fdi_daemon.service.sinks import StatusBoard, StatusSocketServer

    keeper = AlarmKeeper(AlarmSettings(), "m", allow_remote=True)
    keeper.detector_event({"t": 1.0, "kind": "fault_detected"})
    board, stop = StatusBoard(), threading.Event()

    def publish() -> None:  # a fresh snapshot, as the daemon's loop keeps publishing
        while not stop.is_set():
            snapshot = make_snapshot("friction_isolated", wall_time=time.time())
            board.publish({**snapshot, "alarm": keeper.summary()})
            stop.wait(0.1)

    publisher = threading.Thread(target=publish, daemon=True)
    publisher.start()
    server = StatusSocketServer(sock_path, board, requests=keeper.handle)
    screen = TmuxScreen([*dashboard_command(sock_path), "--by", "tester"])
    try:
        text = screen.wait_for("a acknowledge  s shelve  u unshelve  q quit")
        assert "ALARM P1 unacknowledged" in text
        screen.keys("a")
        screen.wait_for("acknowledge the alarm, as tester. Why?")
        screen.keys("-l", "pressure checked")
        screen.keys("Enter")
        screen.wait_for("acknowledged by tester; alarm #1: acknowledged")
        screen.wait_for("alarm P1 acknowledged")  # the trend panel's border, next snapshot
        screen.keys("s")
        screen.wait_for("shelve for how long? [30m]")
        screen.keys("-l", "15m")
        screen.keys("Enter")
        screen.keys("-l", "valve swap")
        screen.keys("Enter")
        screen.wait_for("shelved by tester")
        screen.wait_for("shelved until")
        screen.keys("q")
        assert screen.wait_until_dead()
    finally:
        screen.close()
        server.close()
        stop.set()
        publisher.join(2.0)
    acknowledged, shelved = keeper.take_pending()
    assert (acknowledged["kind"], acknowledged["by"], acknowledged["why"]) == (
        "alarm_acknowledged",
        "tester (status socket)",
        "pressure checked",
    )
    assert (shelved["kind"], shelved["why"]) == ("alarm_shelved", "valve swap")
    assert shelved["until"] - shelved["time"] == pytest.approx(900.0)
