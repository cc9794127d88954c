"""The clearing of an episode that is not friction (docs/detector.md §3, "Clearing"): the
kernel's window statistics checked against a direct computation on the pipeline's own
signals (`detect.pipeline.Pipeline.run`), on a valve at 40 % under weak 6 Hz operation."""

from __future__ import annotations

import functools
import math

import numpy as np
from conftest_detect import changing_operation_spec, sim_rig_model

from fdi_daemon.detect import episode_kernel as E
from fdi_daemon.detect.monitor import Monitor
from fdi_daemon.detect.pipeline import Pipeline
from fdi_daemon.detect.settings import DetectorSettings

#: the run ends here, 2.9 s into the other_fault episode raised at 120.14 s (seed 6)
END_S = 125.0


@functools.cache
def _valve_run():
    """(monitor after the run, the recording, its events) for seed 6's valve at 40 %."""
    from hil_sim.scenarios import scenario_from_dict, simulate

    spec = changing_operation_spec([{"t_s": 120.0, "fault": "valve_gain", "value": 0.4}], END_S)
    rec = simulate(scenario_from_dict(spec), seed=6)
    monitor = Monitor(sim_rig_model())
    events = monitor.run(rec)[0]
    return monitor, rec, [e for e in events if e["kind"] != "calibrated"]


def _signals(monitor, rec):
    """φ = (g1, g2, x̂̈, 1) and r of the last n samples, from a fresh pipeline's batch."""
    n = monitor.detector.window_samples
    batch = Pipeline(sim_rig_model(), n).run(rec.v_in, rec.accel)
    phi = np.column_stack([batch.g1, batch.g2, batch.xhat, np.ones(batch.g1.size)])
    return phi[-n:], batch.residual[-n:]


def _episode(monitor):
    det = monitor.detector
    f, ii, eo = det.arena.f, det.arena.i, det.epi
    return f, ii, eo, ii[eo + E.P_O_SCAL]


def test_the_fault_power_is_the_mean_square_of_the_measured_change_over_the_window():
    """fault_power = mean over the post window of (φᵀΔθ)²/σ²_ref, φ = (g1, g2, x̂̈, 1): the
    same number from the pipeline's batch signals over the last n samples."""
    monitor, rec, events = _valve_run()
    assert [e["kind"] for e in events] == ["fault_detected", "other_fault"]
    f, ii, eo, sc = _episode(monitor)
    change = f[sc + E.S_FAULT_CHANGE : sc + E.S_FAULT_CHANGE + 4].copy()
    assert np.all(np.isfinite(change))  # a valve's loss of gain is a linear change
    assert change[2] < -0.3  # mostly on x̂̈: the acceleration falls with the valve's gain
    phi, _ = _signals(monitor, rec)
    direct = float(np.mean((phi @ change) ** 2)) / f[sc + E.S_SIGMA2_REF]
    assert math.isclose(E.fault_power(f, ii, eo), direct, rel_tol=1e-9)


def test_the_deadband_is_the_test_windows_threshold_over_the_whole_window():
    """Clear only when mean e²/σ²_ref over n samples ≤ 1 + (h − 1)·√(m/n): here the
    innovations against the frozen reference of the last n samples, computed directly, are
    far above it while the valve stays at 40 %."""
    monitor, rec, _ = _valve_run()
    f, ii, eo, sc = _episode(monitor)
    settings = DetectorSettings()
    h, m, n = settings.threshold, ii[eo + E.P_M], ii[eo + E.P_N]
    assert math.isclose(E._clear_excess(ii, eo, h), (h - 1.0) * math.sqrt(m / n))
    phi, r = _signals(monitor, rec)
    e = r - phi @ f[sc + E.S_THETA_REF : sc + E.S_THETA_REF + 4]
    mean_z = float(np.mean(e**2)) / f[sc + E.S_SIGMA2_REF]
    window = f[ii[eo + E.P_O_BEYOND] + (n + 2) * E.W + 14] / (n * f[sc + E.S_SIGMA2_REF])
    assert math.isclose(window, mean_z, rel_tol=1e-9)
    assert mean_z > 1.0 + E._clear_excess(ii, eo, h)  # the fault is there
    assert not E.innovations_back_to_normal(f, ii, eo, E._clear_excess(ii, eo, h))


def test_a_fault_is_described_by_a_linear_change_where_the_refit_leaves_the_deadband():
    """`_described_by_linear_change` against a direct least-squares refit of the last n
    samples: the valve's loss of gain leaves e − φΔθ within the deadband and the refit takes
    most of Σe²; with the refit's SSE raised to just above the deadband, or to where the
    refit takes less than it leaves, the same window is not described."""
    monitor, rec, _ = _valve_run()
    f, ii, eo, sc = _episode(monitor)
    h, n = DetectorSettings().threshold, ii[eo + E.P_N]
    phi, r = _signals(monitor, rec)
    e = r - phi @ f[sc + E.S_THETA_REF : sc + E.S_THETA_REF + 4]
    change, *_ = np.linalg.lstsq(phi, e, rcond=None)
    sse = float(np.sum((e - phi @ change) ** 2))
    scale = n * f[sc + E.S_SIGMA2_REF]
    deadband = 1.0 + E._clear_excess(ii, eo, h)
    assert sse / scale < deadband < float(np.sum(e**2)) / scale
    assert E._described_by_linear_change(f, ii, eo, sse, h)
    assert not E._described_by_linear_change(f, ii, eo, 1.001 * deadband * scale, h)
    # taken = Σe²/scale − left must exceed left − 1: left below half of (Σe²/scale + 1).
    # Here (19.9 + 1)/2 lies above the deadband, so test it under a threshold whose
    # deadband holds both sides of it
    half = 0.5 * (float(np.sum(e**2)) / scale + 1.0)
    wide = 1.0 + 2.0 * half * math.sqrt(n / ii[eo + E.P_M])  # deadband 1 + 2·half
    assert E._described_by_linear_change(f, ii, eo, 0.99 * half * scale, wide)
    assert not E._described_by_linear_change(f, ii, eo, 1.01 * half * scale, wide)
