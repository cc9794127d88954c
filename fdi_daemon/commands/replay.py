"""`fdi replay`: run a recording through the daemon's own monitor (batch or paced)."""

from __future__ import annotations

import argparse
import contextlib

from fdi_daemon.io.columns import add_columns_option

HELP = "replay a recording through the monitor: events, summary and the paper's Figs. 5-7"

#: recordings longer than this are traced every n-th sample for the plot (bounded memory)
TRACE_POINTS = 400_000


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "recording", metavar="REC", help="recording (.csv, .csv.gz, .npz, .mat, .parquet)"
    )
    parser.add_argument(
        "--model",
        required=True,
        metavar="MODEL.yaml",
        help="model file with plant, fault_filter (signature) and settings",
    )
    parser.add_argument("--events", metavar="EVENTS.jsonl", help="write the events (JSON Lines)")
    parser.add_argument("--summary", metavar="SUMMARY.json", help="write the replay summary")
    parser.add_argument(
        "--plot",
        metavar="FILE.png",
        help="acceleration, θ1/θ2 with band and signature, residual, statistic",
    )
    parser.add_argument(
        "--trace",
        metavar="FILE",
        help="write t, theta1, theta2, friction_level, statistic, state per "
        "sample (CSV with a header; .npz with the same names)",
    )
    parser.add_argument(
        "--trace-every",
        type=int,
        default=1,
        metavar="N",
        help="with --trace: every N-th sample (default %(default)s)",
    )
    parser.add_argument(
        "--realtime",
        action="store_true",
        help="pace the samples at fs through the per-tick path (as the daemon)",
    )
    parser.add_argument(
        "--dashboard",
        action="store_true",
        help="with --realtime: show the live dashboard while replaying (q stops)",
    )
    parser.add_argument(
        "--alarms",
        metavar="CONFIG.yaml",
        help="the alarm lifecycle's settings and status period from this daemon "
        "config (default: the built-in alarms section)",
    )
    add_columns_option(parser)


def run(args: argparse.Namespace) -> int:
    _check_arguments(args)
    replay, shown, stopped = _replay(args)
    summary = replay.summary
    if stopped:  # the outputs hold what was replayed
        summary.update(samples=stopped["samples"], interrupted_at_t=stopped["t"])
    written = _write_outputs(args, replay, shown)
    _report(replay.events, summary)
    if written:
        print("wrote " + "; ".join(written))
    if replay.monitor.baseline_note:
        print(f"note: {replay.monitor.baseline_note}")
    if stopped:
        import sys

        print(
            f"fdi replay: interrupted at t = {stopped['t']:.4f} s; the outputs hold the "
            f"{stopped['samples']} sample(s) replayed",
            file=sys.stderr,
        )
        return 130
    return 0


def _check_arguments(args: argparse.Namespace) -> None:
    """Options that do not go together, and output files that would overwrite an input."""
    from fdi_daemon.errors import UserError
    from fdi_daemon.io.outputs import check_outputs

    if args.dashboard and not args.realtime:
        raise UserError(
            "--dashboard needs --realtime (a batch replay is over before a screen could show it)"
        )
    if args.trace_every < 1:
        raise UserError("--trace-every must be a whole number >= 1")
    if args.trace_every != 1 and not args.trace:
        raise UserError("--trace-every thins the trace file: it needs --trace FILE")
    check_outputs(
        {
            "--events": args.events,
            "--summary": args.summary,
            "--plot": args.plot,
            "--trace": args.trace,
        },
        (args.recording, args.model, args.alarms),
        plots=("--plot",),
    )


def _replay(args: argparse.Namespace):
    """(the replay, the rows the trace file or the plot shows every, where a paced replay
    stopped by Ctrl-C stopped: {} if it did not): batch, paced, with the dashboard, or
    streamed piece by piece (a Parquet file, flat memory) with a progress bar."""
    import math

    from fdi_daemon.fleet.replay_one import replay_recording

    settings, status_period_s = _alarm_settings(args.alarms)
    # rows the trace file or the plot shows (the batch path traces them and the readings')
    shown = [args.trace_every if args.trace else 1]  # a streamed replay calls no runner
    stopped: dict = {}

    def runner(monitor, rec, stride):
        n = len(rec)
        shown[0] = (
            args.trace_every if args.trace else (_plot_every(n, stride) if args.plot else stride)
        )
        if args.realtime and args.dashboard:
            from fdi_daemon.dashboard.replay_view import replay_with_dashboard

            return replay_with_dashboard(
                lambda on_tick: _paced(monitor, rec, on_tick),
                monitor,
                str(args.recording),
                args.model,
                n,
            )
        if args.realtime:
            return _paced(monitor, rec, stopped=stopped)
        return _batch(monitor, rec, math.gcd(shown[0], stride))

    bar: list = []  # a streamed replay's progress bar (Progress, task), made at its first piece

    def streamed(done: int, total: int) -> None:
        if not bar:
            if total < 100_000:
                return
            bar.extend(_progress(total, "replay"))
            bar[0].start()
        bar[0].update(bar[1], completed=done)

    try:
        replay = replay_recording(
            args.recording,
            args.model,
            runner,
            columns=args.columns,
            alarm_settings=settings,
            status_period_s=status_period_s,
            # a Parquet file piece by piece (flat memory), unless paced or plotted whole
            stream=not (args.realtime or args.plot),
            progress=streamed,
            trace_every=args.trace_every if args.trace else None,
        )
    finally:
        if bar:
            bar[0].stop()
    return replay, shown[0], stopped


def _write_outputs(args: argparse.Namespace, replay, shown: int) -> list[str]:
    """--events, --summary, --trace (every ``shown`` samples) and --plot; "what PATH" of
    each file written, said at the end."""
    from fdi_daemon.io.outputs import write_json

    events, trace = replay.events, replay.trace
    written: list[str] = []
    if args.events:
        from fdi_daemon.detect.events import write_events

        write_events(args.events, events)
        written.append(f"events {args.events} ({len(events)} lines)")
    if args.summary:
        write_json(args.summary, replay.summary)
        written.append(f"summary {args.summary}")
    if args.trace:
        from fdi_daemon.detect.trace_file import write_trace

        write_trace(args.trace, trace, shown // trace.every)
        rows = -(-len(trace.t) // (shown // trace.every))
        written.append(f"trace {args.trace} ({rows} rows, every {shown} sample{'s' * (shown > 1)})")
    if args.plot:
        _plot(args.plot, replay, shown, title=str(args.recording))
        written.append(f"plot {args.plot}")
    return written


def _plot(path: str, replay, shown: int, title: str) -> None:
    """The replay figure of the trace every ``shown`` samples, the fault's onset marked
    where the recording has a ``fault_active`` column (a simulated one)."""
    import numpy as np

    from fdi_daemon.detect.plots import plot_replay

    rec, trace, monitor = replay.recording, replay.trace, replay.monitor
    onset = None
    if "fault_active" in rec.columns:
        active = np.flatnonzero(np.asarray(rec["fault_active"]) > 0.5)
        onset = float(rec.t[active[0]]) if active.size else None
    plot_replay(
        path,
        _thinned(trace, shown // trace.every),
        replay.events,
        monitor.gamma_f,
        monitor.detector.band,
        monitor.detector.threshold,
        onset,
        title=title,
    )


def _alarm_settings(path: str | None):
    """(alarm settings, status period s): a daemon config's (`--alarms`), else the defaults."""
    from fdi_daemon.alarms.lifecycle import AlarmSettings
    from fdi_daemon.alarms.replay import STATUS_PERIOD_S

    if path is None:
        return AlarmSettings(), STATUS_PERIOD_S
    from fdi_daemon.service.config import load_config

    config = load_config(path)
    return config.alarms["settings"], float(config.service["status_period_s"])


def _plot_every(n: int, stride: int) -> int:
    """Plot every n-th sample: at most `TRACE_POINTS` rows, and a divisor or a multiple of
    the readings' ``stride`` so that one batch trace serves both."""
    need = max(1, -(-n // TRACE_POINTS))
    if need >= stride:
        return stride * -(-need // stride)
    return min(d for d in range(need, stride + 1) if stride % d == 0)


def _thinned(trace, step: int):
    """Every ``step``-th row of a `MonitorTrace`."""
    import dataclasses

    if step == 1:
        return trace
    arrays = {
        f.name: getattr(trace, f.name)[::step]
        for f in dataclasses.fields(trace)
        if f.name != "every"
    }
    return dataclasses.replace(trace, every=trace.every * step, **arrays)


def _progress(total: int, label: str):
    from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

    progress = Progress(
        TextColumn(label),
        BarColumn(),
        TextColumn("{task.percentage:>3.0f}%"),
        TimeRemainingColumn(),
        transient=True,
    )
    task = progress.add_task(label, total=total)
    return progress, task


def _batch(monitor, rec, trace_every: int):
    """The fast path: Monitor.run in chunks, with a progress bar on long files."""
    n = len(rec)
    if n < 100_000:
        return monitor.run(rec, trace_every=trace_every)
    progress, task = _progress(n, "replay")
    with progress:
        return monitor.run(
            rec,
            trace_every=trace_every,
            progress=lambda done, total: progress.update(task, completed=done),
        )


def _paced(monitor, rec, on_tick=None, stopped: dict | None = None):
    """Samples at fs through Monitor.step (the daemon's path).

    Without ``on_tick``: a progress bar and the events printed as they come. With it, a live
    view takes the screen: ``on_tick(monitor, t, new_events)`` is called after every sample.
    With ``stopped``, Ctrl-C ends the replay there (``stopped`` gets its "t" and "samples")
    and the events and trace so far are returned, so that the outputs keep them.
    """
    import time

    import numpy as np

    from fdi_daemon.detect.monitor import TRACE_NAMES, MonitorTrace
    from fdi_daemon.io.sample import Sample

    cols = rec.columns
    n = len(rec)
    t = np.asarray(cols["t"], dtype=float)
    v_in = np.asarray(cols["v_in"], dtype=float)
    accel = np.asarray(cols["accel"], dtype=float)
    position = monitor.position_column(rec)
    seq = np.asarray(cols["seq"], dtype=np.int64) if "seq" in cols else monitor.sample_numbers(t)
    period = 1.0 / monitor.fs_hz
    out = {k: np.empty(n) for k in TRACE_NAMES}
    events = []
    rows, last_seq = 0, None
    progress, task = (None, None) if on_tick is not None else _progress(n, "replay (real time)")
    start = time.monotonic()
    k = 0
    with (
        progress if progress is not None else contextlib.nullcontext(),
        _stop_on_interrupt(stopped, lambda: (float(t[k]), k)),
    ):
        for k in range(n):
            delay = start + k * period - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            new = monitor.step(
                Sample(
                    int(seq[k]), float(t[k]), float(v_in[k]), float(accel[k]), float(position[k])
                )
            )
            events.extend(new)
            if last_seq is None or seq[k] > last_seq:  # not dropped: a row, as Monitor.run
                last_seq = int(seq[k])
                for name, value in zip(TRACE_NAMES, monitor.trace_row(float(t[k]))):
                    out[name][rows] = value
                rows += 1
            if on_tick is not None:
                on_tick(monitor, float(t[k]), new)
                continue
            assert progress is not None  # made when there is no on_tick
            for event in new:
                progress.console.print(_line(event), highlight=False, soft_wrap=True)
            if k % 256 == 0:
                progress.update(task, completed=k + 1)
    events.extend(monitor.finish())
    out = {name: values[:rows] for name, values in out.items()}
    trace = MonitorTrace(every=1, state=out.pop("state").astype(np.int8), **out)
    return events, trace


@contextlib.contextmanager
def _stop_on_interrupt(stopped: dict | None, where):
    """Ctrl-C inside ends the block quietly when ``stopped`` is given, noting ``where()``
    (t, samples done) in it; without ``stopped`` it propagates as usual."""
    try:
        yield
    except KeyboardInterrupt:
        if stopped is None:
            raise
        stopped["t"], stopped["samples"] = where()


def _line(event: dict) -> str:
    extra = ""
    if event.get("theta1") is not None:
        # θ2 multiplies the velocity's filtered regressor: s/m, as γ_f of the signature (1, γ_f)
        extra = f"  θ1={event['theta1']:.3g}  θ2={event['theta2']:.3g} s/m"
    if event.get("friction_level") is not None:
        extra += f"  friction_level={event['friction_level']:.3g}"
    elif "friction_level" in event:  # an episode's level restarts: it takes a few seconds
        extra += "  friction_level=- (not measured yet)"
    if "count" in event:
        extra += f"  count={event['count']} ({event.get('reason', '')})"
    if "missing_samples" in event:
        extra += f"  missing={event['missing_samples']}"
    if "alarm_id" in event:
        level = event.get("level")
        shown = f"{level:.3g}" if level is not None else "- (not measured yet)"
        extra += (
            f"  alarm {event['alarm_id']} {event['state']} priority {event['priority']}"
            f"  level={shown}"
        )
    return f"{event['t']:10.4f} s  {event['kind']}{extra}"


def _report(events: list, summary: dict) -> None:
    from rich.console import Console

    console = Console(soft_wrap=True)  # whole lines: the terminal wraps, never mid-sentence
    shown = [e for e in events if e["kind"] != "bad_sample"][:50]
    for event in shown:
        console.print(_line(event), highlight=False)
    if len(events) > len(shown):
        console.print(f"... {len(events) - len(shown)} more event(s)", highlight=False)
    cls = summary["classification"] or "none"
    det = summary["first_detection_t"]
    console.print(
        f"{summary['samples']} samples at {summary['fs']:g} Hz: "
        f"{summary['alarm_episodes']} alarm episode(s) ({summary['alarms']} "
        f"alarm(s), peak priority {summary['alarm_peak_priority']}), first detection "
        f"{'-' if det is None else f'{det:.4f} s'}, classification {cls}",
        highlight=False,
    )
