"""What the stick phases do to the monitor's window (issue 12), and whether the data show
them: θ1 of eq. (17) over the 1 s window with rows left out by a mask.
Run: ``python studies/stick_window_oracle.py`` (about 15 s; docs/identification.md, "Where the
four-tone level's spread comes from").

Default simulated rig; the shipped model (`configs/model_sim_rig.yaml`, high-pass velocity,
calibrated on `signature_calibration`, fault window 11–40 s). Truth: the mean contact force
of the air bearing after the fault over that of the calibration's fault window (as in
`test_detect_friction_level`). Masks, each applied to the rows of the window sums only
(g1, g2, r as the monitor computes them):

- none: the monitor's θ1;
- the simulator's ``stuck`` flag (an oracle);
- the simulator's true velocity above a share of its window RMS (an oracle);
- the model's own v̂ above the same share (what the data give);
- a quiet accelerometer: a row is left out when |ẍ| < 0.1 m/s² (5× the simulated
  accelerometer's noise) on two samples in a row at it or up to two samples after it (what
  the data give; the two samples after cover the accelerometer's lag into a stick).

``--variants``: the same on rig variants 0–7 of `test_detect_other_rig` too, each with its
own model from `fdi identify` and `fdi signature` (about a minute): one line per rig and
case, error of the median θ1 against the truth.

Printed: median θ1 from 1.5 s after the fault (10 s for the steady run), the 5–95 % range,
θ1 before the fault (the rod seal's friction, which the truth leaves out), and the
accelerometer's 3-sample RMS on stuck and sliding samples (can a stuck load be told
by a quiet accelerometer?).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
WINDOW = 256
CASES = (
    ("test_case_1", 3.05, 1.5),
    ("test_case_2", 2.9, 1.5),
    ("steady_friction_changing_operation", 20.0, 10.0),
)
SHARES = (0.1, 0.2, 0.3)
QUIET_MPS2 = 0.1


def _sliding_sum(x: np.ndarray) -> np.ndarray:
    return np.convolve(x, np.ones(WINDOW))[: x.size]


def masked_theta1(g1, g2, r, keep):
    """θ1 of eq. (17) over the window's kept rows (NaN: fewer than a quarter kept)."""
    k = keep.astype(float)
    a11, a12, a22 = (_sliding_sum(k * x) for x in (g1 * g1, g1 * g2, g2 * g2))
    b1, b2 = _sliding_sum(k * g1 * r), _sliding_sum(k * g2 * r)
    with np.errstate(invalid="ignore", divide="ignore"):
        theta1 = (a22 * b1 - a12 * b2) / (a11 * a22 - a12**2)
    return np.where(_sliding_sum(k) >= WINDOW / 4, theta1, np.nan)


def quiet_rows(accel: np.ndarray, quiet_mps2: float = QUIET_MPS2) -> np.ndarray:
    """Rows at or up to two samples before a pair of samples with |ẍ| < ``quiet_mps2``."""
    quiet = np.abs(accel) < quiet_mps2
    pair = quiet & np.r_[False, quiet[:-1]]
    rows = pair.copy()
    rows[:-1] |= pair[1:]
    rows[:-2] |= pair[2:]
    return rows


def _truth(rec, fault_t, calibrated):
    return np.mean(rec.columns["contact_force"][rec.t >= fault_t + 0.5]) / calibrated


def _theta1_after(batch, keep, after):
    """θ1 with ``keep``'s rows, at the windows after the fault where the rig moves."""
    theta1 = masked_theta1(batch.g1, batch.g2, batch.residual, keep)
    return theta1[after & batch.moving & np.isfinite(theta1)]


def _median_error(batch, keep, after, truth):
    ok = _theta1_after(batch, keep, after)
    return f"{100 * (np.median(ok) / truth - 1):+4.0f} %" if ok.size else "  n/a"


def variants() -> None:
    """One line per rig and case: the median θ1's error with no mask, the simulator's stick
    flag and the quiet accelerometer."""
    import contextlib
    import io
    import tempfile

    from test_detect_other_rig import model_of, record, rig_variant

    from fdi_daemon.detect.pipeline import Pipeline

    print("rig      case          truth  stuck | none    oracle  quiet ẍ")
    for index in (None, *range(8)):
        rig = {} if index is None else rig_variant(index)
        with (
            tempfile.TemporaryDirectory() as tmp,
            contextlib.redirect_stdout(io.StringIO()),
            contextlib.redirect_stderr(io.StringIO()),
        ):
            model = model_of(rig, Path(tmp))
        cal = record(rig, "signature_calibration")
        calibrated = np.mean(cal.columns["contact_force"][cal.t >= 11.0])
        for name, fault_t, settle_s in CASES:
            rec = record(rig, name)
            truth = _truth(rec, fault_t, calibrated)
            stuck = rec.columns["stuck"] > 0.5
            after = rec.t >= fault_t + settle_s
            batch = Pipeline(model, WINDOW).run(rec.v_in, rec.accel)
            cells = [
                _median_error(batch, keep, after, truth)
                for keep in (np.ones(stuck.size, dtype=bool), ~stuck, ~quiet_rows(rec.accel))
            ]
            print(
                f"{'default' if index is None else f'variant {index}':8s} {name[:12]:12s} "
                f"{truth:6.2f} {stuck[after].mean():6.1%} | " + "  ".join(cells)
            )


def _window_rms(x: np.ndarray) -> np.ndarray:
    return np.sqrt(_sliding_sum(x * x) / WINDOW)


def main() -> None:
    sys.path.insert(0, str(REPO / "tests"))
    from conftest_detect import MODEL, scenario_recording

    from fdi_daemon.detect.pipeline import Pipeline
    from fdi_daemon.io.model_file import load_model

    model = load_model(MODEL)
    cal = scenario_recording("signature_calibration")
    calibrated = np.mean(cal.columns["contact_force"][(cal.t >= 11.0) & (cal.t < 40.0)])
    for name, fault_t, settle_s in CASES:
        rec = scenario_recording(name)
        truth = _truth(rec, fault_t, calibrated)
        stuck = rec.columns["stuck"] > 0.5
        after = rec.t >= fault_t + settle_s
        pipeline = Pipeline(model, WINDOW)
        batch = pipeline.run(rec.v_in, rec.accel)
        v_true = rec.columns["velocity_true"]
        masks = {"none": np.ones(rec.t.size, dtype=bool), "not stuck (oracle)": ~stuck}
        for share in SHARES:
            masks[f"|v| > {share} RMS (oracle)"] = np.abs(v_true) > share * _window_rms(v_true)
            masks[f"|v̂| > {share} RMS"] = np.abs(batch.velocity) > share * _window_rms(
                batch.velocity
            )
        masks[f"quiet ẍ < {QUIET_MPS2} m/s²"] = ~quiet_rows(rec.accel)
        accel_rms3 = np.sqrt(np.convolve(rec.accel**2, np.ones(3) / 3)[: rec.t.size])
        print(
            f"{name}: truth {truth:.3f}; load stuck {stuck[after].mean():.1%}; accelerometer "
            f"3-sample RMS stuck p50 {np.median(accel_rms3[stuck & after]):.3f}, sliding "
            f"p1 {np.percentile(accel_rms3[~stuck & after], 1):.3f} m/s²"
            if (stuck & after).any()
            else f"{name}: truth {truth:.3f}; load never stuck"
        )
        before = batch.moving & (rec.t < fault_t) & (rec.t >= WINDOW / rec.fs)
        theta1_before = pipeline.thetas(batch)[0][before]
        print(f"  θ1 before the fault (the seal, no mask): {np.nanmedian(theta1_before):.3f}")
        for label, keep in masks.items():
            ok = _theta1_after(batch, keep, after)
            if ok.size == 0:
                print(f"  {label:26s} no window keeps a quarter of its rows")
                continue
            p5, p50, p95 = np.percentile(ok, [5, 50, 95])
            print(
                f"  {label:26s} θ1 {p50:6.3f} ({p5:.2f}–{p95:.2f}), "
                f"{100 * (p50 / truth - 1):+5.0f} %"
            )


if __name__ == "__main__":
    main()
    if "--variants" in sys.argv[1:]:
        variants()
