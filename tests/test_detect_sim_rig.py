"""Issue 4 targets on the simulated rig (hil_sim): the paper's test cases, the other faults,
and fault-free changing operation."""

import functools
from pathlib import Path

import numpy as np
import pytest
from conftest_detect import (
    MODEL,
    SCENARIOS,
    changing_operation_spec,
    first_event,
    scenario_recording,
    sim_rig_model,
)

from fdi_daemon.detect.monitor import Monitor
from fdi_daemon.detect.settings import DetectorSettings

#: (scenario, fault time in the scenario (s), detection target (s), isolation target (s))
TEST_CASES = [("test_case_1", 3.05, 0.015, 1.5), ("test_case_2", 2.9, 0.035, 0.7)]
OTHER_FAULTS = [
    "fault_accel_bias",
    "fault_valve_gain",
    "fault_supply_pressure",
    "fault_accel_dropout",
    "fault_accel_saturation",
]


def _replay(name, **kwargs):
    return Monitor(sim_rig_model()).run(scenario_recording(name, **kwargs))


@pytest.mark.parametrize("name,fault_s,_detect,isolate_s", TEST_CASES)
def test_test_cases_are_detected_and_isolated_as_friction(name, fault_s, _detect, isolate_s):
    events, _ = _replay(name)
    kinds = [e["kind"] for e in events]
    assert kinds == ["calibrated", "fault_detected", "friction_isolated"]
    detected = first_event(events, "fault_detected")["t"]
    isolated = first_event(events, "friction_isolated")
    assert fault_s <= detected  # nothing before the fault
    assert isolated["t"] - fault_s <= isolate_s
    assert isolated["coulomb_change"] >= 0.3


def test_test_case_2_detected_within_35_ms():
    events, _ = _replay("test_case_2")
    assert first_event(events, "fault_detected")["t"] - 2.9 <= 0.035


@pytest.mark.xfail(
    strict=True,
    reason=(
        "measured 63 ms after the 3.05 s event: the bearing touches down at +16 ms, but the "
        "friction's residual during the sliding half-cycle fades within ~20 ms (the plant's "
        "stiffness) and lifts the statistic to ~12 only; it crosses h = 30 at the first velocity "
        "reversal under friction, +59 ms (also on rig variants with contact at +4 ms)"
    ),
)
def test_test_case_1_detected_within_15_ms():
    events, _ = _replay("test_case_1")
    assert first_event(events, "fault_detected")["t"] - 3.05 <= 0.015


@functools.cache
def own_signature(name, fault_s, tmp):
    """The paper's §IV-B procedure: G_e and γ_f fitted on a recording of the same input and
    fault (another seed, 20 s, the fault window from 1.1 s after the fault) with
    `fdi signature`; returns (model, the window θ of the replay of the seed-0 test case)."""
    from fdi_daemon.cli import main
    from fdi_daemon.io.model_file import load_model
    from fdi_daemon.io.recordings import write_recording
    from hil_sim.scenarios import load_scenario, simulate

    rec = simulate(load_scenario(SCENARIOS / f"{name}.yaml"), seed=1, duration_s=20.0)
    path, model_path = Path(tmp) / f"{name}.npz", Path(tmp) / f"{name}.yaml"
    write_recording(path, rec)
    assert (
        main(
            [
                "signature",
                str(path),
                "--model",
                str(MODEL),
                "--fault-window",
                f"{fault_s + 1.1}:20",
                "-o",
                str(model_path),
            ]
        )
        == 0
    )
    model = load_model(model_path)
    return model, Monitor(model).run(scenario_recording(name))[1]


def test_theta1_of_test_case_1_settles_on_its_own_signature(tmp_path_factory):
    """Against a signature calibrated on the same fault, as the paper calibrates: θ1 (the
    friction level) within ±15 % of 1 from the paper's tracking time on, and staying there
    (θ2 does not: see the xfail below)."""
    _model, trace = own_signature("test_case_1", 3.05, tmp_path_factory.getbasetemp())
    k = np.searchsorted(trace.t, 3.05 + 1.5)
    assert np.all(np.abs(trace.theta1[k:] - 1.0) <= 0.15)


CASE_1_THETA2 = pytest.mark.xfail(
    strict=True,
    reason=(
        "case 1: θ1 is within ±1.1 % of 1 from +1.5 s, but θ2 ranges over 0.56-1.02 against "
        "γ_f = 0.80 (29 % off): under a single 8 Hz sine g1 and g2 are nearly collinear, the γ "
        "profile of the signature is flat (γ_f is arbitrary) and θ2 moves along the "
        "least-squares valley"
    ),
)


@pytest.mark.parametrize(
    "name,fault_s,_detect,isolate_s",
    [pytest.param(*TEST_CASES[0], marks=CASE_1_THETA2), TEST_CASES[1]],
)
def test_theta_tracks_the_signature_within_15_percent(
    name, fault_s, _detect, isolate_s, tmp_path_factory
):
    """The paper's tracking target, against a signature calibrated on another recording of
    the same input and fault (§IV-B): from the tracking time on, θ within ±15 % of (1, γ_f)."""
    model, trace = own_signature(name, fault_s, tmp_path_factory.getbasetemp())
    gamma = model.fault_filter.gamma_f
    if gamma is None:  # one sine: the least cost lies at the grid's end, not a value of γ_f
        sig = model.provenance["signature"]
        assert sig["gamma_f_status"] == "not identified (edge)"
        gamma = sig["gamma_at_least_cost"]  # the γ G_e was fitted at, which θ2 tracks
    k = np.searchsorted(trace.t, fault_s + isolate_s)
    assert np.all(np.abs(trace.theta1[k:] - 1.0) <= 0.15)
    assert np.all(np.abs(trace.theta2[k:] - gamma) <= 0.15 * abs(gamma))


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
@pytest.mark.parametrize("name", OTHER_FAULTS)
def test_other_faults_are_detected_and_not_called_friction(name, seed):
    events, _ = _replay(name, seed=seed)
    kinds = [e["kind"] for e in events]
    assert "fault_detected" in kinds
    assert "friction_isolated" not in kinds
    assert "other_fault" in kinds
    assert first_event(events, "fault_detected")["t"] >= 4.0


@pytest.mark.slow
def test_fault_free_hour_has_no_alarm():
    events, trace = _replay("fault_free_hour")
    assert len(trace.t) == 3600 * 256
    assert [e["kind"] for e in events] == ["calibrated"]


@pytest.mark.soak
def test_fault_free_day_has_no_alarm():
    """24 simulated hours (24 seeds of the changing-operation hour), one monitor each."""
    from hil_sim.scenarios import load_scenario, simulate

    scenario = load_scenario(SCENARIOS / "fault_free_hour.yaml")
    alarms = []
    for hour in range(24):
        rec = simulate(scenario, seed=100 + hour)
        events, _ = Monitor(sim_rig_model()).run(rec, trace_every=len(rec))
        alarms.extend((hour, e["t"]) for e in events if e["kind"] == "fault_detected")
    assert alarms == []


def _scenario(spec, seed=4):
    from hil_sim.scenarios import scenario_from_dict, simulate

    return Monitor(sim_rig_model()).run(simulate(scenario_from_dict(spec), seed=seed))[0]


def _kinds(events):
    return [e["kind"] for e in events if e["kind"] != "calibrated"]


SINE = {"kind": "sine", "amplitude_v": 1.4, "frequency_hz": 8.0}


def test_friction_that_starts_while_the_guard_holds_is_found_by_the_level_path():
    events = _scenario(
        {
            "name": "guard",
            "duration_s": 14.0,
            "excitation": [
                {"kind": "sine", "amplitude_v": 1.0, "frequency_hz": 6.0, "duration_s": 6.0},
                SINE,
            ],
            "events": [{"t_s": 6.3, "bearing_supply": 0.45}],
        }
    )
    assert _kinds(events) == ["fault_detected", "friction_isolated"]
    assert events[1]["path"] == "level" and 6.3 < events[1]["t"] < 6.3 + 2.0 + 1.5


def test_creeping_friction_is_found_by_the_level_path():
    events = _scenario(
        {
            "name": "creep",
            "duration_s": 90.0,
            "excitation": [SINE],
            "drift": {
                "bearing_supply": {"times_s": [0, 10, 80, 90], "values": [1.0, 1.0, 0.3, 0.3]}
            },
        }
    )
    assert _kinds(events) == ["fault_detected", "friction_isolated"]
    assert events[1]["path"] == "level"


def test_friction_that_grows_past_the_isolation_timeout_is_not_called_another_fault():
    """Friction ramped in over 1 s (bearing supply 100 -> 65 %) under a 3.3 + 5 + 8 Hz
    multisine: the alarm comes 1.1 s after the ramp starts, while the Coulomb increase is
    still below friction_min_level. No linear change describes the fault, so the timeout
    does not say other_fault (before: other_fault at +1.1 s, then friction); the evidence
    follows and the episode becomes friction."""
    events = _scenario(
        {
            "name": "ramp",
            "duration_s": 12.0,
            "excitation": [
                {
                    "kind": "multisine",
                    "amplitudes_v": [0.6, 0.6, 0.6],
                    "frequencies_hz": [3.3, 5.0, 8.0],
                }
            ],
            "drift": {
                "bearing_supply": {"times_s": [0, 5, 6, 12], "values": [1.0, 1.0, 0.65, 0.65]}
            },
        }
    )
    assert _kinds(events) == ["fault_detected", "friction_isolated"]
    assert 5.0 < events[1]["t"] < 6.5 and events[2]["t"] < 9.0


@pytest.mark.slow
def test_friction_creeping_in_over_ten_minutes_is_one_episode_never_cleared():
    """Issue 43 item 2: the bearing supply falls 100 -> 62 % over 10 min under changing
    operation (1-9 Hz); an episode the fast path raises holds while the friction level is
    at least half its margin above normal, until the level path confirms it."""
    from studies.creeping_friction_episodes import _creep

    spec, _ = _creep(600.0, 1800.0)
    kinds = _kinds(_scenario(spec, seed=3))
    assert kinds.count("fault_detected") == 1 and "cleared" not in kinds
    assert "friction_isolated" in kinds


def _changing_operation(event, duration_s=200.0, seed=4, removed=None):
    """Random operation (0.3-1.6 V, 1-12 Hz, segments of 5-60 s), ``event`` at 120 s (and
    ``removed`` at 130 s): at seed 4 the operation there is ~9.3 Hz at 0.7 V until ~134 s,
    then 1.3 V."""
    events = [{"t_s": 120.0, **event}] + ([{"t_s": 130.0, **removed}] if removed else [])
    return _scenario(changing_operation_spec(events, duration_s), seed=seed)


@pytest.mark.slow
def test_persistent_friction_under_changing_operation_is_one_episode():
    """A 30 % bearing supply under a weak 9.3 Hz operation holds the load (stuck 98 % of the
    time): one episode, detected at once and never cleared; while the load is held the
    episode says so (`load_stopped`) rather than guessing friction, and friction is isolated
    by its harmonics once the operation moves the load again."""
    events = [e for e in _changing_operation({"bearing_supply": 0.3}) if e["kind"] != "calibrated"]
    kinds = _kinds(events)
    assert kinds.count("fault_detected") == 1 and "cleared" not in kinds
    assert 120.0 <= events[0]["t"] < 120.2
    held = [e for e in events if e["kind"] == "other_fault"]
    assert all(e.get("load_stopped") is True for e in held)
    assert kinds[-1] == "friction_isolated" and events[-1]["friction_evidence"] == "harmonics"


@pytest.mark.slow
@pytest.mark.parametrize(
    "fault",
    [{"fault": "valve_gain", "value": 0.1}, {"fault": "supply_pressure", "value": 0.3}],
    ids=["valve_10_percent", "supply_30_percent"],
)
def test_a_load_stopped_by_a_weak_drive_is_not_friction(fault):
    """The same operation and seed with the drive weakened instead: the load stops as it
    does under friction, and the accelerometer cannot tell the two apart, so a stopped
    load is never friction evidence (before: `friction_isolated` with
    `friction_evidence: load_stopped` at +0.84 s and +12.9 s)."""
    events = _changing_operation(fault, duration_s=150.0)
    kinds = _kinds(events)
    assert "friction_isolated" not in kinds
    assert kinds == ["fault_detected", "other_fault"]
    assert events[-1].get("load_stopped") is True


@pytest.mark.slow
@pytest.mark.parametrize(
    "seed,fault,duration_s",
    [
        (6, {"fault": "valve_gain", "value": 0.4}, 200.0),
        (5, {"fault": "supply_pressure", "value": 0.3}, 180.0),
        (5, {"fault": "valve_gain", "value": 0.4}, 200.0),
    ],
    ids=["valve_40_percent_6_hz", "supply_30_percent_2_hz", "valve_40_percent_then_1_hz"],
)
def test_a_weakened_drive_is_not_cleared_while_it_lasts(seed, fault, duration_s):
    """Under weak operation one test window at a time stays below h although the fault is
    there (seed 6, 0.25 V at 6 Hz: T 10-27 against h = 30, 19 times the noise): the episode
    clears on the innovations' mean power over a window (the alarm's deadband), and not
    under operation that would not show the fault as measured (seed 5 from 186 s, 1-2 Hz).
    Before: `cleared` at +1.16 s, +1.09 s and +67.3 s (`studies/other_fault_clearing.py`)."""
    kinds = _kinds(_changing_operation(fault, duration_s=duration_s, seed=seed))
    assert kinds == ["fault_detected", "other_fault"]


@pytest.mark.slow
def test_a_lost_supply_is_not_cleared_under_1_to_2_hz_operation():
    """The supply at 30 % (seed 5): under the 1-2 Hz operation from ~186 s its innovations
    are within the deadband and the fault as measured would show 0.5-0.6 there, below the
    deadband's 7.25, so the clearing count holds. Before (Δθ dropped where it showed below
    the deadband in its own window, 7.0 here): `cleared` at 188.1 s."""
    events = _changing_operation({"fault": "supply_pressure", "value": 0.3}, seed=5)
    assert _kinds(events) == ["fault_detected", "other_fault"]


@pytest.mark.slow
def test_a_lost_supply_raised_by_the_growing_fault_path_is_measured_and_not_cleared():
    """The supply at 60 % (seed 7) is raised by the growing-fault path at 120.38 s and the
    residual test never alarms, so the episode stays unconfirmed; its linear change is still
    measured once it describes the fault, and the clearing count holds under operation that
    would not show it. Before: `cleared` at 174.8 s under 3 Hz operation (never measured).
    Removed at 130 s instead: `cleared` at 139.4 s."""
    events = _changing_operation({"fault": "supply_pressure", "value": 0.6}, seed=7)
    assert _kinds(events) == ["fault_detected"]
    assert events[-1]["path"] == "drift"
    removed = _changing_operation(
        {"fault": "supply_pressure", "value": 0.6},
        seed=7,
        removed={"fault": "supply_pressure", "value": 1.0},
    )
    assert _kinds(removed) == ["fault_detected", "cleared"]
    assert removed[-1]["t"] < 150.0


@pytest.mark.slow
def test_a_weakened_drive_restored_under_changing_operation_is_cleared():
    """The valve at 40 % from 120 s to 130 s (seed 6): cleared within 3 s of the repair."""
    events = [
        e
        for e in _changing_operation(
            {"fault": "valve_gain", "value": 0.4},
            duration_s=140.0,
            seed=6,
            removed={"fault": "valve_gain", "value": 1.0},
        )
        if e["kind"] != "calibrated"
    ]
    assert _kinds(events) == ["fault_detected", "other_fault", "cleared"]
    assert 130.0 < events[-1]["t"] < 133.0


@pytest.mark.parametrize(
    "fault,kind",
    [
        ({"bearing_supply": 0.0}, "friction_isolated"),
        ({"fault": "valve_gain", "value": 0.6}, "other_fault"),
    ],
)
def test_cleared_when_the_fault_goes_away(fault, kind):
    """Cleared once the fault has been gone for friction_clear_s (friction) or clear_s."""
    defaults = DetectorSettings()
    hold = defaults.friction_clear_s if kind == "friction_isolated" else defaults.clear_s
    off = {"bearing_supply": 1.0} if "bearing_supply" in fault else {**fault, "value": 1.0}
    events = _scenario(
        {
            "name": "onoff",
            "duration_s": 8.0 + hold + 6.0,
            "excitation": [SINE],
            "events": [{"t_s": 4.0, **fault}, {"t_s": 8.0, **off}],
        }
    )
    assert _kinds(events) == ["fault_detected", kind, "cleared"]
    assert 8.0 + hold < events[-1]["t"] < 8.0 + hold + 3.5


def test_a_steady_fault_is_not_cleared_where_the_high_pass_level_vanishes():
    """The shipped (high-pass) model under changing operation: at 1.5-3.7 Hz θ1 reads 0.05
    of the fault, but the residual against the pre-fault reference still shows it, so the
    episode stays open (before, it was cleared at 100 s and raised again at 109.5 s)."""
    events = Monitor(sim_rig_model()).run(scenario_recording("steady_friction_changing_operation"))[
        0
    ]
    assert _kinds(events) == ["fault_detected", "friction_isolated"]


@pytest.mark.parametrize("supply", [0.3, 0.62])
def test_friction_removed_under_changing_operation_is_cleared(supply):
    """Friction from 30 s to 90 s under random 1-9 Hz operation: the frozen reference was
    fitted on other operation than the one after the fault, and still clears it."""
    hold = DetectorSettings().friction_clear_s
    events = _scenario(
        {
            "name": "removed",
            "duration_s": 90.0 + hold + 10.0,
            "excitation": [
                {
                    "kind": "random",
                    "amplitude_v": [0.8, 1.6],
                    "frequency_hz": [1.0, 9.0],
                    "segment_s": [5.0, 40.0],
                }
            ],
            "events": [
                {"t_s": 30.0, "bearing_supply": supply},
                {"t_s": 90.0, "bearing_supply": 1.0},
            ],
        },
        seed=0,
    )
    kinds = _kinds(events)
    assert kinds[0] == "fault_detected" and "friction_isolated" in kinds
    assert kinds[-1] == "cleared" and kinds.count("cleared") == 1
    assert 90.0 + hold < events[-1]["t"] < 90.0 + hold + 3.0


@pytest.mark.parametrize(
    "fault,kind",
    [
        ({"bearing_supply": 0.35}, "friction_isolated"),
        ({"fault": "accel_dropout", "value": 1.0}, "other_fault"),
    ],
)
def test_a_fault_is_not_cleared_while_the_rig_rests(fault, kind):
    """Start-stop operation (8 Hz bursts of 5 s, 3 s at rest): at rest nothing shows the
    fault, nor its absence, so the episode stays open through the rests. Before, the
    friction episode was cleared 2 s into the first rest and found again after it."""
    burst = [{**SINE, "duration_s": 5.0}, {"kind": "zero", "duration_s": 3.0}]
    events = _scenario(
        {
            "name": "bursts",
            "duration_s": 40.0,
            "excitation": burst * 5,
            "events": [{"t_s": 10.0, **fault}],
        }
    )
    assert _kinds(events) == ["fault_detected", kind]
    assert 10.0 <= events[1]["t"] < 10.1


@pytest.mark.slow
@pytest.mark.parametrize(
    "excitation",
    [
        [{"kind": "steps", "levels_v": [1.0, -1.0], "hold_s": 0.25, "duration_s": 300.0}],
        [{"kind": "steps", "levels_v": [0.8, -0.8], "hold_s": 1.0, "duration_s": 300.0}],
        [
            {
                "kind": "steps",
                "levels_v": [0.3, -0.5, 0.9, -0.2, 0.6, -1.0, 0.1],
                "hold_s": 0.4,
                "duration_s": 300.0,
            }
        ],
        [{**SINE, "duration_s": 5.0}, {"kind": "zero", "duration_s": 3.0}] * 30,
        [
            {"kind": "sine", "amplitude_v": 0.6, "frequency_hz": 6.0, "duration_s": 7.0},
            {"kind": "zero", "duration_s": 2.0},
        ]
        * 30,
    ],
    ids=["square_2hz", "square_0.5hz", "random_steps", "bursts_8hz", "bursts_6hz_low"],
)
def test_operation_unlike_the_fault_free_hour_raises_no_alarm(excitation):
    """Fault-free regimes the detector was not tuned on (the fault-free hour holds sines,
    multisines and chirps only): square waves, level steps, start-stop bursts; 4-5 min each."""
    duration = sum(segment["duration_s"] for segment in excitation)
    events = _scenario(
        {
            "name": "unseen",
            "duration_s": duration,
            "centring_gain_v_per_m": 30.0,
            "excitation": excitation,
        },
        seed=0,
    )
    assert _kinds(events) == []
