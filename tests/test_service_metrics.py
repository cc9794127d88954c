"""Prometheus exporter: scraped over HTTP and parsed with prometheus_client's own parser."""

from __future__ import annotations

import json
import math
import re
import shutil
import subprocess
import urllib.request
from pathlib import Path

import pytest
from prometheus_client.parser import text_string_to_metric_families

from fdi_daemon import __version__
from fdi_daemon.alarms.lifecycle import LIFECYCLE_KINDS, STATES
from fdi_daemon.detect.events import EVENT_KINDS
from fdi_daemon.service.loop import LatencyHistogram
from fdi_daemon.service.metrics import MetricsServer
from fdi_daemon.service.mqtt_sink import AlarmOutbox
from fdi_daemon.service.sinks import STATE_CODES, StatusBoard

ROOT = Path(__file__).resolve().parents[1]


def scrape(url: str) -> dict[str, dict]:
    """``{family name: {"type", "samples": {(sample name, labels): value}}}``."""
    with urllib.request.urlopen(url, timeout=10) as reply:
        assert reply.status == 200
        assert reply.headers["Content-Type"].startswith("text/plain")
        text = reply.read().decode()
    families = {}
    for family in text_string_to_metric_families(text):
        families[family.name] = {
            "type": family.type,
            "samples": {(s.name, tuple(sorted(s.labels.items()))): s.value for s in family.samples},
        }
    return families


def value(families, family, sample=None, **labels):
    return families[family]["samples"][(sample or family, tuple(sorted(labels.items())))]


class FakeLoop:
    def __init__(self, latencies_us):
        self.tick_latency = LatencyHistogram()
        for v in latencies_us:
            self.tick_latency.add(v)


SNAPSHOT = {
    "time": 1.7e9,
    "t": 25.5,
    "state": "friction_isolated",
    "link": {
        "connected": True,
        "rate_hz": 256.0,
        "samples": 6528,
        "gaps": 2,
        "missing_samples": 7,
        "duplicates": 1,
        "bad_samples": 3,
        "deadline_misses": 4,
        "late_arrivals": 1,
    },
    "monitor": {
        "friction_level": 1.42,
        "theta1": 1.42,
        "theta2": 1.05,
        "statistic": 1.3,
        "threshold": 30.0,
        "residual_rms": None,
    },
    "counters": {"calibrated": 1, "fault_detected": 2, "friction_isolated": 1, "data_gap": 2},
    "uptime_s": 30.0,
    "dropped_outputs": 0,
    "alarm": {
        "state": "acknowledged",
        "state_code": 4,  # shelved
        "alarm_id": 3,
        "priority": 2,
        "annunciated": False,
        "shelved_until": 1.7e9 + 600.0,
        "baseline_level": 0.08,
    },
}


def test_scrape_parses_and_carries_the_status():
    board = StatusBoard()
    board.publish(SNAPSHOT)
    server = MetricsServer(board, "127.0.0.1:0")
    latencies = [50.0] * 90 + [2000.0] * 9 + [30000.0]
    server.watch(FakeLoop(latencies))
    try:
        assert server.url == f"http://127.0.0.1:{server.port}/metrics"
        got = scrape(server.url)
    finally:
        server.close()
    assert value(got, "fdi_friction_level") == 1.42
    assert value(got, "fdi_statistic") == 1.3 and value(got, "fdi_threshold") == 30.0
    # an Enum (state set): in the text format a gauge with one series per state, 1 for the current
    assert got["fdi_state"]["type"] == "gauge"
    states = {
        dict(labels)["fdi_state"]: v for (_, labels), v in got["fdi_state"]["samples"].items()
    }
    assert states == {name: float(name == "friction_isolated") for name in STATE_CODES}
    # not available: NaN, the unit in the name
    assert math.isnan(value(got, "fdi_residual_rms_meters_per_second_squared"))
    assert value(got, "fdi_start_time_seconds") == 1.7e9 - 30.0  # not an uptime
    assert value(got, "fdi_build_info", version=__version__) == 1
    assert value(got, "fdi_baseline_level") == 0.08
    # the operator alarm: acknowledged, shelved, priority 2, alarm 3
    alarm = {
        dict(labels)["fdi_alarm_state"]: v
        for (_, labels), v in got["fdi_alarm_state"]["samples"].items()
    }
    assert alarm == {name: float(name == "acknowledged") for name in STATES}
    assert value(got, "fdi_alarm_priority") == 2 and value(got, "fdi_alarm_id") == 3
    assert value(got, "fdi_alarm_active") == 1 and value(got, "fdi_alarm_acknowledged") == 1
    assert value(got, "fdi_alarm_shelved") == 1 and value(got, "fdi_alarm_annunciated") == 0
    assert got["fdi_samples"]["type"] == "counter"
    assert value(got, "fdi_samples", "fdi_samples_total") == 6528
    assert value(got, "fdi_gaps", "fdi_gaps_total") == 2
    assert value(got, "fdi_deadline_misses", "fdi_deadline_misses_total") == 4
    assert value(got, "fdi_alarm_episodes", "fdi_alarm_episodes_total") == 2
    assert value(got, "fdi_events", "fdi_events_total", kind="data_gap") == 2
    # the histogram: cumulative buckets on the loop's own bin edges, in seconds
    hist = got["fdi_tick_latency_seconds"]
    assert hist["type"] == "histogram"
    buckets = sorted(
        (float(dict(labels)["le"]), v)
        for (name, labels), v in hist["samples"].items()
        if name.endswith("_bucket")
    )
    assert buckets[-1] == (math.inf, 100)
    le, counts = zip(*buckets)
    assert list(counts) == sorted(counts)  # cumulative
    for edge, count in buckets:  # each bucket counts exactly the values below its edge
        assert count == sum(v * 1e-6 < edge for v in latencies), edge
    assert value(got, "fdi_tick_latency_seconds", "fdi_tick_latency_seconds_count") == 100
    assert value(got, "fdi_tick_latency_seconds", "fdi_tick_latency_seconds_sum") == pytest.approx(
        sum(latencies) * 1e-6
    )
    assert 1e-5 == pytest.approx(le[0]) and 10.0 == pytest.approx(le[-2])


def test_only_fdi_metrics_in_a_registry_of_its_own():
    from prometheus_client import REGISTRY

    board = StatusBoard()
    server = MetricsServer(board, "127.0.0.1:0")
    try:
        got = scrape(server.url)
    finally:
        server.close()
    assert all(name.startswith(("fdi_", "process_", "python_")) for name in got), sorted(got)
    assert "process_start_time_seconds" in got and "python_info" in got
    assert "fdi_friction_level" not in {m.name for m in REGISTRY.collect()}
    assert value(got, "fdi_state", fdi_state="starting") == 1
    assert math.isnan(value(got, "fdi_friction_level"))
    assert "fdi_tick_latency_seconds" not in got  # no loop watched yet
    # every counter is there at 0 before its first count, so increase() sees the first one
    counters = [f for f, fam in got.items() if fam["type"] == "counter" and f.startswith("fdi_")]
    assert len(counters) >= 9
    for family in counters:
        assert set(got[family]["samples"].values()) == {0.0}, family
    kinds = {dict(labels)["kind"] for _, labels in got["fdi_events"]["samples"]}
    assert kinds == set(EVENT_KINDS) | set(LIFECYCLE_KINDS)
    assert value(got, "fdi_alarm_state", fdi_alarm_state="normal") == 1


@pytest.mark.skipif(shutil.which("promtool") is None, reason="promtool is not installed")
def test_promtool_finds_nothing_to_lint(tmp_path):
    """Prometheus's own linter over a full scrape (fdi, process and platform metrics)."""

    class Mqtt:
        connected = False
        outbox = AlarmOutbox(tmp_path / "outbox.jsonl", max_messages=10)

    board = StatusBoard()
    board.publish(SNAPSHOT)
    server = MetricsServer(board, "127.0.0.1:0", mqtt=Mqtt())
    server.watch(FakeLoop([100.0, 2000.0]))
    try:
        with urllib.request.urlopen(server.url, timeout=10) as reply:
            text = reply.read()
    finally:
        server.close()
    assert b"fdi_alarm_state" in text and b"process_cpu_seconds_total" in text
    lint = subprocess.run(
        ["promtool", "check", "metrics"], input=text, capture_output=True, timeout=60
    )
    assert lint.returncode == 0 and not lint.stdout and not lint.stderr, lint


def test_grafana_dashboard_queries_the_exported_metrics(tmp_path):
    class Mqtt:  # what the exporter reads of the MQTT sink
        connected = True
        outbox = AlarmOutbox(tmp_path / "outbox.jsonl", max_messages=10)

    board = StatusBoard()
    board.publish(SNAPSHOT)
    server = MetricsServer(board, "127.0.0.1:0", mqtt=Mqtt())
    server.watch(FakeLoop([100.0]))
    try:
        exported = set(scrape(server.url))
    finally:
        server.close()
    dashboard = json.loads((ROOT / "configs" / "grafana_fdi.json").read_text())
    exprs = [target["expr"] for panel in dashboard["panels"] for target in panel.get("targets", [])]
    assert exprs
    exprs += [
        v["query"]["query"]
        for v in dashboard["templating"]["list"]
        if "query" in v.get("query", {})
    ]
    used = set()
    for expr in exprs:
        for name in exported:
            if name in expr:
                used.add(name)
    for needed in (
        "fdi_friction_level",
        "fdi_statistic",
        "fdi_state",
        "fdi_alarm_episodes",
        "fdi_samples",
        "fdi_gaps",
        "fdi_deadline_misses",
        "fdi_tick_latency_seconds",
        "fdi_alarm_state",
        "fdi_alarm_priority",
        "fdi_alarm_acknowledged",
        "fdi_alarm_shelved",
        "fdi_baseline_level",
        "fdi_residual_rms_meters_per_second_squared",
    ):
        assert needed in used, f"no panel shows {needed}"
    for expr in exprs:  # every metric a panel asks for exists
        for name in re.findall(r"\bfdi_[a-z0-9_]+", expr):
            base = re.sub(r"_(total|bucket|count|sum)$", "", name)
            assert base in exported, f"{name} in the dashboard is not exported"


@pytest.mark.skipif(shutil.which("promtool") is None, reason="promtool is not installed")
def test_grafana_queries_are_valid_promql(tmp_path):
    """Every dashboard query, Grafana's variables filled in, parses (promtool check rules)."""
    import yaml

    dashboard = json.loads((ROOT / "configs" / "grafana_fdi.json").read_text())
    exprs = [target["expr"] for panel in dashboard["panels"] for target in panel.get("targets", [])]
    filled = [e.replace("$instance", ".*").replace("$__range", "1h") for e in exprs]
    rules = {
        "groups": [
            {
                "name": "fdi_dashboard",
                "rules": [
                    {"record": f"fdi_dashboard:q{i}", "expr": e} for i, e in enumerate(filled)
                ],
            }
        ]
    }
    path = tmp_path / "rules.yml"
    path.write_text(yaml.safe_dump(rules))
    check = subprocess.run(
        ["promtool", "check", "rules", str(path)], capture_output=True, text=True
    )
    assert check.returncode == 0 and f"{len(exprs)} rules found" in check.stdout, check


def test_grafana_provisioning_loads_the_dashboard_directory():
    """The provider file is what Grafana reads: one file provider over the dashboard's folder."""
    import yaml

    provisioning = yaml.safe_load(
        (ROOT / "configs" / "grafana" / "fdi_dashboards.yaml").read_text()
    )
    assert provisioning["apiVersion"] == 1
    (provider,) = provisioning["providers"]
    assert provider["type"] == "file" and provider["options"]["path"].endswith("/configs")
    dashboards = list((ROOT / "configs").glob("*.json"))  # what the provider loads there
    assert [p.name for p in dashboards] == ["grafana_fdi.json"]
    assert json.loads(dashboards[0].read_text())["uid"] == "fdi-friction"


def test_a_taken_port_is_one_clear_config_error(tmp_path):
    from fdi_daemon.errors import ConfigError
    from fdi_daemon.service.config import config_from_dict
    from fdi_daemon.service.daemon import Sinks

    first = MetricsServer(StatusBoard(), "127.0.0.1:0")
    try:
        cfg = config_from_dict(
            {
                "link": {"kind": "modbus-tcp"},
                "model": {"path": "model.yaml"},
                "metrics": {"listen": f"127.0.0.1:{first.port}"},
                "sinks": {"status_socket": None, "stdout": False},
                "recorder": {"enabled": False},
                "service": {"state_dir": str(tmp_path)},
            },
            "rig.yaml",
            tmp_path,
        )
        with pytest.raises(
            ConfigError,
            match=rf"rig.yaml: cannot open an output: metrics "
            rf"exporter on 127.0.0.1:{first.port}: ",
        ):
            Sinks(cfg, 256.0, "modbus-tcp", StatusBoard())
    finally:
        first.close()
