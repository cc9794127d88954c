"""The replay figure says what a reader needs: calibration period, data gaps, a visible band,
and why no alarm came when the fault was there during calibration."""

from __future__ import annotations

import matplotlib.patches as mpatches
import numpy as np
import pytest
from conftest_detect import scenario_recording, sim_rig_model

from fdi_daemon.detect.monitor import Monitor
from fdi_daemon.detect.plots import CALIBRATION_NOTE, replay_figure
from fdi_daemon.io.recordings import Recording


def replay(rec):
    monitor = Monitor(sim_rig_model())
    events, trace = monitor.run(rec, trace_every=1)
    return monitor, events, trace


def extents(patch) -> tuple[float, float, float, float]:
    """(x0, x1, y0, y1) of an axvspan/axhspan patch in its own coordinates."""
    if isinstance(patch, mpatches.Rectangle):
        x, y = patch.get_x(), patch.get_y()
        return x, x + patch.get_width(), y, y + patch.get_height()
    xy = patch.get_xy()
    return xy[:, 0].min(), xy[:, 0].max(), xy[:, 1].min(), xy[:, 1].max()


def spans(ax) -> list[tuple[float, float]]:
    """(x0, x1) of the vertical spans (full height: axvspan) of an axes."""
    return [(x0, x1) for x0, x1, y0, y1 in map(extents, ax.patches) if (y0, y1) == (0, 1)]


@pytest.fixture(scope="module")
def test_case_2():
    rec = scenario_recording("test_case_2")
    keep = np.ones(len(rec), dtype=bool)
    keep[1000:1010] = False  # a gap of 10 samples at 3.9 s
    gappy = Recording({k: v[keep] for k, v in rec.columns.items()}, dict(rec.meta))
    return rec, replay(gappy)


def text_of(fig) -> str:
    return " ".join(t.get_text() for ax in fig.axes for t in ax.texts)


def test_calibration_period_gaps_and_band_are_marked(test_case_2):
    rec, (monitor, events, trace) = test_case_2
    (cal,) = [e for e in events if e["kind"] == "calibrated"]
    (gap,) = [e for e in events if e["kind"] == "data_gap"]
    onset = float(rec.t[np.flatnonzero(rec["fault_active"] > 0.5)[0]])
    fig = replay_figure(
        trace, events, monitor.gamma_f, monitor.detector.band, monitor.detector.threshold, onset
    )
    ax_a, ax_1, ax_2 = fig.axes[:3]
    found = spans(ax_a)
    period = 1 / 256
    assert any(
        abs(x0 - (cal["t"] - cal["samples"] * period)) < 1e-6 and abs(x1 - cal["t"]) < 1e-6
        for x0, x1 in found
    ), found
    assert any(
        abs(x0 - (gap["t"] - 11 * period)) < 1e-6 and abs(x1 - gap["t"]) < 1e-6 for x0, x1 in found
    ), found
    labels = ax_a.get_legend().get_texts()
    assert {"calibration (learnt as normal)", "data gap"} <= {t.get_text() for t in labels}
    for ax, key in ((ax_1, "theta1"), (ax_2, "theta2")):
        lo, hi = monitor.detector.band[key]
        shaded = [p for p in ax.patches if np.allclose(extents(p)[2:], [lo, hi])]
        assert shaded, f"{key}: the band is not shaded"
        legend = ax.get_legend()
        assert any(t.get_text().startswith("band [") for t in legend.get_texts())
    assert CALIBRATION_NOTE not in text_of(fig)  # the fault came after the calibration
    fig.canvas.draw()
    for ax in fig.axes:  # legends to the right of the data, never on it
        assert ax.get_legend().get_window_extent().x0 >= ax.get_window_extent().x1


def test_a_fault_present_during_calibration_is_explained():
    rec = scenario_recording("test_case_2")
    onset = 0.3  # pretend: the ground truth says the fault was there from 0.3 s
    monitor, events, trace = replay(rec)
    assert not [e for e in events if e["kind"] == "fault_detected" and e["t"] < 2.9]
    fig = replay_figure(
        trace, events, monitor.gamma_f, monitor.detector.band, monitor.detector.threshold, onset
    )
    assert "calibrated on these data: a fault present here is learnt as normal" in text_of(
        fig
    ).replace("\n", " ")
