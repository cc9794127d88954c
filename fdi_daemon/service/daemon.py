"""The daemon: wires config, model, monitor, link, sinks and recorder, and runs the loop.

Lifecycle: build everything from the config (a mistake is a `ConfigError`, one line,
exit 2), tell systemd READY=1, run the loop; SIGTERM/SIGINT stop it cleanly (queues
drained, files fsynced, sockets removed, STOPPING=1); so does SIGHUP when the daemon draws
its dashboard on the terminal that hung up (`hangup_stops`); otherwise SIGHUP reloads the
config and the model: the new set is built first and swapped in only if it builds,
otherwise the daemon logs why and keeps running on the old one. A reload restarts the
monitor (it calibrates again) and reopens the link and the sinks; a simulated device keeps
running.

The alarm (`AlarmKeeper`: lifecycle, trend minute) and the event counters outlive a reload
(the same object goes on, unless the new model gives the level another unit) and a restart
(the state file in the state directory, `fdi_daemon.service.state_file`).
"""

from __future__ import annotations

import gc
import logging
import signal
import sqlite3
import sys
import threading
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from fdi_daemon.errors import ConfigError, UserError
from fdi_daemon.io.model_file import FdiModel, load_model
from fdi_daemon.io.sample import Sample
from fdi_daemon.service.alarm_keeper import AlarmKeeper
from fdi_daemon.service.config import RigConfig, check_link, load_config
from fdi_daemon.service.loop import ServiceLoop
from fdi_daemon.service.notify import Notifier, watchdog_period_s
from fdi_daemon.service.recorder import Recorder
from fdi_daemon.service.sinks import (
    EventLog,
    ModbusStatusServer,
    PriorityFormatter,
    StatusBoard,
    StatusSocketServer,
    StdoutLog,
    Worker,
    journald_attached,
    stamp_event,
)
from fdi_daemon.service.state_file import model_identity, read_state, write_state
from fdi_daemon.service.state_lock import StateDirLock
from fdi_daemon.service.trend import open_trend_store

if TYPE_CHECKING:
    from fdi_daemon.io.links.base import Link
    from hil_sim.devices import SimulatedDevice

log = logging.getLogger("fdi.daemon")

#: after this long compiling the kernels, `prepare` says what it is doing (s)
COMPILE_NOTICE_S = 2.0


def setup_logging(level: int = logging.INFO) -> None:
    """Log records on stderr; with ``<N>`` priorities when journald reads it."""
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(PriorityFormatter(journald_attached()))
    root = logging.getLogger()
    root.handlers[:] = [handler]
    root.setLevel(level)
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)  # its errors come back to us


class Sinks:
    """The sink worker, the recorder worker and the servers of one config.

    The MQTT sink and the metrics exporter are imported only when the config enables them
    (their libraries are the optional ``fleet`` extra).
    """

    def __init__(
        self,
        config: RigConfig,
        fs_hz: float,
        link_kind: str,
        board: StatusBoard,
        keeper: AlarmKeeper | None = None,
    ) -> None:
        self.board = board
        sinks = config.sinks
        self.event_log = None
        self.stdout = StdoutLog() if sinks["stdout"] else None
        self.status_server = None
        self.modbus_server = None
        self.recorder = None
        self.worker = None
        self.recorder_worker = None
        self.mqtt = None
        self.metrics = None
        self.state_path = config.output_path(config.alarms["state_file"])
        self.trend_store = None
        requests = None if keeper is None else keeper.handle
        try:
            if (path := config.output_path(sinks["event_log"])) is not None:
                self.event_log = EventLog(path)
            if (path := config.output_path(sinks["status_socket"])) is not None:
                self.status_server = StatusSocketServer(path, board, requests=requests)
            mb = sinks["modbus_status"]
            if mb["enabled"]:
                self.modbus_server = ModbusStatusServer(
                    board,
                    mb["host"],
                    mb["port"],
                    mb["device_id"],
                    requests=requests if config.alarms["allow_remote_acknowledge"] else None,
                )
                log.info(
                    "Modbus status registers on %s:%d (device id %d)",
                    mb["host"],
                    self.modbus_server.port,
                    mb["device_id"],
                )
            rec = config.recorder
            if rec["enabled"]:
                self.recorder = Recorder(
                    config.output_path(rec["dir"]),
                    fs_hz,
                    rec["rotate_seconds"],
                    rec["rotate_bytes"],
                    rec["fsync_period_s"],
                    rec["keep_files"],
                    meta={"link": link_kind, "config": config.source},
                    archive_format=rec["format"],
                )
            if config.mqtt["enabled"]:
                from fdi_daemon.service.mqtt_sink import MqttSink

                self.mqtt = MqttSink(
                    config.mqtt,
                    config.output_path(config.mqtt["buffer_file"]),
                    config.source,
                    config.service["queue_size"],
                )
            if config.metrics["listen"] is not None:
                from fdi_daemon.service.metrics import MetricsServer

                self.metrics = MetricsServer(
                    board, config.metrics["listen"], self.mqtt, config.source
                )
            if (
                keeper is not None
                and (path := config.output_path(config.alarms["trend"])) is not None
            ):
                self.trend_store = open_trend_store(
                    path, {"steps": list(config.alarms["steps"]), "model": keeper.model}
                )
        except (OSError, sqlite3.Error) as exc:
            self.close()
            raise ConfigError(f"{config.source}: cannot open an output: {exc}") from None
        except UserError:
            self.close()
            raise
        queue_size = config.service["queue_size"]
        self.worker = Worker("sinks", self._handle, queue_size)
        if self.recorder is not None:
            self.recorder_worker = Worker("recorder", self._record, queue_size)

    # --- Outputs protocol of the loop
    def event(self, event: dict) -> None:
        assert self.worker is not None  # made at the end of __init__
        self.worker.put(("event", event), critical=True)

    def samples(self, samples: list[Sample]) -> None:
        if self.recorder_worker is not None:
            self.recorder_worker.put(samples)

    def status(self, snapshot: dict) -> None:
        assert self.worker is not None  # made at the end of __init__
        self.worker.put(("status", snapshot))
        if self.recorder_worker is not None:
            self.recorder_worker.put(None)  # an idle recorder still fsyncs on time

    def alarm_state(self, state: dict) -> None:
        if self.state_path is not None:
            assert self.worker is not None  # made at the end of __init__
            self.worker.put(("state", state), critical=True)

    def trend(self, row: dict) -> None:
        if self.trend_store is not None:
            assert self.worker is not None  # made at the end of __init__
            self.worker.put(("trend", row), critical=True)

    def dropped(self) -> int:
        return sum(w.dropped for w in (self.worker, self.recorder_worker) if w is not None) + (
            self.mqtt.dropped() if self.mqtt is not None else 0
        )

    # --- worker threads
    def _handle(self, item: tuple[str, Any]) -> None:
        kind, payload = item
        if kind == "status":
            self.board.publish(payload)
            if self.mqtt is not None:
                self.mqtt.status(payload)
            return
        if kind in ("state", "trend"):
            try:
                if kind == "state":
                    write_state(self.state_path, payload)
                else:
                    assert self.trend_store is not None  # trend rows are queued only then
                    self.trend_store.append(payload)
            except (OSError, sqlite3.Error) as exc:  # the disk failed: say so, go on
                log.error(
                    "cannot write the %s: %s", "state file" if kind == "state" else "trend", exc
                )
            return
        stamped = stamp_event(payload)
        if self.mqtt is not None:
            self.mqtt.event(stamped)
        try:
            if self.event_log is not None:
                self.event_log.write(stamped)
        finally:  # the stdout line even when the log's disk failed (the worker logs why)
            if self.stdout is not None:
                self.stdout.write(payload)

    def _record(self, samples: list[Sample] | None) -> None:
        assert self.recorder is not None  # the recorder worker runs only with a recorder
        if samples is None:
            self.recorder.sync_if_due()
        else:
            self.recorder.append(samples)

    def close(self) -> None:
        for worker in (self.worker, self.recorder_worker):
            if worker is not None:
                worker.close()
        for thing in (
            self.recorder,
            self.event_log,
            self.status_server,
            self.modbus_server,
            self.mqtt,
            self.metrics,
            self.trend_store,
        ):
            if thing is not None:
                try:
                    thing.close()
                except (OSError, sqlite3.Error) as exc:
                    log.error("closing %s: %s", type(thing).__name__, exc)


def freeze_heap() -> None:
    """Collect once, then move every object alive now out of the cyclic GC's reach.

    The daemon's heap after start-up (numpy, scipy, numba, pymodbus: about a million
    objects) made each full collection hold the GIL for 140-370 ms, measured on the
    simulated rig: a stall of every thread and a burst of deadline misses. After
    ``gc.freeze()`` the collector only scans objects made later (Python docs, gc.freeze).
    On a reload the previous set is unfrozen first, so what the old config left behind
    can still be collected (one long pause, during the reload).
    """
    gc.unfreeze()
    gc.collect()
    gc.freeze()


def model_with_overrides(config: RigConfig) -> FdiModel:
    """The config's model with ``monitor.detector`` / ``monitor.velocity`` merged in."""
    model = load_model(config.model_path)
    for key in ("detector", "velocity"):
        if key in config.monitor:
            setattr(model, key, {**getattr(model, key), **config.monitor[key]})
    fs = config.service["fs"]
    if fs is not None and abs(fs - model.fs) > 1e-9 * model.fs:
        raise ConfigError(
            f"{config.source}: service.fs = {fs:g} Hz but the model "
            f"{config.model_path} was identified at {model.fs:g} Hz"
        )
    return model


def start_simulated_device(settings: dict[str, Any]) -> SimulatedDevice:
    """The built-in simulated rig served in-process over a real transport (hil_sim)."""
    from hil_sim.devices import ScheduledFault, SimulatedDevice, realtime_rig

    faults = [ScheduledFault(f["at_s"], f["name"], f["value"]) for f in settings["faults"]]
    try:
        rt = realtime_rig(settings["scenario"], seed=settings["seed"], faults=faults)
    except ValueError as exc:
        raise ConfigError(f"simulated_device: {exc}") from None
    device = SimulatedDevice(settings["transport"], rt, seed=settings["seed"])
    try:
        device.start()
    except OSError as exc:
        raise UserError(
            f"simulated_device: cannot start the {settings['transport']} device: {exc}"
        ) from None
    return device


class Daemon:
    """`fdi run`: one config, one loop; signals for stop and reload."""

    def __init__(
        self,
        config_path: str | Path | None = None,
        echo=print,
        state_dir: str | Path | None = None,
        hangup_stops: bool = False,
    ) -> None:
        self.config_path = config_path
        self.state_dir = state_dir  # `fdi run --state-dir`: wins over service.state_dir
        self.hangup_stops = hangup_stops  # `fdi run --dashboard`: SIGHUP = terminal gone
        self.echo = echo
        self.notifier = Notifier()
        self.board = StatusBoard()
        self.device: SimulatedDevice | None = (
            None  # the in-process simulated device, if the config asks for one
        )
        self.config: RigConfig | None = None
        self.loop: ServiceLoop | None = None
        self.sinks: Sinks | None = None
        self.link: Link | None = None
        self.keeper: AlarmKeeper | None = None
        self.lock: StateDirLock | None = None  # one daemon per state folder
        self.inherited_counts: dict[str, int] = {}  # the event counts the state file held
        self._wake = threading.Event()
        self._stopping = False
        self._reload = False

    # ------------------------------------------------------------------ building
    def prepare(self, config: RigConfig) -> tuple[FdiModel, Any, dict[str, Any]]:
        """Model, monitor and link settings of a config: checks, nothing opened yet. The
        monitor's kernels are compiled (or loaded from the cache) here, before serving."""
        model = model_with_overrides(config)
        from fdi_daemon.detect.monitor import Monitor

        monitor = Monitor(model)
        # numba compiles the kernels once after an install or an update (about a minute) and
        # caches them: say so when it takes long, so a first run does not look hung
        notice = threading.Timer(
            COMPILE_NOTICE_S,
            self.echo,
            (
                "compiling the monitor's kernels "
                "(once after an install or an update: about a minute; cached "
                "for later runs) ...",
            ),
        )
        notice.daemon = True
        notice.start()
        try:
            monitor.warm_up()
        finally:
            notice.cancel()
        return model, monitor, self.link_config(config)

    def assemble(
        self, config: RigConfig, model: FdiModel, monitor: Any, link_config: dict[str, Any]
    ) -> tuple[ServiceLoop, Sinks, Link]:
        """Open the sinks and make the link and the loop of a prepared config."""
        from fdi_daemon.io.links.base import make_reconnecting_link

        link = make_reconnecting_link(link_config, fs_hz=model.fs)
        keeper = self.alarm_keeper(config, model)
        sinks = Sinks(config, model.fs, link_config["kind"], self.board, keeper)
        model_info = {"path": str(config.model_path), "provenance": model.provenance}
        if self.loop is None:
            self.inherited_counts = dict(keeper.event_counts)
        counts = self.loop.event_counts if self.loop is not None else keeper.event_counts
        loop = ServiceLoop(
            link,
            monitor,
            sinks,
            fs_hz=model.fs,
            deadline_s=config.service["deadline_s"],
            read_timeout_s=config.service["read_timeout_s"],
            status_period_s=config.service["status_period_s"],
            model_info=model_info,
            notifier=self.notifier,
            watchdog_period_s=watchdog_period_s(),
            alarms=keeper,
            event_counts=counts,
        )
        self.keeper = keeper
        if sinks.metrics is not None:
            sinks.metrics.watch(loop)
        return loop, sinks, link

    def load_config(self) -> RigConfig:
        """The rig config, with `fdi run --state-dir` applied."""
        config = load_config(self.config_path)
        if self.state_dir is not None:
            config.service["state_dir"] = str(self.state_dir)
        if config.state_dir.exists() and not config.state_dir.is_dir():
            # it was "cannot open an output: [Errno 17] File exists", blaming the config
            raise ConfigError(
                f"state directory {config.state_dir} (--state-dir or "
                f"service.state_dir) is a file, not a directory"
            )
        return config

    def alarm_keeper(self, config: RigConfig, model: FdiModel) -> AlarmKeeper:
        """The alarm of this model: the running one (a reload), the state file's (a
        restart), or a fresh one; with the config's settings."""
        identity = model_identity(model)
        alarms = config.alarms
        keeper = self.keeper
        if keeper is not None and keeper.model == identity:
            keeper.reconfigure(alarms["settings"], alarms["allow_remote_acknowledge"])
            return keeper
        if keeper is not None:
            log.warning(
                "the reloaded model gives the friction level another unit (fs, plant "
                "or fault filter changed): the alarm state starts afresh"
            )
        path = config.output_path(alarms["state_file"])
        stored = read_state(path, identity) if path is not None else None
        try:
            keeper = AlarmKeeper(
                alarms["settings"],
                identity,
                stored=stored,
                allow_remote=alarms["allow_remote_acknowledge"],
            )
        except ValueError as exc:
            log.warning("state file %s: %s: refused, starting with a fresh state", path, exc)
            return AlarmKeeper(
                alarms["settings"], identity, allow_remote=alarms["allow_remote_acknowledge"]
            )
        if stored is not None and (trend := config.output_path(alarms["trend"])) is not None:
            keeper.recall_trend(trend)  # the same model: its last hours
        return keeper

    def link_config(self, config: RigConfig) -> dict[str, Any]:
        if config.simulated_device is None:
            return dict(config.link)
        if self.device is None:
            self.device = start_simulated_device(config.simulated_device)
            faults = (
                ", ".join(
                    f"{f['name']}={f['value']:g} at t={f['at_s']:g} s"
                    for f in config.simulated_device["faults"]
                )
                or "none"
            )
            self.echo(
                f"simulated rig: {self.device.transport} device at {self.device.where}; "
                f"scheduled faults: {faults}"
            )
        link = {**self.device.link_config, **config.link}
        check_link(link, config.source)
        return link

    # ------------------------------------------------------------------ running
    def run(self, duration_s: float | None = None) -> int:
        self.config = self.load_config()
        self.lock = StateDirLock(self.config.state_dir)
        self.lock.acquire()  # before any output is opened: a second daemon is refused here
        try:
            self.loop, self.sinks, self.link = self.assemble(
                self.config, *self.prepare(self.config)
            )
        except BaseException:
            self._stop_device()
            self.lock.release()
            raise
        previous = self._install_signals()
        end = None if duration_s is None else time.monotonic() + duration_s
        try:
            freeze_heap()
            self.link.open()
            self.announce()
            self.notifier.ready(f"starting; link {self.link.describe()}")
            while True:
                remaining = None if end is None else max(0.0, end - time.monotonic())
                self.loop.run(self._wake, remaining)
                if self._reload and not self._stopping:
                    self._reload = False
                    self._wake.clear()
                    self.reload()
                    continue
                break
        finally:
            self.notifier.stopping("stopping")
            try:
                self.shutdown()  # a second SIGTERM meanwhile must not kill it half-way
            finally:
                self._restore_signals(previous)
                self.lock.release()
        return 0

    def announce(self) -> None:
        assert self.config is not None and self.sinks is not None and self.link is not None
        sinks = self.sinks
        lines = [
            f"fdi run: config {self.config.source}",
            f"  model   {self.config.model_path}",
            f"  link    {self.link.describe()}",
            f"  state   {self.config.state_dir}/",
        ]
        if sinks.event_log is not None:
            lines.append(f"  events  {sinks.event_log.path}")
        if sinks.recorder is not None:
            lines.append(f"  records {sinks.recorder.directory}/")
        if sinks.status_server is not None:
            lines.append(
                f"  status  {sinks.status_server.path}  (fdi dashboard --connect "
                f"{sinks.status_server.path})"
            )
        if sinks.modbus_server is not None:
            lines.append(
                f"  modbus  {sinks.modbus_server.host}:{sinks.modbus_server.port} "
                f"(status registers, docs/status_registers.md)"
            )
        if sinks.mqtt is not None:
            lines.append(
                f"  mqtt    {sinks.mqtt.where} {sinks.mqtt.prefix}/event, "
                f"{sinks.mqtt.prefix}/status"
            )
        if sinks.metrics is not None:
            lines.append(f"  metrics {sinks.metrics.url}")
        if self.keeper is not None and (carried := self.keeper.carried_over()) is not None:
            lines.append(f"  {carried}")
        self.echo("\n".join(lines))

    def reload(self) -> None:
        """SIGHUP: rebuild from the (possibly edited) config; keep the old one on failure.

        The loop's counters restart with the new loop (the Modbus counters too).
        """
        self.notifier.reloading()
        log.info("SIGHUP: reloading %s", self.config_path or "the default config")
        assert self.lock is not None  # reload runs inside run(), which holds the lock
        lock = self.lock
        try:
            config = self.load_config()
            if self.config is not None and config.state_dir != self.config.state_dir:
                lock = StateDirLock(config.state_dir)
                lock.acquire()
            try:
                prepared = self.prepare(config)
            except BaseException:
                if lock is not self.lock:
                    lock.release()
                raise
        except (UserError, OSError) as exc:
            log.error("reload failed, keeping the previous config: %s", exc)
            self.notifier.ready("reload failed; previous config kept")
            return
        assert self.config is not None and self.link is not None and self.sinks is not None
        self.link.close()
        self.echo(self.summary() + " (before the reload)")
        self.sinks.close()  # the new sinks bind the same socket paths and ports
        try:
            self.loop, self.sinks, self.link = self.assemble(config, *prepared)
            self.config = config
            if lock is not self.lock:
                self.lock.release()
                self.lock = lock
        except (UserError, OSError) as exc:
            if lock is not self.lock:
                lock.release()
            log.error(
                "reload failed while opening the outputs, back to the previous config: %s", exc
            )
            self.loop, self.sinks, self.link = self.assemble(
                self.config, *self.prepare(self.config)
            )
        freeze_heap()
        self.link.open()
        self.notifier.ready(f"reloaded; link {self.link.describe()}")
        self.announce()

    def shutdown(self) -> None:
        if self.link is not None:
            self.link.close()
        if self.loop is not None:
            self.echo(self.summary())
        if self.sinks is not None:
            self.sinks.close()
        self._stop_device()
        self.notifier.close()

    def _stop_device(self) -> None:
        if self.device is not None:
            self.device.stop()
            self.device = None

    def summary(self) -> str:
        loop = self.loop
        assert loop is not None
        lat = loop.tick_latency.summary()
        late = loop.lateness.summary()
        counts = ", ".join(f"{k} {v}" for k, v in sorted(loop.event_counts.items())) or "none"
        this_run = {
            k: n - self.inherited_counts.get(k, 0) for k, n in sorted(loop.event_counts.items())
        }
        this_run_text = ", ".join(f"{k} {n}" for k, n in this_run.items() if n > 0) or "none"
        return (
            f"fdi run: {loop.samples} samples, {loop.gaps} gaps, {loop.duplicates} "
            f"duplicates; tick latency p50 {lat['p50']:.0f} µs p99 {lat['p99']:.0f} µs "
            f"max {lat['max']:.0f} µs; lateness p50 {late['p50'] / 1e3:.1f} ms p99 "
            f"{late['p99'] / 1e3:.1f} ms; deadline misses {loop.deadline_misses} "
            f"(> {loop.deadline_s * 1e3:g} ms; {loop.late_arrivals} arrived late); "
            f"dropped outputs "
            f"{self.sinks.dropped() if self.sinks else 0}; events of this run: "
            f"{this_run_text}; since the alarm state began (kept across restarts): {counts}"
        )

    # ------------------------------------------------------------------ signals
    def _install_signals(self) -> dict:
        if threading.current_thread() is not threading.main_thread():
            return {}
        previous = {}
        for signum, handler in (
            (signal.SIGTERM, self._on_stop),
            (signal.SIGINT, self._on_stop),
            (signal.SIGHUP, self._on_stop if self.hangup_stops else self._on_reload),
        ):
            previous[signum] = signal.signal(signum, handler)
        return previous

    @staticmethod
    def _restore_signals(previous: dict) -> None:
        for signum, handler in previous.items():
            signal.signal(signum, handler)

    def stop(self) -> None:
        """Stop as SIGTERM does; from any thread (the dashboard's `q` or its hangup)."""
        self._stopping = True
        self._wake.set()

    def _on_stop(self, signum, frame) -> None:
        self.stop()

    def _on_reload(self, signum, frame) -> None:
        self._reload = True
        self._wake.set()
