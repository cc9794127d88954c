"""The dashboard loop: a `rich.live.Live` screen redrawn at >= 10 Hz from a snapshot provider.

A *snapshot provider* is any callable returning a `Frame` (the latest snapshot and an optional
notice). The dashboard only ever calls it; it never touches the monitor, so a slow terminal
can not slow the 256 Hz loop:

- `fdi dashboard` uses `fdi_daemon.dashboard.client.SocketProvider` (the daemon's status
  socket);
- in-process views (`fdi run --dashboard`, `fdi replay --realtime --dashboard`) let the sample
  loop `publish()` snapshots into a `LatestSnapshot` (a lock held only to swap a reference)
  and run the loop with `run_alongside(work, provider)`.

`q` quits (stdin in cbreak mode when it is a terminal); Ctrl-C quits too. `fdi dashboard`
passes `controls` that also send alarm requests (`fdi_daemon.dashboard.operator.AlarmKeys`),
with the keys and prompts in a footer line. When the terminal
goes away (an ssh drop, a closed window: reads see end of file, writes fail with EIO or
EPIPE) the loop ends with "hangup" instead of drawing to nobody.
"""

from __future__ import annotations

import contextlib
import logging
import os
import select
import signal
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol, TextIO

from rich.console import Console
from rich.live import Live
from rich.text import Text

from fdi_daemon.dashboard.render import render
from fdi_daemon.errors import UserError

DEFAULT_REFRESH_HZ = 10.0

log = logging.getLogger("fdi.dashboard")


class TerminalGone(Exception):
    """The terminal hung up: end of file on its input (or a read error)."""


class DashboardConsole(Console):
    """A rich Console for the dashboard: a broken pipe is the terminal gone (rich's default
    points stdout at /dev/null and raises SystemExit, which in the drawing thread would end
    only that thread, silently, and leave the daemon running for nobody)."""

    def on_broken_pipe(self) -> None:
        raise TerminalGone("broken pipe")


@dataclass(frozen=True)
class Frame:
    """What the dashboard draws next: the latest snapshot (None before the first one) and a
    notice shown on top of it (e.g. "daemon not reachable, retrying")."""

    snapshot: dict[str, Any] | None
    notice: str | None = None


SnapshotProvider = Callable[[], Frame]


class Controls(Protocol):
    """What keys do: `feed` gets what was typed and returns True to quit; `footer` is the
    line under the dashboard for the snapshot's alarm section (None: no footer)."""

    def feed(self, typed: str) -> bool: ...

    def footer(self, alarm: dict[str, Any] | None) -> Text | None: ...


class QuitKey:
    """`q` quits; no footer."""

    def feed(self, typed: str) -> bool:
        return "q" in typed.lower()

    def footer(self, alarm: dict[str, Any] | None) -> Text | None:
        return None


class LatestSnapshot:
    """The in-process snapshot provider: the producer publishes, the dashboard reads.

    `publish` and `__call__` only swap a reference under a lock, so neither side waits for
    the other's work (building a snapshot, rendering a frame).
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._frame = Frame(None)

    def publish(self, snapshot: dict[str, Any], notice: str | None = None) -> None:
        frame = Frame(snapshot, notice)
        with self._lock:
            self._frame = frame

    def __call__(self) -> Frame:
        with self._lock:
            return self._frame


class KeyReader:
    """Single key presses from stdin, without Enter, while in the `with` block.

    In a terminal stdin is put in cbreak mode (signals such as Ctrl-C still work) and restored
    on exit; otherwise no keys are read and `wait` just sleeps.
    """

    def __init__(self, stream: TextIO | None = None) -> None:
        self._stream = stream if stream is not None else sys.stdin
        self._fd: int | None = None
        self._saved: list | None = None

    def __enter__(self) -> KeyReader:
        try:
            fd = self._stream.fileno()
        except (AttributeError, OSError, ValueError):
            return self
        if not os.isatty(fd):
            return self
        import termios
        import tty

        self._fd = fd
        self._saved = termios.tcgetattr(fd)
        tty.setcbreak(fd, termios.TCSANOW)
        return self

    def __exit__(self, *exc: object) -> None:
        if self._fd is not None and self._saved is not None:
            import termios

            with contextlib.suppress(termios.error, OSError):  # a hung-up terminal
                termios.tcsetattr(self._fd, termios.TCSADRAIN, self._saved)
        self._fd = self._saved = None

    @property
    def interactive(self) -> bool:
        return self._fd is not None

    def wait(self, timeout_s: float) -> str:
        """Characters typed within `timeout_s` ("" if none; sleeps when not interactive).
        Raises TerminalGone at the end of the terminal's input (it hung up): a hung-up
        terminal is always readable, so going on would spin."""
        if self._fd is None:
            time.sleep(max(timeout_s, 0.0))
            return ""
        try:
            ready, _, _ = select.select([self._fd], [], [], max(timeout_s, 0.0))
            if not ready:
                return ""
            data = os.read(self._fd, 64)
        except OSError as exc:
            raise TerminalGone(exc.strerror or str(exc)) from None
        if not data:
            raise TerminalGone("end of input")
        return data.decode("utf-8", errors="replace")


def run_dashboard(
    provider: SnapshotProvider,
    *,
    refresh_hz: float = DEFAULT_REFRESH_HZ,
    console: Console | None = None,
    stop: threading.Event | None = None,
    keys: KeyReader | None = None,
    controls: Controls | None = None,
) -> str:
    """Redraw at `refresh_hz` until `q`, Ctrl-C or `stop` is set; returns why it ended:
    "quit" (q), "interrupt" (Ctrl-C), "hangup" (the terminal went away: end of its input, or
    a write to it failed) or "stopped". `keys`, if given, is already entered by the caller;
    otherwise stdin is read while the loop runs. `controls` handle what is typed (default:
    `QuitKey`)."""
    if keys is None:
        with KeyReader() as own_keys:
            return run_dashboard(
                provider,
                refresh_hz=refresh_hz,
                console=console,
                stop=stop,
                keys=own_keys,
                controls=controls,
            )
    console = console or DashboardConsole()
    controls = controls or QuitKey()

    def draw(live: Live) -> None:
        frame = provider()
        alarm = (frame.snapshot or {}).get("alarm")
        footer = controls.footer(alarm if isinstance(alarm, dict) else None)
        live.update(render(frame.snapshot, frame.notice, footer), refresh=True)

    period_s = 1.0 / refresh_hz
    try:
        with Live(
            console=console,
            screen=console.is_terminal,
            auto_refresh=False,
            redirect_stdout=False,
            redirect_stderr=False,
        ) as live:
            next_frame = time.monotonic()
            while not (stop is not None and stop.is_set()):
                draw(live)
                next_frame += period_s
                now = time.monotonic()
                if next_frame < now:
                    next_frame = now
                typed = keys.wait(next_frame - now)
                if typed and controls.feed(typed):
                    return "quit"
            draw(live)  # stopped: leave the final state on screen
    except KeyboardInterrupt:
        return "interrupt"
    except (TerminalGone, OSError) as exc:  # OSError: EIO/EPIPE writing to a dead terminal
        log.warning("the dashboard's terminal is gone (%s)", exc)
        return "hangup"
    return "stopped"


def run_alongside(
    work: Callable[[], int],
    provider: SnapshotProvider,
    *,
    request_stop: Callable[[], None] | None = None,
    linger: bool = False,
    refresh_hz: float = DEFAULT_REFRESH_HZ,
    console: Console | None = None,
    held_output: Path | None = None,
) -> int:
    """Run `work` in this (main) thread with the dashboard drawn from a background thread.

    `work` keeps the main thread so its signal handlers (SIGTERM, SIGINT) work as without a
    dashboard. `q`, and the terminal going away, call `request_stop` (default: raise SIGINT
    in this process, i.e. what Ctrl-C does). With `linger`, the final state stays on screen
    after `work` returns until `q` (only when stdin is a terminal). While the dashboard owns
    a terminal, whatever `work` prints (log lines, events) is held back, in `held_output` if
    given (kept: it is all there is to read after a hangup), and its last lines are shown
    afterwards (`captured_output`). Returns `work`'s exit code.
    """
    stop = threading.Event()
    done = threading.Event()

    def frames() -> Frame:
        frame = provider()
        if done.is_set():
            return Frame(frame.snapshot, frame.notice or "finished, press q to quit")
        return frame

    with contextlib.ExitStack() as stack:
        keys = stack.enter_context(KeyReader())
        if console is None:
            console = stack.enter_context(captured_output(keep=held_output))

        def show() -> None:
            ended = run_dashboard(
                frames, refresh_hz=refresh_hz, console=console, stop=stop, keys=keys
            )
            if ended in ("quit", "hangup") and not done.is_set():
                (request_stop or (lambda: signal.raise_signal(signal.SIGINT)))()

        thread = threading.Thread(target=show, name="fdi-dashboard", daemon=True)
        thread.start()
        try:
            code = work()
            done.set()
            if linger:
                try:
                    while thread.is_alive() and keys.interactive:
                        thread.join(0.1)
                except KeyboardInterrupt:
                    pass
            return code
        finally:
            stop.set()
            thread.join(2.0)


@contextlib.contextmanager
def captured_output(tail_lines: int = 40, keep: Path | None = None) -> Iterator[Console]:
    """A Console on the terminal while file descriptors 1 and 2 point at a file: `keep`
    (overwritten, left in place) or else a temporary file.

    Everything else the process prints meanwhile (print, logging handlers, C libraries) would
    scribble over the full-screen dashboard; it goes to the file instead and its last
    `tail_lines` lines are printed when the block ends. If the terminal is gone by then, 1
    and 2 go to /dev/null instead (the output stays in `keep`). Without a terminal on stdout
    nothing is redirected and the Console writes to stdout as usual.
    """
    if not sys.stdout.isatty():
        yield DashboardConsole()
        return
    try:
        if keep is not None:
            keep.parent.mkdir(parents=True, exist_ok=True)
        held_file = open(keep, "w+b") if keep is not None else tempfile.TemporaryFile()
    except OSError as exc:
        raise UserError(
            f"{keep}: cannot hold the output there while the dashboard is on "
            f"screen: {exc.strerror or exc}"
        ) from None
    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(1), os.dup(2)]
    terminal = os.fdopen(os.dup(1), "w", encoding="utf-8")
    with held_file as held:
        os.dup2(held.fileno(), 1)
        os.dup2(held.fileno(), 2)
        try:
            yield DashboardConsole(file=terminal)
        finally:
            sys.stdout.flush()
            sys.stderr.flush()
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            for fd in saved:
                os.close(fd)
            with contextlib.suppress(OSError):
                terminal.close()
            size = held.seek(0, os.SEEK_END)
            held.seek(max(0, size - 200 * tail_lines))
            lines = held.read().decode("utf-8", errors="replace").splitlines()
            if size > 200 * tail_lines:
                lines = lines[1:]  # the first one may be cut
            if len(lines) > tail_lines or size > 200 * tail_lines:
                lines.insert(
                    -tail_lines,
                    f"[earlier output in {keep}]"
                    if keep is not None
                    else "[earlier output not shown]",
                )
            try:
                sys.stdout.write("".join(line + "\n" for line in lines[-tail_lines - 1 :]))
                sys.stdout.flush()
            except OSError:  # the terminal hung up: nobody to tell, and nothing may fail later
                devnull = os.open(os.devnull, os.O_WRONLY)
                os.dup2(devnull, 1)
                os.dup2(devnull, 2)
                os.close(devnull)
