"""Rig config validation: defaults, every key checked, errors naming the key path."""

from pathlib import Path

import pytest

from fdi_daemon.errors import ConfigError
from fdi_daemon.service.config import SECTIONS, config_from_dict, default_config_path, load_config
from fdi_daemon.service.config_models import Section

ROOT = Path(__file__).resolve().parents[1]


def minimal(**sections):
    data = {
        "link": {"kind": "modbus-tcp", "host": "127.0.0.1", "port": 5502},
        "model": {"path": "model.yaml"},
    }
    data.update(sections)
    return data


def test_defaults_are_filled_in(tmp_path):
    cfg = config_from_dict(minimal(), "rig.yaml", tmp_path)
    assert cfg.model_path == tmp_path / "model.yaml"
    assert cfg.sinks["modbus_status"]["host"] == "127.0.0.1"
    assert cfg.recorder["fsync_period_s"] == 1.0
    assert cfg.service["deadline_s"] == 0.05
    assert cfg.link == {"kind": "modbus-tcp", "host": "127.0.0.1", "port": 5502}
    assert cfg.simulated_device is None


@pytest.mark.parametrize(
    "data, key",
    [
        ({"linkk": {}}, "linkk"),
        ({"sinks": {"modbus_status": {"prot": 1}}}, "sinks.modbus_status.prot"),
        ({"recorder": {"rotate_minutes": 5}}, "recorder.rotate_minutes"),
        ({"service": {"deadline": 0.1}}, "service.deadline"),
        ({"monitor": {"detectr": {}}}, "monitor.detectr"),
    ],
)
def test_unknown_keys_are_errors_naming_the_path(data, key):
    with pytest.raises(ConfigError, match=rf"{key.replace('.', '[.]')}: unknown key"):
        config_from_dict(minimal(**data), "rig.yaml")


@pytest.mark.parametrize(
    "data, key",
    [
        ({"sinks": {"modbus_status": {"port": 70000}}}, "sinks.modbus_status.port"),
        ({"sinks": {"modbus_status": {"port": "502"}}}, "sinks.modbus_status.port"),
        ({"sinks": {"stdout": "yes"}}, "sinks.stdout"),
        ({"recorder": {"fsync_period_s": 2.0}}, "recorder.fsync_period_s"),
        ({"recorder": {"rotate_seconds": -1}}, "recorder.rotate_seconds"),
        ({"recorder": {"rotate_bytes": True}}, "recorder.rotate_bytes"),
        ({"service": {"fs": 0}}, "service.fs"),
        ({"service": {"queue_size": 1.5}}, "service.queue_size"),
        ({"service": {"deadline_s": None}}, "service.deadline_s"),
        ({"sinks": "all"}, "sinks"),
        ({"alarms": {"steps": "x"}}, "alarms.steps"),  # a KeyError naming the type list
        ({"alarms": {"steps": [3, 1]}}, "alarms.steps"),
    ],
)
def test_bad_values_are_errors_naming_the_key(data, key):
    with pytest.raises(ConfigError) as info:
        config_from_dict(minimal(**data), "rig.yaml")
    message = str(info.value)
    assert message.startswith("rig.yaml: ") and key in message and "\n" not in message


def test_null_disables_an_output():
    cfg = config_from_dict(minimal(sinks={"status_socket": None, "event_log": None}), "rig")
    assert cfg.sinks["status_socket"] is None and cfg.sinks["event_log"] is None
    assert cfg.sinks["stdout"] is True


def test_link_and_model_are_required():
    with pytest.raises(ConfigError, match="link is required"):
        config_from_dict({"model": {"path": "m.yaml"}}, "rig.yaml")
    with pytest.raises(ConfigError, match="link.kind must be one of"):
        config_from_dict({"link": {"kind": "carrier-pigeon"}, "model": {"path": "m"}})
    with pytest.raises(ConfigError, match="model.path is required"):
        config_from_dict({"link": {"kind": "serial", "port": "/dev/ttyUSB0"}}, "rig.yaml")


def test_link_settings_are_checked_by_the_links_rules():
    with pytest.raises(ConfigError, match=r"^rig.yaml: link.port: required"):
        config_from_dict({"link": {"kind": "serial"}, "model": {"path": "m"}}, "rig.yaml")
    with pytest.raises(ConfigError, match=r"^rig.yaml: link.baud: unknown key"):
        config_from_dict(
            {
                "link": {"kind": "serial", "port": "/dev/ttyS0", "baud": 9600},
                "model": {"path": "m"},
            },
            "rig.yaml",
        )


def test_simulated_device_section():
    data = {
        "model": {"path": "m.yaml"},
        "simulated_device": {
            "transport": "serial",
            "faults": [{"at_s": 30, "accel_bias": 0.2}, {"at_s": 20, "bearing_supply": 0.3}],
        },
    }
    cfg = config_from_dict(data, "rig.yaml")
    assert cfg.link == {}
    assert [f["at_s"] for f in cfg.simulated_device["faults"]] == [20.0, 30.0]
    assert cfg.simulated_device["faults"][0] == {
        "at_s": 20.0,
        "name": "bearing_supply",
        "value": 0.3,
    }
    bad = {"model": {"path": "m"}, "simulated_device": {"faults": [{"at_s": 1, "rust": 1}]}}
    with pytest.raises(ConfigError, match=r"simulated_device.faults\[0\].rust: unknown key"):
        config_from_dict(bad, "rig.yaml")
    bad = {
        "model": {"path": "m"},
        "simulated_device": {"faults": [{"at_s": 1, "bearing_supply": 3}]},
    }
    with pytest.raises(ConfigError, match=r"faults\[0\].bearing_supply must be a fraction"):
        config_from_dict(bad, "rig.yaml")
    with pytest.raises(ConfigError, match="link.kind: set by simulated_device"):
        config_from_dict({**data, "link": {"kind": "serial"}}, "rig.yaml")


def test_output_paths_are_under_the_state_dir(tmp_path, monkeypatch):
    monkeypatch.setenv("STATE_DIRECTORY", str(tmp_path / "state"))
    cfg = config_from_dict(minimal(), "rig.yaml")
    assert cfg.output_path(cfg.sinks["event_log"]) == tmp_path / "state" / "events.jsonl"
    assert cfg.output_path("/abs/x.jsonl") == Path("/abs/x.jsonl")
    assert cfg.output_path(None) is None
    cfg = config_from_dict(minimal(service={"state_dir": str(tmp_path / "s2")}), "rig.yaml")
    assert cfg.output_path("r") == tmp_path / "s2" / "r"


def test_load_config_reports_file_problems(tmp_path):
    with pytest.raises(ConfigError, match="no such config file"):
        load_config(tmp_path / "missing.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("link: [\n")
    with pytest.raises(ConfigError, match="not valid YAML at line"):
        load_config(bad)
    bad.write_text("- 1\n- 2\n")
    with pytest.raises(ConfigError, match="must be a mapping"):
        load_config(bad)


@pytest.mark.parametrize(
    "path",
    [default_config_path()] + sorted((ROOT / "configs").glob("rig_*.yaml")),
    ids=lambda p: p.name,
)
def test_shipped_configs_are_valid(path):
    cfg = load_config(path)
    assert cfg.model_path.name.endswith(".yaml")


def leaf_keys(model, prefix=""):
    for key, field in model.model_fields.items():
        if isinstance(field.annotation, type) and issubclass(field.annotation, Section):
            yield from leaf_keys(field.annotation, f"{prefix}{key}.")
        else:
            yield f"{prefix}{key}"


def test_schema_fields_are_documented():
    doc = (ROOT / "docs" / "service.md").read_text()
    for section, model in SECTIONS.items():
        assert f"`{section}:`" in doc
        for key in leaf_keys(model):
            assert f"| `{key}` |" in doc, f"{section}.{key} is not in docs/service.md"


def test_packaged_model_is_the_shipped_one():
    """The default config's model (package data) is configs/model_sim_rig.yaml.

    fdi_daemon/data/model_sim_rig.yaml is a symlink to it (a wheel gets the content), so the
    two never drift apart; were it replaced by a copy, this test catches a stale one."""
    packaged = load_config().model_path
    shipped = ROOT / "configs" / "model_sim_rig.yaml"
    if not (packaged.exists() and shipped.exists()):
        pytest.skip("model_sim_rig.yaml not in both places yet")
    assert packaged.read_bytes() == shipped.read_bytes(), (
        "fdi_daemon/data/model_sim_rig.yaml differs from configs/model_sim_rig.yaml"
    )


def test_default_state_dir_is_systemds_then_xdg_never_the_working_directory(tmp_path, monkeypatch):
    monkeypatch.delenv("STATE_DIRECTORY", raising=False)
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    monkeypatch.delenv("XDG_STATE_HOME", raising=False)
    assert config_from_dict(minimal()).state_dir == tmp_path / "home" / ".local" / "state" / "fdi"
    monkeypatch.setenv("XDG_STATE_HOME", "relative/ignored")  # the XDG spec: absolute only
    assert config_from_dict(minimal()).state_dir == tmp_path / "home" / ".local" / "state" / "fdi"
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path / "xdg"))
    assert config_from_dict(minimal()).state_dir == tmp_path / "xdg" / "fdi"
    monkeypatch.setenv("STATE_DIRECTORY", f"{tmp_path / 'sd'}:{tmp_path / 'other'}")
    assert config_from_dict(minimal()).state_dir == tmp_path / "sd"  # under systemd
    cfg = config_from_dict(minimal(service={"state_dir": "~/mine"}))
    assert cfg.state_dir == tmp_path / "home" / "mine"  # the config's own wins


@pytest.mark.parametrize(
    "sections, message",
    [
        # an event log pointed at the replayed recording would append JSON lines to it
        (
            {
                "link": {"kind": "replay", "path": "rec.csv"},
                "sinks": {"event_log": "{dir}/rec.csv"},
            },
            r"sinks.event_log {dir}/rec.csv: is also an input of this command \(link.path\)",
        ),
        (
            {"alarms": {"state_file": "{dir}/model.yaml"}},
            r"alarms.state_file {dir}/model.yaml: is also an input of this command \(model.path\)",
        ),
        (
            {"alarms": {"trend": "events.jsonl"}},
            "alarms.trend and sinks.event_log name the same file {state}/events.jsonl",
        ),
    ],
)
def test_an_output_that_is_an_input_or_another_output_is_refused(tmp_path, sections, message):
    state = tmp_path / "state"
    data = minimal(service={"state_dir": str(state)})
    for name, section in sections.items():
        data[name] = {
            k: v.format(dir=tmp_path) if isinstance(v, str) else v for k, v in section.items()
        }
    (tmp_path / "rec.csv").write_text("t,v_in,accel\n")
    with pytest.raises(ConfigError, match=message.format(dir=tmp_path, state=state)):
        config_from_dict(data, "rig.yaml", tmp_path)


@pytest.mark.parametrize(
    "data, message",
    [
        (
            {"service": {"deadlin_s": 1}},
            "service.deadlin_s: unknown key (did you mean 'deadline_s'?)",
        ),
        (
            {"mqtt": {"tls": {"ca_fle": "x"}}},
            "mqtt.tls.ca_fle: unknown key (did you mean 'ca_file'?)",
        ),
        ({"recorder": {"keep": 1}}, "recorder.keep: unknown key (known: enabled, dir, "),
        ({"aalarms": {}}, "aalarms: unknown key (did you mean 'alarms'?)"),
    ],
)
def test_unknown_keys_suggest_the_key_meant(data, message):
    with pytest.raises(ConfigError) as info:
        config_from_dict(minimal(**data), "rig.yaml")
    assert str(info.value).startswith(f"rig.yaml: {message}")


def test_link_typos_suggest_the_key_meant():
    """Issue 47: `link.wrd_order` named every known key but not the one meant."""
    data = minimal()
    data["link"] = {**data["link"], "wrd_order": "big"}
    with pytest.raises(
        ConfigError,
        match=r"^rig.yaml: link.wrd_order: unknown key \(did you mean 'word_order'\?\)$",
    ):
        config_from_dict(data, "rig.yaml")


def test_null_sections_take_their_defaults_and_settings_are_typed():
    cfg = config_from_dict(minimal(sinks={"modbus_status": None}, mqtt={"tls": None}), "rig.yaml")
    assert cfg.sinks["modbus_status"]["port"] == 5020 and cfg.mqtt["tls"]["enabled"] is False
    assert cfg.settings.sinks.modbus_status.port == 5020  # the typed view of the same values
    assert cfg.settings.service.deadline_s == cfg.service["deadline_s"] == 0.05


def test_several_problems_are_counted_on_one_line():
    with pytest.raises(ConfigError) as info:
        config_from_dict(minimal(service={"fs": -1, "queue_size": 0}), "rig.yaml")
    assert str(info.value) == (
        "rig.yaml: service.fs must be a positive number (got -1) (and 1 more problem(s))"
    )


def test_the_shipped_json_schema_is_the_generated_one():
    """fdi_daemon/data/config.schema.json: regenerate with python -m fdi_daemon.service.config_schema."""
    from fdi_daemon.service.config_schema import SCHEMA_PATH, schema_text

    assert SCHEMA_PATH.read_text() == schema_text()


@pytest.mark.parametrize(
    "path",
    [default_config_path()] + sorted((ROOT / "configs").glob("rig_*.yaml")),
    ids=lambda p: p.name,
)
def test_shipped_configs_satisfy_the_json_schema(path):
    """What an editor checks: the shipped configs pass, a typo and a wrong type do not."""
    jsonschema = pytest.importorskip("jsonschema")
    import json

    import yaml

    from fdi_daemon.service.config_schema import SCHEMA_PATH

    schema = json.loads(SCHEMA_PATH.read_text())
    data = yaml.safe_load(path.read_text())
    jsonschema.validate(data, schema)
    jsonschema.validate({**data, "sinks": None}, schema)  # an empty section: the defaults
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate({**data, "sinks": {"stdot": True}}, schema)
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate({**data, "recorder": {"rotate_bytes": "1 GB"}}, schema)


def test_a_simulated_fault_entry_takes_every_fault_of_the_fake_device():
    from fdi_daemon.service.config_models import SIM_FAULT_KEYS, SimFault

    assert set(SimFault.model_fields) == {"at_s", *SIM_FAULT_KEYS}


def test_a_fault_without_its_time_names_what_is_missing():
    bad = {"model": {"path": "m"}, "simulated_device": {"faults": [{"accel_bias": 0.1}]}}
    with pytest.raises(ConfigError) as info:
        config_from_dict(bad, "rig.yaml")
    assert str(info.value) == (
        "rig.yaml: simulated_device.faults[0].at_s is required (sample time of the fault (s))"
    )
