"""How right each velocity is after test case 2's bearing supply cut (docs/detector.md §4a).
Run: ``python studies/supply_cut_velocity.py`` (seconds).

Test case 2 on the default simulated rig (8 Hz sine, supply cut at 2.9 s, the load stuck
about a fifth of the time afterwards) against the simulator's true velocity from 3.5 to
6 s: sign agreement while the load moves, RMS error while it moves and RMS of v̂ while it
is stuck, for the high-pass estimator and the model observer at several residual-path
cut-offs (the plant model is the shipped one, exact before the fault and far off after).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]


def main() -> None:
    sys.path.insert(0, str(REPO / "tests"))
    from conftest_detect import scenario_recording, sim_rig_model

    from fdi_daemon.core.velocity_observer import velocity_from_settings
    from fdi_daemon.diagnose.augment import nominal_plant
    from fdi_daemon.ident.signature import plant_residual

    rec = scenario_recording("test_case_2")
    fs = rec.fs
    accel = rec.accel
    residual = plant_residual(nominal_plant(sim_rig_model()), rec.v_in, accel)
    truth = rec.columns["velocity_true"]
    after = (rec.t >= 3.5) & (rec.t < 6.0)
    stuck = after & (np.abs(truth) < 1e-4)
    moving = after & ~stuck
    print(
        f"stuck {stuck.sum() / after.sum():.0%} of 3.5-6 s; true velocity RMS "
        f"{1e3 * np.std(truth[after]):.1f} mm/s"
    )
    estimates = {"high-pass 1 Hz": velocity_from_settings({"method": "highpass"}, fs).run(accel)}
    for hz in (0.5, 0.2, 0.1, 0.05):
        block = velocity_from_settings(
            {"method": "model_observer", "highpass_hz": hz, "leak_hz": min(0.02, hz / 5)}, fs
        )
        estimates[f"observer {hz:g} Hz"] = block.run(accel, accel - residual)
    for name, v in estimates.items():
        sign = np.mean(np.sign(v[moving]) == np.sign(truth[moving]))
        error = 1e3 * np.sqrt(np.mean((v[moving] - truth[moving]) ** 2))
        held = 1e3 * np.sqrt(np.mean(v[stuck] ** 2))
        print(
            f"{name:16s} sign right while moving {sign:.1%}, error while moving "
            f"{error:.2f} mm/s, |v̂| while stuck {held:.2f} mm/s"
        )


if __name__ == "__main__":
    main()
