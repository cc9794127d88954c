"""MQTT conventions against a real mosquitto on 127.0.0.1: availability with a last will that
leaves the last status retained (a real process killed by SIGKILL), the operator alarm retained
on its own topic through its whole lifecycle, events by kind, Home Assistant discovery."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest
from mqtt_support import Broker, Subscriber, needs_mosquitto
from test_service_mqtt import sink_settings

from fdi_daemon.alarms.lifecycle import AlarmSettings
from fdi_daemon.service.alarm_keeper import AlarmKeeper
from fdi_daemon.service.mqtt_sink import MqttSink
from fdi_daemon.service.sinks import stamp_event

PREFIX = "fdi/lab/rig7"
SNAPSHOT = {
    "time": 1.7e9,
    "state": "friction_isolated",
    "t": 20.5,
    "monitor": {"friction_level": 1.42, "theta1": 1.42, "theta2": 1.0, "statistic": 3.5},
    "link": {"connected": True, "samples": 5000},
    "counters": {"fault_detected": 1},
}


class Clock:
    """A wall clock the test moves (s)."""

    def __init__(self) -> None:
        self.now = 1.7e9

    def __call__(self) -> float:
        return self.now


def retained(broker: Broker, topic: str, what: str) -> list[dict[str, Any]]:
    """What a subscriber that connects now gets as retained on ``topic``."""
    late = Subscriber(broker.port, topic, client_id=f"late-{time.monotonic_ns()}")
    try:
        return late.wait(lambda s: [m for m in s.messages if m["retain"]], 20, what, broker.tail)
    finally:
        late.close()


@needs_mosquitto
def test_availability_and_last_status_survive_a_sigkill(tmp_path):
    """A sink in a real process publishes a status, then dies by SIGKILL: the broker's last
    will marks it offline on the availability topic; the status stays retained."""
    broker = Broker(tmp_path / "broker").start()
    script = f"""
import sys, time
from test_service_mqtt import sink_settings
from fdi_daemon.service.mqtt_sink import MqttSink
sink = MqttSink(sink_settings({broker.port}), {str(tmp_path / "outbox.jsonl")!r})
sink.status({SNAPSHOT!r})
print("ready", flush=True)
time.sleep(120)
"""
    sub = Subscriber(broker.port, f"{PREFIX}/#")
    proc = subprocess.Popen(
        [sys.executable, "-c", script],
        cwd=str(tmp_path),
        env={**os.environ, "PYTHONPATH": str(Path(__file__).parent)},
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        sub.wait(lambda s: s.on("/status") and s.on("/availability"), 30, "online", broker.tail)
        online = sub.on("/availability")[0]["payload"]
        assert online["state"] == "online" and online["time"].endswith("Z")
        assert online["reason"] == "connected"
        status = sub.on("/status")[-1]["payload"]
        assert status["friction_level"] == 1.42
        proc.send_signal(signal.SIGKILL)
        proc.wait(30)
        sub.wait(
            lambda s: s.on("/availability")[-1]["payload"]["state"] == "offline",
            60,
            "the last will",
            broker.tail,
        )
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(30)
        sub.close()
    try:
        late = {m["topic"]: m["payload"] for m in retained(broker, f"{PREFIX}/#", "retained")}
        assert late[f"{PREFIX}/availability"] == {
            "schema": 2,
            "state": "offline",
            "time": None,  # a will is fixed at connect: the status's time is the last seen
            "reason": "connection lost",
        }
        assert late[f"{PREFIX}/status"] == status  # the last known friction level stays
    finally:
        broker.stop()


@needs_mosquitto
def test_the_operator_alarm_is_retained_through_its_lifecycle(tmp_path):
    """raise, acknowledge, shelve, unshelve, return to normal: each updates the retained
    alarm; each lifecycle event goes on its own ``event/<kind>`` topic with ``seq``."""
    clock = Clock()
    keeper = AlarmKeeper(
        AlarmSettings(return_delay_s=3.0, smoothing_s=1.0), "m", allow_remote=True, clock=clock
    )
    broker = Broker(tmp_path / "broker").start()
    sub = Subscriber(broker.port, f"{PREFIX}/#")
    sink = MqttSink(sink_settings(broker.port), tmp_path / "outbox.jsonl")
    expected: list[tuple[str, bool, bool]] = []  # (state, acknowledged, shelved) per step

    def emit(events: list[dict[str, Any]], state: str, acknowledged: bool, shelved: bool):
        assert events, state
        for event in events:
            sink.event(stamp_event(event))
        expected.append((state, acknowledged, shelved))
        sub.wait(lambda s: len(s.on("/alarm")) >= len(expected), 20, f"alarm {state}", broker.tail)
        got = sub.on("/alarm")[len(expected) - 1]["payload"]
        assert (got["state"], got["acknowledged"], got["shelved"]) == expected[-1]
        assert got["alarm_id"] == 1 and got["since"].endswith("Z")
        return got

    try:
        sub.wait(lambda s: s.on("/availability"), 20, "online", broker.tail)
        raised = emit(
            keeper.detector_event({"t": 1.0, "kind": "fault_detected"}),
            "unacknowledged",
            False,
            False,
        )
        assert raised["active"] is True and raised["priority"] >= 1
        assert raised["units"]["since"] == "RFC 3339"
        clock.now += 5
        assert keeper.request("acknowledge", "test")["ok"]
        emit(keeper.take_pending(), "acknowledged", True, False)
        clock.now += 5
        assert keeper.request("shelve", "test", 600.0)["ok"]
        shelved = emit(keeper.take_pending(), "acknowledged", True, True)
        assert shelved["state_code"] == 4 and shelved["shelved_until"].endswith("Z")
        clock.now += 5
        assert keeper.request("unshelve", "test")["ok"]
        emit(keeper.take_pending(), "acknowledged", True, False)
        events = keeper.detector_event({"t": 30.0, "kind": "cleared"})
        for _ in range(10):  # the level back at the baseline, one reading a second
            clock.now += 1.0
            events += keeper.status({"t": 31.0, "monitor": {"friction_level": 0.0}})[0]
        returned = emit(events, "normal", True, False)
        assert returned["active"] is False
        kinds = [m["topic"].rpartition("/")[2] for m in sub.events()]
        assert kinds == [
            "alarm_raised",
            "alarm_acknowledged",
            "alarm_shelved",
            "alarm_unshelved",
            "alarm_returned",
        ]
        assert [m["payload"]["seq"] for m in sub.events()] == [1, 2, 3, 4, 5]
        assert all(m["qos"] == 1 for m in sub.events())
        late = retained(broker, f"{PREFIX}/alarm", "the retained alarm")
        assert late[0]["payload"]["state"] == "normal"
    finally:
        sink.close()
        sub.close()
        broker.stop()


@needs_mosquitto
def test_home_assistant_discovery_parses_into_sensors_on_published_topics(tmp_path):
    """A discovery subscriber builds sensors from the retained configs; each one's state
    topic is published by the daemon and its value template renders the payload."""
    jinja2 = pytest.importorskip("jinja2")
    broker = Broker(tmp_path / "broker").start()
    sink = MqttSink(sink_settings(broker.port), tmp_path / "outbox.jsonl")
    try:
        sink.status(
            {**SNAPSHOT, "alarm": {"state": "unacknowledged", "alarm_id": 2, "priority": 3}}
        )
        deadline = time.monotonic() + 20
        while not sink.connected and time.monotonic() < deadline:
            time.sleep(0.05)
        configs = retained(broker, "homeassistant/#", "the discovery configs")
        data = {m["topic"]: m["payload"] for m in retained(broker, f"{PREFIX}/#", "the data")}
    finally:
        sink.close()
        broker.stop()
    sensors = {}
    for message in configs:
        component, node, object_id, last = message["topic"].split("/")[1:]
        config = message["payload"]
        assert last == "config" and component in ("sensor", "binary_sensor")
        assert config["unique_id"] == f"{node}_{object_id}"
        assert config["device"]["identifiers"] == [node] and config["device"]["sw_version"]
        assert config["availability_topic"] == f"{PREFIX}/availability"
        availability = jinja2.Template(config["availability_template"]).render(
            value_json=data[config["availability_topic"]]
        )
        assert availability == config["payload_available"]  # the daemon is online
        state = data[config["state_topic"]]  # a topic the daemon publishes, retained
        sensors[object_id] = jinja2.Template(config["value_template"]).render(value_json=state)
        if component == "binary_sensor":
            assert sensors[object_id] in ("ON", "OFF")
        if config.get("device_class") == "enum":
            assert sensors[object_id] in config["options"]
    assert sensors["friction_level"] == "1.42" and sensors["state"] == "friction_isolated"
    assert sensors["alarm_state"] == "unacknowledged" and sensors["alarm_priority"] == "3"
    assert sensors["alarm_active"] == "ON" and sensors["link_connected"] == "ON"
    assert len(sensors) == len(configs) == 9
    units = {m["payload"].get("unit_of_measurement") for m in configs}
    assert "s" in units and json.dumps(configs)  # JSON all the way
