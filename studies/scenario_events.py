"""The detector's events on the scenarios of `configs/scenarios` (seeds 0 and 1), one line
each, to diff two versions of the code: a change meant to be faster must not move them
(docs/detector.md §6). Run: ``python studies/scenario_events.py > events.txt`` (a minute),
with each version (``git worktree``), then ``diff``.
"""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from conftest_detect import scenario_recording, sim_rig_model  # noqa: E402

from fdi_daemon.detect.monitor import Monitor  # noqa: E402

SCENARIOS = (
    "test_case_1",
    "test_case_2",
    "fault_accel_bias",
    "fault_valve_gain",
    "fault_supply_pressure",
    "fault_accel_saturation",
    "fault_accel_dropout",
    "steady_friction_changing_operation",
)


def main() -> None:
    for name in SCENARIOS:
        for seed in (0, 1):
            events, _ = Monitor(sim_rig_model()).run(
                scenario_recording(name, seed=seed), trace_every=64
            )
            kinds = [(e["kind"], round(e["t"], 4)) for e in events if e["kind"] != "calibrated"]
            print(name, seed, kinds)


if __name__ == "__main__":
    main()
