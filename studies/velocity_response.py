"""Gain and phase of the velocity estimates against the simulator's true velocity, per
frequency (docs/detector.md, §1 "Velocity"). Run: ``python studies/velocity_response.py``.

The default simulated rig (fault-free, seal friction only) is driven by one sine per
frequency; over the last whole periods of each run the fundamental of v̂ is divided by
that of the true velocity (least squares on cos/sin). The plant model is the shipped one
(configs/model_sim_rig.yaml: Ĝ identified from a 1.5–18.8 Hz chirp, so at 0.5–1 Hz it is
an extrapolation), which is what the observer's model path runs on.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
FREQUENCIES_HZ = (0.5, 1.0, 2.0, 3.0, 5.0, 8.0, 10.0)


def _fundamental(x, t, f):
    w = 2 * math.pi * f
    basis = np.column_stack([np.cos(w * t), np.sin(w * t)])
    c, s = np.linalg.lstsq(basis, x, rcond=None)[0]
    return complex(c, -s)


def response(f_hz: float, amplitude_v: float = 1.0, settle_s: float = 6.0, seed: int = 0):
    """{estimator: (gain, phase error °)} of v̂/v_true at f_hz on the default rig."""
    from fdi_daemon.core.iir import IIRFilter
    from fdi_daemon.core.velocity import VelocityEstimator
    from fdi_daemon.core.velocity_observer import ModelVelocityObserver
    from fdi_daemon.core.velocity_position import PositionVelocityObserver
    from fdi_daemon.io.model_file import load_model
    from hil_sim.scenarios import scenario_from_dict, simulate

    periods = max(4, int(math.ceil(4 * f_hz)))
    duration = settle_s + periods / f_hz
    rec = simulate(
        scenario_from_dict(
            {
                "name": "velocity_response",
                "duration_s": duration,
                "seed": seed,
                "centring_gain_v_per_m": 30.0,
                "excitation": [{"kind": "sine", "amplitude_v": amplitude_v, "frequency_hz": f_hz}],
            }
        )
    )
    model = load_model(REPO / "configs" / "model_sim_rig.yaml")
    xhat = IIRFilter(model.plant_b, model.plant_a).run(rec.v_in)
    estimates = {
        "highpass": VelocityEstimator(model.fs).run(rec.accel),
        "model_observer": ModelVelocityObserver(model.fs).run(rec.accel, xhat),
        "position_observer": PositionVelocityObserver(model.fs, crossover_hz=15.0).run(
            rec.accel, rec["position"]
        ),
    }
    last = rec.t >= rec.t[-1] - periods / f_hz + 0.5 / model.fs
    truth = _fundamental(rec.columns["velocity_true"][last], rec.t[last], f_hz)
    out = {}
    for name, v in estimates.items():
        ratio = _fundamental(v[last], rec.t[last], f_hz) / truth
        out[name] = (abs(ratio), math.degrees(np.angle(ratio)))
    return out


def table(frequencies=FREQUENCIES_HZ) -> dict[float, dict[str, tuple[float, float]]]:
    return {f: response(f) for f in frequencies}


if __name__ == "__main__":
    print(
        "| f (Hz) | high-pass gain | phase | model observer gain | phase | "
        "position observer (15 Hz) gain | phase |"
    )
    print("|---|---|---|---|---|---|---|")
    for f, row in table().items():
        cells = " | ".join(f"{g:.3f} | {p:+.1f}°" for g, p in row.values())
        print(f"| {f:g} | {cells} |")
