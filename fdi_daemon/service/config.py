"""The rig config of `fdi run` (YAML), validated key by key.

Every key is checked by the pydantic models of `config_models` (types, defaults, ranges): an
unknown key, a wrong type or a value out of range is a `ConfigError` of one line naming the
key path (``sinks.modbus_status.port``; `config_errors`), with the key meant for a typo.
Defaults are in the models, ``docs/service.md`` and ``data/config.schema.json``.

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
    metrics: {listen}  # Prometheus exporter, e.g. 127.0.0.1:19108; null (default) = off

Secrets (the MQTT password) are never read from the YAML: ``mqtt.password`` is refused;
``mqtt.password_file`` or ``mqtt.password_env`` name where the daemon reads it.
    alarms: {steps, deadband, raise_delay_s, lower_delay_s, return_delay_s, max_shelve_s,
             allow_remote_acknowledge, state_file, trend}

Reconnect backoff is the link's: ``link.reconnect: {backoff_initial_s, backoff_max_s,
stall_timeout_s}`` (see `fdi_daemon.io.links.base`).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any, overload

from pydantic import ValidationError

from fdi_daemon.alarms.lifecycle import AlarmSettings
from fdi_daemon.errors import ConfigError, UserError
from fdi_daemon.io.yaml_file import read_yaml
from fdi_daemon.service.config_errors import one_line
from fdi_daemon.service.config_models import SECTIONS, RigFile

__all__ = [
    "RigConfig",
    "load_config",
    "config_from_dict",
    "default_config_path",
    "default_state_dir",
    "SECTIONS",
]

LINK_KINDS = ("serial", "modbus-tcp", "modbus-rtu", "replay", "sim")
TOP_LEVEL = tuple(RigFile.model_fields)
#: keys that would put a secret into the YAML, refused with where to put it instead
SECRET_KEYS = ("password", "passwd", "secret")


@dataclass
class RigConfig:
    """A validated config: plain mappings with every default filled in, and the typed
    `RigFile` they come from."""

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
    settings: RigFile  #: the validated file, typed (the mappings above are its dump)

    @property
    def state_dir(self) -> Path:
        configured = self.service["state_dir"]
        if configured:
            return Path(configured).expanduser()
        return default_state_dir()

    @overload
    def output_path(self, value: str) -> Path: ...
    @overload
    def output_path(self, value: None) -> None: ...
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
    _no_secrets(data.get("mqtt"), source)
    try:
        rig = RigFile.model_validate(data)
    except ValidationError as exc:
        raise ConfigError(f"{source}: {one_line(exc, RigFile)}") from None
    sim = _resolve_scenario(_simulated_device(rig), base_dir)
    link = _resolve_replay_path(_link(rig.link, sim is not None, source), base_dir)
    if rig.model.path is None:
        raise ConfigError(f"{source}: model.path is required (the model file to monitor with)")
    model_path = Path(rig.model.path).expanduser()
    if not model_path.is_absolute():
        model_path = base_dir / model_path
    config = RigConfig(
        source=source,
        base_dir=base_dir,
        link=link,
        simulated_device=sim,
        model_path=model_path,
        monitor={k: dict(v) for k, v in rig.monitor.model_dump().items() if v},
        sinks=rig.sinks.model_dump(),
        recorder=rig.recorder.model_dump(),
        service=rig.service.model_dump(),
        mqtt=_mqtt(rig, source, base_dir),
        metrics=rig.metrics.model_dump(),
        alarms=_alarms(rig, source),
        settings=rig,
    )
    check_files(config)
    return config


def _no_secrets(given: Any, source: str) -> None:
    """A secret written into the ``mqtt`` section is refused with where it belongs."""
    for key in SECRET_KEYS:
        if isinstance(given, dict) and key in given:
            raise ConfigError(
                f"{source}: mqtt.{key}: secrets are not read from the config; "
                "put the password in a file (mqtt.password_file) or an "
                "environment variable (mqtt.password_env)"
            )


def _mqtt(rig: RigFile, source: str, base_dir: Path) -> dict[str, Any]:
    """The ``mqtt`` section with its files resolved beside the config."""
    mqtt = rig.mqtt.model_dump()
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


def _alarms(rig: RigFile, source: str) -> dict[str, Any]:
    """The alarms section; its settings checked together (deadband below the lowest step)."""
    alarms = rig.alarms.model_dump()
    alarms["steps"] = tuple(alarms["steps"])
    names = [f.name for f in fields(AlarmSettings)]
    try:
        alarms["settings"] = AlarmSettings(**{k: alarms[k] for k in names})
    except ValueError as exc:
        raise ConfigError(f"{source}: alarms: {exc}") from None
    return alarms


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


def _simulated_device(rig: RigFile) -> dict[str, Any] | None:
    """The simulated device's settings, its faults as {at_s, name, value} in time order."""
    sim = rig.simulated_device
    if sim is None:
        return None
    faults = [
        {"at_s": f.at_s, "name": name, "value": value}
        for f in sim.faults
        for name, value in [f.setting()]
    ]
    out = sim.model_dump(exclude={"faults"})
    out["faults"] = sorted(faults, key=lambda f: f["at_s"])
    return out


def _resolve_scenario(sim: dict[str, Any] | None, base_dir: Path) -> dict[str, Any] | None:
    if sim is not None and sim["scenario"] is not None:
        path = Path(sim["scenario"]).expanduser()
        sim = {**sim, "scenario": str(path if path.is_absolute() else base_dir / path)}
    return sim
