"""The rig config's sections as pydantic models: types, defaults, ranges, doc lines.

Strict (``"502"`` is not a port, ``true`` is not a number, an int is a number), unknown keys
forbidden. `fdi_daemon.service.config` turns a validation error into one line naming the
key path; ``fdi_daemon/data/config.schema.json`` is `RigFile`'s JSON Schema (for editors).
The ``link`` mapping is the links' own (`fdi_daemon.io.links.base.link_settings`) and the
``monitor`` sections the model file's, so both are free mappings here.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Annotated, Any, Literal

from pydantic import AfterValidator, BaseModel, ConfigDict, Field, model_validator

from fdi_daemon.alarms.lifecycle import AlarmSettings
from hil_sim.devices.realtime import FAULT_NAMES

__all__ = ["RigFile", "SIM_TRANSPORTS", "SIM_FAULT_KEYS", "SECTIONS"]

SIM_TRANSPORTS = ("modbus-tcp", "modbus-rtu", "serial")
#: the faults a simulated_device.faults entry may set (the fake device's own list)
SIM_FAULT_KEYS = FAULT_NAMES


def _rule(ok: Callable[[Any], bool], problem: str) -> AfterValidator:
    """A check after the type's: ``ok(value)`` or a ValueError ``problem`` (the error line
    reads ``<key path> <problem> (got <value>)``)."""

    def check(value: Any) -> Any:
        if not ok(value):
            raise ValueError(problem)
        return value

    return AfterValidator(check)


def _is_listen(v: str) -> bool:
    host, sep, port = v.rpartition(":")
    return bool(sep and host and port.isdigit() and int(port) <= 65535)


def _is_steps(v: list[float]) -> bool:
    return bool(v) and all(0 < x < math.inf for x in v) and all(a < b for a, b in zip(v, v[1:]))


_POSITIVE = _rule(lambda v: v > 0 and math.isfinite(v), "must be a positive number")
Positive = Annotated[float, _POSITIVE]
PositiveInt = Annotated[int, _POSITIVE]
NonNegative = Annotated[float, _rule(lambda v: v >= 0 and math.isfinite(v), "must be >= 0")]
Port = Annotated[
    int, _rule(lambda v: 0 <= v <= 65535, "must be a TCP port 0..65535 (0 = any free port)")
]
TopicLevel = Annotated[
    str,
    _rule(
        lambda v: bool(v) and not any(c in v for c in "/+#\0"),
        "must be a non-empty MQTT topic level without / + #",
    ),
]
DeviceId = Annotated[int, _rule(lambda v: 0 <= v <= 247, "must be a Modbus device id 0..247")]
FsyncPeriod = Annotated[
    float, _rule(lambda v: 0 < v <= 1.0, "must be in (0, 1] s (a SIGKILL may lose at most 1 s)")
]
Fraction = Annotated[float, _rule(lambda v: 0 <= v <= 1, "must be a fraction in [0, 1]")]
Listen = Annotated[
    str, _rule(_is_listen, "must be HOST:PORT, e.g. 127.0.0.1:19108 (port 0 = any free port)")
]
Steps = Annotated[list[float], _rule(_is_steps, "must be a list of positive, increasing levels")]
Transport = Annotated[
    str, _rule(lambda v: v in SIM_TRANSPORTS, f"must be one of {', '.join(SIM_TRANSPORTS)}")
]


def _nullable_object(schema: dict[str, Any]) -> None:
    """A section's JSON Schema: an empty section (``sinks:``, YAML null) is allowed."""
    schema["type"] = ["object", "null"]


class Section(BaseModel):
    """A config section: strict types, no unknown keys, ``null`` = all defaults."""

    model_config = ConfigDict(
        extra="forbid", strict=True, frozen=True, json_schema_extra=_nullable_object
    )

    @model_validator(mode="before")
    @classmethod
    def _null_is_empty(cls, data: Any) -> Any:
        return {} if data is None else data


class ModelSection(Section):
    path: str | None = Field(
        default=None,
        description="model file (YAML) from `fdi identify` + `fdi signature`; "
        "relative to the config file",
    )


class ModbusStatus(Section):
    enabled: bool = Field(default=False, description="serve the status registers over Modbus TCP")
    host: str = Field(
        default="127.0.0.1", description="address to bind (loopback unless configured)"
    )
    port: Port = Field(default=5020, description="TCP port (0 = any free port, logged at start)")
    device_id: DeviceId = Field(default=1, description="Modbus device id (unit) answered")


class Sinks(Section):
    event_log: str | None = Field(
        default="events.jsonl",
        description="JSON Lines event log (append; fsync on alarms); null disables",
    )
    stdout: bool = Field(
        default=True, description="one log line per event on stdout (journald priorities)"
    )
    status_socket: str | None = Field(
        default="status.sock",
        description="Unix socket serving the JSON status snapshot; null disables",
    )
    modbus_status: ModbusStatus = ModbusStatus()


class Recorder(Section):
    enabled: bool = Field(
        default=True, description="write the raw samples as rotating CSV recordings"
    )
    dir: str = Field(default="recordings", description="folder for the recordings")
    rotate_seconds: Positive = Field(
        default=3600.0, description="start a new file after this many s of samples"
    )
    rotate_bytes: PositiveInt = Field(default=200_000_000, description="or after this many bytes")
    fsync_period_s: FsyncPeriod = Field(default=1.0, description="flush + fsync period, <= 1 s")
    keep_files: Annotated[int, _rule(lambda v: v >= 0, "must be >= 0")] = Field(
        default=0, description="delete the oldest recordings beyond this many (0 keeps all)"
    )
    format: Literal["parquet", "csv"] = Field(
        default="parquet", description="archive: parquet (closed CSVs converted) or csv"
    )


class ServiceSection(Section):
    fs: Positive | None = Field(
        default=None, description="sampling rate in Hz; null = the model's fs"
    )
    deadline_s: Positive = Field(
        default=0.05,
        description="a tick finished later than this after its sample time (paced by the "
        "device counter) is a deadline miss",
    )
    status_period_s: Positive = Field(
        default=0.1, description="how often the status snapshot is refreshed"
    )
    queue_size: PositiveInt = Field(
        default=4096,
        description="bound of the queue to the sink thread (non-critical items beyond it are "
        "dropped and counted)",
    )
    read_timeout_s: Positive = Field(default=0.05, description="longest wait in one link read")
    state_dir: str | None = Field(
        default=None,
        description="base of relative output paths; null = $STATE_DIRECTORY or else "
        "$XDG_STATE_HOME/fdi (~/.local/state/fdi)",
    )


class MqttTls(Section):
    enabled: bool = Field(default=False, description="connect with TLS")
    ca_file: str | None = Field(
        default=None,
        description="CA certificate(s) (PEM) to check the broker with; null = the system's",
    )
    cert_file: str | None = Field(
        default=None, description="client certificate (PEM) for mutual TLS"
    )
    key_file: str | None = Field(default=None, description="the client certificate's key (PEM)")


class Mqtt(Section):
    enabled: bool = Field(default=False, description="publish events and status to an MQTT broker")
    host: str = Field(default="127.0.0.1", description="broker host")
    port: Port = Field(default=1883, description="broker port (8883 is the usual one with TLS)")
    site: TopicLevel = Field(default="site", description="first topic level: fdi/<site>/<rig>/...")
    rig: TopicLevel | None = Field(
        default=None, description="second topic level; null = this host's name"
    )
    client_id: str | None = Field(
        default=None, description="MQTT client id; null = fdi-<site>-<rig>"
    )
    keepalive_s: PositiveInt = Field(
        default=30,
        description="MQTT keepalive (s); a silent daemon is declared offline after 1.5 times this",
    )
    username: str | None = Field(default=None, description="user name for the broker")
    password_file: str | None = Field(
        default=None,
        description="file holding the password (first line), relative to the config file",
    )
    password_env: str | None = Field(
        default=None, description="environment variable holding the password"
    )
    tls: MqttTls = MqttTls()
    status_period_s: Positive = Field(
        default=1.0, description="how often the retained status is published"
    )
    discovery_prefix: str | None = Field(
        default="homeassistant",
        description="topic prefix of the Home Assistant MQTT discovery messages; null = none",
    )
    buffer_file: str = Field(
        default="mqtt-outbox.jsonl",
        description="alarms waiting for the broker, on disk (relative to state_dir)",
    )
    buffer_max_messages: PositiveInt = Field(
        default=10000,
        description="bound of that buffer; beyond it the oldest alarm is dropped and counted",
    )


class Metrics(Section):
    listen: Listen | None = Field(
        default=None, description="HOST:PORT of the Prometheus exporter; null = off"
    )


_ALARM = AlarmSettings()  # the alarm defaults


class Alarms(Section):
    steps: Steps = Field(
        default=list(_ALARM.steps),
        description="friction levels above the baseline (units of the signature) that step "
        "the alarm priority up",
    )
    deadband: NonNegative = Field(
        default=_ALARM.deadband, description="a priority falls only below its step minus this"
    )
    raise_delay_s: NonNegative = Field(
        default=_ALARM.raise_delay_s,
        description="the level stays above a step this long before the priority rises",
    )
    lower_delay_s: NonNegative = Field(
        default=_ALARM.lower_delay_s,
        description="... below step - deadband this long before it falls",
    )
    return_delay_s: NonNegative = Field(
        default=_ALARM.return_delay_s,
        description="detector cleared and level back at the baseline (moving time) this long "
        "before the alarm returns to normal",
    )
    return_level: Positive = Field(
        default=_ALARM.return_level,
        description="level above the baseline under which the fault counts as gone",
    )
    max_shelve_s: Positive = Field(default=_ALARM.max_shelve_s, description="longest shelving")
    smoothing_s: NonNegative = Field(
        default=_ALARM.smoothing_s,
        description="time constant of the level smoothing the alarm decides on",
    )
    allow_remote_acknowledge: bool = Field(
        default=False,
        description="accept acknowledge/shelve requests on the status socket and Modbus",
    )
    state_file: str | None = Field(
        default="state.json", description="alarm state kept across restarts; null disables"
    )
    trend: str | None = Field(
        default="trend.sqlite", description="friction trend, one row per minute; null disables"
    )


class SimFault(Section):
    """One fault of the simulated rig: its sample time and exactly one setting."""

    at_s: NonNegative = Field(description="sample time of the fault (s)")
    bearing_supply: Fraction | None = None
    accel_bias: float | None = None
    valve_gain: float | None = None
    supply_pressure: float | None = None
    accel_dropout: float | None = None
    accel_saturation: float | None = None

    @model_validator(mode="after")
    def _exactly_one(self) -> SimFault:
        if sum(getattr(self, k) is not None for k in SIM_FAULT_KEYS) != 1:
            raise ValueError(f"must set exactly one of {', '.join(SIM_FAULT_KEYS)}")
        return self

    def setting(self) -> tuple[str, float]:
        """(name, value) of the fault's one setting."""
        return next((k, v) for k in SIM_FAULT_KEYS if (v := getattr(self, k)) is not None)


class SimulatedDevice(Section):
    transport: Transport = Field(
        default="modbus-tcp",
        description="fake device protocol: modbus-tcp | modbus-rtu | serial (pty)",
    )
    scenario: str | None = Field(
        default=None,
        description="scenario YAML played by the rig (relative to the config file); null = "
        "the fake device's default",
    )
    seed: int = Field(default=0, description="seed of the simulated rig's noise")
    faults: list[SimFault] = Field(
        default_factory=list, description="faults injected: [{at_s: 20, bearing_supply: 0.35}]"
    )


class Monitor(Section):
    detector: dict[str, Any] | None = Field(
        default=None, description="overrides the model's detector"
    )
    velocity: dict[str, Any] | None = Field(
        default=None, description="overrides the model's velocity"
    )


class RigFile(BaseModel):
    """A rig config file of `fdi run` (YAML)."""

    model_config = ConfigDict(extra="forbid", strict=True, frozen=True, title="fdi rig config")

    link: dict[str, Any] | None = Field(
        default=None,
        description="the field link: kind serial | modbus-tcp | modbus-rtu | replay | sim and "
        "its settings (docs/service.md); left out with simulated_device",
    )
    simulated_device: SimulatedDevice | None = None
    model: ModelSection = ModelSection()
    monitor: Monitor = Monitor()
    sinks: Sinks = Sinks()
    recorder: Recorder = Recorder()
    service: ServiceSection = ServiceSection()
    mqtt: Mqtt = Mqtt()
    metrics: Metrics = Metrics()
    alarms: Alarms = Alarms()


#: the sections with documented keys (docs/service.md has a table per section)
SECTIONS: dict[str, type[Section]] = {
    "model": ModelSection,
    "sinks": Sinks,
    "recorder": Recorder,
    "service": ServiceSection,
    "mqtt": Mqtt,
    "metrics": Metrics,
    "alarms": Alarms,
    "simulated_device": SimulatedDevice,
}
