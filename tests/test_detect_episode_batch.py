"""Alarm episodes in the batch path: the episode's arithmetic and decisions run in the
compiled kernel (`detect.episode_kernel`), so a replay of an incident hands Python only the
ticks that raise events, and stays bit-equal to the per-tick path (gaps included)."""

import functools

import numpy as np
import pytest
from conftest_detect import model_copy, scenario_recording, sim_rig_model

from fdi_daemon.detect.detector import STATES, Detector
from fdi_daemon.detect.monitor import Monitor
from fdi_daemon.io.recordings import Recording
from fdi_daemon.io.sample import Sample


@functools.cache
def _incident():
    """240 s of changing operation with friction creeping in (the bench's incident)."""
    from fdi_daemon.bench.incident import creeping_fault_scenarios
    from hil_sim.scenarios import simulate

    return simulate(creeping_fault_scenarios(240.0, seed=0)[1])


def _stepped(monitor, rec):
    seq = np.asarray(rec.columns.get("seq", np.arange(len(rec))))
    events, stat, state, theta1 = [], [], [], []
    for k in range(len(rec)):
        events.extend(
            monitor.step(
                Sample(int(seq[k]), float(rec.t[k]), float(rec.v_in[k]), float(rec.accel[k]))
            )
        )
        det = monitor.detector
        stat.append(det.statistic)
        state.append(STATES.index(det.state))
        theta1.append(det.theta1)
    events.extend(monitor.finish())
    return events, np.array(stat), np.array(state), np.array(theta1)


def _count_decisions(monkeypatch):
    calls = []
    original = Detector.decide

    def spy(self, code, t):
        calls.append(code)
        return original(self, code, t)

    monkeypatch.setattr(Detector, "decide", spy)
    return calls


def test_an_incident_replays_with_python_only_on_event_ticks(monkeypatch):
    rec = _incident()
    calls = _count_decisions(monkeypatch)
    events, trace = Monitor(sim_rig_model()).run(rec)
    episode_states = np.isin(
        trace.state,
        [STATES.index(s) for s in ("fault_detected", "friction_isolated", "other_fault")],
    )
    assert any(e["kind"] == "fault_detected" for e in events)
    assert episode_states.sum() > 20 * 256  # many seconds inside episodes ...
    detector_events = [e for e in events if e["kind"] not in ("bad_sample", "data_gap")]
    assert len(calls) == len(detector_events)  # ... and Python saw only the events


def test_an_incident_is_bit_equal_per_tick_and_batch():
    rec = _incident()
    ev_step, stat, state, theta1 = _stepped(Monitor(sim_rig_model()), rec)
    ev_batch, trace = Monitor(sim_rig_model()).run(rec)
    assert ev_batch == ev_step
    np.testing.assert_array_equal(trace.statistic, stat)
    np.testing.assert_array_equal(trace.state, state)
    np.testing.assert_array_equal(trace.theta1, theta1)


@pytest.mark.parametrize("method", ["sequential", "band"])
def test_a_gap_inside_an_episode_is_handled_alike(method):
    """A data gap while an episode runs restarts its windows (the episode goes on)."""
    rec = scenario_recording("test_case_2" if method == "sequential" else "test_case_1")
    model = (
        sim_rig_model()
        if method == "sequential"
        else model_copy(detector={**(sim_rig_model().detector or {}), "method": "band"})
    )
    _, trace = Monitor(model).run(rec)
    k = int(np.flatnonzero(trace.state >= STATES.index("fault_detected"))[0])
    keep = np.ones(len(rec), dtype=bool)
    keep[k + 40 : k + 60] = False  # 20 samples lost during the episode
    cols = {name: np.asarray(v)[keep] for name, v in rec.columns.items()}
    if "seq" not in cols:
        cols["seq"] = np.flatnonzero(keep)
    gappy = Recording(cols, dict(rec.meta))
    ev_step, stat, state, _ = _stepped(Monitor(model), gappy)
    ev_batch, trace = Monitor(model).run(gappy)
    assert any(e["kind"] == "data_gap" for e in ev_batch)
    assert ev_batch == ev_step
    np.testing.assert_array_equal(trace.statistic, stat)
    np.testing.assert_array_equal(trace.state, state)
