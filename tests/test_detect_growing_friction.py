"""The growing-fault path (issue 43): Page's CUSUM of the innovations along the signature's
regressor (`core.cusum`, `detect.kernel._drift_tick`), on friction that grows linearly to half
the signature's size over 1 s (`studies/growing_friction_detection.py` builds the ramps)."""

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

THREE_TONE = G.OPERATIONS["three-tone 2.5/6/8.5 Hz"]
LOW = G.OPERATIONS["low 1.2/2/2.9 Hz"]


@functools.cache
def _ramp(operation_name: str, seed: int = 4):
    from hil_sim.scenarios import scenario_from_dict, simulate

    spec = G.ramp_spec(G.OPERATIONS[operation_name], {}, duration_s=14.0)
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


def test_the_drift_path_is_bit_equal_per_tick_and_in_batch():
    """The step/batch contract: the same events and the same final CUSUM (one sample at a
    time against `Monitor.run`, whose kernel returns to Python only on event ticks)."""
    rec = _ramp("three-tone 2.5/6/8.5 Hz")
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


@pytest.mark.xfail(
    strict=True,
    reason=(
        "issue 43 target not met under 1.2/2/2.9 Hz: the high-pass velocity's sign is wrong "
        "for much of each cycle there (docs/detector.md §4a), the CUSUM of the innovations "
        "along the signature peaks at 60–90 against h = 201 and the ramp is not found on "
        "the default rig, v0 or v1 (docs/detector.md, 'Growing friction')"
    ),
)
def test_half_size_ramp_over_one_second_found_within_1_5_s_low_frequency():
    events = _events(sim_rig_model(), _ramp("low 1.2/2/2.9 Hz"))
    detected = first_event(events, "fault_detected")
    assert detected is not None and detected["t"] - G.ONSET_S <= 1.5


def test_the_drift_threshold_follows_the_stated_false_alarm_rate():
    from fdi_daemon.core.cusum import cusum_threshold

    model = copy.deepcopy(sim_rig_model())
    det = Monitor(model).detector
    assert det.drift_threshold == pytest.approx(8 * cusum_threshold(10.0, 256.0))
    model.detector = {**(model.detector or {}), "drift_false_alarm_years": 1.0}
    assert Monitor(model).detector.drift_threshold == pytest.approx(8 * cusum_threshold(1.0, 256.0))
