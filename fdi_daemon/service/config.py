"""The rig config of `fdi run` (YAML), validated key by key.

Every key is checked: an unknown key, a wrong type or a value out of range is a
`ConfigError` naming the key path (``sinks.modbus_status.port``). Defaults are listed in
`SCHEMA` below and in ``docs/service.md``.

Paths. ``model.path`` is relative to the config file's folder. Output paths (event log,
recorder folder, status socket) are relative to ``service.state_dir``, whose default is
``$STATE_DIRECTORY`` (set by systemd's ``StateDirectory=``) or else ``$XDG_STATE_HOME/fdi``
(``~/.local/state/fdi``); see `default_state_dir`.

Sections::

    link:              # passed to fdi_daemon.io.links.make_link (its keys are the link's)
      kind: modbus-tcp # serial | modbus-tcp | modbus-rtu | replay | sim
      ...
    simulated_device:  # optional: serve the simulated rig in-process and link to it
      transport: modbus-tcp     # modbus-tcp | modbus-rtu | serial
      scenario: null            # excitation program (configs/scenarios/*.yaml)
      seed: 0
      faults: [{at_s: 20.0, bearing_supply: 0.35}]
    model: {path: model.yaml}
    monitor: {detector: {...}, velocity: {...}}   # override the model's sections
    sinks: {event_log, stdout, status_socket, modbus_status: {enabled, host, port, device_id}}
    recorder: {enabled, dir, rotate_seconds, rotate_bytes, fsync_period_s, keep_files, format}
    service: {fs, deadline_s, status_period_s, queue_size, read_timeout_s, state_dir}
    mqtt: {enabled, host, port, site, rig, username, password_file, password_env, tls: {...}, ...}
    metrics: {listen}  # Prometheus exporter, e.g. 127.0.0.1:9108; null (default) = off

Secrets (the MQTT password) are never read from the YAML: ``mqtt.password`` is refused;
``mqtt.password_file`` or ``mqtt.password_env`` name where the daemon reads it.
    alarms: {steps, deadband, raise_delay_s, lower_delay_s, return_delay_s, max_shelve_s,
             allow_remote_acknowledge, state_file, trend}

Reconnect backoff is the link's: ``link.reconnect: {backoff_initial_s, backoff_max_s,
stall_timeout_s}`` (see `fdi_daemon.io.links.base`).
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from fdi_daemon.alarms.lifecycle import AlarmSettings
from fdi_daemon.errors import ConfigError, UserError
from fdi_daemon.io.yaml_file import read_yaml

__all__ = [
    "RigConfig",
    "load_config",
    "config_from_dict",
    "default_config_path",
    "default_state_dir",
    "SCHEMA",
]

LINK_KINDS = ("serial", "modbus-tcp", "modbus-rtu", "replay", "sim")
SIM_TRANSPORTS = ("modbus-tcp", "modbus-rtu", "serial")
SIM_FAULT_KEYS = (
    "bearing_supply",
    "accel_bias",
    "valve_gain",
    "supply_pressure",
    "accel_dropout",
    "accel_saturation",
)


@dataclass(frozen=True)
class Field:
    """One scalar key: accepted types, default, optional range check and its doc line."""

    types: tuple[type, ...]
    default: Any
    doc: str
    check: Callable[[Any], str | None] | None = None
    nullable: bool = False


def _positive(v: Any) -> str | None:
    return None if v > 0 and math.isfinite(v) else "must be a positive number"


def _non_negative(v: Any) -> str | None:
    return None if v >= 0 and math.isfinite(v) else "must be >= 0"


def _port(v: Any) -> str | None:
    return None if 0 <= v <= 65535 else "must be a TCP port 0..65535 (0 = any free port)"


def _device_id(v: Any) -> str | None:
    return None if 0 <= v <= 247 else "must be a Modbus device id 0..247"


def _fsync_period(v: Any) -> str | None:
    return None if 0 < v <= 1.0 else "must be in (0, 1] s (a SIGKILL may lose at most 1 s)"


def _fraction(v: Any) -> str | None:
    return None if 0 <= v <= 1 else "must be a fraction in [0, 1]"


def _topic_level(v: Any) -> str | None:
    bad = not v or any(c in v for c in "/+#\0")
    return "must be a non-empty MQTT topic level without / + #" if bad else None


def _listen(v: Any) -> str | None:
    host, sep, port = v.rpartition(":")
    if sep and host and port.isdigit() and int(port) <= 65535:
        return None
    return "must be HOST:PORT, e.g. 127.0.0.1:9108 (port 0 = any free port)"


def _steps(v: Any) -> str | None:
    ok = (
        v
        and all(
            isinstance(x, (int, float)) and not isinstance(x, bool) and 0 < x < math.inf for x in v
        )
        and all(a < b for a, b in zip(v, v[1:]))
    )
    return None if ok else "must be a list of positive, increasing levels"


def _one_of(*choices: str) -> Callable[[Any], str | None]:
    def check(v: Any) -> str | None:
        return None if v in choices else f"must be one of {', '.join(choices)}"

    return check


_ALARM = AlarmSettings()  # the alarm defaults
NUM = (int, float)
STR = (str,)
BOOL = (bool,)
INT = (int,)

#: section -> key -> Field, or section -> key -> nested dict of Fields
SCHEMA: dict[str, dict[str, Any]] = {
    "model": {
        "path": Field(
            STR,
            None,
            "model file (YAML) from `fdi identify` + `fdi signature`; relative to the config file",
        ),
    },
    "sinks": {
        "event_log": Field(
            STR,
            "events.jsonl",
            "JSON Lines event log (append; fsync on alarms); null disables",
            nullable=True,
        ),
        "stdout": Field(BOOL, True, "one log line per event on stdout (journald priorities)"),
        "status_socket": Field(
            STR,
            "status.sock",
            "Unix socket serving the JSON status snapshot; null disables",
            nullable=True,
        ),
        "modbus_status": {
            "enabled": Field(BOOL, False, "serve the status registers over Modbus TCP"),
            "host": Field(STR, "127.0.0.1", "address to bind (loopback unless configured)"),
            "port": Field(INT, 5020, "TCP port (0 = any free port, logged at start)", _port),
            "device_id": Field(INT, 1, "Modbus device id (unit) answered", _device_id),
        },
    },
    "recorder": {
        "enabled": Field(BOOL, True, "write the raw samples as rotating CSV recordings"),
        "dir": Field(STR, "recordings", "folder for the recordings"),
        "rotate_seconds": Field(
            NUM, 3600.0, "start a new file after this many s of samples", _positive
        ),
        "rotate_bytes": Field(INT, 200_000_000, "or after this many bytes", _positive),
        "fsync_period_s": Field(NUM, 1.0, "flush + fsync period, <= 1 s", _fsync_period),
        "keep_files": Field(
            INT, 0, "delete the oldest recordings beyond this many (0 keeps all)", _non_negative
        ),
        "format": Field(
            STR,
            "parquet",
            "archive: parquet (closed CSVs converted) or csv",
            _one_of("parquet", "csv"),
        ),
    },
    "service": {
        "fs": Field(
            NUM, None, "sampling rate in Hz; null = the model's fs", _positive, nullable=True
        ),
        "deadline_s": Field(
            NUM,
            0.05,
            "a tick finished later than this after its sample "
            "time (paced by the device counter) is a deadline miss",
            _positive,
        ),
        "status_period_s": Field(NUM, 0.1, "how often the status snapshot is refreshed", _positive),
        "queue_size": Field(
            INT,
            4096,
            "bound of the queue to the sink thread (non-critical "
            "items beyond it are dropped and counted)",
            _positive,
        ),
        "read_timeout_s": Field(NUM, 0.05, "longest wait in one link read", _positive),
        "state_dir": Field(
            STR,
            None,
            "base of relative output paths; null = "
            "$STATE_DIRECTORY or else $XDG_STATE_HOME/fdi "
            "(~/.local/state/fdi)",
            nullable=True,
        ),
    },
    "mqtt": {
        "enabled": Field(BOOL, False, "publish events and status to an MQTT broker"),
        "host": Field(STR, "127.0.0.1", "broker host"),
        "port": Field(INT, 1883, "broker port (8883 is the usual one with TLS)", _port),
        "site": Field(STR, "site", "first topic level: fdi/<site>/<rig>/...", _topic_level),
        "rig": Field(
            STR, None, "second topic level; null = this host's name", _topic_level, nullable=True
        ),
        "client_id": Field(STR, None, "MQTT client id; null = fdi-<site>-<rig>", nullable=True),
        "keepalive_s": Field(
            INT,
            30,
            "MQTT keepalive (s); a silent daemon is declared offline after 1.5 times this",
            _positive,
        ),
        "username": Field(STR, None, "user name for the broker", nullable=True),
        "password_file": Field(
            STR,
            None,
            "file holding the password (first line), relative to the config file",
            nullable=True,
        ),
        "password_env": Field(
            STR, None, "environment variable holding the password", nullable=True
        ),
        "tls": {
            "enabled": Field(BOOL, False, "connect with TLS"),
            "ca_file": Field(
                STR,
                None,
                "CA certificate(s) (PEM) to check the broker with; null = the system's",
                nullable=True,
            ),
            "cert_file": Field(STR, None, "client certificate (PEM) for mutual TLS", nullable=True),
            "key_file": Field(STR, None, "the client certificate's key (PEM)", nullable=True),
        },
        "status_period_s": Field(NUM, 1.0, "how often the retained status is published", _positive),
        "buffer_file": Field(
            STR,
            "mqtt-outbox.jsonl",
            "alarms waiting for the broker, on disk (relative to state_dir)",
        ),
        "buffer_max_messages": Field(
            INT,
            10000,
            "bound of that buffer; beyond it the oldest alarm is dropped and counted",
            _positive,
        ),
    },
    "metrics": {
        "listen": Field(
            STR, None, "HOST:PORT of the Prometheus exporter; null = off", _listen, nullable=True
        ),
    },
    "alarms": {
        "steps": Field(
            (list,),
            _ALARM.steps,
            "friction levels above the baseline (units "
            "of the signature) that step the alarm "
            "priority up",
            _steps,
        ),
        "deadband": Field(
            NUM, _ALARM.deadband, "a priority falls only below its step minus this", _non_negative
        ),
        "raise_delay_s": Field(
            NUM,
            _ALARM.raise_delay_s,
            "the level stays above a step this long before the priority rises",
            _non_negative,
        ),
        "lower_delay_s": Field(
            NUM,
            _ALARM.lower_delay_s,
            "... below step - deadband this long before it falls",
            _non_negative,
        ),
        "return_delay_s": Field(
            NUM,
            _ALARM.return_delay_s,
            "detector cleared and level back at the "
            "baseline (moving time) this long before the "
            "alarm returns to normal",
            _non_negative,
        ),
        "return_level": Field(
            NUM,
            _ALARM.return_level,
            "level above the baseline under which the fault counts as gone",
            _positive,
        ),
        "max_shelve_s": Field(NUM, _ALARM.max_shelve_s, "longest shelving", _positive),
        "smoothing_s": Field(
            NUM,
            _ALARM.smoothing_s,
            "time constant of the level smoothing the alarm decides on",
            _non_negative,
        ),
        "allow_remote_acknowledge": Field(
            BOOL, False, "accept acknowledge/shelve requests on the status socket and Modbus"
        ),
        "state_file": Field(
            STR, "state.json", "alarm state kept across restarts; null disables", nullable=True
        ),
        "trend": Field(
            STR, "trend.sqlite", "friction trend, one row per minute; null disables", nullable=True
        ),
    },
    "simulated_device": {
        "transport": Field(
            STR,
            "modbus-tcp",
            "fake device protocol: modbus-tcp | modbus-rtu | serial (pty)",
            _one_of(*SIM_TRANSPORTS),
        ),
        "scenario": Field(
            STR,
            None,
            "scenario YAML played by the rig (relative to the config "
            "file); null = the fake device's default",
            nullable=True,
        ),
        "seed": Field(INT, 0, "seed of the simulated rig's noise"),
    },
}

TOP_LEVEL = (
    "link",
    "simulated_device",
    "model",
    "monitor",
    "sinks",
    "recorder",
    "service",
    "mqtt",
    "metrics",
    "alarms",
)
#: keys that would put a secret into the YAML, refused with where to put it instead
SECRET_KEYS = ("password", "passwd", "secret")


@dataclass
class RigConfig:
    """A validated config: plain mappings with every default filled in."""

    source: str
    base_dir: Path
    link: dict[str, Any]
    simulated_device: dict[str, Any] | None
    model_path: Path
    monitor: dict[str, dict[str, Any]]
    sinks: dict[str, Any]
    recorder: dict[str, Any]
    service: dict[str, Any]
    mqtt: dict[str, Any]
    metrics: dict[str, Any]
    alarms: dict[str, Any]

    @property
    def state_dir(self) -> Path:
        configured = self.service["state_dir"]
        if configured:
            return Path(configured).expanduser()
        return default_state_dir()

    def output_path(self, value: str | None) -> Path | None:
        """An output path from the config, relative ones under ``state_dir``."""
        if value is None:
            return None
        path = Path(value).expanduser()
        return path if path.is_absolute() else self.state_dir / path


def default_state_dir() -> Path:
    """Where outputs go when the config names no ``service.state_dir``: systemd's
    ``$STATE_DIRECTORY`` (its first entry) under the unit, else the XDG base directory
    spec's ``$XDG_STATE_HOME/fdi`` (an absolute $XDG_STATE_HOME only, default
    ``~/.local/state/fdi``), never the current directory."""
    systemd = os.environ.get("STATE_DIRECTORY", "").split(":")[0]
    if systemd:
        return Path(systemd)
    xdg = os.environ.get("XDG_STATE_HOME", "")
    base = Path(xdg) if xdg and Path(xdg).is_absolute() else Path.home() / ".local" / "state"
    return base / "fdi"


def default_config_path() -> Path:
    """The embedded default: the simulated rig over a real link with a friction fault."""
    return Path(__file__).resolve().parents[1] / "data" / "default_config.yaml"


def load_config(path: str | Path | None = None) -> RigConfig:
    """Read and validate a rig config (the embedded default when path is None)."""
    path = Path(path) if path is not None else default_config_path()
    data = read_yaml(path, "config")
    return config_from_dict(data, str(path), path.resolve().parent)


def config_from_dict(data: Any, source: str = "config", base_dir: Path | None = None) -> RigConfig:
    """Validate a parsed config mapping; errors name ``source`` and the key path."""
    base_dir = base_dir or Path.cwd()
    if not isinstance(data, dict):
        raise ConfigError(
            f"{source}: a rig config must be a mapping with sections {', '.join(TOP_LEVEL)}"
        )
    _no_unknown(data, TOP_LEVEL, "", source)
    sim = _resolve_scenario(_simulated_device(data, source), base_dir)
    link = _resolve_replay_path(_link(data.get("link"), sim is not None, source), base_dir)
    model = _section(data, "model", source)
    if model["path"] is None:
        raise ConfigError(f"{source}: model.path is required (the model file to monitor with)")
    model_path = Path(model["path"]).expanduser()
    if not model_path.is_absolute():
        model_path = base_dir / model_path
    config = RigConfig(
        source=source,
        base_dir=base_dir,
        link=link,
        simulated_device=sim,
        model_path=model_path,
        monitor=_monitor(data.get("monitor"), source),
        sinks=_section(data, "sinks", source),
        recorder=_section(data, "recorder", source),
        service=_section(data, "service", source),
        mqtt=_mqtt(data, source, base_dir),
        metrics=_section(data, "metrics", source),
        alarms=_alarms(data, source),
    )
    check_files(config)
    return config


def _mqtt(data: Mapping, source: str, base_dir: Path) -> dict[str, Any]:
    """The ``mqtt`` section; a secret written into it is refused, a password file resolved."""
    given = data.get("mqtt")
    for key in SECRET_KEYS:
        if isinstance(given, dict) and key in given:
            raise ConfigError(
                f"{source}: mqtt.{key}: secrets are not read from the config; "
                "put the password in a file (mqtt.password_file) or an "
                "environment variable (mqtt.password_env)"
            )
    mqtt = _section(data, "mqtt", source)
    if mqtt["password_file"] is not None and mqtt["password_env"] is not None:
        raise ConfigError(f"{source}: mqtt.password_file and mqtt.password_env: set one")
    mqtt["password_file"] = _beside(mqtt["password_file"], base_dir)
    for key in ("ca_file", "cert_file", "key_file"):
        mqtt["tls"][key] = _beside(mqtt["tls"][key], base_dir)
    return mqtt


def _beside(value: str | None, base_dir: Path) -> str | None:
    """A file named in the config: relative paths are relative to the config's folder."""
    if value is None:
        return None
    path = Path(value).expanduser()
    return str(path if path.is_absolute() else base_dir / path)


def _alarms(data: Mapping, source: str) -> dict[str, Any]:
    """The alarms section; its settings checked together (deadband below the lowest step)."""
    alarms = _section(data, "alarms", source)
    alarms["steps"] = tuple(float(x) for x in alarms["steps"])
    try:
        alarms["settings"] = AlarmSettings(
            **{
                k: alarms[k]
                for k in (
                    "steps",
                    "deadband",
                    "raise_delay_s",
                    "lower_delay_s",
                    "return_delay_s",
                    "max_shelve_s",
                    "smoothing_s",
                    "return_level",
                )
            }
        )
    except ValueError as exc:
        raise ConfigError(f"{source}: alarms: {exc}") from None
    return alarms


def _no_unknown(data: Mapping, known: tuple[str, ...] | Mapping, prefix: str, source: str) -> None:
    for key in data:
        if key not in known:
            raise ConfigError(f"{source}: {prefix}{key}: unknown key (known: {', '.join(known)})")


def _section(data: Mapping, name: str, source: str) -> dict[str, Any]:
    value = data.get(name)
    if value is None:
        value = {}
    if not isinstance(value, dict):
        raise ConfigError(f"{source}: {name} must be a mapping")
    return _fill(value, SCHEMA[name], f"{name}.", source)


def _fill(value: Mapping, schema: Mapping[str, Any], prefix: str, source: str) -> dict[str, Any]:
    _no_unknown(value, schema, prefix, source)
    out: dict[str, Any] = {}
    for key, spec in schema.items():
        path = f"{prefix}{key}"
        given = value.get(key)
        if isinstance(spec, dict):
            if given is None:
                given = {}
            if not isinstance(given, dict):
                raise ConfigError(f"{source}: {path} must be a mapping")
            out[key] = _fill(given, spec, f"{path}.", source)
        else:
            out[key] = _scalar(given, spec, path, source, key in value)
    return out


def _scalar(value: Any, spec: Field, path: str, source: str, present: bool) -> Any:
    if value is None:
        if not present:
            return spec.default
        if spec.nullable:
            return None
        if spec.default is not None:
            raise ConfigError(f"{source}: {path} may not be null (default {spec.default!r})")
        return None
    if isinstance(value, bool) and bool not in spec.types:
        raise ConfigError(f"{source}: {path} must be {_type_names(spec.types)}, not {value!r}")
    if not isinstance(value, spec.types):
        raise ConfigError(f"{source}: {path} must be {_type_names(spec.types)}, not {value!r}")
    if spec.types == NUM:
        value = float(value)
    if spec.check is not None and (problem := spec.check(value)):
        raise ConfigError(f"{source}: {path} {problem} (got {value!r})")
    return value


def _type_names(types: tuple[type, ...]) -> str:
    names = {
        int: "a whole number",
        float: "a number",
        str: "a string",
        bool: "true or false",
        list: "a list",
        dict: "a mapping",
    }
    if types == NUM:
        return "a number"
    return " or ".join(names[t] for t in types)


def _link(value: Any, simulated: bool, source: str) -> dict[str, Any]:
    if value is None:
        if simulated:
            return {}
        raise ConfigError(
            f"{source}: link is required (a mapping with kind: "
            f"{' | '.join(LINK_KINDS)}), or a simulated_device section"
        )
    if not isinstance(value, dict):
        raise ConfigError(f"{source}: link must be a mapping with a kind")
    if simulated:
        if "kind" in value:
            raise ConfigError(
                f"{source}: link.kind: set by simulated_device.transport; "
                "leave it out when simulated_device is given"
            )
        return dict(value)
    kind = value.get("kind")
    if kind not in LINK_KINDS:
        raise ConfigError(
            f"{source}: link.kind must be one of {', '.join(LINK_KINDS)} (got {kind!r})"
        )
    check_link(value, source)
    return dict(value)


def _resolve_replay_path(link: dict[str, Any], base_dir: Path) -> dict[str, Any]:
    """A replay link's relative ``path`` is relative to the config file, like model.path."""
    if link.get("kind") == "replay" and isinstance(link.get("path"), str):
        path = Path(link["path"]).expanduser()
        link = {**link, "path": str(path if path.is_absolute() else base_dir / path)}
    return link


def check_link(link: Mapping[str, Any], source: str) -> None:
    """Validate a link mapping with the links' own rules (errors name ``link.<key>``)."""
    from fdi_daemon.io.links.base import link_settings

    try:
        link_settings(link, "link")
    except ConfigError as exc:
        raise ConfigError(f"{source}: {exc}") from None


def check_files(config: RigConfig) -> None:
    """The daemon's output files (event log, status socket, alarm state, trend, MQTT outbox)
    are none of its inputs (the model, a replayed recording) and no two of them one file
    (`io.outputs.check_outputs`): an event log pointed at the replayed recording would
    append to it. A ConfigError names the key."""
    from fdi_daemon.io.outputs import check_outputs

    inputs = {"model.path": config.model_path}
    if config.link.get("kind") == "replay" and config.link.get("path"):
        inputs["link.path"] = Path(config.link["path"])
    outputs = {
        "sinks.event_log": config.sinks["event_log"],
        "sinks.status_socket": config.sinks["status_socket"],
        "alarms.state_file": config.alarms["state_file"],
        "alarms.trend": config.alarms["trend"],
        "mqtt.buffer_file": config.mqtt["buffer_file"] if config.mqtt["enabled"] else None,
    }
    try:
        check_outputs(
            {key: config.output_path(value) for key, value in outputs.items()},
            inputs,
            new_dirs=True,
        )
    except UserError as exc:
        raise ConfigError(f"{config.source}: {exc}") from None


def _simulated_device(data: Mapping, source: str) -> dict[str, Any] | None:
    value = data.get("simulated_device")
    if value is None:
        return None
    if not isinstance(value, dict):
        raise ConfigError(f"{source}: simulated_device must be a mapping")
    faults_given = value.get("faults", [])
    rest = {k: v for k, v in value.items() if k != "faults"}
    out = _fill(rest, SCHEMA["simulated_device"], "simulated_device.", source)
    if not isinstance(faults_given, list):
        raise ConfigError(
            f"{source}: simulated_device.faults must be a list of {{at_s: s, <fault>: value}}"
        )
    faults = []
    for i, fault in enumerate(faults_given):
        path = f"simulated_device.faults[{i}]"
        if not isinstance(fault, dict):
            raise ConfigError(
                f"{source}: {path} must be a mapping like {{at_s: 20, bearing_supply: 0.35}}"
            )
        _no_unknown(fault, ("at_s",) + SIM_FAULT_KEYS, f"{path}.", source)
        at = _scalar(
            fault.get("at_s"), Field(NUM, None, "", _non_negative), f"{path}.at_s", source, True
        )
        if at is None:
            raise ConfigError(f"{source}: {path}.at_s is required (sample time of the fault)")
        settings = {k: v for k, v in fault.items() if k != "at_s"}
        if len(settings) != 1:
            raise ConfigError(
                f"{source}: {path} must set exactly one of {', '.join(SIM_FAULT_KEYS)}"
            )
        ((name, setting),) = settings.items()
        check = _fraction if name == "bearing_supply" else None
        setting = _scalar(setting, Field(NUM, None, "", check), f"{path}.{name}", source, True)
        faults.append({"at_s": at, "name": name, "value": setting})
    out["faults"] = sorted(faults, key=lambda f: f["at_s"])
    return out


def _resolve_scenario(sim: dict[str, Any] | None, base_dir: Path) -> dict[str, Any] | None:
    if sim is not None and sim["scenario"] is not None:
        path = Path(sim["scenario"]).expanduser()
        sim = {**sim, "scenario": str(path if path.is_absolute() else base_dir / path)}
    return sim


def _monitor(value: Any, source: str) -> dict[str, dict[str, Any]]:
    if value is None:
        return {}
    if not isinstance(value, dict):
        raise ConfigError(f"{source}: monitor must be a mapping with detector/velocity")
    _no_unknown(value, ("detector", "velocity"), "monitor.", source)
    for key, section in value.items():
        if section is not None and not isinstance(section, dict):
            raise ConfigError(f"{source}: monitor.{key} must be a mapping")
    return {k: dict(v) for k, v in value.items() if v}
