"""The real-time rig driver: same samples as the offline simulation, faults changeable live."""

import numpy as np
import pytest

from hil_sim.devices.realtime import ScheduledFault, realtime_rig
from hil_sim.scenarios import scenario_from_dict, simulate

SCENARIO = {
    "duration_s": 3.0,
    "centring_gain_v_per_m": 30.0,
    "excitation": [
        {"kind": "sine", "amplitude_v": 1.4, "frequency_hz": 8.0, "duration_s": 1.0},
        {
            "kind": "random",
            "amplitude_v": [0.5, 1.5],
            "frequency_hz": [2, 10],
            "segment_s": [0.3, 0.8],
        },
    ],
    "events": [
        {"t_s": 1.2, "bearing_supply": 0.4},
        {"t_s": 2.0, "fault": "accel_bias", "value": 0.5},
    ],
}


def drive(rt, seconds, rng):
    """Advance with a fake clock in random steps (late and early callers alike)."""
    now, out = 0.0, []
    rt.start(0.0)
    while now < seconds:
        now += float(rng.uniform(0.0, 0.05))
        out += rt.advance(now)
    return out


def test_realtime_rig_equals_the_offline_simulation_bit_for_bit():
    scenario = scenario_from_dict(SCENARIO)
    ref = simulate(scenario, seed=4)
    out = drive(realtime_rig(scenario, seed=4), 2.95, np.random.default_rng(0))
    n = len(out)
    assert n <= len(ref)
    assert n > 700
    assert [s.seq for s in out] == list(range(n))
    for name in ("t", "v_in", "accel", "position"):
        got = np.array([getattr(s, name) for s in out])
        np.testing.assert_array_equal(got, ref[name][:n], err_msg=name)
    injected = np.array([s.fault_injected for s in out])
    first_faulty = 308  # the first sample at or after 1.2 s: ceil(1.2 * 256)
    assert not injected[:first_faulty].any() and injected[first_faulty:].all()


def test_due_ticks_follow_the_clock():
    rt = realtime_rig(seed=0)
    rt.start(100.0)
    assert rt.due(100.0) == 1  # tick 0 is due at start
    assert rt.due(101.0) == 257
    assert len(rt.advance(100.5)) == 129
    assert rt.next_tick_time == pytest.approx(100.0 + 129 / 256)
    assert rt.advance(100.5) == []


def test_faults_changed_while_running_apply_at_the_next_tick():
    rt = realtime_rig(seed=1, faults=[ScheduledFault(0.5, "valve_gain", 0.5)])
    rt.start(0.0)
    rt.advance(0.25)
    rt.set_bearing_supply(0.3)
    assert rt.faults()["bearing_supply"] == 0.3 and rt.rig.bearing_supply == 1.0
    rt.advance(0.3)
    assert rt.rig.bearing_supply == 0.3
    rt.advance(0.6)
    assert rt.rig.fault("valve_gain") == 0.5
    with pytest.raises(ValueError):
        rt.set_fault("warp_drive", 1.0)
    with pytest.raises(ValueError):
        rt.set_fault("valve_gain", -1.0)
    with pytest.raises(ValueError):
        realtime_rig(seed=1, faults=[ScheduledFault(1.0, "nonsense", 0.0)])


def test_a_late_caller_gets_a_burst_not_a_hole():
    rt = realtime_rig(seed=2)
    rt.start(0.0)
    first = rt.advance(0.1)
    burst = rt.advance(5.0)  # five seconds late
    seqs = [s.seq for s in first + burst]
    assert seqs == list(range(len(seqs))) and len(seqs) == 1281
