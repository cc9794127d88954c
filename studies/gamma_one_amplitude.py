"""Is γ_f identifiable from issue 12's one-amplitude four-tone calibration? (docs/identification.md,
"γ_f from one amplitude"). Run: ``python studies/gamma_one_amplitude.py`` (about two minutes).

The four-tone run (2, 3.3, 5, 8 Hz at 0.45 V, bearing supply 45 % from 4 s; `fdi signature`
window 5-20 s) is simulated twice, with and without the fault; the difference of the
noise-free accelerations is what the fault alone did (no model error, no noise). Each line is
the cost profile of eq. (13) as `fdi signature` fits it (G_e a free [4 3 0] output-error
filter, γ on a grid), with the simulator's true velocity, for:

- the fault's own acceleration; and the same with the force that holds the stuck load
  (the simulator's stuck flag) left free, estimated by least squares; and that fit on what
  `fdi signature` sees, the measured residual r = ẍ − Ĝ v_in, with the true velocity and
  stuck flag, and with the observer's v̂ and the sticks found where the accelerometer is quiet;
- a control: the shipped G_e driven by sign v + 3.33 v (5 % noise);
- the shipped G_e driven by the simulator's contact friction force, as it is, and set to 0
  while the load is stuck (then the force is a function of v only);
- the shipped G_e driven by the contact friction without its Stribeck excess;
- no G_e at all: the friction force itself against c·(sign v + γ v) while sliding.

Each line: the γ of least cost, the cost at 0, 2, 3.33 and 5 relative to the least, and the share
of the signal explained. The simulator's μ_k and c_v give γ = c_v/μ_k = 3.33 s/m.
"""

from __future__ import annotations

import copy
import sys
from pathlib import Path

import numpy as np
from scipy import signal

REPO = Path(__file__).resolve().parents[1]
FS = 256.0
WINDOW_S = (5.0, 20.0)
GRID = np.arange(0.0, 10.001, 0.25)
SHOWN = (0.0, 2.0, 3.33, 5.0)


def _profile_line(label: str, grid: np.ndarray, sse: np.ndarray, spread: float) -> str:
    rel = sse / sse.min()
    at = "  ".join(f"{g:g}: {np.interp(g, grid, rel):.3f}" for g in SHOWN)
    return (
        f"{label:<44} least cost at γ {grid[np.argmin(sse)]:5.2f}; relative cost {at}; "
        f"explained {100 * (1 - sse.min() / spread):.1f} %"
    )


def _free_stick_profile(
    accel: np.ndarray, velocity: np.ndarray, stuck: np.ndarray, grid: np.ndarray
) -> np.ndarray:
    """Σe² per γ of r = G_e (x_f + s), x_f = sign v + γ v while sliding, s free while stuck
    (the force that holds the load): G_e [4 3 0] by output error given s, s by least squares
    given G_e, alternated eight times from s = 0, each γ warm-started from its neighbour."""
    from scipy.linalg import toeplitz

    from fdi_daemon.ident.output_error import fit_output_error

    held = np.flatnonzero(stuck)
    pulse = np.r_[1.0, np.zeros(len(accel) - 1)]
    start, sse = None, []
    for gamma in grid:
        sliding = np.where(stuck, 0.0, np.sign(velocity) + gamma * velocity)
        hold = np.zeros(len(accel))
        for _ in range(8):
            fit = fit_output_error(sliding + hold, accel, 4, 3, 0, start=start)
            start = (fit.b, fit.f)
            response = signal.lfilter(fit.b, fit.f, pulse)
            on_held = toeplitz(response, np.zeros(len(accel)))[:, held]
            hold[held] = np.linalg.lstsq(
                on_held, accel - fit.y_sim + on_held @ hold[held], rcond=None
            )[0]
        fit = fit_output_error(sliding + hold, accel, 4, 3, 0, start=start)
        sse.append(fit.sse)
    return np.array(sse)


def _measured(fault: dict, window: slice, model):
    """What `fdi signature` has instead: r = ẍ − Ĝ v_in of the measured acceleration over the
    window (``model``: the shipped model, made on this rig), and (label, velocity, stuck rows) with the
    true velocity and stuck flag, and with the model observer's v̂ and the rows where the
    accelerometer is quiet (`stick_window_oracle.quiet_rows`)."""
    from stick_window_oracle import quiet_rows

    from fdi_daemon.core.velocity_observer import velocity_from_settings
    from fdi_daemon.diagnose.augment import nominal_plant
    from fdi_daemon.ident.signature import plant_residual

    accel = np.asarray(fault["accel"], float)
    residual = plant_residual(nominal_plant(model), fault["v_in"], accel)
    observer = velocity_from_settings({"method": "model_observer"}, fs_hz=FS)
    found = quiet_rows(accel)
    return residual[window], (
        (
            "measured r, true v and stuck, hold free",
            fault["velocity_true"],
            fault["stuck"][window] > 0.5,
        ),
        (
            "measured r, observer v̂, quiet ẍ, hold free",
            observer.run(accel, accel - residual),
            found[window],
        ),
    )


def main() -> None:
    sys.path.insert(0, str(REPO / "tests"))
    sys.path.insert(0, str(REPO))
    from test_detect_friction_level import LOW_FREQUENCY_CALIBRATION

    from fdi_daemon.ident.signature import estimate_signature
    from fdi_daemon.io.model_file import load_model
    from hil_sim.scenarios import scenario_from_dict, simulate

    model = load_model(REPO / "fdi_daemon" / "data" / "model_sim_rig.yaml")
    fault = simulate(scenario_from_dict(LOW_FREQUENCY_CALIBRATION)).columns
    spec = copy.deepcopy(LOW_FREQUENCY_CALIBRATION)
    spec["events"] = []
    healthy = simulate(scenario_from_dict(spec)).columns
    first, end = (int(t * FS) for t in WINDOW_S)
    v = fault["velocity_true"]
    by_fault = fault["accel_true"] - healthy["accel_true"]
    window = slice(first, end)
    spread = float(np.sum((by_fault[window] - by_fault[window].mean()) ** 2))
    print(f"stuck {100 * fault['stuck'][window].mean():.0f} % of the window")

    sig = estimate_signature(by_fault[:end], v[:end], grid=GRID, fit_from=first)
    print(_profile_line("the fault's own acceleration", GRID, sig.sse, spread))
    coarse = GRID[::2]
    sse = _free_stick_profile(by_fault[window], v[window], fault["stuck"][window] > 0.5, coarse)
    print(_profile_line("... the holding force free while stuck", coarse, sse, spread))
    residual, rows = _measured(fault, window, model)
    for label, velocity, stuck in rows:
        sse = _free_stick_profile(residual, velocity[window], stuck, coarse)
        r_spread = float(np.sum((residual - residual.mean()) ** 2))
        print(_profile_line(label, coarse, sse, r_spread))

    g_e = model.fault_filter
    noise = np.random.default_rng(0).standard_normal(len(v))
    stuck = fault["stuck"] > 0.5
    contact = fault["contact_force"]
    for label, force in (
        ("control: sign v + 3.33 v through G_e", -(np.sign(v) + 3.33 * v)),
        ("the friction force through G_e", fault["friction_force"]),
        ("... set to 0 while the load is stuck", fault["friction_force"] * ~stuck),
        ("μ_k N sign v + c_v N v through G_e", 0.30 * contact * np.sign(v) + 1.0 * contact * v),
    ):
        seen = signal.lfilter(g_e.b, g_e.f, -force)
        seen += 0.05 * np.std(seen[window]) * noise
        sig = estimate_signature(seen[:end], v[:end], grid=GRID, fit_from=first)
        spread = float(np.sum((seen[window] - seen[window].mean()) ** 2))
        print(_profile_line(label, GRID, sig.sse, spread))

    force = fault["friction_force"][window]
    sliding = fault["stuck"][window] < 0.5
    sse = []
    for gamma in GRID:
        x = (np.sign(v) + gamma * v)[window][sliding]
        e = force[sliding] - x * (x @ force[sliding]) / (x @ x)
        sse.append(float(e @ e))
    f_spread = float(np.sum((force[sliding] - force[sliding].mean()) ** 2))
    print(_profile_line("the friction force itself, sliding", GRID, np.array(sse), f_spread))


if __name__ == "__main__":
    main()
