"""The MQTT messages other than events: availability, operator alarm, Home Assistant discovery.

Pure functions from the daemon's snapshots and events to ``(topic, payload)``; the transport
is `fdi_daemon.service.mqtt_sink`. Topics, ``<prefix>`` = ``fdi/<site>/<rig>``
(docs/service.md, MQTT):

- ``<prefix>/availability`` (retained): ``{"state": "online"|"offline", "time", "reason"}``.
  The last will is the offline message with ``time: null`` (a will is fixed at connect; the
  retained status's ``time`` says when the rig was last seen).
- ``<prefix>/alarm`` (retained): the operator alarm (ISA-18.2 state, priority, acknowledged,
  shelved, alarm id, since), from the lifecycle events and the status snapshot's ``alarm``.
- ``homeassistant/<component>/<node>/<object>/config`` (retained): Home Assistant MQTT
  discovery of the sensors over the status and alarm topics.
"""

from __future__ import annotations

import re
from typing import Any

from fdi_daemon import __version__
from fdi_daemon.alarms.lifecycle import STATE_CODES as ALARM_STATE_CODES
from fdi_daemon.alarms.lifecycle import STATES as ALARM_STATES
from fdi_daemon.detect.events import EVENT_SCHEMA
from fdi_daemon.service.sinks import STATE_CODES, rfc3339

#: the units of the numeric fields of the status, alarm and event payloads (``units``)
UNITS = {
    "t": "s",
    "friction_level": "multiple of the calibrated fault (1 = the calibrated fault)",
    "level": "multiple of the calibrated fault (1 = the calibrated fault)",
    "baseline_level": "multiple of the calibrated fault (1 = the calibrated fault)",
    "residual_rms": "m/s^2",
    "statistic": "1",
    "threshold": "1",
    "time": "RFC 3339",
    "since": "RFC 3339",
    "shelved_until": "RFC 3339",
}


def with_units(payload: dict[str, Any]) -> dict[str, Any]:
    """The payload with ``units``: the unit of each of its fields that has one."""
    return {**payload, "units": {k: UNITS[k] for k in payload if k in UNITS}}


def availability(online: bool, when: float | None, reason: str) -> dict[str, Any]:
    """The availability message; ``when`` None for the last will (time of loss unknown)."""
    return {
        "schema": EVENT_SCHEMA,
        "state": "online" if online else "offline",
        "time": None if when is None else rfc3339(when),
        "reason": reason,
    }


def _time(value: Any) -> str | None:
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return rfc3339(value)
    return value if isinstance(value, str) else None


def alarm_from_summary(summary: dict[str, Any], now: float) -> dict[str, Any]:
    """The alarm message from the snapshot's ``alarm`` section (`AlarmKeeper.summary`);
    ``since`` is when the alarm started (the summary has no time of the last change)."""
    state = summary.get("state", "normal")
    shelved = summary.get("state_code") == ALARM_STATE_CODES["shelved"]
    return alarm_message(
        state,
        int(summary.get("priority") or 0),
        int(summary.get("alarm_id") or 0),
        shelved,
        summary.get("shelved_until") if shelved else None,
        summary.get("started"),
        summary.get("level"),
        summary.get("baseline_level"),
        now,
    )


def alarm_from_event(event: dict[str, Any], baseline: float | None) -> dict[str, Any]:
    """The alarm message after a lifecycle event (`AlarmLifecycle` event fields);
    ``since`` is the event's time: the last lifecycle change."""
    shelved = bool(event.get("shelved"))
    return alarm_message(
        event.get("state", "normal"),
        int(event.get("priority") or 0),
        int(event.get("alarm_id") or 0),
        shelved,
        event.get("until") if shelved else None,
        event.get("time"),
        event.get("level"),
        baseline,
        event.get("time"),
    )


def alarm_message(
    state: str,
    priority: int,
    alarm_id: int,
    shelved: bool,
    shelved_until: Any,
    since: Any,
    level: Any,
    baseline_level: Any,
    now: Any,
) -> dict[str, Any]:
    """The retained operator alarm (times: epoch s or RFC 3339 strings)."""
    return with_units(
        {
            "schema": EVENT_SCHEMA,
            "time": _time(now),
            "alarm_id": alarm_id,
            "state": state,
            "state_code": ALARM_STATE_CODES["shelved" if shelved else state],
            "priority": priority,
            "active": state in ("unacknowledged", "acknowledged"),
            "acknowledged": state in ("acknowledged", "normal"),
            "shelved": shelved,
            "shelved_until": _time(shelved_until),
            "since": _time(since),
            "level": level,
            "baseline_level": baseline_level,
        }
    )


def _node_id(prefix: str) -> str:
    """A Home Assistant node id from the topic prefix (letters, digits, ``_`` and ``-``)."""
    return re.sub(r"[^A-Za-z0-9_-]", "_", prefix)


#: (component, object id, name, topic suffix, value template, extra config)
DISCOVERED: tuple[tuple[str, str, str, str, str, dict[str, Any]], ...] = (
    (
        "sensor",
        "state",
        "Monitor state",
        "status",
        "{{ value_json.state }}",
        {"device_class": "enum", "options": list(STATE_CODES)},
    ),
    (
        "sensor",
        "friction_level",
        "Friction level",
        "status",
        "{{ value_json.friction_level }}",
        {"unit_of_measurement": "x fault", "state_class": "measurement"},
    ),
    (
        "sensor",
        "statistic",
        "Detection statistic",
        "status",
        "{{ value_json.statistic }}",
        {"state_class": "measurement"},
    ),
    (
        "sensor",
        "sample_time",
        "Sample time",
        "status",
        "{{ value_json.t }}",
        {"unit_of_measurement": "s", "device_class": "duration", "entity_category": "diagnostic"},
    ),
    (
        "binary_sensor",
        "link_connected",
        "Data link",
        "status",
        "{{ 'ON' if value_json.link_connected else 'OFF' }}",
        {"device_class": "connectivity", "entity_category": "diagnostic"},
    ),
    (
        "sensor",
        "alarm_state",
        "Alarm state",
        "alarm",
        "{{ value_json.state }}",
        {"device_class": "enum", "options": list(ALARM_STATES)},
    ),
    ("sensor", "alarm_priority", "Alarm priority", "alarm", "{{ value_json.priority }}", {}),
    (
        "binary_sensor",
        "alarm_active",
        "Friction alarm",
        "alarm",
        "{{ 'ON' if value_json.active else 'OFF' }}",
        {"device_class": "problem"},
    ),
    (
        "binary_sensor",
        "alarm_shelved",
        "Alarm shelved",
        "alarm",
        "{{ 'ON' if value_json.shelved else 'OFF' }}",
        {},
    ),
)


def discovery(prefix: str, discovery_prefix: str) -> list[tuple[str, dict[str, Any]]]:
    """Home Assistant MQTT discovery: ``(config topic, config)`` for each sensor."""
    node = _node_id(prefix)
    device = {
        "identifiers": [node],
        "name": f"fdi {prefix.removeprefix('fdi/')}",
        "manufacturer": "fdi",
        "model": "friction fault detection (servo-pneumatic actuator)",
        "sw_version": __version__,
    }
    messages = []
    for component, object_id, name, suffix, template, extra in DISCOVERED:
        config = {
            "name": name,
            "unique_id": f"{node}_{object_id}",
            "object_id": f"{node}_{object_id}",
            "device": device,
            "state_topic": f"{prefix}/{suffix}",
            "value_template": template,
            "availability_topic": f"{prefix}/availability",
            "availability_template": "{{ value_json.state }}",
            "payload_available": "online",
            "payload_not_available": "offline",
            **extra,
        }
        messages.append((f"{discovery_prefix}/{component}/{node}/{object_id}/config", config))
    return messages
