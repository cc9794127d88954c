"""The friction level as a physical quantity (issue 12), against the simulator's truth.

The models: the shipped plant (configs/model_sim_rig.yaml) with a signature identified by
`fdi signature --velocity-method model_observer` (or ``position_observer``: the LVDT fused
with the accelerometer) on the paired 6 Hz calibration run (bearing supply 45 %).
Truths come from the simulator, never from the code under test:
- γ_f: bearing_viscous_per_n / bearing_mu_kinetic of hil_sim.rig.params (the contact
  friction is μ·N·sign v + c·N·v, so viscous/Coulomb = c/μ whatever the contact force N);
- a fault's size: its Coulomb force μ·N over the calibration fault's, i.e. the mean
  contact force N of the air bearing (ground-truth column ``contact_force``) after the
  fault over that of the calibration run's fault window (the seal's friction is there
  before and after, and is not part of the fault).
"""

import numpy as np
import pytest
from conftest_detect import (
    MODEL,
    PAIRED_SIGNATURE_WINDOWS,
    model_copy,
    scenario_recording,
    sim_rig_model,
)

from fdi_daemon.cli import main
from fdi_daemon.detect.monitor import Monitor
from fdi_daemon.io.model_file import load_model, save_model
from fdi_daemon.io.recordings import write_recording
from hil_sim.rig.params import RigParams

CALIBRATION = "signature_calibration_paired"


def _signature(tmp_path_factory, method):
    root = tmp_path_factory.mktemp(method)
    rec = write_recording(root / "paired.npz", scenario_recording(CALIBRATION))
    out = root / "model.yaml"
    assert (
        main(
            [
                "signature",
                str(rec),
                "--model",
                str(MODEL),
                *PAIRED_SIGNATURE_WINDOWS,
                "--velocity-method",
                method,
                "-o",
                str(out),
            ]
        )
        == 0
    )
    return load_model(out)


@pytest.fixture(scope="module")
def observer_model(tmp_path_factory):
    return _signature(tmp_path_factory, "model_observer")


@pytest.fixture(scope="module")
def position_model(tmp_path_factory):
    return _signature(tmp_path_factory, "position_observer")


def _fault_size(rec, fault_t):
    cal = scenario_recording(CALIBRATION)
    calibrated = np.mean(cal.columns["contact_force"][cal.t >= 22.0])
    return float(np.mean(rec.columns["contact_force"][rec.t >= fault_t + 0.5]) / calibrated)


def _level(model, rec, after_t):
    events, trace = Monitor(model).run(rec)
    level = trace.friction_level[(trace.t >= after_t) & np.isfinite(trace.friction_level)]
    return events, level


def test_gamma_f_within_20_percent_of_the_rigs_with_an_interval_holding_it(observer_model):
    params = RigParams()
    truth = params.bearing_viscous_per_n / params.bearing_mu_kinetic
    sig = observer_model.provenance["signature"]
    # the one-carrier 6 Hz run's 99 % interval (2.1-4.27 since its ends are read between
    # grid points) covers 22 % of the grid: "poorly identified", not flat; the six-carrier
    # run of README step 2 identifies γ_f (test_gamma_interval_coverage.py)
    assert sig["gamma_f_status"] in ("identified", "poorly identified")
    assert abs(observer_model.fault_filter.gamma_f / truth - 1) <= 0.2
    lo, hi = sig["cost_profile"]["interval_99"]
    assert lo <= truth <= hi
    assert sig["fault_filter_vaf_percent_full_band"] >= 50.0


@pytest.mark.parametrize(
    "case, fault_t, low, high", [("test_case_1", 3.05, 0.35, 0.5), ("test_case_2", 2.9, 2.0, 2.6)]
)
def test_the_shipped_model_reports_a_fault_at_its_size(case, fault_t, low, high):
    """The shipped model (high-pass velocity, `fdi signature` on README step 2's paired
    signature_calibration_paired_carriers.yaml, fault window 62-122 s): test case 1 (bearing
    supply 65 %) and test case 2 (supply cut) from 1.5 s after the fault within ±10 % of
    their size (measured -3.7 % and +1.1 %; with the one-amplitude model shipped before, -0 %
    and +1 %, where θ1 alone read +21 % and -25 %: under one sine g1 and g2 are nearly
    collinear, and the friction a fault adds moves θ along their valley, while its multiple
    of the calibrated regressor g1 + γ_f g2, the level, stays put)."""
    rec = scenario_recording(case)
    cal = scenario_recording("signature_calibration_paired_carriers")
    inside = (cal.t >= 62.0) & (cal.t < 122.0)
    truth = float(
        np.mean(rec.columns["contact_force"][rec.t >= fault_t + 0.5])
        / np.mean(cal.columns["contact_force"][inside])
    )
    assert low < truth < high  # the scenario is what this test means it to be
    events, level = _level(sim_rig_model(), rec, fault_t + 1.5)
    assert [e["kind"] for e in events] == ["calibrated", "fault_detected", "friction_isolated"]
    assert abs(np.median(level) / truth - 1) <= 0.10


@pytest.mark.xfail(
    strict=True,
    reason="measured +48 % (0.628 for 0.424): after the fault the "
    "observer's velocity still carries the model's free motion into g2 (θ2 8.1 "
    "against γ_f θ1 = 1.3), and the level on the signature's direction (1, γ_f) "
    "counts it; θ1 alone read -8 % (docs/detector.md §4a)",
)
def test_with_the_observer_a_fault_of_known_size_is_reported_at_its_size(observer_model):
    """Test case 1 (bearing supply 65 %, 0.42 of the calibrated fault): within ±10 %."""
    rec = scenario_recording("test_case_1")
    truth = _fault_size(rec, 3.05)
    assert 0.35 < truth < 0.5  # the scenario is what this test means it to be
    events, level = _level(observer_model, rec, 3.05 + 1.5)
    assert [e["kind"] for e in events] == ["calibrated", "fault_detected", "friction_isolated"]
    assert abs(np.median(level) / truth - 1) <= 0.10


@pytest.mark.xfail(
    strict=True,
    reason="measured: a bearing supply cut (2.3x the calibrated "
    "fault, the load held 12 % of the time) reads 0.59 and is other_fault "
    "with the observer (docs/detector.md)",
)
def test_a_large_fault_is_reported_at_its_size(observer_model):
    rec = scenario_recording("test_case_2")
    truth = _fault_size(rec, 2.9)
    events, level = _level(observer_model, rec, 2.9 + 1.5)
    assert [e["kind"] for e in events][-1] == "friction_isolated"
    assert abs(np.median(level) / truth - 1) <= 0.10


def _steady():
    return scenario_recording("steady_friction_changing_operation")


def test_a_steady_fault_under_changing_operation_is_one_episode(observer_model):
    """Bearing supply 45 % from 20 s under 160 s of changing operation (1-9 Hz, 0.8-1.6 V):
    one episode, never cleared. With the high-pass model it was cleared and raised three
    times (docs/detector.md)."""
    events, _ = Monitor(observer_model).run(_steady())
    kinds = [e["kind"] for e in events]
    assert kinds == ["calibrated", "fault_detected", "friction_isolated"]
    assert 20.0 <= events[1]["t"] <= 20.1


def test_the_shipped_models_steady_fault_level_stays_within_20_percent_of_its_median():
    """The high-pass model's reported level leaves out the windows where its velocity is not
    trusted (1.5-3.7 Hz) and takes the median over 10 s: from 10 s after the fault the 5th
    and 95th percentiles are within 20 % of the median (measured -11/+5 %, median 0.957; with
    the one-amplitude model shipped before -7/+6 %, 0.983), the median within 10 % of the
    fault."""
    rec = _steady()
    _, level = _level(sim_rig_model(), rec, 30.0)
    median = np.median(level)
    lo, hi = np.percentile(level, [5, 95])
    assert lo >= 0.8 * median and hi <= 1.2 * median
    assert abs(median / _fault_size(rec, 20.0) - 1) <= 0.10
    assert level.size > 0.5 * np.sum(rec.t >= 30.0)  # shown most of the time


@pytest.mark.xfail(
    strict=True,
    reason="measured: 5th-95th percentile at -35/+38 % of the "
    "median (1.05 against a truth of 1.0) with the level read only above half the "
    "calibration's band (5.5-6.5 Hz: from 2.75 Hz, shown 74 % of the time); -77/+36 % "
    "before that gate, when the observer's velocity was trusted at every operation: on "
    "this rig G_e from one 6 Hz calibration does not describe friction at 1-3 Hz, nor "
    "within 20 % above (docs/identification.md)",
)
def test_a_steady_faults_level_stays_within_20_percent_of_its_median(observer_model):
    rec = _steady()
    _, level = _level(observer_model, rec, 30.0)
    median = np.median(level)
    lo, hi = np.percentile(level, [5, 95])
    assert lo >= 0.8 * median and hi <= 1.2 * median
    assert abs(median / _fault_size(rec, 20.0) - 1) <= 0.10


def test_with_position_a_large_fault_is_reported_at_its_size(position_model):
    """The LVDT fused with the accelerometer: test case 2 (2.3x the calibrated fault) is
    isolated as friction and reported within ±10 % (measured -7 %; +8 % with θ1 for the
    level)."""
    rec = scenario_recording("test_case_2")
    truth = _fault_size(rec, 2.9)
    assert 2.0 < truth < 2.6
    events, level = _level(position_model, rec, 2.9 + 1.5)
    assert [e["kind"] for e in events] == ["calibrated", "fault_detected", "friction_isolated"]
    assert abs(np.median(level) / truth - 1) <= 0.10
    params = RigParams()
    gamma_truth = params.bearing_viscous_per_n / params.bearing_mu_kinetic
    assert abs(position_model.fault_filter.gamma_f / gamma_truth - 1) <= 0.2


def test_with_position_a_steady_faults_median_level_is_its_size(position_model):
    """Under changing operation the median level from 10 s after the fault is within 10 %
    of the truth (measured -9.5 %; -8 % with θ1 for the level)."""
    rec = _steady()
    _, level = _level(position_model, rec, 30.0)
    assert abs(np.median(level) / _fault_size(rec, 20.0) - 1) <= 0.10


def test_with_position_a_steady_fault_is_one_episode(position_model):
    """At 1.8 Hz the load sticks 11 % of the time and θ slides along the g1/g2 valley, so
    the level drops below half its margin; the residual against the pre-fault reference
    still shows the fault, so it is not cleared (it was three times on the level alone)."""
    events, _ = Monitor(position_model).run(_steady())
    assert [e["kind"] for e in events] == ["calibrated", "fault_detected", "friction_isolated"]


#: a calibration run with low-frequency content and one amplitude (issue 12's procedure):
#: four equal tones at 2, 3.3, 5 and 8 Hz, bearing supply 45 % from 4 s, fault window 5-20 s
LOW_FREQUENCY_CALIBRATION = {
    "name": "low_frequency_calibration",
    "duration_s": 20.0,
    "seed": 0,
    "centring_gain_v_per_m": 30.0,
    "excitation": [
        {
            "kind": "multisine",
            "amplitudes_v": [0.45] * 4,
            "frequencies_hz": [2.0, 3.3, 5.0, 8.0],
            "duration_s": 20.0,
        }
    ],
    "events": [{"t_s": 4.0, "bearing_supply": 0.45}],
}


@pytest.fixture(scope="module")
def low_frequency_models(tmp_path_factory):
    """`fdi signature` on the four-tone run with a plant-only model: by default (auto) and
    with ``--velocity-method highpass``; (calibration recording, {"default": model,
    "highpass": model})."""
    from hil_sim.scenarios import scenario_from_dict, simulate

    root = tmp_path_factory.mktemp("low_frequency")
    cal = simulate(scenario_from_dict(LOW_FREQUENCY_CALIBRATION))
    rec = write_recording(root / "cal.npz", cal)
    save_model(root / "plant.yaml", model_copy(velocity=None, fault_filter=None))
    models = {}
    for name, extra in (("default", []), ("highpass", ["--velocity-method", "highpass"])):
        out = root / f"{name}.yaml"
        assert (
            main(
                [
                    "signature",
                    str(rec),
                    "--model",
                    str(root / "plant.yaml"),
                    "--fault-window",
                    "5:20",
                    *extra,
                    "-o",
                    str(out),
                ]
            )
            == 0
        )
        models[name] = load_model(out)
    return cal, models


def test_auto_keeps_the_velocity_whose_signature_fits(low_frequency_models):
    """A plant-only model gets ``--velocity-method auto``: the high-pass estimator, and where
    its signature explains less than half of the fault residual (here its lead of 35-60° at
    2-3.3 Hz), the model-based observer, kept because it explains more. The steady fault's
    level is then nearer the simulator's truth than with the high-pass model (measured: +10 %
    against +38 %)."""
    cal, models = low_frequency_models
    sig = models["default"].provenance["signature"]
    assert sig["velocity_method"] == "auto"
    explained = sig["vaf_percent_by_velocity"]
    assert explained["highpass"] < 50.0 < explained["model_observer"]
    assert models["default"].velocity["method"] == "model_observer"
    assert models["highpass"].velocity.get("method", "highpass") == "highpass"
    steady = _steady()
    truth = np.mean(steady.columns["contact_force"][steady.t >= 20.5]) / np.mean(
        cal.columns["contact_force"][cal.t >= 5.0]
    )
    error = {
        name: abs(np.median(_level(model, steady, 30.0)[1]) / truth - 1)
        for name, model in models.items()
    }
    assert error["default"] < error["highpass"]


def test_with_the_observer_a_clipping_accelerometer_is_not_friction(low_frequency_models):
    """The saturation fault clips the 8 Hz peaks, where the velocity reverses and the
    observer's sign(v̂) switches: without the rail check the harmonics check called the
    residual pulses friction. Clipped windows are no friction evidence: an other fault."""
    _, models = low_frequency_models
    events, _ = Monitor(models["default"]).run(
        scenario_recording("fault_accel_saturation", duration_s=64.0)
    )
    assert [e["kind"] for e in events if e["kind"] != "calibrated"] == [
        "fault_detected",
        "other_fault",
    ]
    assert events[-1]["accel_clipping"] is True  # the event says why
    events, _ = Monitor(models["default"]).run(
        scenario_recording("fault_valve_gain", duration_s=64.0)
    )
    assert events[-1]["kind"] == "other_fault" and "accel_clipping" not in events[-1]


def test_the_level_after_a_fault_does_not_depend_on_the_sample_the_monitor_started_at():
    """The level's picks restart with the episode: test case 1 monitored from its first
    sample and from 7, 23 and 41 samples later (the pick period is 64 samples) reports the
    same level 1.5 s after the detection. Before, the picks kept the phase of the monitor's
    start, and three runs of README's command read 0.53, 0.83 and 1.05 at the same
    isolation. No pick mixes the windows before the detection: the level is not shown
    until one window after it."""
    rec = scenario_recording("test_case_1")
    levels = []
    for start in (0, 7, 23, 41):
        events, trace = Monitor(sim_rig_model()).run(rec.samples(slice(start, None)))
        detected = next(e["t"] for e in events if e["kind"] == "fault_detected")
        first = trace.t[np.isfinite(trace.friction_level) & (trace.t > detected)][0]
        assert first >= detected + 1.0 - 1e-9
        levels.append(trace.friction_level[trace.t >= detected + 1.5][0])
    assert np.isfinite(levels[0])
    assert levels == pytest.approx([levels[0]] * 4, rel=1e-3)
