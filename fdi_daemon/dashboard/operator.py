"""The operator's alarm requests (acknowledge, shelve, unshelve) over the status socket, for
`fdi alarm` and the dashboard's keys: one way to build a request, to read its answer and to
show an alarm in a line.

The daemon decides (`fdi_daemon.service.alarm_keeper.AlarmKeeper.request`, the lifecycle's
rules) and writes who, when and why into its event log; a refusal comes back with its reason.
`AlarmKeys` is the dashboard's side: `a`, `s`, `u` open a prompt in the footer (shelve asks
how long, every request asks why), Enter sends, Esc cancels, and the daemon's answer stays in
the footer for a few seconds.
"""

from __future__ import annotations

import getpass
import re
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from rich.text import Text

from fdi_daemon.dashboard.client import DaemonUnreachable

#: the socket's name of each action (as `fdi alarm` spells them)
REQUESTS = {"ack": "acknowledge", "shelve": "shelve", "unshelve": "unshelve"}

#: duration units (seconds each)
_DURATION_UNITS = {"s": 1.0, "m": 60.0, "h": 3600.0, "d": 86400.0}
_DURATION = re.compile(r"^\s*(\d+(?:\.\d*)?|\.\d+)\s*([smhd]?)\s*$")


def parse_duration(text: str) -> float:
    """``90``, ``90s``, ``30m``, ``8h``, ``1d`` as seconds (> 0); ValueError otherwise."""
    match = _DURATION.match(text)
    if match is None or float(match.group(1)) <= 0:
        raise ValueError(
            f"not a duration: {text!r} (a positive number with s, m, h or d, e.g. 30m)"
        )
    return float(match.group(1)) * _DURATION_UNITS[match.group(2) or "s"]


def requester(by: str | None) -> str:
    """Who asks: `by`, or else the login name."""
    if by is not None:
        return by
    try:
        return getpass.getuser()
    except (KeyError, OSError):  # no passwd entry, no LOGNAME
        return "unknown"


def alarm_request(
    action: str, by: str, why: str = "", duration_s: float | None = None
) -> dict[str, Any]:
    """The status socket's request line for `action` (ack, shelve, unshelve)."""
    return {"request": REQUESTS[action], "by": by, "why": why, "duration_s": duration_s}


def outcome(action: str, by: str, answer: dict[str, Any]) -> tuple[bool, str]:
    """(accepted, one line) for the daemon's `answer` to `action`."""
    if not answer.get("ok"):
        return False, f"{action} refused: {answer.get('error')}"
    return True, f"{answer.get('result')} by {by}; {alarm_line(answer.get('alarm') or {})}"


def alarm_line(alarm: dict[str, Any]) -> str:
    """The alarm section of a snapshot in one line."""
    if not alarm:
        return "alarm: none (this daemon keeps no alarm)"
    if alarm.get("state", "normal") == "normal" and not alarm.get("alarm_id"):
        return "alarm: normal (no alarm since the state began)"
    started = alarm.get("started")
    since = (
        time.strftime("%Y-%m-%d %H:%M:%S %z", time.localtime(started))
        if isinstance(started, (int, float))
        else "?"
    )
    text = (
        f"alarm #{alarm.get('alarm_id')}: {str(alarm.get('state')).replace('_', ' ')}, "
        f"P{alarm.get('priority')} (peak P{alarm.get('peak_priority')}), since {since}"
    )
    level = alarm.get("level")
    if isinstance(level, (int, float)):
        text += f", level {level:.3g} above the baseline"
    until = alarm.get("shelved_until")
    if isinstance(until, (int, float)) and until > time.time():
        text += f", shelved until {time.strftime('%H:%M:%S', time.localtime(until))}"
    return text


# ---------------------------------------------------------------- the dashboard's keys

#: key -> action
ACTION_KEYS = {"a": "ack", "s": "shelve", "u": "unshelve"}
_VERBS = {"ack": "acknowledge the alarm", "shelve": "shelve the alarm", "unshelve": "unshelve"}
_ENTER, _BACKSPACE, _ESCAPE = "\r\n", "\x7f\b", "\x1b"
MAX_TYPED = 200


@dataclass
class _Prompt:
    action: str
    field: str  # "duration" or "why"
    typed: str = ""
    duration_s: float | None = None


class AlarmKeys:
    """The dashboard's key handling with alarm requests.

    `ask` sends one request line and returns the daemon's answer (raising
    `DaemonUnreachable` when there is none; `SocketProvider.ask`); `by` is who asks; `shelve_for_s` is the shelving offered when the
    operator just presses Enter at "how long". `feed` takes what was typed and returns True
    to quit; `footer` is the line to show under the dashboard.
    """

    MESSAGE_S = 8.0

    def __init__(
        self,
        ask: Callable[[dict[str, Any]], dict[str, Any]],
        by: str,
        shelve_for_s: float = 1800.0,
        monotonic: Callable[[], float] = time.monotonic,
    ):
        self._ask = ask
        self.by = by
        self.shelve_for_s = shelve_for_s
        self._monotonic = monotonic
        self.prompt: _Prompt | None = None
        self.message: tuple[bool, str, float] | None = None  # (ok, line, shown until)

    def feed(self, typed: str) -> bool:
        """Handle the characters typed; True when the operator asked to quit."""
        if _ESCAPE in typed:  # Esc (or an arrow key's sequence) cancels a prompt
            if self.prompt is not None:
                self.prompt = None
                self._say(True, "cancelled")
            return False
        for char in typed:
            if self.prompt is None:
                if char.lower() == "q":
                    return True
                action = ACTION_KEYS.get(char.lower())
                if action is not None:
                    self.prompt = _Prompt(action, "duration" if action == "shelve" else "why")
                    self.message = None
            elif char in _ENTER:
                self._enter()
            elif char in _BACKSPACE:
                self.prompt.typed = self.prompt.typed[:-1]
            elif char.isprintable() and len(self.prompt.typed) < MAX_TYPED:
                self.prompt.typed += char
        return False

    def _enter(self) -> None:
        prompt = self.prompt
        assert prompt is not None
        if prompt.field == "duration":
            try:
                prompt.duration_s = (
                    parse_duration(prompt.typed) if prompt.typed.strip() else self.shelve_for_s
                )
            except ValueError as exc:
                self._say(False, str(exc))
                prompt.typed = ""
                return
            prompt.field, prompt.typed = "why", ""
            return
        self.prompt = None
        request = alarm_request(prompt.action, self.by, prompt.typed.strip(), prompt.duration_s)
        try:
            answer = self._ask(request)
        except DaemonUnreachable as exc:
            self._say(False, f"{prompt.action}: no answer from the daemon ({exc})")
            return
        self._say(*outcome(prompt.action, self.by, answer))

    def _say(self, ok: bool, line: str) -> None:
        self.message = (ok, line, self._monotonic() + self.MESSAGE_S)

    def footer(self, alarm: dict[str, Any] | None = None) -> Text:
        """The prompt being typed (and what was wrong with the last entry), else the last answer (for a few seconds), else the keys;
        `alarm` is the snapshot's alarm section (requests may be disabled there)."""
        text = Text(no_wrap=True, overflow="ellipsis")
        prompt = self.prompt
        if prompt is not None:
            if prompt.field == "duration":
                question = f"shelve for how long? [{_short(self.shelve_for_s)}] "
            else:
                question = f"{_VERBS[prompt.action]}, as {self.by}. Why? "
            text.append(f" {question}", style="bold")
            text.append(prompt.typed + "▏", style="reverse" if not prompt.typed else None)
            text.append("  Enter sends, Esc cancels", style="dim")
            if self.message is not None and self._monotonic() < self.message[2]:
                text.append(f"  {self.message[1]}", style="bold red")  # e.g. a bad duration
            return text
        if self.message is not None and self._monotonic() < self.message[2]:
            ok, line, _ = self.message
            text.append(f" {line}", style="green" if ok else "bold red")
            return text
        if isinstance(alarm, dict) and alarm.get("remote_acknowledge") is False:
            text.append(
                " alarm requests disabled on this daemon (alarms.allow_remote_acknowledge)",
                style="dim",
            )
        else:
            for key, label in (("a", "acknowledge"), ("s", "shelve"), ("u", "unshelve")):
                text.append(f" {key}", style="bold reverse")
                text.append(f" {label} ", style="dim")
        text.append(" q", style="bold reverse")
        text.append(" quit", style="dim")
        return text


def _short(seconds: float) -> str:
    """A duration as `parse_duration` reads it back (30m, 8h, 90s)."""
    for unit, size in (("d", 86400.0), ("h", 3600.0), ("m", 60.0)):
        if seconds >= size and seconds % size == 0:
            return f"{seconds / size:g}{unit}"
    return f"{seconds:g}s"
