"""The diagnose workflow end to end, in the order of the package's stages:

baseline and form of the test (`baseline`, `inverse`) -> noise floor and dead time
(`floor`) and localisation (`localize`) -> candidate effects by place (`input_effects`,
`force`, `output_effects`, fitted by `effects`) -> selection (`select`) -> report (`report`,
`plots`, `augment`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from threadpoolctl import threadpool_limits

from fdi_daemon.diagnose import signals
from fdi_daemon.diagnose.augment import AugmentedPlant
from fdi_daemon.diagnose.baseline import in_form, prepare
from fdi_daemon.diagnose.effects import BASE_TERMS, Context
from fdi_daemon.diagnose.floor import FLOOR_MARGIN, delay_by_correlation, noise_floor
from fdi_daemon.diagnose.inverse import noise_floor as inverse_floor
from fdi_daemon.diagnose.localize import localize
from fdi_daemon.diagnose.select import Selection, select_effects


@dataclass
class DiagnoseResult:
    ctx: Context
    info: dict
    selection: Selection
    plant: AugmentedPlant  # Ĝ + chosen effects
    y_measured: np.ndarray  # in the comparison domain
    y_before: np.ndarray
    y_after: np.ndarray
    gap_before: float
    gap_after: float
    where_before: dict
    where_after: dict

    @property
    def named(self) -> list[str]:
        return [e.named_as for e in self.selection.chosen if e.name not in BASE_TERMS]

    @property
    def ambiguous(self) -> list[dict]:
        """Rounds whose named effect did not beat another by the margin: ``effects`` [A, B],
        their held-out ``gaps``, the per-block gain and its spread (`select.margin`)."""
        return self.selection.ambiguous


@threadpool_limits.wrap(limits=1, user_api="blas")
def run_diagnose(
    u: np.ndarray,
    y: np.ndarray,
    fs_hz: float,
    output_kind: str = "acceleration",
    plant_b: np.ndarray | None = None,
    plant_a: np.ndarray | None = None,
    order: int | None = None,
    progress=None,
    form: str = "auto",
) -> DiagnoseResult:
    """plant_b/plant_a: Ĝ (acceleration) from a model file; None: fit a linear baseline
    (of ``order``, None: chosen from the data). form: see `baseline.prepare`.

    When ``auto`` finds a velocity or position record whose free run does not drift, the
    record is tested in both forms and the one whose named effects leave the smaller share
    of its own held-out gap is kept (a tie keeps the form the baseline suggested;
    ``form_reason`` gives both shares): a linear fit of closed-loop data or of a
    nonlinear system can look stable and still leave the effects nothing to explain in a
    free run (a stage under a position loop resting between moves), or bend a slow mode in
    that argues for the force balance when the simulation explains the data.

    The BLAS runs on one thread (``threadpool_limits``): OpenBLAS splits some sums by its
    thread count, which follows the machine's cores, and the loop fits follow those
    roundings (the rig's 3.4 N Coulomb friction under 0.4 V was named with an input
    saturation on one and on four threads, alone on two). The products are small,
    so one thread is also the fastest: that record 8.1 s on one thread, 10.8 s on two (a
    2-core machine, `git show b57fd1a:docs/diagnose.md` §9)."""
    y = np.asarray(y, float)
    ctx, info = prepare(u, y, fs_hz, output_kind, plant_b, plant_a, order, form)
    result = _diagnose(*in_form(ctx, info, y, info["form"]), y, progress)
    if not info.get("form_undecided"):
        return result
    other_form = "simulation" if info["form"] == "inverse_dynamics" else "inverse_dynamics"
    other = _diagnose(*in_form(ctx, info, y, other_form), y, progress)
    best = other if _left(other) < _left(result) else result
    simulated, balance = (result, other) if other_form == "inverse_dynamics" else (other, result)
    best.info["form_reason"] = (
        f"{result.info['form_reason']}: both forms were tested, the effects named left "
        f"{_left(simulated):.3g} of the simulation's gap and {_left(balance):.3g} of the "
        "force balance's, so the "
        + ("model is simulated" if best is simulated else "force balance is tested")
    )
    return best


def _left(result: DiagnoseResult) -> float:
    """The share of its held-out gap that a diagnosis leaves."""
    return result.gap_after / result.gap_before if result.gap_before > 0 else 1.0


def _diagnose(ctx: Context, info: dict, y: np.ndarray, progress) -> DiagnoseResult:
    """The workflow in one form of the test (`baseline.in_form`; module docstring)."""
    fs_hz = ctx.fs_hz
    simulated = ctx.form == "simulation"
    test = ctx.split.test
    y_meas = info["y_dom"]
    gap_before = signals.nrmse(y_meas[test], ctx.y0[test])
    floor = (
        noise_floor(y_meas, y_meas - ctx.y0, ctx.u, fs_hz, ctx.split.warmup, test)
        if simulated
        else inverse_floor(
            y,
            ctx.output_kind,
            ctx.u,
            ctx.target + ctx.y0,
            info["inverse_baseline"],
            ctx.lowpass,
            fs_hz,
            test,
        )
    )
    floor["at_floor"] = bool(
        floor["floor"] is not None and gap_before <= FLOOR_MARGIN * floor["floor"]
    )
    info["noise_floor"] = floor
    if simulated:
        fit = ctx.split.fit
        info["dead_time_by_correlation_s"] = delay_by_correlation(
            y_meas[fit], ctx.y0[fit], fs_hz, ctx.max_delay_samples
        )
    if floor["at_floor"]:  # nothing to find: the nominal model is as good as the noise
        selection = Selection([], [], np.zeros_like(ctx.target))
    else:
        floor_sse = (
            None
            if floor["floor"] is None
            else (FLOOR_MARGIN * floor["floor"]) ** 2
            * float(np.sum((y_meas[test] - np.mean(y_meas[test])) ** 2))
        )
        selection = select_effects(ctx, progress=progress, refit_linear=True, floor_sse=floor_sse)
    plant = AugmentedPlant(
        fs_hz,
        info["plant_b"],
        info["plant_a"],
        ctx.output_kind,
        info["highpass_hz"],
        selection.chosen if simulated else [],
        domain=info["domain"],
    )
    y_after = plant.run(ctx.u) if simulated else ctx.y0 + selection.prediction
    e_before = y_meas - ctx.y0
    e_after = y_meas - y_after
    return DiagnoseResult(
        ctx=ctx,
        info=info,
        selection=selection,
        plant=plant,
        y_measured=y_meas,
        y_before=ctx.y0,
        y_after=y_after,
        gap_before=gap_before,
        gap_after=signals.nrmse(y_meas[test], y_after[test]),
        where_before=localize(e_before, y_meas, ctx.u, ctx.v, ctx.x, fs_hz, test),
        where_after=localize(e_after, y_meas, ctx.u, ctx.v, ctx.x, fs_hz, test),
    )
