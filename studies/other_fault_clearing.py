"""Is a fault other than friction cleared while it is still there? (docs/detector.md §3,
"Clearing"). Run: ``python studies/other_fault_clearing.py [SEEDS]`` (default 4-9, about
two minutes).

Random operation (0.3-1.6 V, 1-12 Hz, segments of 5-60 s, as
`tests/test_detect_sim_rig.py::_changing_operation`) on the simulated rig with the shipped
model; a weakened drive (valve gain, supply pressure) or an accelerometer bias from 120 s,
either to the end at 200 s (persistent: it must never be cleared) or until 130 s (removed:
it must be cleared after 130 s). Prints per fault the persistent runs cleared while the
fault was there, and the removed runs' clearing times after the removal.
"""

from __future__ import annotations

import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
for path in (REPO, REPO / "tests"):
    if str(path) not in sys.path:
        sys.path.insert(0, str(path))

#: label -> (fault event, the event that removes it)
FAULTS = {
    "valve 10 %": ({"fault": "valve_gain", "value": 0.1}, {"fault": "valve_gain", "value": 1.0}),
    "valve 40 %": ({"fault": "valve_gain", "value": 0.4}, {"fault": "valve_gain", "value": 1.0}),
    "valve 60 %": ({"fault": "valve_gain", "value": 0.6}, {"fault": "valve_gain", "value": 1.0}),
    "supply 30 %": (
        {"fault": "supply_pressure", "value": 0.3},
        {"fault": "supply_pressure", "value": 1.0},
    ),
    "supply 60 %": (
        {"fault": "supply_pressure", "value": 0.6},
        {"fault": "supply_pressure", "value": 1.0},
    ),
    "accel bias 0.5": (
        {"fault": "accel_bias", "value": 0.5},
        {"fault": "accel_bias", "value": 0.0},
    ),
}
ONSET_S, REMOVED_S, END_S = 120.0, 130.0, 200.0


def events(model, seed: int, fault: dict, removal: dict | None) -> list[dict]:
    """The monitor's events (calibration left out) on one run."""
    from conftest_detect import changing_operation_spec

    from fdi_daemon.detect.monitor import Monitor
    from hil_sim.scenarios import scenario_from_dict, simulate

    timed = [{"t_s": ONSET_S, **fault}] + ([{"t_s": REMOVED_S, **removal}] if removal else [])
    spec = changing_operation_spec(timed, END_S)
    out = Monitor(model).run(simulate(scenario_from_dict(spec), seed=seed))[0]
    return [e for e in out if e["kind"] != "calibrated"]


def main(seeds: list[int]) -> None:
    from conftest_detect import sim_rig_model

    model = sim_rig_model()
    print(
        f"seeds {seeds[0]}-{seeds[-1]}; persistent from {ONSET_S:g} s to {END_S:g} s, "
        f"removed at {REMOVED_S:g} s"
    )
    for label, (fault, removal) in FAULTS.items():
        early, late, missed = [], [], []
        for seed in seeds:
            kept = events(model, seed, fault, None)
            early += [f"{seed}:+{e['t'] - ONSET_S:.2f}" for e in kept if e["kind"] == "cleared"]
            gone = events(model, seed, fault, removal)
            cleared = [
                e["t"] - REMOVED_S for e in gone if e["kind"] == "cleared" and e["t"] > REMOVED_S
            ]
            detected = any(e["kind"] == "fault_detected" for e in gone)
            if cleared:
                late.append(f"{seed}:+{cleared[0]:.1f}")
            elif detected:
                missed.append(str(seed))
        print(
            f"{label:15s} persistent cleared: {', '.join(early) or 'never'}; "
            f"removed, cleared after: {', '.join(late) or '-'}"
            f"{'; never cleared: seeds ' + ', '.join(missed) if missed else ''}",
            flush=True,
        )


if __name__ == "__main__":
    arg = sys.argv[1] if len(sys.argv) > 1 else "4-9"
    lo, _, hi = arg.partition("-")
    main(list(range(int(lo), int(hi or lo) + 1)))
