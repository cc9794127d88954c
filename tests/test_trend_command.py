"""`fdi trend --csv`: times at full precision; `--plot` on a short span."""

from __future__ import annotations

import csv
from datetime import datetime, timezone

import numpy as np

from fdi_daemon.cli import main
from fdi_daemon.service.trend import TrendStore

START = 1_795_866_960.0  # 2026-11-28 11:56 UTC, a minute boundary


def short_store(tmp_path, minutes: int = 6):
    """A trend store of ``minutes`` minute rows with a level rising through a step."""
    from fdi_daemon.service.trend import MinuteAggregator

    store = TrendStore(tmp_path / "trend.sqlite", {"steps": [0.5, 1.0]})
    agg = MinuteAggregator()
    rng = np.random.default_rng(3)
    for k in range(minutes * 6 + 1):
        now = START + 10.0 * k + 0.25
        agg.baseline, agg.priority = 0.1, int(k > minutes * 3)
        row = agg.level(now, 0.1 + 0.15 * k / 6 + 0.02 * rng.standard_normal())
        if row is not None:
            store.append(row)
    store.close()
    return tmp_path / "trend.sqlite"


def test_csv_times_are_rfc3339_with_ms_and_unix_seconds_to_the_ms(tmp_path, capsys):
    db = short_store(tmp_path)
    assert main(["trend", "--db", str(db), "--csv", str(tmp_path / "t.csv")]) == 0
    with open(tmp_path / "t.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 6
    for k, row in enumerate(rows):
        assert row["time_utc"] == datetime.fromtimestamp(START + 60 * k, timezone.utc).strftime(
            "%Y-%m-%dT%H:%M:%S.000Z"
        )
        assert row["time_unix"] == f"{START + 60 * k:.3f}"
        assert row["period_s"] == "60" and row["readings"] == "6"
    assert float(rows[0]["level_mean"]) > 0


def test_plot_of_a_short_span_has_distinct_time_labels(tmp_path, monkeypatch):
    """Six minutes gave six '11-28 11:56' labels; each label now differs."""
    import matplotlib.figure

    from fdi_daemon.service import trend_plot

    seen: list[list[str]] = []
    save = trend_plot.save_figure

    def keep_labels(fig: matplotlib.figure.Figure, path):
        fig.canvas.draw()
        seen.append([tick.get_text() for tick in fig.axes[1].get_xticklabels() if tick.get_text()])
        return save(fig, path)

    monkeypatch.setattr(trend_plot, "save_figure", keep_labels)
    db = short_store(tmp_path)
    assert main(["trend", "--db", str(db), "--plot", str(tmp_path / "trend.png")]) == 0
    labels = seen[0]
    assert len(labels) >= 3 and len(set(labels)) == len(labels), labels
