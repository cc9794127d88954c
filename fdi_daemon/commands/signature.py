"""`fdi signature`: friction-signature filter G_e and γ_f from a fault window (eqs. 11–13)."""

from __future__ import annotations

import argparse
from typing import Any

from fdi_daemon.io.columns import add_columns_option

HELP = "identify the friction signature (G_e, gamma_f) from a window with a friction fault"

#: ``--velocity-method auto`` in order: the paper's high-pass estimator, and where its
#: signature does not fit (G_e·x_f explains less than LOW_VAF_PERCENT of the fault residual,
#: the level would not be physical) the model-based observer if it explains more. Both are
#: computed from the valve voltage and the accelerometer alone (the position observer needs
#: a position sensor on every sample, a choice the user makes).
AUTO_METHODS = ("highpass", "model_observer")
DRIFT_NEEDS_HIGHPASS = "--drift-highpass-hz needs the high-pass velocity estimator"


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("recording", metavar="REC", help="recording with a friction fault")
    parser.add_argument(
        "--model",
        required=True,
        metavar="MODEL.yaml",
        help="model file holding the plant (from `fdi identify`)",
    )
    parser.add_argument(
        "--fault-window",
        required=True,
        metavar="T0:T1",
        help="time window (s) in which the fault is present",
    )
    parser.add_argument(
        "-o",
        "--output",
        required=True,
        metavar="MODEL.yaml",
        help="model file to write (may equal --model)",
    )
    parser.add_argument(
        "--plot",
        metavar="FILE.png",
        help="residual vs filtered friction signal (Fig. 8) and the γ profile",
    )
    parser.add_argument(
        "--gamma-grid",
        default="0:10:0.2",
        metavar="LO:HI:STEP",
        help="γ grid (default %(default)s, the paper's 51 points)",
    )
    parser.add_argument(
        "--orders",
        default="4:3:0",
        metavar="NB:NF:NK",
        help="G_e orders as MATLAB oe (default %(default)s)",
    )
    parser.add_argument(
        "--highpass-hz",
        type=float,
        help="velocity estimator high-pass cut-off (default: the model's "
        "velocity settings, else 1 Hz; with model_observer, 0.5 Hz on "
        "the residual path)",
    )
    parser.add_argument(
        "--drift-highpass-hz",
        type=float,
        metavar="HZ",
        help="also fit the growing-fault path's own G_e and gamma with the velocity's "
        "high-pass at HZ (lower than the monitor's, so that sign v is right at 1-3 Hz; "
        "stored as fault_filter.drift; high-pass velocity only; docs/detector.md §3)",
    )
    parser.add_argument(
        "--velocity-method",
        choices=("auto", "highpass", "model_observer", "position_observer"),
        help="velocity estimate: the accelerometer through a high-pass and an "
        "integrator, the model-based observer (right in phase at 1-3 Hz), "
        "or position and acceleration fused (needs a position column; "
        "docs/detector.md); auto: highpass, or model_observer where the "
        "high-pass signature explains less than half of the fault "
        "residual and the observer's more (docs/identification.md). "
        "Default: the model's velocity settings, else auto. The "
        "monitor uses the same",
    )
    parser.add_argument(
        "--flat-fraction",
        type=float,
        default=0.2,
        help="call gamma_f poorly identified when its 99 %% interval covers more "
        "than this fraction of the grid (default %(default)s)",
    )
    parser.add_argument(
        "--prefilter-hz",
        type=float,
        help="high-pass (3rd-order Butterworth) applied alike to the residual "
        "and the friction signal before the fit (default: none)",
    )
    parser.add_argument(
        "--reference-window",
        metavar="R0:R1",
        help="fault-free pass of the SAME excitation (same length as the fault "
        "window, earlier in the recording): fit the differential residual "
        "r(t) - r(t - lag), so the plant model's error cancels",
    )
    parser.add_argument(
        "--lowpass-hz",
        type=float,
        help="choose gamma on the excitation's fundamentals: an 8th-order "
        "Butterworth low-pass applied alike to the residual and the "
        "friction signal (e.g. 1.5x the excitation frequency); G_e is then "
        "refitted on the full band at gamma_f (default: none)",
    )
    parser.add_argument(
        "--max-pole-radius",
        type=float,
        help="bound on G_e's poles (default: sqrt of the plant's largest pole "
        "radius, i.e. G_e's memory at most twice the plant's slowest mode)",
    )
    parser.add_argument(
        "--min-depth",
        type=float,
        default=0.01,
        help="flag the profile flat when max/min cost over the grid is below "
        "1 + this (default %(default)s)",
    )
    add_columns_option(parser)


def _orders(text: str) -> tuple[int, int, int]:
    from fdi_daemon.commands.identify import MAX_ORDER, parse_range
    from fdi_daemon.errors import UserError

    values = parse_range(text, "--orders", 3)
    nb, nf, nk = (int(v) for v in values)
    if (
        any(v != int(v) for v in values)
        or not 1 <= nb <= MAX_ORDER
        or not 0 <= nf <= MAX_ORDER
        or nk < 0
    ):
        raise UserError(
            f"--orders must be whole numbers 1<=NB<={MAX_ORDER}:0<=NF<={MAX_ORDER}"
            f":NK>=0, got {text!r}"
        )
    return nb, nf, nk


def run(args: argparse.Namespace) -> int:
    from fdi_daemon.errors import UserError
    from fdi_daemon.io.model_file import save_model

    cal = _Calibration(args)
    model, method = cal.model, cal.method
    fits = cal.fits_by_velocity(AUTO_METHODS if method == "auto" else (method,))
    # of those tried, the velocity under which the signature explains most of the residual
    full_band_vaf, full_band_pct, _, estimator, result, fault_fit = max(
        fits, key=lambda fit: fit[0]
    )
    drift = None
    if args.drift_highpass_hz is not None:  # the growing-fault path's own signature
        if estimator.settings().get("method", "highpass") != "highpass":
            raise UserError(DRIFT_NEEDS_HIGHPASS)  # auto took the observer
        slow = {**estimator.settings(), "highpass_hz": args.drift_highpass_hz}
        drift = cal.fit("highpass", _estimator(slow, model.fs, args.model))
    explained = {fit[2]: round(float(fit[0]), 2) for fit in fits}
    band = cal.store(result, fault_fit, estimator, drift)
    prov = dict(model.provenance)
    prov["signature"] = _signature_provenance(
        args,
        [cal.t0, cal.t1],
        int(cal.inside.sum()),
        cal.radius,
        method,
        explained,
        result,
        (float(full_band_pct), float(full_band_vaf)),
    )
    if drift is not None:
        prov["signature"]["drift"] = _drift_provenance(drift, args.drift_highpass_hz)
    model.provenance = prov
    save_model(args.output, model)
    if args.plot:
        from fdi_daemon.ident.plots import plot_signature

        plot_signature(
            args.plot,
            cal.t[cal.first : cal.end],
            result.residual,
            result,
            residual_label=_fitted_residual_label(args),
            velocity=estimator.settings().get("method", "highpass"),
        )
    _report(
        args,
        result,
        estimator,
        fault_fit,
        band,
        full_band_pct,
        full_band_vaf,
        explained if method == "auto" else None,
    )
    if drift is not None:
        _report_drift(drift, args.drift_highpass_hz)
    return 0


class _Calibration:
    """The recording, the model and the fault window of one `fdi signature` run, and the
    signature fitted on them under a velocity estimator (eqs. 11–13)."""

    def __init__(self, args: argparse.Namespace) -> None:
        import numpy as np

        from fdi_daemon.commands.identify import load_io
        from fdi_daemon.detect.monitor import check_stable
        from fdi_daemon.diagnose.augment import nominal_plant
        from fdi_daemon.errors import UserError
        from fdi_daemon.ident import signature as sig
        from fdi_daemon.ident.signature_advice import CalibrationContext, plant_resonance_hz
        from fdi_daemon.io.model_file import load_model

        self.args = args
        self.t0, self.t1, self.grid, self.orders = _checked_options(args)
        self.model = model = load_model(args.model)
        check_stable(model.plant_a, "plant.a")  # an unstable Ĝ gives no residual to fit
        self.rec, self.v_in, self.accel = load_io(args.recording, args.columns)
        self.t = self.rec.t
        self.inside = _fault_window(args, self.rec, model.fs, self.t0, self.t1, self.orders)
        # a plant-only model (`fdi identify`'s) has no velocity yet: auto; a model with
        # velocity settings keeps them (without a method: the high-pass estimator, as every
        # model before)
        self.method = args.velocity_method or (
            model.velocity.get("method", "highpass") if model.velocity else "auto"
        )
        if args.drift_highpass_hz is not None and self.method not in ("auto", "highpass"):
            raise UserError(DRIFT_NEEDS_HIGHPASS)
        self.prefilter = _prefilter(args, model.fs)
        radius = args.max_pole_radius
        if radius is None:
            radius = sig.plant_pole_bound(model.plant_a)
        elif not 0 < radius <= 1:
            raise UserError("--max-pole-radius must lie in (0, 1]")
        self.radius = radius
        # residual (eq. 3) and velocity from the recording start, so that filter start-up
        # transients have settled before the window; the fit uses the window only
        self.plant_residual = sig.plant_residual(nominal_plant(model), self.v_in, self.accel)
        self.residual = self.plant_residual
        window = np.flatnonzero(self.inside)
        self.first, self.end = int(window[0]), int(window[-1]) + 1
        self.start = 0
        if args.reference_window is not None:
            lag = _reference_lag(args, self.t, self.v_in, self.first, self.end, self.rec.fs)
            self.residual = sig.reference_difference(self.residual, lag)
            self.start = lag  # the difference exists from one lag on
        self.context = CalibrationContext(
            fs_hz=float(model.fs),
            referenced=args.reference_window is not None,
            resonance_hz=plant_resonance_hz(model.plant_a, float(model.fs)),
        )

    def fit(self, candidate: str, estimator: Any) -> tuple[Any, ...]:
        """(VAF %, fit %, candidate, estimator, result, G_e) of the signature under
        ``estimator``'s velocity: the γ profile, then G_e on the full band at γ_f."""
        from fdi_daemon.ident import signature as sig

        args, start, end, first = self.args, self.start, self.end, self.first
        velocity = _velocity(estimator, self.rec, args.recording, self.accel, self.plant_residual)
        result = _estimate(
            sig,
            self.residual[start:end],
            velocity[start:end],
            first - start,
            self.grid,
            self.orders,
            self.prefilter,
            args.flat_fraction,
            args.min_depth,
            self.radius,
            candidate,
            self.context,
        )
        fault_fit = result.fit
        if args.lowpass_hz is not None:  # G_e for the monitor: full band, at gamma_f
            fault_fit = sig.fit_fault_filter(
                self.residual[start:end],
                velocity[start:end],
                result.gamma_f,
                self.orders,
                first - start,
                self.radius,
            )
        full_band_pct = sig.fit_percent(self.residual[first:end], fault_fit.y_sim)
        full_band_vaf = sig.variance_accounted_for(self.residual[first:end], fault_fit.y_sim)
        return full_band_vaf, full_band_pct, candidate, estimator, result, fault_fit

    def fits_by_velocity(self, candidates: tuple[str, ...]) -> list[tuple[Any, ...]]:
        """`fit` under each candidate velocity in turn, until one explains at least
        LOW_VAF_PERCENT of the fault residual (``--velocity-method auto``)."""
        from fdi_daemon.core.velocity import DEFAULT_SETTINGS
        from fdi_daemon.detect.settings import velocity_settings
        from fdi_daemon.ident import signature as sig

        fits: list[tuple[Any, ...]] = []
        for candidate in candidates:
            if fits and fits[-1][0] >= sig.LOW_VAF_PERCENT:
                break  # the signature fits: keep the estimator tried first
            settings = velocity_settings(self.model.velocity or DEFAULT_SETTINGS)
            if candidate != settings.get("method", "highpass"):
                settings = {"method": candidate}  # the other method's own defaults
            if self.args.highpass_hz is not None:
                settings["highpass_hz"] = self.args.highpass_hz
            fits.append(self.fit(candidate, _estimator(settings, self.model.fs, self.args.model)))
        return fits

    def store(self, result: Any, fault_fit: Any, estimator: Any, drift: Any) -> Any:
        """G_e, γ_f, the calibration's band and the drift signature into the model, and the
        estimator's velocity settings; returns the band (Hz)."""
        from fdi_daemon.ident import signature as sig
        from fdi_daemon.io.model_file import FaultFilter

        nk = self.orders[2]
        # at the grid's edge γ_f is no value: null in the model (the monitor's G_e, fitted
        # at the edge γ, is kept; the band method, which tracks (1, γ_f), refuses such a model)
        band = sig.calibration_band_hz(self.v_in[self.first : self.end], float(self.model.fs))
        self.model.fault_filter = FaultFilter(
            b=fault_fit.b,
            f=fault_fit.f,
            nk=nk,
            gamma_f=None if result.at_edge else result.gamma_f,
            band_hz=band,
            drift=None if drift is None else _drift_filter(drift, nk, self.args.drift_highpass_hz),
        )
        self.model.velocity = estimator.settings()
        return band


def _checked_options(args: argparse.Namespace) -> tuple[float, float, Any, tuple[int, int, int]]:
    """(t0, t1, the γ grid, (nb, nf, nk)) from the options, each checked (one line each)."""
    from fdi_daemon.commands.identify import parse_range
    from fdi_daemon.errors import UserError
    from fdi_daemon.ident import signature as sig
    from fdi_daemon.io.outputs import check_outputs

    t0, t1 = parse_range(args.fault_window, "--fault-window")
    if not t1 > t0:
        raise UserError(f"--fault-window needs T0 < T1, got {args.fault_window}")
    lo, hi, step = parse_range(args.gamma_grid, "--gamma-grid", 3)
    try:
        grid = sig.gamma_grid(lo, hi, step)
    except ValueError as exc:
        raise UserError(f"--gamma-grid: {exc}") from None
    if len(grid) < 3:
        raise UserError("--gamma-grid needs at least 3 points")
    orders = _orders(args.orders)
    if not 0 < args.flat_fraction <= 1:
        raise UserError("--flat-fraction must lie in (0, 1]")
    if not args.min_depth >= 0:
        raise UserError("--min-depth must be >= 0")
    if args.drift_highpass_hz is not None and not args.drift_highpass_hz > 0:
        raise UserError("--drift-highpass-hz must be > 0")
    check_outputs(
        {"--output": args.output, "--plot": args.plot},
        (args.recording, args.model),
        plots=("--plot",),
        rewrites={"--output": args.model},
    )
    return t0, t1, grid, orders


def _fault_window(
    args: argparse.Namespace, rec: Any, fs: float, t0: float, t1: float, orders: tuple[int, ...]
) -> Any:
    """The samples of the fault window [t0, t1) s (a boolean mask), checked against the
    recording: its rate is the model's ``fs``, the window lies inside it and holds enough
    samples for the orders."""
    from fdi_daemon.errors import UserError
    from fdi_daemon.io.recordings import same_rate

    if not same_rate(rec.fs, fs):
        raise UserError(f"{args.recording}: fs = {rec.fs:g} Hz but the model has fs = {fs:g} Hz")
    t = rec.t
    if t0 < t[0] or t1 > t[-1] + 1.0 / rec.fs:
        raise UserError(
            f"--fault-window {args.fault_window} lies outside the recording "
            f"({t[0]:g} to {t[-1]:g} s)"
        )
    inside = (t >= t0) & (t < t1)
    needed = 2 * (sum(orders) + 10)
    if inside.sum() < needed:
        raise UserError(
            f"--fault-window {args.fault_window} holds {int(inside.sum())} "
            f"samples; at least {needed} are needed"
        )
    return inside


def _signature_provenance(
    args: argparse.Namespace,
    window_s: list[float],
    samples: int,
    radius: float,
    method: str,
    explained: dict[str, float],
    result: Any,
    fits_percent: tuple[float, float],
) -> dict[str, Any]:
    """provenance.signature: the source and command, the window (s) and its samples, the
    options, the velocity tried, how well G_e explains the residual (``fits_percent``: fit
    % and VAF % on the full band), γ_f's status and cost profile, the recommendation."""
    from fdi_daemon.commands.identify import parse_range
    from fdi_daemon.ident import provenance

    return {
        **provenance.source_entry(args.recording, provenance.command_line("signature", args)),
        "fault_window_s": window_s,
        "samples": samples,
        "reference_window_s": (
            None
            if args.reference_window is None
            else list(parse_range(args.reference_window, "--reference-window"))
        ),
        "prefilter_hz": args.prefilter_hz,
        "lowpass_hz": args.lowpass_hz,
        "max_pole_radius": float(radius),
        "velocity_method": method,
        "vaf_percent_by_velocity": explained,
        "fault_filter_fit_percent_full_band": fits_percent[0],
        "fault_filter_vaf_percent_full_band": fits_percent[1],
        "gamma_f_status": result.status,
        "gamma_at_least_cost": float(result.gamma_f),
        "cost_profile": result.summary(),
        "cost_profile_relative": [round(float(c), 6) for c in result.relative_cost()],
        "recommendation": result.recommendation,
    }


def _estimator(settings: dict[str, Any], fs: float, model_path: str) -> Any:
    """The velocity estimator of ``settings`` (a bad setting: one line naming the model)."""
    from fdi_daemon.core.velocity_observer import velocity_from_settings
    from fdi_daemon.errors import ConfigError

    try:
        return velocity_from_settings(settings, fs_hz=fs)
    except ValueError as exc:
        raise ConfigError(f"{model_path}: velocity: {exc}") from None


def _drift_filter(drift: tuple[Any, ...], nk: int, highpass_hz: float) -> Any:
    """The model's ``fault_filter.drift`` from the fit under the low cut-off's velocity: G_e
    and the γ it was fitted at (least cost, also at the grid's edge)."""
    from fdi_daemon.io.model_file import DriftFilter

    result, fault_fit = drift[4], drift[5]
    return DriftFilter(
        b=fault_fit.b, f=fault_fit.f, nk=nk, gamma=float(result.gamma_f), highpass_hz=highpass_hz
    )


def _drift_provenance(drift: tuple[Any, ...], highpass_hz: float) -> dict[str, Any]:
    """How well the growing-fault path's signature is known (provenance.signature.drift)."""
    vaf, pct, _, _, result, _ = drift
    return {
        "highpass_hz": float(highpass_hz),
        "gamma_f_status": result.status,
        "interval_99": [float(v) for v in result.interval],
        "fault_filter_fit_percent_full_band": float(pct),
        "fault_filter_vaf_percent_full_band": float(vaf),
    }


def _report_drift(drift: tuple[Any, ...], highpass_hz: float) -> None:
    """One line on the growing-fault path's signature."""
    vaf, _, _, _, result, _ = drift
    print(
        f"drift signature   : high-pass {highpass_hz:g} Hz, γ {result.gamma_f:.4g} (99 % "
        f"{result.interval[0]:.3g} .. {result.interval[1]:.3g}, {result.status}), G_e "
        f"explains {vaf:.1f} % of the fault residual's variance"
    )


def _velocity(estimator, rec, path, accel, residual):
    """v̂ over the whole recording with the estimator's inputs (x̂̈ = ẍ − r, or position)."""
    import numpy as np

    from fdi_daemon.errors import UserError

    if estimator.needs_model:
        return estimator.run(accel, accel - residual)
    if estimator.needs_position:
        if "position" not in rec.columns:
            raise UserError(f"{path}: velocity method position_observer needs a position column")
        return estimator.run(accel, np.asarray(rec.columns["position"], dtype=float))
    return estimator.run(accel)


def _fitted_residual_label(args) -> str:
    """What the fit saw: the residual r (eq. 3), less the fault-free reference, filtered."""
    label = "residual r" + (" − fault-free reference" if args.reference_window else "")
    filters = [
        f"{kind}-passed {hz:g} Hz"
        for kind, hz in (("high", args.prefilter_hz), ("low", args.lowpass_hz))
        if hz is not None
    ]
    return ", ".join([label, *filters])


def _prefilter(args, fs):
    """L applied alike to r and x_f: optional high-pass, optional low-pass (cascaded SOS)."""
    import numpy as np
    from scipy.signal import butter

    from fdi_daemon.errors import UserError
    from fdi_daemon.ident.signature import lowpass_prefilter

    sections = []
    if args.prefilter_hz is not None:
        if not 0 < args.prefilter_hz < fs / 2:
            raise UserError(f"--prefilter-hz must lie in (0, {fs / 2:g})")
        sections.append(butter(3, args.prefilter_hz, btype="high", fs=fs, output="sos"))
    if args.lowpass_hz is not None:
        if not 0 < args.lowpass_hz < fs / 2:
            raise UserError(f"--lowpass-hz must lie in (0, {fs / 2:g})")
        if args.prefilter_hz is not None and not args.lowpass_hz > args.prefilter_hz:
            raise UserError("--lowpass-hz must lie above --prefilter-hz")
        sections.append(lowpass_prefilter(args.lowpass_hz, fs))
    return np.vstack(sections) if sections else None


def _reference_lag(args, t, v_in, first, end, fs) -> int:
    """Samples between the reference window and the fault window; checks that the reference
    holds the same excitation (the recorded valve voltage agrees to 10 % rms)."""
    import numpy as np

    from fdi_daemon.commands.identify import parse_range
    from fdi_daemon.errors import UserError

    r0, r1 = parse_range(args.reference_window, "--reference-window")
    length = (end - first) / fs
    if abs((r1 - r0) - length) > 1.5 / fs:
        raise UserError(
            f"--reference-window {args.reference_window} must be as long as the "
            f"fault window ({length:g} s)"
        )
    ref_first = int(np.searchsorted(t, r0 - 0.5 / fs))
    lag = first - ref_first
    if r0 < t[0] or lag < end - first:
        raise UserError(
            f"--reference-window {args.reference_window} must lie in the recording "
            "and end before the fault window starts"
        )
    ref, win = v_in[first - lag : end - lag], v_in[first:end]
    mismatch = float(np.sqrt(np.mean((win - ref) ** 2) / max(np.mean(win**2), 1e-300)))
    if mismatch > 0.1:
        raise UserError(
            f"--reference-window {args.reference_window}: the valve voltage differs "
            f"from the fault window's by {100 * mismatch:.0f} % rms; play the same "
            "excitation in both"
        )
    return lag


def _estimate(
    sig,
    residual,
    velocity,
    fit_from,
    grid,
    orders,
    prefilter,
    flat_fraction,
    min_depth,
    radius,
    method,
    context,
):
    from rich.console import Console
    from rich.progress import Progress

    from fdi_daemon.errors import UserError

    with Progress(console=Console(stderr=True), transient=True) as progress:
        task = progress.add_task(
            f"γ grid, {method} velocity (OE fit per point, 3 sweeps)",
            total=sig.sweep_fits(len(grid)),
        )
        try:
            return sig.estimate_signature(
                residual,
                velocity,
                grid,
                orders,
                flat_fraction=flat_fraction,
                min_depth=min_depth,
                prefilter=prefilter,
                fit_from=fit_from,
                max_pole_radius=radius,
                on_step=lambda: progress.advance(task),
                context=context,
            )
        except ValueError as exc:
            raise UserError(f"signature: {exc}") from None


def _interval_parts(result) -> str:
    """How the interval was made: the profile's LR interval and the block bootstrap's."""
    info = result.info
    if info.get("interval_99_bootstrap") is None:
        return f" (N_eff = {result.effective_samples:.0f})"
    (p0, p1), (b0, b1) = info["interval_99_profile"], info["interval_99_bootstrap"]
    edge = "; whole grid: least cost at its end" if result.at_edge else ""
    return (
        f" (profile {p0:.3g}..{p1:.3g} with N_eff = {result.effective_samples:.0f}; "
        f"block bootstrap {b0:.3g}..{b1:.3g}, blocks of {info['bootstrap_block_samples']} "
        f"samples{edge})"
    )


def _report(
    args, result, estimator, fault_fit, band, full_band_pct, full_band_vaf, explained
) -> None:
    """The summary; ``band``: the calibration's band (Hz); ``explained``: VAF % per velocity
    that auto tried, or None."""
    import sys

    from fdi_daemon.ident.signature import LOW_VAF_PERCENT

    rel = result.relative_cost()
    gamma = (
        f"not identified (edge): least cost at γ = {result.gamma_f:.4g}, the end of the "
        "grid; stored as null"
        if result.at_edge
        else f"{result.gamma_f:.4g}"
    )
    velocity = estimator.settings()
    if velocity.get("method") == "position_observer":
        described = (
            f"position_observer, crossover {velocity['crossover_hz']:g} Hz, damping "
            f"{velocity['damping']:g}"
        )
    else:
        described = (
            f"{velocity.get('method', 'highpass')}, high-pass "
            f"{velocity['highpass_hz']:g} Hz order {velocity['highpass_order']}"
            + (f", leak {velocity['leak_hz']:g} Hz" if "leak_hz" in velocity else "")
            + f", {velocity['integrator']} integrator"
        )
    if explained is not None:
        described += (
            " (auto: G_e explains "
            + ", ".join(f"{vaf:.1f} % with {name}" for name, vaf in explained.items())
            + ")"
        )
    lines = [
        f"gamma_f           : {gamma} (grid {result.grid[0]:g}..{result.grid[-1]:g}"
        f" step {result.grid[1] - result.grid[0]:g}, refined)",
        f"99 % interval     : {result.interval[0]:.3g} .. {result.interval[1]:.3g}"
        + _interval_parts(result),
        f"cost profile      : SSE(γ)/SSE(γ_f) from {rel.min():.4f} to {rel.max():.4f}"
        f" ({result.status.upper() if result.status != 'identified' else 'identifiable'})",
        f"G_e fit           : {result.info['fit_percent']:.2f} % of the residual explained "
        f"(1 - NRMSE), variance accounted for {result.info['vaf_percent']:.1f} %, "
        f"orders [nb nf nk] = {list(result.orders)}",
        f"G_e (model file)  : b = {[round(float(v), 6) for v in fault_fit.b]}, "
        f"f = {[round(float(v), 6) for v in fault_fit.f]}; explains {full_band_vaf:.1f} % of "
        f"the unfiltered fault residual's variance ({full_band_pct:.2f} % 1 - NRMSE)",
        f"velocity          : {described}",
        f"calibration band  : {band[0]:g} .. {band[1]:g} Hz (the excitation in the fault window)",
        f"model written     : {args.output}",
    ]
    print("\n".join(lines))
    if full_band_vaf < LOW_VAF_PERCENT:
        print(
            f"fdi signature: warning: G_e x_f explains only {full_band_vaf:.1f} % of the fault "
            f"residual's variance (< {LOW_VAF_PERCENT:g} %): the friction level will not be "
            "physical. Use "
            + (
                ""
                if velocity.get("method") == "model_observer"
                else "--velocity-method auto or model_observer and "
            )
            + "a calibration run with the rig's operating frequencies "
            "(docs/identification.md)",
            file=sys.stderr,
        )
    if result.recommendation is not None:
        print(
            f"fdi signature: warning: {result.recommendation} (G_e x_f explains "
            f"{result.info['vaf_percent']:.1f} % of the residual's variance; 99 % interval "
            f"of gamma {result.interval[0]:.3g}..{result.interval[1]:.3g})",
            file=sys.stderr,
        )
