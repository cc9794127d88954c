"""The dashboard view for prepared snapshots, read back as the text a terminal would show."""

from __future__ import annotations

import math

import pytest
from conftest_dashboard import STATES, make_snapshot, screen_text
from rich.console import Console

from fdi_daemon.dashboard.plot import BraillePlot, Series, render_lines
from fdi_daemon.dashboard.render import STATE_BADGES, render

SIZES = [(80, 24), (100, 30), (200, 50), (60, 18)]


def lines_of(text: str) -> list[str]:
    return text.rstrip("\n").split("\n")


@pytest.mark.parametrize("width,height", SIZES)
@pytest.mark.parametrize("state", STATES)
def test_state_numbers_and_alarms_shown_at_every_size(state, width, height):
    text = screen_text(render(make_snapshot(state)), width, height)
    lines = lines_of(text)
    assert len(lines) == height
    assert all(len(line) <= width for line in lines)
    assert STATE_BADGES[state][0] in lines[0]
    assert "+0.0123" in text and "-0.0456" in text
    assert "friction_isolated" in text and "fault_detected" in text


@pytest.mark.parametrize("width,height", [(80, 24), (200, 50)])
def test_link_health_model_and_plot_titles(width, height):
    text = screen_text(render(make_snapshot("monitoring")), width, height)
    for expected in (
        "256.0 Hz",
        "33280",
        "gaps 3",
        "CRC 7",
        "bad 0",
        "42 µs/317 µs",
        "deadline miss",
        "3.210e-02",
        "configs/sim/model.yaml",
        "tool: fdi signature",
        "band [-0.05, 0.05]",
        "band [-0.08, 0.08]",
        "sig 2.4",
        "t 100.0 … 130.0 s",
    ):
        assert expected in text, expected


def test_plots_use_braille_cells_and_leave_them_out_without_history():
    full = screen_text(render(make_snapshot("monitoring")))
    empty = screen_text(render(make_snapshot("monitoring", history_points=0)))
    assert sum("\u2800" < ch <= "\u28ff" for ch in full) > 100
    assert not any("\u2800" <= ch <= "\u28ff" for ch in empty)
    assert "no data yet" in empty


def test_calibrating_with_nan_theta_and_no_band():
    snapshot = make_snapshot(
        "calibrating", theta=(math.nan, math.nan), band=None, history_points=0, n_alarms=0
    )
    text = screen_text(render(snapshot))
    assert "CALIBRATING" in text
    assert "θ1 —" in text and "θ2 —" in text
    assert "band —" in text
    assert "calibrating…" in text
    assert "no events" in text


def test_nan_history_points_break_the_trace_without_error():
    snapshot = make_snapshot("calibrating")
    history = snapshot["monitor"]["history"]
    history["theta1"][:150] = [math.nan] * 150
    history["theta2"] = [math.nan] * len(history["t"])
    text = screen_text(render(snapshot))
    assert "CALIBRATING" in text


def test_many_alarms_newest_first_and_cut_to_the_room():
    snapshot = make_snapshot("friction_isolated", n_alarms=40)
    text = screen_text(render(snapshot), 80, 24)
    assert "alarms & events (40)" in text
    rows = [line for line in lines_of(text) if " s " in line and "θ +" in line]
    times = [float(line.split(" s ")[0].split("│")[-1]) for line in rows]
    assert times == sorted(times, reverse=True)
    assert times[0] == pytest.approx(100.0 + 39 * 0.5)
    assert 3 <= len(times) < 40
    wide = screen_text(render(snapshot), 200, 50)
    wide_rows = [line for line in lines_of(wide) if " s " in line and "θ +" in line]
    assert len(wide_rows) > len(rows)


def test_alarm_row_shows_extra_fields():
    snapshot = make_snapshot(n_alarms=0)
    snapshot["alarms"] = [{"t": 12.5, "kind": "data_gap", "missing": 7}]
    text = screen_text(render(snapshot))
    assert "12.500 s" in text and "data_gap" in text and "missing=7" in text


def test_notice_with_last_known_snapshot_and_without_any():
    notice = "daemon not reachable, retrying (no socket at /run/fdi/status.sock)"
    with_last = screen_text(render(make_snapshot("fault_detected"), notice))
    assert "daemon not reachable, retrying" in with_last
    assert "FAULT DETECTED" in with_last and "last known" in with_last
    nothing = screen_text(render(None, notice))
    assert nothing.count("not reachable") >= 2


def test_malformed_sections_do_not_break_the_view():
    snapshot = {
        "state": "monitoring",
        "link": None,
        "monitor": {"theta1": "x", "band": [1], "history": {"t": [1, 2]}},
        "alarms": ["not a dict"],
        "model": {"provenance": {"nested": {"k": [1.5, 2]}}},
    }
    text = screen_text(render(snapshot))
    assert "MONITORING" in text and "no link information" in text
    assert "nested.k: 1.5, 2" in text


def test_unknown_state_is_shown_verbatim():
    text = screen_text(render(make_snapshot("degraded")))
    assert "DEGRADED" in text


def test_signature_far_off_scale_is_marked_not_drawn():
    snapshot = make_snapshot("monitoring", gamma_f=50.0)
    text = screen_text(render(snapshot))
    assert "sig 50↑" in text
    near = screen_text(render(make_snapshot("friction_isolated", theta=(0.98, 2.3))))
    assert "sig 2.4↑" not in near and "sig 2.4" in near


def test_trace_rows_follow_the_values():
    """A rising ramp puts its first point in the bottom row and its last in the top row."""
    plot = BraillePlot(
        series=[Series(style="", t=[0.0, 1.0, 2.0, 3.0], y=[0.0, 1.0, 2.0, 3.0])],
        y_range=(0.0, 3.0),
    )
    lines = [line.plain for line in render_lines(plot, 30, 4)]
    assert lines[0].startswith("      3┤") and lines[-1].startswith("      0┤")
    body = [line[8:] for line in lines]
    assert body[-1][0] != " " and body[-1][-1] == " "
    assert body[0][-1] != " " and body[0][0] == " "


def test_band_level_drawn_dashed_on_its_row():
    plot = BraillePlot(
        series=[
            Series(style="", level=1.0, dashed=True),
            Series(style="", t=[0.0, 1.0], y=[0.0, 0.0]),
        ],
        y_range=(0.0, 1.0),
    )
    top = render_lines(plot, 40, 3)[0].plain[8:]
    assert top.count(" ") > 10 and top.strip()


def test_console_without_fixed_height_uses_console_height():
    console = Console(record=True, width=90, height=30, color_system=None)
    console.print(render(make_snapshot()))
    assert len(lines_of(console.export_text())) == 30


def test_theta_plane_only_where_there_is_room():
    snapshot = make_snapshot("friction_isolated", theta=(0.98, 2.3))
    assert "θ2 vs θ1" in screen_text(render(snapshot), 200, 50)
    assert "θ2 vs θ1" not in screen_text(render(snapshot), 80, 24)
    assert "θ2 vs θ1" not in screen_text(render(snapshot), 100, 50)
    calibrating = make_snapshot("calibrating", history_points=0)
    assert "no θ yet" in screen_text(render(calibrating), 200, 50)


def test_provenance_sections_are_summarised_first():
    snapshot = make_snapshot()
    snapshot["model"]["provenance"] = {
        "identify": {
            "source": "/data/chirp.csv",
            "date_utc": "2026-11-21T17:06:06+00:00",
            "metrics": {"fit_percent": 94.241, "band_hz": [1.5, 18.75]},
        },
        "signature": {
            "source": "/data/sig.csv",
            "date_utc": "2026-11-21T17:06:19+00:00",
            "cost_profile": {"gamma_f": 2.94153, "flat": True},
        },
    }
    text = screen_text(render(snapshot), 240, 40)
    assert "identify: fit 94.2 %, 2026-11-21, chirp.csv" in text
    assert "signature: γ_f 2.94 (flat cost), 2026-11-21, sig.csv" in text
    assert "θ2 vs θ1" in text  # the model panel makes room for the θ plane
    tall = screen_text(render(snapshot), 100, 60)
    assert "identify.metrics.band_hz" in tall  # no θ plane below 120 columns: details
    small = screen_text(render(snapshot), 80, 24)
    assert "identify: fit 94.2" in small and "signature: γ_f 2.9" in small


def daemon_events() -> list[dict]:
    """Events as the daemon writes them (fields of a real `fdi run`)."""
    common = {"statistic": 1.27, "threshold": 30.0, "method": "sequential"}
    return [
        {
            "t": 2.38671875,
            "kind": "calibrated",
            "theta1": 0.0474,
            "theta2": -1.67,
            **common,
            "friction_level": 0.0474,
            "band": {"theta1": [0.03, 0.06], "theta2": [-1.9, -1.3]},
            "samples": 256,
        },
        {
            "t": 20.01953125,
            "kind": "fault_detected",
            "theta1": 0.0262,
            "theta2": -1.4,
            **common,
            "statistic": 64.72,
            "friction_level": 0.0262,
            "path": "fast",
        },
        {
            "t": 20.546875,
            "kind": "friction_isolated",
            "theta1": 1.43,
            "theta2": 0.805,
            **common,
            "friction_level": 1.43,
            "coulomb_change": 1.6048,
            "friction_evidence": "harmonics",
        },
    ]


def test_event_rows_at_80x24_show_kind_time_and_key_fields_whole():
    snapshot = make_snapshot("friction_isolated", n_alarms=0)
    snapshot["alarms"] = daemon_events()
    rows = [
        line
        for line in lines_of(screen_text(render(snapshot), 80, 24))
        if " s " in line and ("_" in line or "calibrated" in line)
    ]
    text = "\n".join(rows)
    assert "20.547 s friction_isolated  Δθ1 +1.6 harmonics" in text
    assert "20.020 s fault_detected     stat 64.7/30 fast" in text
    assert "2.387 s calibrated         samples 256" in text
    assert "…" not in text  # whole fields only, never cut after θ


def test_theta_plot_titles_are_their_legend():
    from fdi_daemon.dashboard.render import BAND_STYLE, SIGNATURE_STYLE, TRACE_STYLE, theta_title

    monitor = make_snapshot("friction_isolated", theta=(0.98, 2.3))["monitor"]
    title = theta_title(monitor, 0, 50, "drawn")
    assert title.plain == "━ θ1 +0.98 ━ sig 1 ╍ band [-0.05, 0.05]"
    styles = {title.plain[span.start : span.end].split()[1]: span.style for span in title.spans}
    assert styles == {"θ1": TRACE_STYLE, "sig": SIGNATURE_STYLE, "band": BAND_STYLE}


def test_model_panel_at_80x24_gives_one_row_to_file_paths():
    import yaml
    from conftest_detect import MODEL

    snapshot = make_snapshot()
    snapshot["model"] = {
        "path": "/home/user/rigs/fdi_daemon/data/model_sim_rig.yaml",
        "provenance": yaml.safe_load(MODEL.read_text())["provenance"],
    }
    lines = lines_of(screen_text(render(snapshot), 80, 24))
    top = next(i for i, line in enumerate(lines) if "─ model ─" in line)
    panel = [line[:30] for line in lines[top + 1 :] if line.startswith("│")]
    assert "model_sim_rig.yaml" in panel[0]
    assert sum("/" in row for row in panel) == 1, panel  # paths: the model file only
    assert any("identify: fit" in row for row in panel)
    assert any("signature: γ_f" in row for row in panel)
