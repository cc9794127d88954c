"""How rough is the force loop's training error around the fits `fdi diagnose` makes? (issue
42, property 3; docs/diagnose.md §9). Run: ``python studies/diagnose_loop_roughness.py``
(about a minute).

The rig's seal friction records of `studies/diagnose_plant_rounding.py` (0.5 N pure Coulomb;
3 N Coulomb with 3.5 N static), diagnosed once; for the first fit of the candidate
``coulomb_friction`` on the base (``loop_stiffness``, ``linear_refit``), at the parameters of
each stage of `force.in_the_loop` (1: the feed-forward start, 3: the passes, 4: the joint
fit), the loop's training SSE is evaluated again with every parameter times (1 + ε·n), n
standard normal (six draws, seeded), and the largest relative change printed per ε. A
smooth optimum changes by about ε·(its gradient terms), 1e-12 → ~1e-12; where a change of
1e-8 (the finite-difference step of the joint fit's Jacobian) moves the SSE by 1e-2, the
Jacobian is noise and the fit's path is picked by rounding. Also prints the loop's spring
numerator (B_x of ``loop_stiffness``) at each stage.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

#: relative parameter perturbations tried
EPSILONS = (1e-12, 1e-8, 1e-6, 1e-4)
#: the fit looked at
EFFECTS = ["loop_stiffness", "linear_refit", "coulomb_friction"]


def capture_stages(force) -> dict:
    """Wrap `force._LoopFit`'s stages to keep (fit, θ_ff, B_F) of the first fit of EFFECTS."""
    kept: dict = {}
    fit_class = force._LoopFit
    start, refine, joint = fit_class.feed_forward_start, fit_class.refine, fit_class.joint_fit

    def ours(loop) -> bool:
        return [e.name for e in loop.effects] == EFFECTS

    def feed_forward_start(loop, b_path):
        theta = start(loop, b_path)
        if ours(loop) and "1 start" not in kept:
            nums = np.outer(theta[loop.n_ff :], b_path)
            kept["1 start"] = (loop, theta[: loop.n_ff].copy(), nums)
        return theta

    def passes(loop, best_ff, best_nums):
        out = refine(loop, best_ff, best_nums)
        if ours(loop) and "3 passes" not in kept:
            kept["3 passes"] = (loop, out[1].copy(), out[2].copy())
        return out

    def joint_fit(loop, *fit):
        out = joint(loop, *fit)
        if ours(loop) and "4 joint" not in kept:
            kept["4 joint"] = (loop, out[1].copy(), out[2].copy())
        return out

    fit_class.feed_forward_start = feed_forward_start
    fit_class.refine = passes
    fit_class.joint_fit = joint_fit
    return kept


def roughness(loop, theta_ff: np.ndarray, nums: np.ndarray, rng) -> list[float]:
    """Per ε of EPSILONS: the largest |SSE(θ(1 + εn))/SSE(θ) − 1| over six draws."""
    sse0 = loop.run(theta_ff, nums)[1]
    theta = np.concatenate([theta_ff, nums.ravel()])
    out = []
    for eps in EPSILONS:
        changes = []
        for _ in range(6):
            t = theta * (1.0 + eps * rng.standard_normal(theta.size))
            sse = loop.run(t[: loop.n_ff], t[loop.n_ff :].reshape(nums.shape))[1]
            changes.append(abs(sse / sse0 - 1.0))
        out.append(max(changes))
    return out


def main() -> None:
    from fdi_daemon.diagnose import force
    from fdi_daemon.diagnose.workflow import run_diagnose
    from studies.diagnose_plant_rounding import CASES
    from tests.diagnose_cases import RIG_FS, rig_model, rig_recording

    print("relative change of the loop's training SSE under parameters × (1 + ε n)")
    for label, (coulomb_n, static_n) in CASES.items():
        kept = capture_stages(force)
        u, y = rig_recording(
            rms_v=0.8,
            duration_s=40.0,
            variant=(("seal_coulomb_n", coulomb_n), ("seal_static_n", static_n)),
        )
        run_diagnose(u, y, RIG_FS, "acceleration", *rig_model())
        rng = np.random.default_rng(0)
        print(label)
        for stage, (loop, theta_ff, nums) in kept.items():
            rough = roughness(loop, theta_ff, nums, rng)
            cells = "  ".join(f"ε {e:g}: {r:.1e}" for e, r in zip(EPSILONS, rough))
            spring = np.round(nums[0], 3).tolist()
            print(f"  {stage:9s} {cells}   loop spring B_x {spring}", flush=True)


if __name__ == "__main__":
    main()
