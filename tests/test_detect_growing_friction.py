"""The growing-fault path (issue 43): Page's CUSUM of the innovations along the signature's
regressor (`core.cusum`, `detect.kernel._drift_tick`), on friction that grows linearly to half
the signature's size over 1 s (`studies/growing_friction_detection.py` builds the ramps;
`studies/growing_friction_velocity.py` the models with a position-fused velocity)."""

from __future__ import annotations

import copy
import functools
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest_detect import first_event, scenario_recording, sim_rig_model

from fdi_daemon.detect.monitor import Monitor
from fdi_daemon.io.sample import Sample

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "studies"))
import growing_friction_detection as G  # noqa: E402
import growing_friction_velocity as V  # noqa: E402

THREE_TONE = G.OPERATIONS["three-tone 2.5/6/8.5 Hz"]
LOW = G.OPERATIONS["low 1.2/2/2.9 Hz"]


#: an accelerometer bias step after the drift path's raise (9.16 s on the three-tone ramp):
#: a fault off friction's direction that the residual test alarms on
BIAS_T_S, BIAS_MPS2 = 12.0, 2.0


@functools.cache
def _ramp(operation_name: str, seed: int = 4, bias: bool = False):
    """The 1 s half-size ramp from 8 s (14 s long); ``bias``: with the bias step."""
    from hil_sim.scenarios import scenario_from_dict, simulate

    spec = G.ramp_spec(G.OPERATIONS[operation_name], {}, duration_s=14.0 + 2.0 * bias)
    if bias:
        spec["events"].append({"t_s": BIAS_T_S, "fault": "accel_bias", "value": BIAS_MPS2})
    return simulate(scenario_from_dict(spec), seed=seed)


def _events(model, rec):
    return [e for e in Monitor(model).run(rec)[0] if e["kind"] != "calibrated"]


def test_the_drift_path_raises_an_unconfirmed_fault_on_growing_friction_and_never_clears():
    events = _events(sim_rig_model(), _ramp("three-tone 2.5/6/8.5 Hz"))
    detected = first_event(events, "fault_detected")
    assert detected["path"] == "drift" and detected["unconfirmed"] is True
    assert detected["drift_statistic"] > detected["drift_threshold"]
    assert detected["t"] > G.ONSET_S  # nothing before the onset
    kinds = [e["kind"] for e in events]
    assert kinds.count("fault_detected") == 1 and "cleared" not in kinds


def test_without_the_drift_path_the_growing_friction_is_not_found():
    """``drift_shift_level: 0`` is the detector before the path: silent on the same ramp."""
    model = G.without_drift_path(sim_rig_model())
    assert _events(model, _ramp("three-tone 2.5/6/8.5 Hz")) == []


def test_a_drift_raised_episode_stays_unconfirmed_past_the_isolation_timeout():
    """The drift path tests friction's direction only: without friction isolated and
    without the residual test's alarm (the fast path's evidence of a fault), the episode
    is neither other_fault nor cleared (before: other_fault at +3.16 s, timeout 2 s)."""
    model = sim_rig_model()
    rec = _ramp("three-tone 2.5/6/8.5 Hz")
    events = _events(model, rec)
    detected = first_event(events, "fault_detected")
    timeout_s = Monitor(model).detector.settings.isolation_timeout_s
    assert rec.t[-1] > detected["t"] + timeout_s + 1.0
    assert [e["kind"] for e in events] == ["fault_detected"]


def test_a_drift_raised_episode_is_other_fault_a_timeout_after_the_residual_test_alarms():
    """A bias step of the accelerometer during the drift-raised episode: the residual test's
    alarm is the evidence of a fault, and with no friction isolated within the isolation
    timeout from it the episode is other_fault once the bias describes the fault: within
    one window of the episode's refit after the timeout (measured +2.59 s, timeout 2 s)."""
    model = sim_rig_model()
    events = _events(model, _ramp("three-tone 2.5/6/8.5 Hz", bias=True))
    detector = Monitor(model).detector
    timeout_s = detector.settings.isolation_timeout_s
    window_s = detector.window_samples / model.fs
    assert [e["kind"] for e in events] == ["fault_detected", "other_fault"]
    assert events[0]["path"] == "drift" and events[0]["t"] < BIAS_T_S
    assert BIAS_T_S + timeout_s < events[1]["t"] <= BIAS_T_S + timeout_s + window_s


@pytest.mark.parametrize("bias", [False, True], ids=["ramp", "ramp_then_bias"])
def test_the_drift_path_is_bit_equal_per_tick_and_in_batch(bias):
    """The step/batch contract: the same events and the same final CUSUM (one sample at a
    time against `Monitor.run`, whose kernel returns to Python only on event ticks)."""
    rec = _ramp("three-tone 2.5/6/8.5 Hz", bias=bias)
    batch_monitor = Monitor(sim_rig_model())
    batch, trace = batch_monitor.run(rec)
    mon = Monitor(sim_rig_model())
    stepped, statistic = [], []
    for k in range(len(rec)):
        sample = Sample(k, float(rec.t[k]), float(rec.v_in[k]), float(rec.accel[k]))
        stepped.extend(mon.step(sample))
        statistic.append(mon.detector.statistic)
    stepped.extend(mon.finish())
    assert any(e.get("path") == "drift" for e in batch)
    assert batch == stepped
    np.testing.assert_array_equal(trace.statistic, statistic)
    assert batch_monitor.detector.drift_statistic == mon.detector.drift_statistic


@pytest.mark.parametrize(
    "name,fault_s,today_s", [("test_case_1", 3.05, 0.0633), ("test_case_2", 2.9, 0.0180)]
)
def test_test_cases_are_detected_no_later_than_before(name, fault_s, today_s):
    events = _events(sim_rig_model(), scenario_recording(name))
    assert [e["kind"] for e in events] == ["fault_detected", "friction_isolated"]
    assert fault_s <= events[0]["t"] <= fault_s + today_s + 1e-9


@pytest.mark.slow
def test_a_fault_free_hour_is_silent_with_the_drift_path():
    rec = scenario_recording("fault_free_hour", seed=0)
    events, _ = Monitor(sim_rig_model()).run(rec, trace_every=len(rec))
    assert [e for e in events if e["kind"] == "fault_detected"] == []


def test_half_size_ramp_over_one_second_found_within_1_5_s_default_rig():
    events = _events(sim_rig_model(), _ramp("three-tone 2.5/6/8.5 Hz"))
    detected = first_event(events, "fault_detected")
    assert detected is not None and 0.0 < detected["t"] - G.ONSET_S <= 1.5


@pytest.fixture(scope="module")
def variant_models():
    return G.models(("v0", "v1"))


@pytest.mark.slow
@pytest.mark.parametrize("rig", ["v0", "v1"])
def test_half_size_ramp_over_one_second_found_within_1_5_s_rig_variants(variant_models, rig):
    from hil_sim.scenarios import scenario_from_dict, simulate

    overrides, model = variant_models[rig]
    spec = G.ramp_spec(THREE_TONE, overrides, duration_s=14.0)
    events = _events(model, simulate(scenario_from_dict(spec), seed=4))
    detected = first_event(events, "fault_detected")
    assert detected is not None and 0.0 < detected["t"] - G.ONSET_S <= 1.5
    assert "cleared" not in [e["kind"] for e in events]


@pytest.mark.parametrize("seed", G.LOWCUT_SEEDS)
def test_half_size_ramp_over_one_second_found_within_1_5_s_low_frequency(seed):
    """Under 1.2/2/2.9 Hz the shipped model's drift path, on its own 0.5 Hz high-pass velocity
    and G_e (README step 2's ``--drift-highpass-hz 0.5``) with its own reference fit on them,
    finds the ramp on every seed of the study; one episode."""
    events = _events(sim_rig_model(), _ramp("low 1.2/2/2.9 Hz", seed))
    detected = first_event(events, "fault_detected")
    assert detected is not None and 0.0 < detected["t"] - G.ONSET_S <= 1.5
    assert detected["path"] == "drift"
    assert "cleared" not in [e["kind"] for e in events]


def test_the_drift_signature_changes_only_the_growing_fault_path():
    """θ, the friction level and the residual test stay on the monitor's own velocity and
    G_e: with or without ``fault_filter.drift``, test case 2 gives the same trace and events."""
    model = sim_rig_model()
    assert model.fault_filter.drift is not None and model.fault_filter.drift.highpass_hz == 0.5
    without = copy.deepcopy(model)
    without.fault_filter.drift = None
    rec = scenario_recording("test_case_2")
    (events, trace), (events0, trace0) = Monitor(model).run(rec), Monitor(without).run(rec)
    assert [e["kind"] for e in events] == [e["kind"] for e in events0]
    assert [e["t"] for e in events] == [e["t"] for e in events0]
    for name in ("theta1", "theta2", "statistic", "friction_level"):
        np.testing.assert_array_equal(getattr(trace, name), getattr(trace0, name))


def test_the_drift_cusum_has_its_own_reference_on_the_drift_regressors():
    """With a drift signature the CUSUM's reference is (R) fitted on its regressors (G_d[sign
    v̂_d], G_d[v̂_d], x̂̈, 1), not the residual test's on g1, g2; a data gap restarts it with the
    other windows; without a drift signature there is none (the residual test's is used)."""
    model = sim_rig_model()
    mon = Monitor(model)
    rec = _ramp("low 1.2/2/2.9 Hz")
    for k in range(int(G.ONSET_S * 256)):
        mon.step(Sample(k, float(rec.t[k]), float(rec.v_in[k]), float(rec.accel[k])))
    det = mon.detector
    assert det.drift_test is not None and det.drift_test.ok and det.residual_test.ok
    assert det.drift_test.theta[:2] != det.residual_test.theta[:2]
    det.restart()
    assert not det.drift_test.ok
    without = copy.deepcopy(model)
    without.fault_filter.drift = None
    assert Monitor(without).detector.drift_test is None


@pytest.fixture(scope="module")
def drift_variant_models():
    """README step 2 with ``--drift-highpass-hz 0.5`` on each variant's own recordings."""
    return G.step2_models(("--drift-highpass-hz", "0.5"), ("v0", "v1", "v2"))


V0_LOW = pytest.mark.xfail(
    strict=True,
    reason=(
        "v0 under 1.2/2/2.9 Hz: the drift CUSUM on its 0.5 Hz velocity and reference peaks at "
        "0.83-0.98 h within 1.5 s on seeds 4-6, 8, 9 (found on seed 7 only, +0.69 s; the whole "
        "monitor on 0.5 Hz likewise): at each reversal of its 1-3 Hz motion the load sticks and the "
        "residual turns against g1 for ~15 ticks (a stuck load is not the Coulomb regressor's "
        "sliding friction), so S loses what the ramp gave it; not the velocity's phase "
        "(docs/detector.md §3, 'The 1–3 Hz ramp without position')"
    ),
)
V1_LOW_SEED_7 = pytest.mark.xfail(
    strict=True,
    reason=(
        "v1 under 1.2/2/2.9 Hz, seed 7: the drift CUSUM peaks at 0.99 h within 1.5 s (2.5-3.1 h "
        "on the other seeds); docs/detector.md §3, 'The drift path on its own 0.5 Hz velocity'"
    ),
)
LOW_VARIANT_CASES = (
    [pytest.param("v0", 4, marks=V0_LOW)]
    + [
        pytest.param("v1", seed, marks=V1_LOW_SEED_7) if seed == 7 else ("v1", seed)
        for seed in G.LOWCUT_SEEDS
    ]
    + [("v2", seed) for seed in G.LOWCUT_SEEDS]
)


@pytest.mark.slow
@pytest.mark.parametrize("rig,seed", LOW_VARIANT_CASES)
def test_half_size_ramp_found_within_1_5_s_low_frequency_rig_variants(
    drift_variant_models, rig, seed
):
    from hil_sim.scenarios import scenario_from_dict, simulate

    overrides, model = drift_variant_models[rig]
    spec = G.ramp_spec(LOW, overrides, duration_s=14.0)
    events = _events(model, simulate(scenario_from_dict(spec), seed=seed))
    detected = first_event(events, "fault_detected")
    assert detected is not None and 0.0 < detected["t"] - G.ONSET_S <= 1.5
    assert "cleared" not in [e["kind"] for e in events]


@pytest.mark.slow
@pytest.mark.parametrize("rig", ["default", "v0", "v1"])
def test_half_size_ramp_found_within_1_5_s_low_frequency_with_a_position_fused_velocity(
    tmp_path_factory, rig
):
    """Where the rig records position: the signature made with ``--velocity-method
    position_observer`` on the paired calibration run (sign v̂ right at 1–3 Hz) and the drift
    path matched to ``drift_shift_level`` 0.2 find the 1 s half-size ramp under 1.2/2/2.9 Hz
    operation (`studies/growing_friction_velocity.py`; docs/detector.md §3)."""
    from test_detect_other_rig import rig_variant

    from hil_sim.scenarios import scenario_from_dict, simulate

    overrides = {} if rig == "default" else rig_variant(int(rig[1:]))
    methods = ("position_observer",)
    model = V.paired_models(overrides, tmp_path_factory.mktemp(rig), methods)[methods[0]]
    model = V.with_shift(model, V.POSITION_SHIFT)
    spec = G.ramp_spec(LOW, overrides, duration_s=14.0)
    events = _events(model, simulate(scenario_from_dict(spec), seed=4))
    detected = first_event(events, "fault_detected")
    assert detected is not None and 0.0 < detected["t"] - G.ONSET_S <= 1.5
    assert "cleared" not in [e["kind"] for e in events]


def test_the_drift_threshold_follows_the_stated_false_alarm_rate():
    from fdi_daemon.core.cusum import cusum_threshold

    model = copy.deepcopy(sim_rig_model())
    det = Monitor(model).detector
    assert det.drift_threshold == pytest.approx(8 * cusum_threshold(10.0, 256.0))
    model.detector = {**(model.detector or {}), "drift_false_alarm_years": 1.0}
    assert Monitor(model).detector.drift_threshold == pytest.approx(8 * cusum_threshold(1.0, 256.0))
