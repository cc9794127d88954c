"""`fdi trend`: the daemon's friction trend (one row per minute) over days and months."""

from __future__ import annotations

import argparse

HELP = "show the friction trend the daemon keeps: level against baseline and alarm steps"


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--state-dir",
        metavar="D",
        help="the daemon's state directory (default: $STATE_DIRECTORY, else "
        "$XDG_STATE_HOME/fdi, i.e. ~/.local/state/fdi); the trend is "
        "D/trend.sqlite",
    )
    parser.add_argument(
        "--db", metavar="TREND.sqlite", help="the trend file itself (instead of --state-dir)"
    )
    parser.add_argument(
        "--since",
        metavar="DATE",
        help="from this UTC date or date-time on (2026-11-01, 2026-11-01T06:00)",
    )
    parser.add_argument("--csv", metavar="F", help="write the rows as CSV")
    parser.add_argument(
        "--plot",
        metavar="F.png",
        help="level (mean, min-max) against the baseline and the alarm steps, "
        "and the alarm priority, over time",
    )


def run(args: argparse.Namespace) -> int:
    import sqlite3
    from pathlib import Path

    from fdi_daemon.errors import UserError
    from fdi_daemon.io.outputs import check_outputs
    from fdi_daemon.service.config import default_state_dir
    from fdi_daemon.service.trend import TREND_FILE, read_trend, trend_meta

    path = Path(args.db) if args.db else Path(args.state_dir or default_state_dir()) / TREND_FILE
    if not path.is_file():
        raise UserError(
            f"{path}: no trend file (`fdi run` writes one row a minute to "
            f"alarms.trend in its state directory)"
        )
    check_outputs({"--csv": args.csv, "--plot": args.plot}, (path,), plots=("--plot",))
    since = _since(args.since)
    try:
        data = read_trend(path, since)
        meta = trend_meta(path)
    except sqlite3.Error as exc:
        raise UserError(f"{path}: not a readable trend database ({exc})") from None
    for line in daily_lines(data):
        print(line)
    if not len(data["time_unix"]):
        print(f"{path}: no rows" + (f" since {args.since}" if args.since else ""))
    if args.csv:
        write_csv(args.csv, data)
    if args.plot:
        from fdi_daemon.service.trend_plot import plot_trend

        plot_trend(args.plot, data, meta.get("steps") or [], title=str(path))
    return 0


def _since(text: str | None) -> float | None:
    from datetime import datetime, timezone

    from fdi_daemon.errors import UserError

    if text is None:
        return None
    try:
        when = datetime.fromisoformat(text)
    except ValueError:
        raise UserError(f"--since {text!r}: not a date (2026-11-01 or 2026-11-01T06:00)") from None
    if when.tzinfo is None:
        when = when.replace(tzinfo=timezone.utc)
    return when.timestamp()


def daily_lines(data) -> list[str]:
    """One summary line per UTC day."""
    import numpy as np

    t = data["time_unix"]
    if not t.size:
        return []
    day = (t // 86400).astype(np.int64)
    lines = [
        f"{'day (UTC)':10}  {'minutes':>7}  {'level mean':>10}  {'max':>6}  "
        f"{'baseline':>8}  {'priority max':>12}  {'command RMS V':>13}"
    ]
    from datetime import datetime, timezone

    for d in np.unique(day):
        sel = day == d
        level = data["level_mean"][sel]
        has = np.isfinite(level)
        mean = np.average(level[has], weights=data["readings"][sel][has]) if has.any() else np.nan
        high = np.nanmax(data["level_max"][sel]) if has.any() else np.nan
        base = data["baseline"][sel]
        base = base[np.isfinite(base)]
        cmd = data["command_rms_v"][sel]
        cmd = cmd[np.isfinite(cmd)]
        date = datetime.fromtimestamp(int(d) * 86400, timezone.utc).strftime("%Y-%m-%d")
        lines.append(
            f"{date:10}  {int(sel.sum()):7d}  {mean:10.3f}  {high:6.3f}  "
            f"{(base[-1] if base.size else np.nan):8.3f}  "
            f"{int(np.max(data['priority'][sel])):12d}  "
            f"{(np.median(cmd) if cmd.size else np.nan):13.3f}"
        )
    return lines


def csv_cell(name: str, value: float) -> str:
    """One CSV value: empty for NaN, ``time_unix`` in seconds to the millisecond, whole
    numbers (counts, priority, state) as integers, other readings to 6 significant digits."""
    if value != value:
        return ""
    if name == "time_unix":
        return f"{value:.3f}"
    if float(value).is_integer() and abs(value) < 2**53:
        return str(int(value))
    return f"{value:.6g}"


def write_csv(path, data) -> None:
    """The rows with ``time_utc`` (RFC 3339, milliseconds) first; see `csv_cell`."""
    import csv
    from datetime import datetime, timezone

    from fdi_daemon.errors import UserError

    names = list(data)
    try:
        with open(path, "w", newline="", encoding="utf-8") as fh:
            writer = csv.writer(fh)
            writer.writerow(["time_utc"] + names)
            for i in range(len(data["time_unix"])):
                when = datetime.fromtimestamp(float(data["time_unix"][i]), timezone.utc)
                writer.writerow(
                    [when.isoformat(timespec="milliseconds").replace("+00:00", "Z")]
                    + [csv_cell(n, float(data[n][i])) for n in names]
                )
    except OSError as exc:
        raise UserError(f"{path}: cannot write: {exc.strerror or exc}") from None
