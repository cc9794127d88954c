"""Measure the trend file's size: DAYS of minute rows through `TrendStore.append`.

Usage: ``python studies/trend_size.py FOLDER [DAYS]`` (default 365). Appends one row per
simulated minute (a level creeping up, seeded noise) exactly as the daemon does (one
transaction per row, the hourly fold past retention) and prints the file size at 90 and
180 days and at the end. Figures: docs/service.md, "Friction trend".
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from fdi_daemon.service.trend import TREND_FILE, TrendStore


def main(folder: str, days: float = 365.0) -> None:
    folder_path = Path(folder)
    folder_path.mkdir(parents=True, exist_ok=True)
    for old in folder_path.glob(TREND_FILE + "*"):
        old.unlink()
    path = folder_path / TREND_FILE
    rng = np.random.default_rng(0)
    store = TrendStore(path, {"steps": [0.25, 0.5, 1.0]})
    first = 29_000_000 - 29_000_000 % 1440  # a UTC midnight, as a minute number
    n = int(days * 1440)
    start = time.perf_counter()
    for k in range(n):
        level = 0.08 + 1.2 * k / n + 0.03 * rng.standard_normal()
        store.append(
            {
                "minute": first + k,
                "level_mean": level,
                "level_min": level - 0.06,
                "level_max": level + 0.06,
                "baseline": 0.08,
                "command_rms_v": 0.8 + 0.4 * rng.random(),
                "readings": 600,
                "samples": 15360,
                "priority": min(3, int(level / 0.4)),
                "alarm_state": 1,
            }
        )
        if k in (90 * 1440, 180 * 1440):
            print(f"day {k // 1440}: {path.stat().st_size / 1e6:.2f} MB", flush=True)
    store.close()
    print(
        f"{days:g} days, {n} rows appended in {time.perf_counter() - start:.0f} s; "
        f"{path.name} {path.stat().st_size / 1e6:.2f} MB"
    )


if __name__ == "__main__":
    main(sys.argv[1], float(sys.argv[2]) if len(sys.argv) > 2 else 365.0)
