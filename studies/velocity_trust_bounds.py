"""The bounds of the trusted-velocity gate (docs/detector.md §3, "Clearing"), measured on
friction that creeps in under changing operation (the recordings of
`creeping_friction_episodes.py`, shipped high-pass model with a baseline). Run:
``python studies/velocity_trust_bounds.py`` (several minutes).

For each phase bound and share: the clearing count replayed on the sliding-window level
(eq. 17) from the first detection on, trusted ticks below half the baseline's margin
counting, other trusted ticks resetting, untrusted ticks holding. Its longest run is how
close the friction, still there, came to being cleared (`friction_clear_s`, 10 s); the
share of trusted ticks is how often friction that has gone could show it.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
from creeping_friction_episodes import _creep, models
from scipy.signal import butter, lfilter

PHASES_DEG = (20.0, 25.0, 30.0, 40.0)
SHARES = (0.2, 0.3, 0.4, 0.5)


def _window_sums(x: np.ndarray, n: int) -> np.ndarray:
    c = np.concatenate([[0.0], np.cumsum(x)])
    out = np.full(x.size, np.nan)
    out[n - 1 :] = c[n:] - c[:-n]
    return out


def _longest_run(trusted: np.ndarray, normal: np.ndarray) -> int:
    run = best = 0
    for ok, low in zip(trusted, normal):
        if ok:
            run = run + 1 if low else 0
            best = max(best, run)
    return best


def measure(model, rec) -> list[str]:
    from fdi_daemon.core.velocity_observer import trusted_from_hz
    from fdi_daemon.detect.monitor import Monitor
    from fdi_daemon.detect.pipeline import Pipeline

    monitor = Monitor(model)
    events, _ = monitor.run(rec, trace_every=len(rec))
    first = next(e["t"] for e in events if e["kind"] == "fault_detected")
    n = monitor.detector.window_samples
    pl = Pipeline(model, n, min_velocity_rms_mps=monitor.settings.min_velocity_rms_mps)
    b = pl.run(np.asarray(rec.columns["v_in"]), np.asarray(rec.columns["accel"]))
    s = b.sums
    with np.errstate(invalid="ignore", divide="ignore"):
        theta1 = (s[:, 2] * s[:, 3] - s[:, 1] * s[:, 4]) / (s[:, 0] * s[:, 2] - s[:, 1] ** 2)
        over = monitor.over_baseline(theta1, b.v_rms)
    sel = (np.asarray(rec.columns["t"]) > first) & b.moving & (b.counts == n)
    v2 = _window_sums(b.velocity**2, n)
    lines = []
    for phase in PHASES_DEG:
        f_hz = trusted_from_hz(pl.velocity, phase)
        low = lfilter(*butter(2, f_hz, fs=model.fs), b.velocity)
        share = _window_sums(low**2, n) / v2
        cells = []
        for bound in SHARES:
            trusted = share <= bound
            run_s = _longest_run(trusted[sel], over[sel] < 0.5) / model.fs
            cells.append(f"{bound:.1f}: {run_s:5.1f} s, {np.mean(trusted[sel]):.0%} trusted")
        lines.append(f"  {phase:4.0f}° ({f_hz:3.1f} Hz)  " + " | ".join(cells))
    return lines


if __name__ == "__main__":
    from hil_sim.scenarios import scenario_from_dict, simulate

    with tempfile.TemporaryDirectory() as tmp:
        model = models(Path(tmp), ["highpass"])["highpass + baseline"]
        for ramp_s, record_s in ((600.0, 1800.0), (3600.0, 7200.0)):
            spec, _ = _creep(ramp_s, record_s)
            print(
                f"creeping over {ramp_s:.0f} s: longest run below half the margin, "
                f"trusted share, per phase bound and velocity share",
                flush=True,
            )
            print("\n".join(measure(model, simulate(scenario_from_dict(spec)))), flush=True)
