"""MQTT sink: the on-disk alarm outbox, the config's secrets, and a real mosquitto broker.

The broker tests start their own mosquitto on 127.0.0.1 (a free port, a generated config,
persistence in the test's folder) and stop it; they are skipped only when mosquitto is not
installed (.ci/run installs it).
"""

from __future__ import annotations

import json
import subprocess
import time
from datetime import datetime

import pytest
from mqtt_support import Broker, Subscriber, needs_mosquitto

from fdi_daemon.errors import ConfigError
from fdi_daemon.service.config import config_from_dict
from fdi_daemon.service.mqtt_sink import (
    AlarmOutbox,
    MqttSink,
    read_password,
    status_payload,
    topic_prefix,
)
from fdi_daemon.service.sinks import stamp_event


def minimal(**sections):
    data = {
        "link": {"kind": "modbus-tcp", "host": "127.0.0.1", "port": 5502},
        "model": {"path": "model.yaml"},
    }
    data.update(sections)
    return data


def alarm(t, kind="fault_detected"):
    return stamp_event({"t": t, "kind": kind, "theta1": 0.5, "theta2": 0.1})


# ----------------------------------------------------------------------------- outbox


def test_outbox_bounded_drops_the_oldest_but_never_the_one_in_flight(tmp_path):
    box = AlarmOutbox(tmp_path / "out.jsonl", max_messages=3)
    ids = [box.add(alarm(float(t)))[0]["seq"] for t in range(3)]
    assert ids == [1, 2, 3] and box.lost == 0
    _, dropped = box.add(alarm(3.0), in_flight=1)  # 1 is with the broker: drop 2 instead
    assert [m["seq"] for m in dropped] == [2] and box.lost == 1
    _, dropped = box.add(alarm(4.0), in_flight=None)
    assert [m["seq"] for m in dropped] == [1] and box.lost == 2
    assert [m["seq"] for m in box.pending.values()] == [3, 4, 5]
    assert [m["t"] for m in box.pending.values()] == [2.0, 3.0, 4.0]


def test_outbox_survives_a_restart_in_order_and_flags_what_was_sent(tmp_path):
    path = tmp_path / "out.jsonl"
    box = AlarmOutbox(path, max_messages=100)
    for t in range(4):
        box.add(alarm(float(t)))
    box.mark_sent(1)
    box.ack(1)
    box.mark_sent(2)  # handed to the broker, no acknowledgement: the daemon dies here
    box.close()
    with open(path, "a") as fh:
        fh.write('{"ack": 3')  # a line torn by the crash
    again = AlarmOutbox(path, max_messages=100)
    assert [(m["seq"], m.get("dup", False)) for m in again.pending.values()] == [
        (2, True),
        (3, False),
        (4, False),
    ]
    for message_id in (2, 3, 4):
        again.ack(message_id)
    again.close()
    assert path.read_text().splitlines() == ['{"next_id":5}']  # compacted, ids go on
    third = AlarmOutbox(path, max_messages=100)
    assert len(third) == 0 and third.add(alarm(9.0))[0]["seq"] == 5


def test_status_payload_carries_the_friction_level_and_buffer_losses(tmp_path):
    box = AlarmOutbox(tmp_path / "out.jsonl", max_messages=1)
    box.add(alarm(1.0))
    box.add(alarm(2.0))
    snap = {
        "time": 1.7e9,
        "state": "friction_isolated",
        "t": 20.5,
        "monitor": {"friction_level": 1.42, "theta1": 1.42, "theta2": 1.0},
        "link": {"connected": True, "samples": 5000},
        "counters": {"fault_detected": 1},
    }
    payload = status_payload(snap, box, skipped_events=3)
    assert (
        "online" not in payload and payload["state"] == "friction_isolated"
    )  # availability has it
    assert payload["units"] == {
        "t": "s",
        "friction_level": "multiple of the calibrated fault (1 = the calibrated fault)",
        "statistic": "1",
        "threshold": "1",
        "residual_rms": "m/s^2",
        "time": "RFC 3339",
    }
    assert payload["friction_level"] == 1.42 and payload["alarm_episodes"] == 1
    assert payload["mqtt"] == {"buffered": 1, "lost": 1, "skipped_events": 3}
    assert payload["time"] == "2023-11-14T22:13:20.000000Z"


# ----------------------------------------------------------------------------- event lines


def test_event_lines_carry_rfc3339_time_and_schema_and_keep_t_and_kind():
    event = {"t": 20.019, "kind": "fault_detected", "theta1": 0.1, "theta2": None}
    line = stamp_event(event, now=1795456800.123456)
    assert line["t"] == 20.019 and line["kind"] == "fault_detected" and line["schema"] == 2
    assert line["time"] == "2026-11-23T18:00:00.123456Z"
    assert datetime.fromisoformat(line["time"].replace("Z", "+00:00")).timestamp() == pytest.approx(
        1795456800.123456, abs=1e-6
    )
    assert "time" not in event  # the loop's copy (status alarms) is left alone
    # a link event keeps the wall clock at which the link layer noticed it
    lost = stamp_event({"t": None, "kind": "link_lost", "time": 1795456799.5}, now=1.0)
    assert lost["t"] is None and lost["time"] == "2026-11-23T17:59:59.500000Z"


def test_replay_event_files_carry_the_schema_but_no_wall_clock(tmp_path):
    from fdi_daemon.detect.events import read_events, write_events

    write_events(tmp_path / "ev.jsonl", [{"t": 1.0, "kind": "calibrated"}])
    (line,) = read_events(tmp_path / "ev.jsonl")
    assert line == {"t": 1.0, "kind": "calibrated", "schema": 2}


# ----------------------------------------------------------------------------- config


def test_mqtt_and_metrics_are_off_by_default(tmp_path):
    cfg = config_from_dict(minimal(), "rig.yaml", tmp_path)
    assert cfg.mqtt["enabled"] is False and cfg.metrics["listen"] is None
    assert cfg.mqtt["host"] == "127.0.0.1" and cfg.mqtt["tls"]["enabled"] is False


@pytest.mark.parametrize("key", ["password", "passwd", "secret"])
def test_a_secret_written_into_the_config_is_refused(key):
    with pytest.raises(
        ConfigError,
        match=rf"mqtt\.{key}: secrets are not read from the "
        r"config.*password_file.*password_env",
    ):
        config_from_dict(
            minimal(mqtt={"enabled": True, "username": "fdi", key: "hunter2"}), "rig.yaml"
        )


def test_password_from_a_file_beside_the_config_or_the_environment(tmp_path, monkeypatch):
    (tmp_path / "mqtt.secret").write_text("s3cret\n")
    cfg = config_from_dict(
        minimal(
            mqtt={
                "username": "fdi",
                "password_file": "mqtt.secret",
                "tls": {"enabled": True, "ca_file": "ca.pem"},
            }
        ),
        "rig.yaml",
        tmp_path,
    )
    assert cfg.mqtt["password_file"] == str(tmp_path / "mqtt.secret")
    assert cfg.mqtt["tls"]["ca_file"] == str(tmp_path / "ca.pem")
    assert read_password(cfg.mqtt) == "s3cret"
    monkeypatch.setenv("FDI_MQTT_PASSWORD", "from-env")
    env = config_from_dict(
        minimal(mqtt={"username": "fdi", "password_env": "FDI_MQTT_PASSWORD"}), "rig.yaml"
    )
    assert read_password(env.mqtt) == "from-env"
    monkeypatch.delenv("FDI_MQTT_PASSWORD")
    with pytest.raises(ConfigError, match="FDI_MQTT_PASSWORD is not set"):
        read_password(env.mqtt, "rig.yaml")
    (tmp_path / "mqtt.secret").unlink()
    with pytest.raises(ConfigError, match="mqtt.password_file: cannot read"):
        read_password(cfg.mqtt, "rig.yaml")


@pytest.mark.parametrize(
    "section, message",
    [
        ({"mqtt": {"password_file": "a", "password_env": "B"}}, "set one"),
        ({"mqtt": {"site": "plant/hall"}}, "mqtt.site must be a non-empty MQTT topic level"),
        ({"mqtt": {"rig": "#"}}, "mqtt.rig must be"),
        ({"mqtt": {"port": 70000}}, "mqtt.port"),
        ({"mqtt": {"tls": {"ca": "x"}}}, "mqtt.tls.ca: unknown key"),
        ({"metrics": {"listen": "19108"}}, "metrics.listen must be HOST:PORT"),
        ({"metrics": {"port": 19108}}, "metrics.port: unknown key"),
    ],
)
def test_bad_mqtt_and_metrics_settings_name_the_key(section, message):
    with pytest.raises(ConfigError, match=message):
        config_from_dict(minimal(**section), "rig.yaml")


def test_password_without_user_is_refused(tmp_path):
    (tmp_path / "pw").write_text("x")
    cfg = config_from_dict(minimal(mqtt={"password_file": "pw"}), "rig.yaml", tmp_path)
    with pytest.raises(ConfigError, match="needs mqtt.username"):
        read_password(cfg.mqtt)


# ----------------------------------------------------------------------------- a real broker


def sink_settings(port, **more):
    cfg = config_from_dict(
        minimal(mqtt={"enabled": True, "port": port, "site": "lab", "rig": "rig7", **more}),
        "rig.yaml",
    )
    return cfg.mqtt


def alarm_ids(sub):
    return [m["payload"]["seq"] for m in sub.events() if "seq" in m["payload"]]


def check_at_least_once_in_order(sub, expected_ids):
    """Every alarm at least once; first arrivals in order; every repeat flagged ``dup``."""
    seen: list[int] = []
    for m in sub.events():
        message_id = m["payload"].get("seq")
        if message_id is None:
            continue
        if message_id in seen:
            assert m["dup"] or m["payload"].get("dup"), f"unflagged duplicate {m}"
        else:
            seen.append(message_id)
    assert seen == expected_ids


@needs_mosquitto
def test_alarms_wait_on_disk_while_the_broker_is_away_and_arrive_in_order(tmp_path):
    broker = Broker(tmp_path / "broker").start()
    sub = Subscriber(broker.port, "fdi/lab/rig7/#")
    outbox = tmp_path / "state" / "mqtt-outbox.jsonl"
    sink = MqttSink(sink_settings(broker.port), outbox)
    try:
        sub.wait(lambda s: s.on("/availability"), 20, "the availability", broker.tail)
        assert sub.on("/availability")[0]["payload"]["state"] == "online"
        sink.event(stamp_event({"t": 2.0, "kind": "calibrated"}))
        sink.event(alarm(10.0))
        sub.wait(lambda s: alarm_ids(s) == [1], 20, "the first alarm", broker.tail)
        assert [m["payload"]["kind"] for m in sub.events()] == ["calibrated", "fault_detected"]
        assert sub.events()[1]["qos"] == 1 and sub.events()[0]["qos"] == 0

        broker.stop()  # the broker goes away during the alarm
        deadline = time.monotonic() + 20
        while sink.connected and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not sink.connected
        kinds = ["friction_isolated", "cleared", "fault_detected", "other_fault"]
        for i, kind in enumerate(kinds):
            sink.event(alarm(11.0 + i, kind))
        sink.event(stamp_event({"t": 15.0, "kind": "data_gap", "missing_samples": 3}))
        deadline = time.monotonic() + 20
        while len(sink.outbox) < 4 and time.monotonic() < deadline:
            time.sleep(0.05)
        on_disk = [
            json.loads(line)["msg"]["kind"]
            for line in outbox.read_text().splitlines()
            if '"msg"' in line
        ]
        assert on_disk == kinds  # kept on disk, in order, while the broker is away
        assert sink.skipped_events == 1  # the data_gap is not an alarm: skipped, counted

        broker.start()  # back on the same port, with the subscriber's session
        sub.wait(lambda s: len(alarm_ids(s)) >= 5, 60, "the buffered alarms", broker.tail)
        check_at_least_once_in_order(sub, [1, 2, 3, 4, 5])
        assert [m["payload"]["kind"] for m in sub.events() if "seq" in m["payload"]] == [
            "fault_detected"
        ] + kinds
        deadline = time.monotonic() + 20
        while len(sink.outbox) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert len(sink.outbox) == 0
    finally:
        sink.close()
        sub.close()
        broker.stop()
    assert outbox.read_text().splitlines() == ['{"next_id":6}']
    offline = sub.on("/availability")[-1]
    assert offline["retain"] is False  # a live subscriber sees it as it comes
    assert offline["payload"]["state"] == "offline" and offline["payload"]["reason"] == "stopped"
    assert offline["payload"]["time"].endswith("Z")
    assert all(m["payload"].get("state") != "offline" for m in sub.on("/status"))


@needs_mosquitto
def test_an_alarm_sent_before_a_crash_is_sent_again_flagged_dup(tmp_path):
    broker = Broker(tmp_path / "broker").start()
    outbox = tmp_path / "mqtt-outbox.jsonl"
    box = AlarmOutbox(outbox, max_messages=10)
    box.add(alarm(10.0))
    box.add(alarm(10.5, "friction_isolated"))
    box.mark_sent(1)  # the daemon died before the broker's acknowledgement was recorded
    box.close()
    sub = Subscriber(broker.port, "fdi/lab/rig7/event/#")
    sink = MqttSink(sink_settings(broker.port), outbox)
    try:
        sub.wait(lambda s: len(alarm_ids(s)) >= 2, 30, "the alarms", broker.tail)
        first, second = [m["payload"] for m in sub.events()]
        assert (first["seq"], first.get("dup")) == (1, True)
        assert (second["seq"], second.get("dup")) == (2, None)
        check_at_least_once_in_order(sub, [1, 2])
    finally:
        sink.close()
        sub.close()
        broker.stop()


@needs_mosquitto
def test_password_and_tls_from_the_config_against_a_broker_that_requires_them(tmp_path, caplog):
    certs = tmp_path / "certs"
    certs.mkdir()

    def openssl(*args):
        subprocess.run(["openssl", *args], check=True, capture_output=True, cwd=certs)

    openssl(
        "req",
        "-x509",
        "-newkey",
        "rsa:2048",
        "-nodes",
        "-days",
        "2",
        "-subj",
        "/CN=fdi test CA",
        "-keyout",
        "ca.key",
        "-out",
        "ca.pem",
    )
    openssl(
        "req",
        "-newkey",
        "rsa:2048",
        "-nodes",
        "-subj",
        "/CN=127.0.0.1",
        "-keyout",
        "server.key",
        "-out",
        "server.csr",
    )
    (certs / "san.ext").write_text("subjectAltName=IP:127.0.0.1\n")
    openssl(
        "x509",
        "-req",
        "-in",
        "server.csr",
        "-CA",
        "ca.pem",
        "-CAkey",
        "ca.key",
        "-CAcreateserial",
        "-days",
        "2",
        "-extfile",
        "san.ext",
        "-out",
        "server.pem",
    )
    passwd = tmp_path / "broker.passwd"
    subprocess.run(
        ["mosquitto_passwd", "-b", "-c", str(passwd), "fdi", "s3cret"],
        check=True,
        capture_output=True,
    )
    broker = Broker(
        tmp_path / "broker",
        extra=(
            f"allow_anonymous false\npassword_file {passwd}\ncafile {certs / 'ca.pem'}\n"
            f"certfile {certs / 'server.pem'}\nkeyfile {certs / 'server.key'}\n"
        ),
    ).start()
    (tmp_path / "mqtt.secret").write_text("s3cret\n")
    settings = config_from_dict(
        minimal(
            mqtt={
                "enabled": True,
                "port": broker.port,
                "site": "lab",
                "rig": "rig7",
                "username": "fdi",
                "password_file": "mqtt.secret",
                "tls": {"enabled": True, "ca_file": "certs/ca.pem"},
            }
        ),
        "rig.yaml",
        tmp_path,
    ).mqtt
    sub = Subscriber(
        broker.port,
        "fdi/lab/rig7/#",
        username="fdi",
        password="s3cret",
        ca_file=str(certs / "ca.pem"),
    )
    sink = MqttSink(settings, tmp_path / "outbox.jsonl")
    try:
        sink.event(alarm(10.0))
        sub.wait(lambda s: alarm_ids(s) == [1], 30, "the alarm over TLS", broker.tail)
        assert sub.on("/availability")[0]["payload"]["state"] == "online"
    finally:
        sink.close()
        sub.close()
    # the same broker refuses a wrong password: the sink never connects, the alarm waits
    (tmp_path / "mqtt.secret").write_text("wrong\n")
    caplog.set_level("WARNING", logger="fdi.mqtt")
    refused = MqttSink(settings, tmp_path / "outbox2.jsonl")
    try:
        refused.event(alarm(11.0))
        deadline = time.monotonic() + 30
        while broker.tail().count("not authorised") < 2 and time.monotonic() < deadline:
            time.sleep(0.1)
        assert broker.tail().count("not authorised") >= 2  # paho keeps retrying
        assert not refused.connected and len(refused.outbox) == 1
        said = [r.getMessage() for r in caplog.records if r.name == "fdi.mqtt"]
        assert len([m for m in said if "refused the connection" in m]) == 1, said
    finally:
        refused.close(timeout_s=0.5)
        broker.stop()


def test_topic_prefix_defaults_to_the_host_name(monkeypatch):
    import socket

    monkeypatch.setattr(socket, "gethostname", lambda: "rig-12.plant.example")
    settings = config_from_dict(minimal(mqtt={"site": "hall3"}), "rig.yaml").mqtt
    assert topic_prefix(settings) == "fdi/hall3/rig-12"


@needs_mosquitto
def test_daemon_sinks_send_the_event_log_line_and_reopen_after_a_reload(tmp_path):
    """The daemon's `Sinks` wiring: the MQTT message is the event log's line (same
    ``time``) plus ``id``; closing and rebuilding them (what SIGHUP does) rebinds the
    metrics port and reconnects with the same client id, and ids go on."""
    from mqtt_support import free_port

    from fdi_daemon.service.daemon import Sinks
    from fdi_daemon.service.sinks import StatusBoard

    broker = Broker(tmp_path / "broker").start()
    metrics_port = free_port()
    cfg = config_from_dict(
        minimal(
            mqtt={"enabled": True, "port": broker.port, "site": "lab", "rig": "rig7"},
            metrics={"listen": f"127.0.0.1:{metrics_port}"},
            sinks={"status_socket": None, "stdout": False},
            recorder={"enabled": False},
            service={"state_dir": str(tmp_path / "state")},
        ),
        "rig.yaml",
        tmp_path,
    )
    sub = Subscriber(broker.port, "fdi/lab/rig7/event/#")
    try:
        for reload in range(2):
            sinks = Sinks(cfg, 256.0, "modbus-tcp", StatusBoard())
            try:
                assert sinks.metrics.port == metrics_port
                sinks.event(
                    {
                        "t": 20.0 + reload,
                        "kind": "fault_detected",
                        "theta1": 1.0,
                        "theta2": float("nan"),
                    }
                )
                sub.wait(lambda s: len(alarm_ids(s)) == reload + 1, 30, "the alarm", broker.tail)
            finally:
                sinks.close()
    finally:
        sub.close()
        broker.stop()
    lines = [
        json.loads(line) for line in (tmp_path / "state" / "events.jsonl").read_text().splitlines()
    ]
    messages = [m["payload"] for m in sub.events()]
    assert [m["seq"] for m in messages] == [1, 2]
    assert [{k: v for k, v in m.items() if k not in ("seq", "units")} for m in messages] == lines
    assert all(line["schema"] == 2 and line["theta2"] is None for line in lines)


def test_a_broker_that_never_answers_holds_up_nothing(tmp_path):
    """A TCP peer that accepts and never sends CONNACK: alarms go to the outbox file,
    statuses are dropped, and close() comes back (what is not delivered stays on disk)."""
    import socket

    silent = socket.socket()
    silent.bind(("127.0.0.1", 0))
    silent.listen()
    outbox = tmp_path / "outbox.jsonl"
    sink = MqttSink(sink_settings(silent.getsockname()[1]), outbox)
    try:
        for i in range(50):
            sink.event(alarm(float(i)))
            sink.status({"state": "monitoring"})
        deadline = time.monotonic() + 30
        while len(sink.outbox) < 50 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert len(sink.outbox) == 50 and not sink.connected
    finally:
        sink.close(timeout_s=0.5)
        silent.close()
    assert len(AlarmOutbox(outbox, max_messages=100)) == 50


def test_a_full_buffer_drops_the_oldest_alarms_counts_and_logs_them(tmp_path, caplog):
    import socket

    caplog.set_level("WARNING", logger="fdi.mqtt")
    silent = socket.socket()  # a broker that never answers: nothing is ever delivered
    silent.bind(("127.0.0.1", 0))
    silent.listen()
    sink = MqttSink(
        sink_settings(silent.getsockname()[1], buffer_max_messages=2), tmp_path / "outbox.jsonl"
    )
    try:
        for i in range(5):
            sink.event(alarm(float(i)))
        deadline = time.monotonic() + 30
        while sink.outbox.lost < 3 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert [m["seq"] for m in sink.outbox.pending.values()] == [4, 5]
        assert status_payload({}, sink.outbox)["mqtt"]["lost"] == 3
        dropped = [r.getMessage() for r in caplog.records if "dropped alarm" in r.getMessage()]
        assert len(dropped) == 3 and "dropped alarm message seq 1 " in dropped[0]
        assert dropped[-1].endswith("3 lost since start")
    finally:
        sink.close(timeout_s=0.5)
        silent.close()
