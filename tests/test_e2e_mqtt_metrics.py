"""End to end: the embedded `fdi run` (simulated rig, friction fault at 20 s) with MQTT and
Prometheus metrics on, against a real mosquitto that the test restarts during the alarm.

A subscriber with a persistent session sees the calibration event, then the broker goes
away; the fault is detected and isolated while it is away (the alarms wait in the outbox
file); once the broker is back they arrive, in order. A new subscriber sees the retained
status with the friction level; a metrics scrape parses and shows the alarm; SIGKILL leaves
the last will ("offline", retained). Wall-clock timeouts are generous; nothing asserts on
speed.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
import urllib.request

import pytest
import yaml
from mqtt_support import Broker, Subscriber, needs_mosquitto
from prometheus_client.parser import text_string_to_metric_families

from fdi_daemon.detect.events import ALARM_KINDS as DETECTOR_ALARMS
from fdi_daemon.service.config import default_config_path, load_config

DEFAULT = load_config()
ALARMS = ("fault_detected", "friction_isolated", "other_fault")

pytestmark = [
    pytest.mark.usefixtures("compiled_kernel_cache"),
    pytest.mark.slow,
    needs_mosquitto,
    pytest.mark.skipif(not DEFAULT.model_path.exists(), reason="no packaged model yet"),
]


class Daemon:
    """`python -m fdi_daemon run --config ...`, its output collected line by line."""

    def __init__(self, config, cwd) -> None:
        self.lines: list[str] = []
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "fdi_daemon", "run", "--config", str(config)],
            cwd=cwd,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            env={**os.environ, "PYTHONUNBUFFERED": "1"},
        )
        threading.Thread(target=self._collect, daemon=True).start()

    def _collect(self) -> None:
        for line in self.proc.stdout:
            self.lines.append(line.rstrip("\n"))

    def output(self) -> str:
        return "\n--- daemon\n" + "\n".join(self.lines[-60:])

    def wait_line(self, prefix: str, timeout_s: float = 120.0) -> str:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            assert self.proc.poll() is None, f"daemon exited{self.output()}"
            found = next((ln for ln in self.lines if ln.strip().startswith(prefix)), None)
            if found:
                return found.strip()
            time.sleep(0.1)
        raise AssertionError(f"no '{prefix}' line{self.output()}")


def wait_until(predicate, timeout_s: float, what: str, explain=lambda: ""):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(0.1)
    raise AssertionError(f"timed out waiting for {what}{explain()}")


def read_jsonl(path) -> list[dict]:
    if not path.exists():
        return []
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


def scrape(url: str) -> dict[str, float]:
    with urllib.request.urlopen(url, timeout=10) as reply:
        text = reply.read().decode()
    return {
        s.name + ("" if not s.labels else json.dumps(s.labels, sort_keys=True)): s.value
        for family in text_string_to_metric_families(text)
        for s in family.samples
    }


def test_embedded_run_publishes_its_fault_across_a_broker_restart(tmp_path):
    broker = Broker(tmp_path / "broker").start()
    state = tmp_path / "state"
    config = yaml.safe_load(default_config_path().read_text())
    config["model"]["path"] = str(DEFAULT.model_path)
    config["service"]["state_dir"] = str(state)
    config["mqtt"] = {"enabled": True, "port": broker.port, "site": "lab", "rig": "e2e"}
    config["metrics"] = {"listen": "127.0.0.1:0"}
    (tmp_path / "rig.yaml").write_text(yaml.safe_dump(config))
    (fault,) = DEFAULT.simulated_device["faults"]
    sub = Subscriber(broker.port, "fdi/lab/e2e/#")
    daemon = Daemon(tmp_path / "rig.yaml", tmp_path)
    late = []
    try:
        explain = lambda: broker.tail() + daemon.output()  # noqa: E731
        url = daemon.wait_line("metrics ").split()[1]
        sub.wait(
            lambda s: any(m["payload"]["kind"] == "calibrated" for m in s.events()),
            180,
            "the calibrated event over MQTT",
            explain,
        )
        assert sub.on("/availability")[0]["payload"]["state"] == "online"

        broker.stop()  # the broker goes away before the fault and stays away during it
        events = wait_until(
            lambda: (lambda ev: ev if "friction_isolated" in [e["kind"] for e in ev] else None)(
                read_jsonl(state / "events.jsonl")
            ),
            120,
            "friction_isolated in the event log",
            explain,
        )
        for line in events:
            assert line["schema"] == 2 and line["time"].endswith("Z") and "kind" in line
        outbox = wait_until(
            lambda: (lambda msgs: msgs if len(msgs) >= 2 else None)(
                [
                    r["msg"]
                    for r in read_jsonl(state / "mqtt-outbox.jsonl")
                    if "msg" in r and r["msg"]["kind"] in DETECTOR_ALARMS
                ]
            ),
            30,
            "the alarms in the outbox file",
            explain,
        )
        assert [m["kind"] for m in outbox][:2] == ["fault_detected", "friction_isolated"]

        # the level is measured from one window (1 s) after the detection
        metrics = wait_until(
            lambda: (lambda m: m if m["fdi_friction_level"] > 0 else None)(scrape(url)),
            30,
            "the friction level in the metrics",
            explain,
        )
        assert metrics["fdi_samples_total"] > 0
        assert metrics["fdi_alarm_episodes_total"] >= 1
        states = [metrics[f'fdi_state{{"fdi_state": "{s}"}}'] for s in DETECTOR_ALARMS[:2]]
        assert sum(states) == 1.0  # an Enum: the current state's series is 1
        assert metrics["fdi_tick_latency_seconds_count"] > 0
        assert metrics["fdi_mqtt_connected"] == 0 and metrics["fdi_mqtt_buffered_alarms"] >= 2

        broker.start()  # back: the waiting alarms arrive, in order, each at least once
        sub.wait(
            lambda s: (
                {"fault_detected", "friction_isolated"}
                <= {m["payload"]["kind"] for m in s.events()}
            ),
            60,
            "the alarms after the restart",
            explain,
        )
        alarms = [m["payload"] for m in sub.events() if "seq" in m["payload"]]
        first_seen = list(dict.fromkeys(a["seq"] for a in alarms))
        assert first_seen == sorted(first_seen) and first_seen[0] == 1
        # the detector's alarms, in order (the alarm lifecycle's alarm_* go between them)
        alarms = [a for a in alarms if a["kind"] in DETECTOR_ALARMS]
        assert [a["kind"] for a in alarms][:2] == ["fault_detected", "friction_isolated"]
        assert fault["at_s"] <= alarms[0]["t"] <= alarms[1]["t"] <= fault["at_s"] + 10.0
        seen = set()
        for m in sub.events():
            message_id = m["payload"].get("seq")
            if message_id in seen:
                assert m["dup"] or m["payload"].get("dup"), m
            seen.add(message_id)

        # a subscriber that comes later gets the retained status: online, the friction level
        late.append(Subscriber(broker.port, "fdi/lab/e2e/status", client_id="late-1"))
        retained = late[0].wait(
            lambda s: [m for m in s.on("/status") if m["retain"]],
            30,
            "the retained status",
            explain,
        )[0]["payload"]
        assert retained["state"] in ALARMS
        assert retained["friction_level"] > 0 and retained["alarm_episodes"] >= 1

        last_status = sub.on("/status")[-1]["payload"]
        daemon.proc.send_signal(signal.SIGKILL)  # dies without a word: the last will
        daemon.proc.wait(30)
        sub.wait(
            lambda s: s.on("/availability")[-1]["payload"].get("state") == "offline",
            60,
            "the last will",
            explain,
        )
        assert sub.on("/availability")[-1]["payload"] == {
            "schema": 2,
            "state": "offline",
            "time": None,
            "reason": "connection lost",
        }
        # a later subscriber: offline, and still the last status (friction level) and alarm
        late.append(Subscriber(broker.port, "fdi/lab/e2e/#", client_id="late-2"))
        late[1].wait(
            lambda s: (
                {"availability", "status", "alarm"}
                <= {m["topic"].rpartition("/")[2] for m in s.messages if m["retain"]}
            ),
            30,
            "the retained availability, status and alarm",
            explain,
        )
        assert late[1].on("/availability")[0]["payload"]["state"] == "offline"
        assert late[1].on("/status")[0]["payload"] == last_status
        assert last_status["friction_level"] > 0 and last_status["state"] in ALARMS
        retained_alarm = late[1].on("/alarm")[0]["payload"]
        assert retained_alarm["active"] is True and retained_alarm["alarm_id"] >= 1
    finally:
        if daemon.proc.poll() is None:
            daemon.proc.kill()
            daemon.proc.wait(30)
        for s in [sub] + late:
            s.close()
        broker.stop()
