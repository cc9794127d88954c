"""Does `fdi diagnose` give the same answer when the plant model moves by rounding? (issue 42,
property 3; docs/diagnose.md §9). Run: ``python studies/diagnose_plant_rounding.py [DRAWS]``
(about 7 s per diagnosis; the default 8 draws of two cases: two minutes).

The simulated rig's records of `tests/diagnose_cases.rig_recording` (seed 4, 0.8 V RMS 1–12 Hz
multisine, 40 s) with the seal's friction changed, diagnosed against the shipped model's Ĝ
and against Ĝ with each coefficient times (1 + 1e-12·n), n standard normal (seeded per
draw; draw 0 is the model as shipped). Changes of that size come from rounding: the shipped
Ĝ of 2026-11-29 and the one before it, made by the same `fdi identify` command on the same
chirp at another time, differ by up to 2e-11 relative in a coefficient. Prints per case and
draw the named effects and the held-out gap after, then the number of distinct outcomes:
one, where the diagnosis is a property of the data. The first line names OpenBLAS's kernel
(``OPENBLAS_CORETYPE=Haswell python studies/...`` to choose it: this script loads NumPy
before `fdi_daemon`, whose pin then does nothing).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

#: relative size of the perturbation of each of Ĝ's coefficients
ROUNDING = 1e-12
#: label -> the rig's seal friction (Coulomb N, static N)
CASES = {"seal pure Coulomb 0.5 N": (0.5, 0.5), "seal Coulomb 3 N, static 3.5 N": (3.0, 3.5)}


def perturbed(b: np.ndarray, a: np.ndarray, draw: int) -> tuple[np.ndarray, np.ndarray]:
    """Ĝ's coefficients times (1 + ROUNDING·n), a monic A kept monic; draw 0: as given."""
    if draw == 0:
        return b, a
    rng = np.random.default_rng(draw)
    b = b * (1.0 + ROUNDING * rng.standard_normal(b.size))
    a = a * (1.0 + ROUNDING * rng.standard_normal(a.size))
    a[0] = 1.0
    return b, a


def main(draws: int) -> None:
    from threadpoolctl import threadpool_info

    from fdi_daemon.diagnose.workflow import run_diagnose
    from tests.diagnose_cases import RIG_FS, rig_model, rig_recording

    kernels = {i.get("architecture") for i in threadpool_info() if i["internal_api"] == "openblas"}
    print(f"OpenBLAS kernel: {', '.join(sorted(map(str, kernels)))}", flush=True)
    b, a = rig_model()
    for label, (coulomb_n, static_n) in CASES.items():
        u, y = rig_recording(
            rms_v=0.8,
            duration_s=40.0,
            variant=(("seal_coulomb_n", coulomb_n), ("seal_static_n", static_n)),
        )
        outcomes = set()
        for draw in range(draws):
            result = run_diagnose(u, y, RIG_FS, "acceleration", *perturbed(b, a, draw))
            outcome = (", ".join(result.named) or "nothing", round(result.gap_after, 4))
            outcomes.add(outcome)
            print(f"{label}, draw {draw}: {outcome[0]}, gap after {outcome[1]}", flush=True)
        print(f"{label}: {len(outcomes)} distinct outcome(s) in {draws} draws\n", flush=True)


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 8)
