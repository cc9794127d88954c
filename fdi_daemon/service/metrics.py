"""Prometheus exporter (prometheus_client): the daemon's status as metrics over HTTP.

Off unless ``metrics.listen`` is set; the documented setting is ``127.0.0.1:19108``
(loopback: a Prometheus on another host needs an outside address on purpose; the port lies
outside 9100-9999, the range of Prometheus's default-port allocations, which is full, so it
is no other exporter's registered default). Every value
is read at scrape time, from the status board (the snapshot refreshed every
``service.status_period_s``) and the loop's tick-latency histogram, so nothing runs on the
sample loop's thread. The metrics live in a registry of their own, not prometheus_client's
global one: a scrape shows fdi's metrics only, and a reload starts a clean registry.
Names, units and the Grafana dashboard: docs/service.md, configs/grafana_fdi.json.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import Any

from fdi_daemon import __version__
from fdi_daemon.alarms.lifecycle import LIFECYCLE_KINDS, STATES
from fdi_daemon.detect.events import EVENT_KINDS
from fdi_daemon.errors import ConfigError
from fdi_daemon.service.sinks import STATE_CODES, StatusBoard

#: tick-latency histogram buckets: every 5th upper edge of the loop's own log-spaced bins
#: (`LatencyHistogram`, 20 per decade), i.e. 4 per decade from 10 µs to 10 s
BUCKET_BIN_INDICES = tuple(range(20, 141, 5))


def _number(value: Any) -> float:
    """A snapshot value as a sample value (missing -> NaN)."""
    if isinstance(value, bool):
        return float(value)
    return float(value) if isinstance(value, (int, float)) else math.nan


class StatusCollector:
    """A prometheus_client collector over the status board (and the loop, once watched)."""

    GAUGES = (  # name, help, snapshot path
        (
            "fdi_friction_level",
            "friction level (1 = the calibrated fault): median over the "
            "last seconds of trusted windows of the residual's multiple of g1 + gamma_f g2",
            ("monitor", "friction_level"),
        ),
        ("fdi_theta1", "θ1 estimate (Coulomb term, eq. 15)", ("monitor", "theta1")),
        ("fdi_theta2", "θ2 estimate (viscous term, eq. 15)", ("monitor", "theta2")),
        ("fdi_statistic", "detection statistic", ("monitor", "statistic")),
        ("fdi_threshold", "detection threshold of the statistic", ("monitor", "threshold")),
        (
            "fdi_residual_rms_meters_per_second_squared",
            "RMS of the model residual r = ẍ - x̂̈ (eq. 3), m/s²",
            ("monitor", "residual_rms"),
        ),
        (
            "fdi_baseline_level",
            "fault-free friction level of the model's baseline, units of the signature "
            "(NaN: the model has none)",
            ("alarm", "baseline_level"),
        ),
        (
            "fdi_alarm_priority",
            "operator alarm priority: 0 none, 1..3 alarm steps crossed (ISA-18.2)",
            ("alarm", "priority"),
        ),
        ("fdi_alarm_id", "number of the current (or last) operator alarm", ("alarm", "alarm_id")),
        ("fdi_link_connected", "1 while the data link is up", ("link", "connected")),
        ("fdi_sample_rate_hz", "samples per second over the last ~2 s", ("link", "rate_hz")),
        ("fdi_sample_time_seconds", "sample time t of the last sample, s", ("t",)),
    )
    COUNTERS = (  # name (without _total), help, snapshot path
        ("fdi_samples", "samples received", ("link", "samples")),
        ("fdi_gaps", "data gaps (sequence jumps)", ("link", "gaps")),
        ("fdi_missing_samples", "samples missing in those gaps", ("link", "missing_samples")),
        ("fdi_duplicate_samples", "repeated or backward samples skipped", ("link", "duplicates")),
        (
            "fdi_bad_samples",
            "samples rejected as bad (non-finite, saturated, CRC)",
            ("link", "bad_samples"),
        ),
        (
            "fdi_deadline_misses",
            "ticks finished later than service.deadline_s after their due time",
            ("link", "deadline_misses"),
        ),
        (
            "fdi_late_arrivals",
            "deadline misses whose sample already arrived late",
            ("link", "late_arrivals"),
        ),
        (
            "fdi_alarm_episodes",
            "alarm episodes (fault_detected events)",
            ("counters", "fault_detected"),
        ),
        (
            "fdi_dropped_outputs",
            "non-critical sink items dropped (queue full)",
            ("dropped_outputs",),
        ),
    )

    def __init__(self, board: StatusBoard, mqtt: Any = None) -> None:
        self.board = board
        self.mqtt = mqtt
        self.loop: Any = None

    def collect(self) -> Iterator[Any]:
        from prometheus_client.core import (
            CounterMetricFamily,
            GaugeMetricFamily,
            HistogramMetricFamily,
            InfoMetricFamily,
            StateSetMetricFamily,
        )

        snap = self.board.snapshot()
        yield InfoMetricFamily("fdi_build", "fdi version", value={"version": __version__})
        for name, doc, path in self.GAUGES:
            yield GaugeMetricFamily(name, doc, value=_number(_get(snap, path)))
        for name, doc, path in self.COUNTERS:
            yield CounterMetricFamily(name, doc, value=_number(_get(snap, path) or 0))
        yield _one_of(StateSetMetricFamily, "fdi_state", "monitor state", STATE_CODES, snap)
        uptime_s = snap.get("uptime_s")
        yield GaugeMetricFamily(
            "fdi_start_time_seconds",
            "start of the sample loop (restarts on reload), Unix time, s",
            value=round(snap["time"] - uptime_s, 3)
            if isinstance(uptime_s, (int, float)) and "time" in snap
            else math.nan,
        )
        yield from self._alarm(snap.get("alarm") or {}, GaugeMetricFamily, StateSetMetricFamily)
        counts = snap.get("counters") or {}
        events = CounterMetricFamily("fdi_events", "events by kind", labels=["kind"])
        for kind in dict.fromkeys([*EVENT_KINDS, *LIFECYCLE_KINDS, *sorted(counts)]):
            events.add_metric([str(kind)], counts.get(kind, 0))
        yield events
        if self.loop is not None:
            yield self._tick_latency(HistogramMetricFamily)
        if self.mqtt is not None:
            yield GaugeMetricFamily(
                "fdi_mqtt_connected",
                "1 while the MQTT broker is connected",
                value=float(self.mqtt.connected),
            )
            yield GaugeMetricFamily(
                "fdi_mqtt_buffered_alarms",
                "alarms waiting on disk for the broker",
                value=len(self.mqtt.outbox),
            )
            yield CounterMetricFamily(
                "fdi_mqtt_lost_alarms",
                "alarms dropped from the full MQTT buffer",
                value=self.mqtt.outbox.lost,
            )

    @staticmethod
    def _alarm(alarm: dict[str, Any], gauge: Any, state_set: Any) -> Iterator[Any]:
        """The operator alarm's lifecycle (ISA-18.2, `fdi_daemon.alarms.lifecycle`)."""
        state = alarm.get("state", "normal")
        yield _one_of(
            state_set, "fdi_alarm_state", "operator alarm state (ISA-18.2)", STATES, alarm
        )
        flags = (
            ("active", "1 while the alarm is active (unacknowledged or acknowledged)"),
            ("acknowledged", "1 while the active alarm is acknowledged"),
            ("shelved", "1 while the alarm is shelved (not annunciated)"),
            ("annunciated", "1 while the alarm is active and not shelved"),
        )
        values = {
            "active": state in ("unacknowledged", "acknowledged"),
            "acknowledged": state == "acknowledged",
            "shelved": alarm.get("state_code") == 4,
            "annunciated": bool(alarm.get("annunciated")),
        }
        for name, doc in flags:
            yield gauge(f"fdi_alarm_{name}", doc, value=float(values[name]))

    def _tick_latency(self, family: Any) -> Any:
        """The loop's tick latency (link delivery to the end of Monitor.step), seconds."""
        hist = self.loop.tick_latency
        counts = list(hist.counts)  # one copy: the loop thread keeps counting
        buckets, seen = [], 0
        edges = iter(BUCKET_BIN_INDICES)
        edge: int | None = next(edges)
        for index, count in enumerate(counts):
            seen += count
            if index == edge:
                buckets.append((f"{hist.upper_edge_us(index) * 1e-6:.6g}", seen))
                edge = next(edges, None)
        buckets.append(("+Inf", sum(counts)))
        return family(
            "fdi_tick_latency_seconds",
            "tick latency: link delivery to the end of Monitor.step, s",
            buckets=buckets,
            sum_value=hist.sum_us * 1e-6,
        )


def _one_of(family: Any, name: str, doc: str, states: Any, source: dict[str, Any]) -> Any:
    """A state set (prometheus_client's ``Enum`` exposition): one series per state, 1 for
    ``source["state"]`` (the first state when missing)."""
    current = source.get("state", next(iter(states)))
    return family(name, doc, value={str(state): state == current for state in states})


def _get(snapshot: dict[str, Any], path: tuple[str, ...]) -> Any:
    value: Any = snapshot
    for key in path:
        value = value.get(key) if isinstance(value, dict) else None
    return value


class MetricsServer:
    """HTTP ``/metrics`` on ``listen`` (``HOST:PORT``; port 0 picks a free one)."""

    def __init__(
        self, board: StatusBoard, listen: str, mqtt: Any = None, source: str = "config"
    ) -> None:
        try:
            from prometheus_client import (
                CollectorRegistry,
                PlatformCollector,
                ProcessCollector,
                start_http_server,
            )
        except ImportError:
            raise ConfigError(
                f"{source}: metrics.listen needs prometheus_client: pip install 'fdi[fleet]'"
            ) from None
        host, _, port = listen.rpartition(":")
        self.host = host.strip("[]")
        self.collector = StatusCollector(board, mqtt)
        self.registry = CollectorRegistry(auto_describe=True)
        self.registry.register(self.collector)
        ProcessCollector(registry=self.registry)
        PlatformCollector(registry=self.registry)
        try:
            self._server, self._thread = start_http_server(
                int(port), addr=self.host, registry=self.registry
            )
        except OSError as exc:
            raise OSError(f"metrics exporter on {listen}: {exc.strerror or exc}") from None
        self.port = self._server.server_address[1]

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}/metrics"

    def watch(self, loop: Any) -> None:
        """Export this loop's tick-latency histogram (set again after a reload)."""
        self.collector.loop = loop

    def close(self) -> None:
        self._server.shutdown()
        self._server.server_close()
        self._thread.join(5.0)
