"""The dashboard's alarm keys (a acknowledge, s shelve, u unshelve) against a real status
socket server with the daemon's alarm keeper: the requests the daemon logs (who, why, how
long), refusals and an absent daemon in the footer, Esc, and q typed into a reason."""

from __future__ import annotations

import pytest
from conftest_dashboard import make_snapshot, screen_text

from fdi_daemon.alarms.lifecycle import AlarmSettings
from fdi_daemon.dashboard.client import SocketProvider
from fdi_daemon.dashboard.operator import AlarmKeys, alarm_request, outcome, parse_duration
from fdi_daemon.dashboard.render import render
from fdi_daemon.service.alarm_keeper import AlarmKeeper
from fdi_daemon.service.sinks import StatusBoard, StatusSocketServer


class Clock:
    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


@pytest.fixture
def daemon(tmp_path):
    """(keeper with alarm #1 raised, socket path) of a real status socket server."""
    keeper = AlarmKeeper(AlarmSettings(max_shelve_s=7200.0), "m", allow_remote=True)
    keeper.detector_event({"t": 1.0, "kind": "fault_detected"})
    board = StatusBoard()
    board.publish({**make_snapshot("friction_isolated"), "alarm": keeper.summary()})
    server = StatusSocketServer(tmp_path / "s.sock", board, requests=keeper.handle)
    try:
        yield keeper, tmp_path / "s.sock"
    finally:
        server.close()


def footer_text(keys: AlarmKeys, alarm: dict | None = None) -> str:
    return keys.footer(alarm).plain


def test_keys_acknowledge_shelve_unshelve_with_who_why_and_how_long(daemon):
    keeper, path = daemon
    provider = SocketProvider(path)
    clock = Clock()
    keys = AlarmKeys(provider.ask, "alice", shelve_for_s=1800.0, monotonic=clock)
    try:
        assert provider().snapshot["state"] == "friction_isolated"
        assert footer_text(keys) == " a acknowledge  s shelve  u unshelve  q quit"
        assert not keys.feed("a")
        assert footer_text(keys).startswith(" acknowledge the alarm, as alice. Why? ")
        assert not keys.feed("bearing q checked")  # q inside a reason is text, not quit
        assert not keys.feed("\x7f" * 9 + "checked\r")
        assert footer_text(keys).startswith(" acknowledged by alice; alarm #1: acknowledged, P1")
        clock.now += AlarmKeys.MESSAGE_S + 1  # the answer leaves the footer after a while
        assert footer_text(keys).startswith(" a acknowledge")

        keys.feed("s")
        assert footer_text(keys).startswith(" shelve for how long? [30m] ")
        keys.feed("1x\r")  # not a duration: said, and asked again
        assert "not a duration: '1x'" in footer_text(keys)
        assert keys.prompt is not None and keys.prompt.field == "duration"
        keys.feed("2h\rrepair of the supply\n")
        assert footer_text(keys).startswith(" shelved by alice; alarm #1: acknowledged")
        assert "shelved until" in footer_text(keys)

        keys.feed("u")
        keys.feed("\r")
        assert footer_text(keys).startswith(" unshelved by alice")
        keys.feed("u\r")  # the daemon refuses: said in the footer
        assert footer_text(keys) == " unshelve refused: not shelved"
        keys.feed("s3h\r\r")  # longer than alarms.max_shelve_s
        assert footer_text(keys) == " shelve refused: shelve duration must be in (0, 7200] s"
    finally:
        provider.close()
    acknowledged, shelved, unshelved = keeper.take_pending()
    assert acknowledged["kind"] == "alarm_acknowledged"
    assert acknowledged["by"] == "alice (status socket)"
    assert acknowledged["why"] == "bearing checked"
    assert shelved["kind"] == "alarm_shelved" and shelved["why"] == "repair of the supply"
    assert shelved["until"] - shelved["time"] == pytest.approx(7200.0)  # unix s here
    assert unshelved["kind"] == "alarm_unshelved" and unshelved["by"] == "alice (status socket)"
    assert "why" not in unshelved


def test_escape_cancels_and_q_quits_only_outside_a_prompt(daemon):
    keeper, path = daemon
    provider = SocketProvider(path)
    keys = AlarmKeys(provider.ask, "bob")
    try:
        keys.feed("a")
        keys.feed("not sure")
        keys.feed("\x1b")
        assert keys.prompt is None and footer_text(keys) == " cancelled"
        keys.feed("s")
        keys.feed("\x1b[A")  # an arrow key's sequence cancels too
        assert keys.prompt is None
        assert keys.feed("q")
    finally:
        provider.close()
    assert keeper.take_pending() == []
    assert keeper.lifecycle.state == "unacknowledged"


def test_no_daemon_and_requests_disabled_are_said_in_the_footer(tmp_path):
    provider = SocketProvider(tmp_path / "none.sock")
    keys = AlarmKeys(provider.ask, "carol")
    keys.feed("a\r")
    assert footer_text(keys) == (
        f" ack: no answer from the daemon (no socket at {tmp_path / 'none.sock'})"
    )
    disabled = AlarmKeys(provider.ask, "carol")
    assert footer_text(disabled, {"remote_acknowledge": False}).startswith(
        " alarm requests disabled on this daemon (alarms.allow_remote_acknowledge)"
    )


def test_footer_is_the_last_line_of_the_screen():
    keys = AlarmKeys(lambda request: {"ok": True}, "dave")
    for width, height in ((120, 40), (70, 20)):  # standard and compact layouts
        lines = screen_text(
            render(make_snapshot("monitoring"), footer=keys.footer()), width, height
        ).splitlines()
        assert len(lines) == height
        assert lines[-1].rstrip() == " a acknowledge  s shelve  u unshelve  q quit"
        assert "MONITORING" in lines[0]


def test_fdi_alarm_and_the_keys_build_the_same_request():
    assert alarm_request("shelve", "eve", "why", parse_duration("30m")) == {
        "request": "shelve",
        "by": "eve",
        "why": "why",
        "duration_s": 1800.0,
    }
    assert outcome("ack", "eve", {"ok": False, "error": "nope"}) == (False, "ack refused: nope")
