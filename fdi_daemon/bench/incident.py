"""Replay speed of an incident against a quiet recording of the same length (`fdi bench`).

A user replays the recording of an incident, not a quiet one, so the batch path must be as
fast while an alarm episode runs. Both recordings come from the simulated rig under the same
changing operation (random sines, multisines and chirps, 0.8–1.6 V, 1–9 Hz) and seed:

- quiet: fault-free throughout;
- incident: friction creeping in (the air-bearing supply falls from 100 % to 45 %, the
  signature run's fault, over the middle third) and staying to the end.

Both are replayed with the built-in simulated rig's model (`fdi_daemon/data`), as
``fdi replay`` does, side by side (`bench.side_by_side`), and timed in wall-clock and
process-CPU seconds.
"""

from __future__ import annotations

import numpy as np

#: the bearing supply of the signature's calibration fault (configs/scenarios)
FAULT_BEARING_SUPPLY = 0.45


def creeping_fault_scenarios(duration_s: float, seed: int = 0):
    """(quiet, incident) scenarios of ``duration_s`` seconds (see the module docstring)."""
    from hil_sim.scenarios import scenario_from_dict

    base = {
        "duration_s": float(duration_s),
        "seed": int(seed),
        "centring_gain_v_per_m": 30.0,
        "excitation": [
            {
                "kind": "random",
                "amplitude_v": [0.8, 1.6],
                "frequency_hz": [1.0, 9.0],
                "segment_s": [5.0, 40.0],
            }
        ],
    }
    third = duration_s / 3.0
    ramp = {
        "bearing_supply": {
            "times_s": [0.0, third, 2 * third, duration_s],
            "values": [1.0, 1.0, FAULT_BEARING_SUPPLY, FAULT_BEARING_SUPPLY],
        }
    }
    return (
        scenario_from_dict({**base, "name": "bench_quiet"}),
        scenario_from_dict({**base, "name": "bench_creeping_fault", "drift": ramp}),
    )


def _figures(rec, wall_s: float, cpu_s: float, events: list) -> dict:
    return {
        "samples": len(rec),
        "wall_s": wall_s,
        "cpu_s": cpu_s,
        "samples_per_s": len(rec) / wall_s,
        "samples_per_cpu_s": len(rec) / cpu_s,
        "alarm_episodes": sum(e["kind"] == "fault_detected" for e in events),
    }


def bench_incident_replay(duration_s: float = 1800.0, seed: int = 0, passes: int = 3) -> dict:
    """Replay the quiet and the incident recording side by side (`bench.side_by_side`),
    ``passes`` times, each by new monitors; returns both figures (medians over the passes)
    and their ratio."""
    from fdi_daemon.bench.side_by_side import BLOCK, side_by_side
    from fdi_daemon.detect.monitor import Monitor
    from fdi_daemon.io.model_file import load_model
    from fdi_daemon.service.config import default_config_path
    from hil_sim.scenarios import simulate

    model = load_model(default_config_path().with_name("model_sim_rig.yaml"))
    quiet_sc, incident_sc = creeping_fault_scenarios(duration_s, seed)
    quiet, incident = simulate(quiet_sc), simulate(incident_sc)
    Monitor(model).run(quiet.samples(slice(0, 4096)))  # load the compiled kernels first
    spent = []
    for _ in range(passes):
        monitors = {"quiet": Monitor(model), "incident": Monitor(model)}
        events: dict[str, list] = {"quiet": [], "incident": []}

        def replay(name, rec):
            return lambda part: events[name].extend(
                monitors[name].run(rec.samples(part), trace_every=BLOCK)[0]
            )

        spent.append(
            side_by_side([replay("quiet", quiet), replay("incident", incident)], len(quiet))
        )
    (q_wall, q_cpu), (i_wall, i_cpu) = np.median(spent, axis=0)
    q = _figures(quiet, q_wall, q_cpu, events["quiet"])
    i = _figures(incident, i_wall, i_cpu, events["incident"])
    return {
        "duration_s": float(duration_s),
        "passes": passes,
        "quiet": q,
        "incident": i,
        "incident_over_quiet": i["samples_per_s"] / q["samples_per_s"],
    }
