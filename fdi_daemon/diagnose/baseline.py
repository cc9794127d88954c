"""Simulate the nominal model: Ĝ from a model file, or a linear baseline fitted on the
training part of the recording (`--fit-linear`), and set up the fitting context.

The linear baseline is an output-error model (eq. 8 form, `fdi_daemon.ident.output_error`:
ARX start, Steiglitz–McBride, Levenberg–Marquardt with stability enforced) fitted in the
measured quantity's domain (order + n poles: the n leaky integrators of `signals`) and
converted back to acceleration for the model file. Output error, not ARX: with noise on the
measured output ARX is biased and the bias would show up as a spurious "missing effect".
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy import signal

from fdi_daemon.diagnose import signals
from fdi_daemon.diagnose.augment import AugmentedPlant
from fdi_daemon.diagnose.effects import EFFECT_NAMES, NAMED_BY_MODE, Context
from fdi_daemon.diagnose.force import s_roots
from fdi_daemon.errors import UserError


def measured_in_domain(y: np.ndarray, n: int, highpass_hz: float, fs_hz: float) -> np.ndarray:
    """Hⁿ y, started in steady state on y[0] (a position record need not start at 0)."""
    if n == 0:
        return np.asarray(y, float).copy()
    b, a = signals.measured_transform(n, highpass_hz, fs_hz)
    zi = signal.lfilter_zi(b, a) * y[0]
    return signal.lfilter(b, a, y, zi=zi)[0]


#: baseline orders tried when --order is not given
ORDER_CHOICES = (2, 4, 6, 8)


def _oe(u: np.ndarray, y: np.ndarray, order: int, n: int):
    from fdi_daemon.ident.output_error import fit_output_error

    nf = order + n
    return fit_output_error(u, y, nb=nf + 1, nf=nf, nk=0)


def choose_order(u: np.ndarray, y_dom: np.ndarray, n: int, split: signals.Split) -> int:
    """Baseline order from the data: fit each of ORDER_CHOICES on the first 3/4 of the
    training part, simulate the last 1/4 (from the fitted initial state onwards, warm-up
    excluded), and keep the lowest order within 2 % of the best validation NRMSE."""
    cut = int(split.train_end * 0.75)
    errors = {}
    for order in ORDER_CHOICES:
        oe = _oe(u[:cut], y_dom[:cut], order, n)
        y_sim = signal.lfilter(oe.b_delayed, oe.f, u[: split.train_end])
        settle = signals.settle_samples(oe.f, (split.train_end - cut) // 2)
        val = slice(cut + settle, split.train_end)
        errors[order] = signals.nrmse(y_dom[val], y_sim[val])
    best = min(errors.values())
    return min(o for o, e in errors.items() if e <= 1.02 * best)


def fit_linear(
    u: np.ndarray, y_dom: np.ndarray, n: int, split: signals.Split, order: int
) -> tuple[np.ndarray, np.ndarray]:
    """Output-error model (b, a in q⁻¹) of the measured quantity, from the training part."""
    oe = _oe(u[: split.train_end], y_dom[: split.train_end], order, n)
    return oe.b_delayed, oe.f


def band_centre_hz(u: np.ndarray, fs_hz: float) -> float:
    """Input-power-weighted median frequency (where the effects are referred to the input)."""
    x = np.asarray(u, float) - np.mean(u)
    nper = min(len(x), 1024)
    f, pxx = signal.welch(x, fs=fs_hz, nperseg=nper)
    if not np.any(pxx[1:] > 0):
        return fs_hz / 20.0
    cum = np.cumsum(pxx[1:]) / np.sum(pxx[1:])
    return float(f[1:][np.searchsorted(cum, 0.5)])


#: share of the free-run error's energy below the input band's low edge above which the
#: free run is "dominated by drift"
DRIFT_SHARE = 0.5


def drift(e: np.ndarray, u: np.ndarray, fs_hz: float) -> dict:
    """How much of a free-run error e sits below the input's band (where 5 % of the input
    power lies below): an integrator's drift, or a closed loop answering the output noise."""
    nper = min(len(e), 4096)
    f, pe = signal.welch(e - np.mean(e), fs=fs_hz, nperseg=nper)
    _, pu = signal.welch(np.asarray(u, float) - np.mean(u), fs=fs_hz, nperseg=nper)
    cum = np.cumsum(pu) / np.sum(pu) if np.sum(pu) > 0 else np.linspace(0, 1, f.size)
    f_low = float(f[max(np.searchsorted(cum, 0.05), 1)])
    share = float(np.sum(pe[f <= f_low]) / np.sum(pe)) if np.sum(pe) > 0 else 0.0
    return {"band_low_hz": f_low, "error_share_below": share}


def zero_at_dc(b: np.ndarray, fs_hz: float, below_hz: float) -> bool:
    """Whether B̂ has a real zero at z = 1, or so near it (below ``below_hz``, the DC block's
    cut-off) that the data cannot tell it from one at 1. An acceleration model with such a
    zero answers no constant input with a constant acceleration: the mechanism holds its
    position (a spring, a chamber's air, a position loop), and a constant force on its mass
    moves it to a new rest, where the acceleration is zero again."""
    s = s_roots(np.asarray(b, float), fs_hz)  # a real zero z > 0: a real s
    return bool(np.any((np.abs(s.imag) < 1e-9 * fs_hz) & (np.abs(s) < 2 * math.pi * below_hz)))


#: a model mode this many times slower than the DC block is marginally stable for the test
MARGINAL = 1.5


def slowest_time_constant(a: np.ndarray, fs_hz: float) -> float:
    """Time constant (s) of the slowest pole of 1/A (inf for a pole on the unit circle)."""
    radius = float(np.max(np.abs(np.roots(a)))) if len(a) > 1 else 0.0
    if radius <= 0.0:
        return 0.0
    return math.inf if radius >= 1.0 else -1.0 / (fs_hz * math.log(radius))


def prepare(
    u: np.ndarray,
    y: np.ndarray,
    fs_hz: float,
    output_kind: str,
    plant_b: np.ndarray | None,
    plant_a: np.ndarray | None,
    order: int | None = None,
    form: str = "auto",
) -> tuple[Context, dict]:
    """The simulation form's context for the effect fits, and the baseline's info with the
    form of the test in ``info["form"]`` (`in_form` makes that form's context); plant None
    -> fit a linear baseline of ``order`` (None: `choose_order`). form: "simulation",
    "inverse_dynamics" or "auto" (inverse dynamics when the free run of a velocity or
    position model is dominated by drift, `drift`)."""
    n_kind = signals.OUTPUT_KINDS[output_kind]
    u = np.asarray(u, float)
    y = np.asarray(y, float)
    hp = signals.highpass_from_input(u, fs_hz)
    y_dom = measured_in_domain(y, n_kind, hp, fs_hz)
    info: dict[str, Any] = {"highpass_hz": hp}
    plant_b, plant_a, domain = _nominal_plant(
        u, y_dom, fs_hz, n_kind, hp, plant_b, plant_a, order, info
    )
    nominal = AugmentedPlant(fs_hz, plant_b, plant_a, output_kind, hp, domain=domain)
    sig = nominal.run_signals(u)
    hp_settle = int(math.ceil(math.log(100.0) * fs_hz / (2 * math.pi * hp)))
    limit = len(u) // 4
    warmup = max(signals.settle_samples(nominal.a_dom, limit), min(hp_settle, limit))
    split = signals.make_split(len(u), warmup)
    ref_hz = band_centre_hz(u, fs_hz)
    # a dead time beyond a quarter period at the band centre (> 90° of phase there) is a
    # wrong model, not a dead time
    max_delay = int(max(1, min(round(0.25 * fs_hz / ref_hz), split.train_end // 20)))
    ctx = Context(
        u=u,
        v=sig["v"],
        x=sig["x"],
        y0=sig["y0"],
        target=y_dom - sig["y0"],
        a_dom=nominal.a_dom,
        b_dom=nominal.b_dom,
        split=split,
        fs_hz=fs_hz,
        output_kind=output_kind,
        ref_hz=ref_hz,
        max_delay_samples=max_delay,
        u_centre=float(np.median(u[split.fit])),
        candidates=_candidates(n_kind, nominal, fs_hz, hp, info["baseline"] == "model file"),
        chain=signals.StateChain(n_kind, fs_hz, hp).coefficients,
        highpass_hz=hp,
    )
    info["y_dom"] = y_dom
    info["plant_b"] = np.asarray(plant_b, float)
    info["plant_a"] = np.asarray(plant_a, float)
    info["domain"] = domain
    info["drift"] = drift((y_dom - sig["y0"])[split.test], u[split.test], fs_hz)
    info["drift"]["slowest_time_constant_s"] = slowest_time_constant(nominal.a_dom, fs_hz)
    info["drift"]["dc_block_time_constant_s"] = 1.0 / (2.0 * math.pi * hp)
    info["form"] = _form(form, n_kind, info)
    return ctx, info


def _nominal_plant(
    u: np.ndarray,
    y_dom: np.ndarray,
    fs_hz: float,
    n_kind: int,
    hp: float,
    plant_b: np.ndarray | None,
    plant_a: np.ndarray | None,
    order: int | None,
    info: dict,
) -> tuple[np.ndarray, np.ndarray, tuple | None]:
    """Ĝ (b, a of the acceleration plant) and, for a fitted baseline, its (b, a) in the
    measured quantity's domain (else None): the model file's plant, or an output-error fit
    of ``order`` (None: `choose_order`) on the training part of the measured ``y_dom``
    (``n_kind`` integrators, DC block at ``hp`` Hz). Sets ``info["baseline"]``; a plant
    that is not stable is a `UserError`."""
    provisional = signals.make_split(len(u), 0)
    domain = None
    if plant_b is None:
        chosen = order if order is not None else choose_order(u, y_dom, n_kind, provisional)
        domain = fit_linear(u, y_dom, n_kind, provisional, chosen)
        plant_b, plant_a = signals.acceleration_plant(*domain, n_kind, hp, fs_hz)
        how = "" if order is not None else " (chosen from the data)"
        info["baseline"] = (
            f"output-error fit, order {chosen}{how}, on t < {provisional.train_end / fs_hz:.3g} s"
        )
    else:
        info["baseline"] = "model file"
    assert plant_a is not None  # given with plant_b, or fitted above
    if len(plant_a) > 1 and np.max(np.abs(np.roots(plant_a))) >= 1.0:
        raise UserError(
            "the model's plant is unstable (a root of plant.a on or outside the "
            "unit circle): it cannot be simulated"
        )
    return plant_b, plant_a, domain


def _candidates(
    n_kind: int, nominal: AugmentedPlant, fs_hz: float, hp: float, model_file: bool
) -> tuple[str, ...]:
    """The candidate effects of the record (`effects.EFFECT_NAMES` in order, those named by
    the mode they move left out): a DC block (a velocity or position record, ``n_kind`` >
    0) removes an offset; a constant force moves no steady acceleration of a mechanism
    that holds its position (`zero_at_dc`); a baseline fitted here (not a ``model_file``)
    already holds the linear effects."""
    skip = (
        ({"sensor_offset"} if n_kind else set())
        | ({"force_offset"} if not n_kind and zero_at_dc(nominal.b_dom, fs_hz, hp) else set())
        | ({"viscous_friction", "dead_time", "stiffness_change"} if not model_file else set())
    )
    return tuple(e for e in EFFECT_NAMES if e not in skip and e not in NAMED_BY_MODE)


def _form(form: str, n_kind: int, info: dict) -> str:
    """The form of the test, with its reason in ``info["form_reason"]``: the user's, or
    for "auto" from ``info["drift"]`` (`drift`): inverse dynamics for a velocity or
    position record (``n_kind`` > 0) whose free-run error lies mostly below the input's
    band (DRIFT_SHARE) or whose model is marginally stable (MARGINAL); a velocity or
    position record whose free run does not drift is ``info["form_undecided"]`` (the
    data decide between the two forms, `workflow`)."""
    if form == "auto":
        d = info["drift"]
        drifting = d["error_share_below"] > DRIFT_SHARE
        marginal = d["slowest_time_constant_s"] > MARGINAL * d["dc_block_time_constant_s"]
        form = "inverse_dynamics" if n_kind and (drifting or marginal) else "simulation"
        info["form_undecided"] = bool(n_kind) and not drifting
        info["form_reason"] = (
            f"{100 * d['error_share_below']:.0f} % of the free-run error lies below the "
            f"input band ({d['band_low_hz']:.3g} Hz); slowest model time constant "
            f"{d['slowest_time_constant_s']:.3g} s against the DC block's "
            f"{d['dc_block_time_constant_s']:.3g} s: "
            + (
                (
                    "a free run drifts, so the force balance is tested"
                    if drifting
                    else "a marginally stable model whose free run does not drift"
                    if marginal
                    else "the free run does not drift"
                )
                if n_kind
                else "the model is simulated"
            )
        )
    else:
        info["form_reason"] = "chosen by the user"
    if form == "inverse_dynamics" and not n_kind:
        raise UserError("the inverse-dynamics form needs a velocity or position output")
    return form


def in_form(ctx: Context, info: dict, y: np.ndarray, form: str) -> tuple[Context, dict]:
    """The context and info of one form of the test, from `prepare`'s simulation context
    (the info is copied: each form keeps its own)."""
    info = dict(info, form=form)
    if form == "inverse_dynamics":
        ctx = inverse_context(ctx.u, y, ctx.fs_hz, ctx.output_kind, ctx.split, info)
    return ctx, info


def inverse_context(u, y, fs_hz, output_kind, split, info) -> Context:
    """The fitting context of the inverse-dynamics form (`inverse`)."""
    from fdi_daemon.diagnose.inverse import INVERSE_CANDIDATES, baseline

    base = baseline(u, y, output_kind, fs_hz, split)
    info["y_dom"] = base["target"]
    info["inverse_baseline"] = base["coefficients"]
    lag = base["lag"]
    info["inverse_lag_s"] = lag / fs_hz
    delayed = f"(t − {lag / fs_hz:.3g} s)" if lag else ""
    info["baseline"] += (
        f"; inverse dynamics: L u{delayed} = M L a + c L v"
        + (" + k L x" if output_kind == "position" else "")
        + (f" (the motion lags the input by {lag} sample{'s' if lag > 1 else ''})" if lag else "")
    )
    candidates = tuple(
        c for c in INVERSE_CANDIDATES if output_kind == "position" or c != "cubic_stiffness"
    )
    return Context(
        u=np.asarray(u, float),
        v=base["v"],
        x=base["x"],
        y0=base["y0"],
        target=base["target"] - base["y0"],
        a_dom=np.array([1.0]),
        b_dom=np.array([1.0]),
        split=split,
        fs_hz=fs_hz,
        output_kind=output_kind,
        ref_hz=0.0,
        max_delay_samples=1,
        candidates=candidates,
        form="inverse_dynamics",
        lowpass=base["lp"],
        base_columns=base["columns"],
        inverse_base=base["coefficients"],
    )
