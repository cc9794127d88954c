"""Why a one-amplitude calibration gives a level that depends on the operation: the load's
stick phases (docs/identification.md, "Where the four-tone level's spread comes from").
Run: ``python studies/stick_phase_levels.py`` (about a minute).

Default simulated rig; plant `configs/model_sim_rig.yaml`; issue 12's four-tone calibration
(`test_detect_friction_level.LOW_FREQUENCY_CALIBRATION`: the load is stuck about a sixth of
the fault window). Three signatures, each with the model observer's velocity:

- ``fdi signature`` as a user runs it (auto keeps the observer; OE fit of G_e, γ grid);
- G_e with the plant model's poles Â (the poles of the force path, eq. 6) and a free
  numerator, fitted by linear least squares on every sample of the fault window;
- the same on the samples where the simulator's load slides (more than 4 samples from a
  stuck one): an oracle, to see what the stick phases do to the signature;
- the same on the rows a quiet accelerometer keeps (`stick_window_oracle.quiet_rows`: what
  the data give).

Each replays the steady fault under changing operation (`steady_friction_changing_operation`;
fault at 20 s, truth ≈ 1 relative to the calibration); printed: the median reported level
per 10 s from 30 s, with the simulator's stuck share and velocity content of the segment.
"""

from __future__ import annotations

import contextlib
import copy
import io
import sys
import tempfile
from pathlib import Path

import numpy as np
import yaml

REPO = Path(__file__).resolve().parents[1]


def _pole_signature(model, cal, residual, velocity, first, keep):
    """G_e = B/Â by linear least squares over a γ grid on the samples ``keep`` (from first)."""
    from scipy.signal import lfilter

    from fdi_daemon.io.model_file import FaultFilter

    a_plant = np.asarray(model.plant_a, dtype=float)
    width = a_plant.size
    best = None
    for gamma in np.arange(0.0, 10.01, 0.2):
        filtered = lfilter([1.0], a_plant, np.sign(velocity) + gamma * velocity)
        lags = np.column_stack(
            [np.concatenate([np.zeros(j), filtered[: filtered.size - j]]) for j in range(width)]
        )[first:][keep[first:]]
        target = residual[first:][keep[first:]]
        b, *_ = np.linalg.lstsq(lags, target, rcond=None)
        sse = float(np.sum((target - lags @ b) ** 2))
        if best is None or sse < best[0]:
            best = (sse, gamma, b, 100 * (1 - sse / float(np.sum((target - target.mean()) ** 2))))
    _, gamma, b, vaf = best
    out = copy.deepcopy(model)
    out.fault_filter = FaultFilter(b=b, f=a_plant, nk=0, gamma_f=float(gamma))
    return out, gamma, vaf


def main() -> None:
    sys.path.insert(0, str(REPO / "tests"))
    from stick_window_oracle import quiet_rows
    from test_detect_friction_level import LOW_FREQUENCY_CALIBRATION

    from fdi_daemon.cli import main as fdi
    from fdi_daemon.core.velocity_observer import velocity_from_settings
    from fdi_daemon.detect.monitor import Monitor
    from fdi_daemon.diagnose.augment import nominal_plant
    from fdi_daemon.ident.signature import plant_residual
    from fdi_daemon.io.model_file import load_model, save_model
    from fdi_daemon.io.recordings import write_recording
    from hil_sim.scenarios import scenario_from_dict, simulate

    cal = simulate(scenario_from_dict(LOW_FREQUENCY_CALIBRATION))
    first = int(5.0 * cal.fs)
    stuck = cal.columns["stuck"] > 0.5
    print(f"calibration: load stuck {stuck[first:].mean():.1%} of the fault window")
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        plant = load_model(REPO / "configs" / "model_sim_rig.yaml")
        plant.velocity, plant.fault_filter = None, None
        save_model(root / "plant.yaml", plant)
        write_recording(root / "cal.npz", cal)
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            assert (
                fdi(
                    [
                        "signature",
                        str(root / "cal.npz"),
                        "--model",
                        str(root / "plant.yaml"),
                        "--fault-window",
                        "5:20",
                        "-o",
                        str(root / "auto.yaml"),
                    ]
                )
                == 0
            )
        auto = load_model(root / "auto.yaml")
    residual = plant_residual(nominal_plant(auto), cal.v_in, cal.accel)
    velocity = velocity_from_settings(auto.velocity, cal.fs).run(cal.accel, cal.accel - residual)
    sliding = np.convolve(stuck.astype(float), np.ones(9), "same") == 0
    every = np.ones(stuck.size, dtype=bool)
    models = {"fdi signature (auto)": (auto, auto.fault_filter.gamma_f, None)}
    for name, keep in (
        ("G_e = B/Â, every sample", every),
        ("G_e = B/Â, sliding samples only", sliding),
        ("G_e = B/Â, quiet-accelerometer rows left out", ~quiet_rows(cal.accel)),
    ):
        models[name] = _pole_signature(auto, cal, residual, velocity, first, keep)

    spec = yaml.safe_load(
        (REPO / "configs" / "scenarios" / "steady_friction_changing_operation.yaml").read_text()
    )
    rec = simulate(scenario_from_dict(spec))
    truth = rec.columns["velocity_true"]
    rec_stuck = rec.columns["stuck"] > 0.5
    edges = np.arange(30.0, rec.t[-1] + 1e-9, 10.0)
    levels = {}
    for name, (model, _, _) in models.items():
        _, trace = Monitor(model).run(rec, trace_every=1)
        levels[name] = trace
    for name, (_, gamma, vaf) in models.items():
        print(f"  {name}: gamma_f {gamma:.2f}" + ("" if vaf is None else f", VAF {vaf:.1f} %"))
    print("segment   stuck  v RMS  v centroid | " + " | ".join(models))
    for a, b in zip(edges[:-1], edges[1:]):
        seg = (rec.t >= a) & (rec.t < b)
        freq = np.fft.rfftfreq(int(seg.sum()), 1.0 / rec.fs)
        power = np.abs(np.fft.rfft(truth[seg])) ** 2
        cells = []
        for trace in levels.values():
            inside = (trace.t >= a) & (trace.t < b) & np.isfinite(trace.friction_level)
            cells.append(
                f"{np.median(trace.friction_level[inside]):.2f}" if inside.any() else "  - "
            )
        print(
            f"{a:3.0f}-{b:3.0f} s  {rec_stuck[seg].mean():5.1%}  "
            f"{1e3 * np.std(truth[seg]):3.0f} mm/s  "
            f"{np.sum(freq * power) / np.sum(power):4.1f} Hz | " + " | ".join(cells)
        )


if __name__ == "__main__":
    main()
