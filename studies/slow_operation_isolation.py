"""The calibrated fault stepped in under slow operation: what the episode says (issue 43,
docs/detector.md §3 "Isolation under slow operation (open)").

``python studies/slow_operation_isolation.py [default v0 v1 v2]`` (about 1 min per rig): the
signature's fault (bearing supply 45 %) stepped in at 8 s under single sines at 2.0, 2.9 and
6 Hz, 2.5 + 2.9 Hz and 1.2/2/2.9 Hz, seeds 4 and 5; prints each run's events after the
calibration (kind, time in s, path)."""

from __future__ import annotations

import sys
from pathlib import Path

sys.path[:0] = [
    str(Path(__file__).resolve().parent),
    str(Path(__file__).resolve().parents[1] / "tests"),
]

from growing_friction_detection import OPERATIONS, models, ramp_spec, replay  # noqa: E402

SLOW = {
    "sine 2.0 Hz": [{"kind": "multisine", "amplitudes_v": [0.8], "frequencies_hz": [2.0]}],
    "sine 2.9 Hz": [{"kind": "multisine", "amplitudes_v": [0.8], "frequencies_hz": [2.9]}],
    "2.5 + 2.9 Hz": [
        {"kind": "multisine", "amplitudes_v": [0.6, 0.6], "frequencies_hz": [2.5, 2.9]}
    ],
    "1.2/2/2.9 Hz": OPERATIONS["low 1.2/2/2.9 Hz"],
    "sine 6 Hz": [{"kind": "multisine", "amplitudes_v": [0.8], "frequencies_hz": [6.0]}],
}


def main(rigs: tuple[str, ...]) -> None:
    for rig_name, (rig, model) in models(rigs).items():
        for name, operation in SLOW.items():
            for seed in (4, 5):
                spec = ramp_spec(operation, rig, ramp_s=0.0, size=1.0, duration_s=24.0)
                events = [
                    (e["kind"], round(e["t"], 2), e.get("path"))
                    for e in replay(model, spec, seed)
                    if e["kind"] != "calibrated"
                ]
                print(f"{rig_name:8s} {name:14s} seed {seed}: {events}", flush=True)


if __name__ == "__main__":
    main(tuple(sys.argv[1:]) or ("default",))
