"""MQTT sink: events and a retained status on a broker; alarms kept on disk until acknowledged.

Topics, ``<prefix>`` = ``fdi/<site>/<rig>``:

- ``<prefix>/event/<kind>``: every event as JSON, as the event log writes it
  (`stamp_event`: ``t``, ``kind``, ..., ``time``, ``schema``) plus ``units``. Alarm kinds
  (detector: ``fault_detected``, ``friction_isolated``, ``other_fault``, ``cleared``; the
  operator alarm's lifecycle: ``alarm_*``) go with QoS 1 through the on-disk `AlarmOutbox`;
  each carries ``seq`` (consecutive per rig, kept across restarts; not the ``alarm_id``)
  and ``dup: true`` when it is published again after a daemon restart because the broker's
  acknowledgement of an earlier send was not recorded. Other kinds go with QoS 0 while the
  broker is there and are skipped (and counted) while it is not; the event log has them all.
- ``<prefix>/status``: retained, every ``status_period_s`` (1 s): `status_payload`
  (``state``, ``friction_level``, θ, counters, the outbox's ``buffered`` and ``lost``,
  ``units``). It stays retained when the daemon dies: the last known friction level.
- ``<prefix>/availability``: retained, QoS 1: ``online`` at every connect; the last will,
  ``offline`` (``time: null``), published by the broker when the connection dies without a
  clean disconnect (SIGKILL, power, network); a clean stop publishes ``offline`` with its
  time itself before disconnecting (`fdi_daemon.service.mqtt_payloads.availability`).
- ``<prefix>/alarm``: retained, QoS 1: the operator alarm, on connect and after every
  lifecycle event (`fdi_daemon.service.mqtt_payloads.alarm_from_event`).
- ``<discovery_prefix>/.../config``: retained, on connect: Home Assistant MQTT discovery
  (`fdi_daemon.service.mqtt_payloads.discovery`), unless ``discovery_prefix`` is null.

Threads. The daemon's sink worker calls `MqttSink.event` / `MqttSink.status`, which only
queue items for this sink's own `Worker`; that thread writes the outbox file and calls
paho's ``publish``, and paho's network thread (``loop_start``) does the socket I/O and the
reconnects. Nothing here runs on the sample loop's thread. paho's callbacks only queue
items too (paho holds its message lock while it runs ``on_publish``). One alarm is in
flight at a time, so alarms reach the broker in the order they were raised, across
reconnects and restarts.
"""

from __future__ import annotations

import collections
import json
import logging
import os
import socket
import time
from pathlib import Path
from typing import Any, TextIO

from fdi_daemon.alarms.lifecycle import LIFECYCLE_KINDS
from fdi_daemon.detect.events import EVENT_SCHEMA
from fdi_daemon.errors import ConfigError
from fdi_daemon.service import mqtt_payloads
from fdi_daemon.service.sinks import ALARM_KINDS, Worker, json_line, rfc3339

log = logging.getLogger("fdi.mqtt")

#: paho's reconnect backoff (s): first retry, cap
RECONNECT_MIN_S = 0.5
RECONNECT_MAX_S = 5.0
#: the last will (retained on the availability topic); a clean stop says when
LAST_WILL = mqtt_payloads.availability(False, None, "connection lost")
#: the outbox file is compacted when it has this many more lines than pending alarms
COMPACT_SLACK_LINES = 1000


def topic_prefix(settings: dict[str, Any]) -> str:
    """``fdi/<site>/<rig>``; the rig defaults to this host's name."""
    rig = settings["rig"] or socket.gethostname().split(".")[0]
    return f"fdi/{settings['site']}/{rig}"


def read_password(settings: dict[str, Any], source: str = "config") -> str | None:
    """The broker password from ``password_file`` (first line) or ``password_env``."""
    if settings["password_file"] is not None:
        path = Path(settings["password_file"])
        try:
            lines = path.read_text(encoding="utf-8").splitlines()
        except OSError as exc:
            raise ConfigError(
                f"{source}: mqtt.password_file: cannot read {path}: {exc.strerror or exc}"
            ) from None
        password: str | None = lines[0] if lines else ""
    elif settings["password_env"] is not None:
        password = os.environ.get(settings["password_env"])
        if password is None:
            raise ConfigError(
                f"{source}: mqtt.password_env: the environment variable "
                f"{settings['password_env']} is not set"
            )
    else:
        return None
    if settings["username"] is None:
        raise ConfigError(f"{source}: mqtt: a password needs mqtt.username")
    return password


class AlarmOutbox:
    """Alarms not yet acknowledged by the broker, oldest first, mirrored in a file.

    The file is JSON Lines, appended to: ``{"msg": {...}}`` when an alarm is added (flushed
    and fsynced), ``{"sent": seq}`` when it is handed to the client, ``{"ack": seq}`` when
    the broker acknowledged it, ``{"drop": seq}`` when the bound pushed it out. (Files of
    fdi 0.1.0, whose messages carry ``id`` for ``seq``, load unchanged.) Loading replays
    these lines; a message that was sent but not acknowledged comes back with ``dup: true``.
    The file is rewritten with only what is pending (and ``{"next_id": n}``, so ``seq``
    never repeats) at load and whenever it holds `COMPACT_SLACK_LINES` lines more than that.
    At most ``max_messages`` wait; adding one more drops the oldest (never the one in
    flight) and counts it in ``lost``.
    """

    def __init__(self, path: str | Path, max_messages: int) -> None:
        self.path = Path(path)
        self.max_messages = max_messages
        self.pending: collections.OrderedDict[int, dict] = collections.OrderedDict()
        self.next_id = 1
        self.lost = 0
        self._sent: set[int] = set()
        self._lines = 0
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._load()
        self._fh: TextIO | None = None
        self._rewrite()

    def __len__(self) -> int:
        return len(self.pending)

    def head(self) -> dict | None:
        return next(iter(self.pending.values()), None)

    def add(self, payload: dict, in_flight: int | None = None) -> tuple[dict, list[dict]]:
        """Queue an alarm; returns it (with ``seq``) and the alarms dropped to make room."""
        message = {**payload, "seq": self.next_id}
        self.next_id += 1
        dropped = []
        while len(self.pending) >= self.max_messages:
            victim = next((i for i in self.pending if i != in_flight), None)
            if victim is None:
                break
            dropped.append(self.pending.pop(victim))
            self._sent.discard(victim)
            self.lost += 1
            self._append({"drop": victim})
        self.pending[message["seq"]] = message
        self._append({"msg": message}, sync=True)
        return message, dropped

    def mark_sent(self, message_id: int) -> None:
        if message_id not in self._sent:
            self._sent.add(message_id)
            self._append({"sent": message_id})

    def ack(self, message_id: int) -> None:
        if self.pending.pop(message_id, None) is not None:
            self._sent.discard(message_id)
            self._append({"ack": message_id})
            if self._lines > len(self.pending) + COMPACT_SLACK_LINES or not self.pending:
                self._rewrite()

    def close(self) -> None:
        if self._fh is not None and not self._fh.closed:
            self._fh.flush()
            os.fsync(self._fh.fileno())
            self._fh.close()

    # ------------------------------------------------------------------ file
    def _load(self) -> None:
        try:
            lines = self.path.read_text(encoding="utf-8").splitlines()
        except FileNotFoundError:
            return
        for number, line in enumerate(lines, 1):
            try:
                record = json.loads(line)
            except ValueError:  # a line torn by a crash: the rest is still good
                log.warning("%s:%d: unreadable line skipped", self.path, number)
                continue
            if "msg" in record:
                message = record["msg"]
                if "seq" not in message:  # written by fdi 0.1.0
                    message["seq"] = message.pop("id")
                self.pending[message["seq"]] = message
                self.next_id = max(self.next_id, message["seq"] + 1)
            elif "next_id" in record:
                self.next_id = max(self.next_id, record["next_id"])
            elif "sent" in record:
                self._sent.add(record["sent"])
            elif "ack" in record or "drop" in record:
                gone = record.get("ack", record.get("drop"))
                self.pending.pop(gone, None)
                self._sent.discard(gone)
        self._sent &= set(self.pending)
        for message_id in self._sent:
            self.pending[message_id]["dup"] = True
        if self.pending:
            log.info(
                "%s: %d alarm(s) from before the restart wait for the broker",
                self.path,
                len(self.pending),
            )

    def _rewrite(self) -> None:
        """Replace the file by the pending alarms only (atomic rename, fsynced)."""
        if self._fh is not None:
            self._fh.close()
        tmp = self.path.with_name(self.path.name + ".tmp")
        records = [{"next_id": self.next_id}] + [{"msg": m} for m in self.pending.values()]
        records += [{"sent": i} for i in self._sent]
        with open(tmp, "w", encoding="utf-8") as fh:
            fh.writelines(json_line(r) for r in records)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, self.path)
        self._fh = open(self.path, "a", encoding="utf-8")
        self._lines = len(records)

    def _append(self, record: dict, sync: bool = False) -> None:
        assert self._fh is not None  # opened by _rewrite in __init__
        self._fh.write(json_line(record))
        self._fh.flush()
        if sync:
            os.fsync(self._fh.fileno())
        self._lines += 1


def status_payload(
    snapshot: dict[str, Any], outbox: AlarmOutbox | None = None, skipped_events: int = 0
) -> dict[str, Any]:
    """The retained status message from a status snapshot (docs/service.md, MQTT)."""
    link = snapshot.get("link") or {}
    monitor = snapshot.get("monitor") or {}
    counters = snapshot.get("counters") or {}
    payload = {
        "schema": EVENT_SCHEMA,
        "time": rfc3339(snapshot.get("time") or time.time()),
        "state": snapshot.get("state", "starting"),
        "t": snapshot.get("t"),
        "friction_level": monitor.get("friction_level"),
        "theta1": monitor.get("theta1"),
        "theta2": monitor.get("theta2"),
        "statistic": monitor.get("statistic"),
        "threshold": monitor.get("threshold"),
        "residual_rms": monitor.get("residual_rms"),
        "link_connected": bool(link.get("connected")),
        "samples": link.get("samples", 0),
        "gaps": link.get("gaps", 0),
        "deadline_misses": link.get("deadline_misses", 0),
        "alarm_episodes": counters.get("fault_detected", 0),
    }
    if outbox is not None:
        payload["mqtt"] = {
            "buffered": len(outbox),
            "lost": outbox.lost,
            "skipped_events": skipped_events,
        }
    return mqtt_payloads.with_units(payload)


class MqttSink:
    """Publishes events and the status of one rig (see the module doc)."""

    def __init__(
        self,
        settings: dict[str, Any],
        outbox_path: str | Path,
        source: str = "config",
        queue_size: int = 4096,
    ) -> None:
        try:
            import paho.mqtt.client as mqtt
        except ImportError:
            raise ConfigError(
                f"{source}: mqtt.enabled needs paho-mqtt: pip install 'fdi[fleet]'"
            ) from None

        self.settings = settings
        self.prefix = topic_prefix(settings)
        self.event_topic = f"{self.prefix}/event"  # + "/<kind>"
        self.status_topic = f"{self.prefix}/status"
        self.availability_topic = f"{self.prefix}/availability"
        self.alarm_topic = f"{self.prefix}/alarm"
        self.discovery_prefix: str | None = settings.get("discovery_prefix", "homeassistant")
        self._alarm: dict[str, Any] | None = None  # the retained operator alarm
        self.where = f"{settings['host']}:{settings['port']}"
        self.status_period_s = settings["status_period_s"]
        self.skipped_events = 0
        self.connected = False
        self._outage_logged = False  # paho retries every few s: say it once per outage
        self._next_status = -float("inf")
        self._last_snapshot: dict[str, Any] = {"state": "starting"}
        self._in_flight: tuple[int, int] | None = None  # (message seq, paho mid)
        password = read_password(settings, source)
        client_id = settings["client_id"] or "fdi-" + self.prefix[4:].replace("/", "-")
        client = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id=client_id)
        if settings["username"] is not None:
            client.username_pw_set(settings["username"], password)
        tls = settings["tls"]
        if tls["enabled"]:
            if tls["key_file"] and not tls["cert_file"]:
                raise ConfigError(f"{source}: mqtt.tls.key_file needs mqtt.tls.cert_file")
            try:
                client.tls_set(
                    ca_certs=tls["ca_file"], certfile=tls["cert_file"], keyfile=tls["key_file"]
                )
            except (OSError, ValueError) as exc:
                raise ConfigError(f"{source}: mqtt.tls: {exc}") from None
        client.will_set(self.availability_topic, json.dumps(LAST_WILL), qos=1, retain=True)
        client.reconnect_delay_set(RECONNECT_MIN_S, RECONNECT_MAX_S)  # type: ignore[arg-type]  # paho annotates int; floats work
        client.on_connect = self._on_connect
        client.on_disconnect = self._on_disconnect
        client.on_connect_fail = self._on_connect_fail
        client.on_publish = self._on_publish
        self._mqtt = mqtt
        self.client = client
        self.outbox = AlarmOutbox(outbox_path, settings["buffer_max_messages"])
        self.worker = Worker("mqtt", self._handle, queue_size)
        client.connect_async(settings["host"], settings["port"], settings["keepalive_s"])
        client.loop_start()

    # --- called by the daemon's sink worker
    def event(self, event: dict) -> None:
        """A stamped event (`stamp_event`)."""
        self.worker.put(("event", event), critical=True)

    def status(self, snapshot: dict[str, Any]) -> None:
        now = time.monotonic()
        if now >= self._next_status:
            self._next_status = now + self.status_period_s
            self.worker.put(("status", snapshot))

    def dropped(self) -> int:
        return self.worker.dropped

    # --- paho's network thread: only queue
    def _on_connect(self, client, userdata, flags, reason_code, properties) -> None:
        if reason_code.is_failure:
            self.worker.put(
                ("down", f"the broker refused the connection: {reason_code}"), critical=True
            )
        else:
            self.worker.put(("connected", None), critical=True)

    def _on_connect_fail(self, client, userdata) -> None:
        self.worker.put(("down", "cannot connect"), critical=True)

    def _on_disconnect(self, client, userdata, flags, reason_code, properties) -> None:
        self.worker.put(("disconnected", str(reason_code)), critical=True)

    def _on_publish(self, client, userdata, mid, reason_code, properties) -> None:
        self.worker.put(("acked", mid), critical=True)

    # --- this sink's worker thread: the outbox and every publish
    def _handle(self, item: tuple[str, Any]) -> None:
        kind, value = item
        if kind == "event":
            self._event(value)
        elif kind == "status":
            self._last_snapshot = value
            if self._alarm is None and value.get("alarm"):
                self._set_alarm(mqtt_payloads.alarm_from_summary(value["alarm"], time.time()))
            if self.connected:
                self._publish(self.status_topic, self._status(), qos=0, retain=True)
        elif kind == "acked":
            if self._in_flight is not None and self._in_flight[1] == value:
                self.outbox.ack(self._in_flight[0])
                self._in_flight = None
        elif kind == "connected":
            self.connected = True
            self._outage_logged = False
            log.info(
                "MQTT connected to %s (topics %s/#); %d alarm(s) waiting",
                self.where,
                self.prefix,
                len(self.outbox),
            )
            self._publish(self.status_topic, self._status(), qos=1, retain=True)
            online = mqtt_payloads.availability(True, time.time(), "connected")
            self._publish(self.availability_topic, online, qos=1, retain=True)
            if self._alarm is not None:
                self._publish(self.alarm_topic, self._alarm, qos=1, retain=True)
            if self.discovery_prefix is not None:
                for topic, config in mqtt_payloads.discovery(self.prefix, self.discovery_prefix):
                    self._publish(topic, config, qos=1, retain=True)
        elif kind in ("disconnected", "down"):
            if not self._outage_logged:
                self._outage_logged = True
                log.warning(
                    "MQTT broker %s: %s (%s); retrying, alarms wait on disk in %s",
                    self.where,
                    "connection lost" if self.connected else "no connection",
                    value,
                    self.outbox.path,
                )
            self.connected = False
        self._pump()

    def _event(self, event: dict) -> None:
        event = mqtt_payloads.with_units(event)
        if event.get("kind") in LIFECYCLE_KINDS:
            baseline = (self._last_snapshot.get("alarm") or {}).get("baseline_level")
            self._set_alarm(mqtt_payloads.alarm_from_event(event, baseline))
        if event.get("kind") not in ALARM_KINDS:
            if self.connected:
                self._publish(f"{self.event_topic}/{event.get('kind')}", event, qos=0)
            else:
                self.skipped_events += 1
            return
        in_flight = self._in_flight[0] if self._in_flight else None
        _, dropped = self.outbox.add(event, in_flight)
        for lost in dropped:
            log.warning(
                "MQTT alarm buffer full (%d): dropped alarm message seq %d (%s at t=%s); "
                "%d lost since start",
                self.outbox.max_messages,
                lost["seq"],
                lost.get("kind"),
                lost.get("t"),
                self.outbox.lost,
            )

    def _set_alarm(self, alarm: dict[str, Any]) -> None:
        """Keep the operator alarm and publish it (retained) while connected."""
        self._alarm = alarm
        if self.connected:
            self._publish(self.alarm_topic, alarm, qos=1, retain=True)

    def _pump(self) -> None:
        """Hand the oldest waiting alarm to the client when none is in flight."""
        if self._in_flight is not None or not self.connected:
            return
        message = self.outbox.head()
        if message is None:
            return
        info = self._publish(f"{self.event_topic}/{message.get('kind')}", message, qos=1)
        if info is not None:
            self._in_flight = (message["seq"], info.mid)
            self.outbox.mark_sent(message["seq"])

    def _publish(self, topic: str, payload: dict, qos: int, retain: bool = False):
        info = self.client.publish(topic, json_line(payload).rstrip("\n"), qos=qos, retain=retain)
        if info.rc == self._mqtt.MQTT_ERR_SUCCESS:
            return info
        if info.rc != self._mqtt.MQTT_ERR_NO_CONN:
            log.error("MQTT publish to %s failed: %s", topic, self._mqtt.error_string(info.rc))
        return None

    def _status(self) -> dict[str, Any]:
        return status_payload(self._last_snapshot, self.outbox, self.skipped_events)

    def close(self, timeout_s: float = 5.0) -> None:
        """Deliver the waiting alarms (for up to ``timeout_s``), mark the rig offline on the
        availability topic (retained; the status stays), disconnect. What is not delivered stays in the outbox file."""
        deadline = time.monotonic() + timeout_s
        while self.connected and len(self.outbox) and time.monotonic() < deadline:
            time.sleep(0.05)
        self.worker.close()
        if self.connected:
            offline = mqtt_payloads.availability(False, time.time(), "stopped")
            info = self.client.publish(
                self.availability_topic, json.dumps(offline), qos=1, retain=True
            )
            if info.rc == self._mqtt.MQTT_ERR_SUCCESS:
                info.wait_for_publish(max(0.1, deadline - time.monotonic()))
        self.client.disconnect()
        self.client.loop_stop()
        self.outbox.close()
