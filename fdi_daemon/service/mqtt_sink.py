"""MQTT sink: events and a retained status on a broker; alarms kept on disk until acknowledged.

Topics, ``<prefix>`` = ``fdi/<site>/<rig>``:

- ``<prefix>/event``: every event as JSON, as the event log writes it (`stamp_event`: ``t``,
  ``kind``, ..., ``time``, ``schema``). Alarm kinds (``fault_detected``,
  ``friction_isolated``, ``other_fault``, ``cleared``) go with QoS 1 through the on-disk
  `AlarmOutbox`; each carries ``id`` (consecutive per rig, kept across restarts) and
  ``dup: true`` when it is published again after a daemon restart because the broker's
  acknowledgement of an earlier send was not recorded. Other kinds go with QoS 0 while the
  broker is there and are skipped (and counted) while it is not; the event log has them all.
- ``<prefix>/status``: retained, every ``status_period_s`` (1 s):
  `status_payload` (``online``, ``state``, ``friction_level``, θ, counters, the outbox's
  ``buffered`` and ``lost``). On every connect a status with ``online: true`` (QoS 1); the
  last will, ``{"online": false, "state": "offline"}`` (retained, QoS 1), is published by the
  broker when the connection dies without a clean disconnect (SIGKILL, power, network);
  a clean stop publishes the same itself before disconnecting.

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
from typing import Any

from fdi_daemon.detect.events import EVENT_SCHEMA
from fdi_daemon.errors import ConfigError
from fdi_daemon.service.sinks import ALARM_KINDS, Worker, json_line, rfc3339

log = logging.getLogger("fdi.mqtt")

#: paho's reconnect backoff (s): first retry, cap
RECONNECT_MIN_S = 0.5
RECONNECT_MAX_S = 5.0
#: the last will (retained on the status topic), also published on a clean stop
OFFLINE = {"schema": EVENT_SCHEMA, "online": False, "state": "offline"}
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
        password = lines[0] if lines else ""
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
    and fsynced), ``{"sent": id}`` when it is handed to the client, ``{"ack": id}`` when the
    broker acknowledged it, ``{"drop": id}`` when the bound pushed it out. Loading replays
    these lines; a message that was sent but not acknowledged comes back with ``dup: true``.
    The file is rewritten with only what is pending (and ``{"next_id": n}``, so ids never
    repeat) at load and whenever it holds `COMPACT_SLACK_LINES` lines more than that.
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
        self._fh = None
        self._rewrite()

    def __len__(self) -> int:
        return len(self.pending)

    def head(self) -> dict | None:
        return next(iter(self.pending.values()), None)

    def add(self, payload: dict, in_flight: int | None = None) -> tuple[dict, list[dict]]:
        """Queue an alarm; returns it (with ``id``) and the alarms dropped to make room."""
        message = {**payload, "id": self.next_id}
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
        self.pending[message["id"]] = message
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
                self.pending[message["id"]] = message
                self.next_id = max(self.next_id, message["id"] + 1)
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
        "online": True,
        "state": snapshot.get("state", "starting"),
        "t": snapshot.get("t"),
        "friction_level": monitor.get("friction_level"),
        "theta1": monitor.get("theta1"),
        "theta2": monitor.get("theta2"),
        "statistic": monitor.get("statistic"),
        "threshold": monitor.get("threshold"),
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
    return payload


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
        self.event_topic = f"{self.prefix}/event"
        self.status_topic = f"{self.prefix}/status"
        self.where = f"{settings['host']}:{settings['port']}"
        self.status_period_s = settings["status_period_s"]
        self.skipped_events = 0
        self.connected = False
        self._outage_logged = False  # paho retries every few s: say it once per outage
        self._next_status = -float("inf")
        self._last_snapshot: dict[str, Any] = {"state": "starting"}
        self._in_flight: tuple[int, int] | None = None  # (alarm id, paho mid)
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
        client.will_set(self.status_topic, json.dumps(OFFLINE), qos=1, retain=True)
        client.reconnect_delay_set(RECONNECT_MIN_S, RECONNECT_MAX_S)
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
        if event.get("kind") not in ALARM_KINDS:
            if self.connected:
                self._publish(self.event_topic, event, qos=0)
            else:
                self.skipped_events += 1
            return
        in_flight = self._in_flight[0] if self._in_flight else None
        _, dropped = self.outbox.add(event, in_flight)
        for lost in dropped:
            log.warning(
                "MQTT alarm buffer full (%d): dropped alarm id %d (%s at t=%s); "
                "%d lost since start",
                self.outbox.max_messages,
                lost["id"],
                lost.get("kind"),
                lost.get("t"),
                self.outbox.lost,
            )

    def _pump(self) -> None:
        """Hand the oldest waiting alarm to the client when none is in flight."""
        if self._in_flight is not None or not self.connected:
            return
        message = self.outbox.head()
        if message is None:
            return
        info = self._publish(self.event_topic, message, qos=1)
        if info is not None:
            self._in_flight = (message["id"], info.mid)
            self.outbox.mark_sent(message["id"])

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
        """Deliver the waiting alarms (for up to ``timeout_s``), mark the rig offline
        (retained), disconnect. What is not delivered stays in the outbox file."""
        deadline = time.monotonic() + timeout_s
        while self.connected and len(self.outbox) and time.monotonic() < deadline:
            time.sleep(0.05)
        self.worker.close()
        if self.connected:
            info = self.client.publish(
                self.status_topic,
                json.dumps({**OFFLINE, "time": rfc3339(time.time())}),
                qos=1,
                retain=True,
            )
            if info.rc == self._mqtt.MQTT_ERR_SUCCESS:
                info.wait_for_publish(max(0.1, deadline - time.monotonic()))
        self.client.disconnect()
        self.client.loop_stop()
        self.outbox.close()
