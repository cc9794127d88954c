"""`fdi identify`: plant model Ĝ (eq. 1) from chirp data by a weighted rational fit (eq. 2)."""

from __future__ import annotations

import argparse

from fdi_daemon.io.columns import add_columns_option, columns_argument

HELP = "identify the plant model G from a friction-free recording (v_in -> accel)"
#: highest model order accepted (`--order` of identify and diagnose, G_e's NB and NF)
MAX_ORDER = 12


def xcorr_verdict(
    xcorr: dict, order: int, recording: str, model: str, columns: dict[str, str] | None = None
) -> list[str]:
    """What an out-of-band residual-input correlation means and what to try (one line;
    none when it is inside the 99 % band of a white residual)."""
    if not xcorr["max_abs"] > xcorr["bound"]:
        return []
    return [
        f"  -> out of band: the residual still follows the input, so the model misses "
        f"input-driven dynamics (a nonlinearity, too low an order, a delay, or too "
        f"noisy a fit); try --order {order + 2}, check the band, or "
        f"`fdi diagnose {recording} --model {model}{columns_argument(columns)}`"
    ]


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("recording", metavar="REC", help="friction-free recording (e.g. a chirp)")
    parser.add_argument(
        "-o", "--output", required=True, metavar="MODEL.yaml", help="model file to write"
    )
    parser.add_argument("--order", type=int, default=4, help="model order n (default 4)")
    parser.add_argument(
        "--plot",
        metavar="FILE.png",
        help="Bode plot of data and model with coherence (paper Fig. 4)",
    )
    parser.add_argument(
        "--validate",
        metavar="REC",
        help="friction-free recording NOT used for fitting, for the validation "
        "metrics (default: report them on the estimation data)",
    )
    parser.add_argument(
        "--method",
        choices=("blackman-tukey", "welch"),
        default="blackman-tukey",
        help="spectral estimate (default %(default)s)",
    )
    parser.add_argument(
        "--lag-samples",
        type=int,
        metavar="M",
        help="Blackman-Tukey lag window length (default: chosen from the data)",
    )
    parser.add_argument(
        "--lag-window",
        choices=("hann", "hamming"),
        default="hann",
        help="lag window shape (default %(default)s)",
    )
    parser.add_argument(
        "--band",
        metavar="LO:HI",
        help="fit band in Hz (default: chosen from coherence and input spectrum)",
    )
    parser.add_argument(
        "--min-coherence",
        type=float,
        default=0.8,
        help="coherence threshold of the automatic band (default %(default)s)",
    )
    add_columns_option(parser)


def parse_range(text: str, what: str, parts: int = 2) -> tuple[float, ...]:
    """'A:B' (or 'A:B:C') -> floats; a UserError naming `what` otherwise."""
    import math

    from fdi_daemon.errors import UserError

    pieces = text.split(":")
    try:
        values = tuple(float(p) for p in pieces)
    except ValueError:
        values = ()
    if len(values) != parts or not all(math.isfinite(v) for v in values):
        form = ":".join(["A", "B", "C"][:parts])
        raise UserError(f"{what} must look like {form} (numbers), got {text!r}")
    return values


def load_io(path: str, columns: dict[str, str] | None = None):
    """Read a recording (its columns renamed by ``columns``, ``--columns``) and return
    (rec, v_in, accel), their values checked (`io.recordings.fit_column`)."""
    from fdi_daemon.io.recordings import fit_column, read_recording

    rec = read_recording(path, columns=columns)
    return rec, fit_column(rec, "v_in", path), fit_column(rec, "accel", path)


def run(args: argparse.Namespace) -> int:
    from fdi_daemon.io.model_file import FdiModel, save_model

    band = _checked_options(args)
    rec, u, y = load_io(args.recording, args.columns)
    ident = _identify(args, rec.fs, u, y, band)
    u_val, y_val, t_val, val_label = _validation_data(args, rec, u, y)
    check = _validate(args, ident, u_val, y_val)
    prov = {"identify": _provenance(args, ident, check, val_label)}
    save_model(
        args.output, FdiModel(fs=rec.fs, plant_b=ident.fit.b, plant_a=ident.fit.a, provenance=prov)
    )
    if args.plot:
        import numpy as np

        from fdi_daemon.ident.plots import plot_identification

        plot_identification(
            args.plot,
            ident.response,
            ident.model_response(),
            ident.band_hz,
            {
                "t": t_val,
                "y": y_val - np.mean(y_val),
                "y_sim": check["y_sim"] - np.mean(y_val),
                "fit_percent": check["fit_percent"],
                "label": val_label,
            },
        )
    _report(args, ident, check, val_label)
    return 0


def _checked_options(args: argparse.Namespace) -> tuple[float, float] | None:
    """The options that need no data, each checked (one line each); the --band (Hz)."""
    from fdi_daemon.errors import UserError
    from fdi_daemon.io.outputs import check_outputs

    if not 1 <= args.order <= MAX_ORDER:
        raise UserError(f"--order must be 1..{MAX_ORDER}, got {args.order}")
    if not 0 <= args.min_coherence <= 1:
        raise UserError(f"--min-coherence must lie in [0, 1], got {args.min_coherence}")
    check_outputs(
        {"--output": args.output, "--plot": args.plot},
        (args.recording, args.validate),
        plots=("--plot",),
    )
    if args.band is None:
        return None
    lo, hi = parse_range(args.band, "--band")
    if not 0 <= lo < hi:
        raise UserError(f"--band needs 0 <= LO < HI, got {args.band}")
    return lo, hi


def _identify(args: argparse.Namespace, fs: float, u, y, band: tuple[float, float] | None):
    """Ĝ from the recording's valve voltage ``u`` (V) and acceleration ``y`` (m/s²), after
    the checks that need the data."""
    from fdi_daemon.errors import UserError
    from fdi_daemon.ident import plant

    if band is not None and band[1] > fs / 2:
        raise UserError(f"--band {args.band} reaches above fs/2 = {fs / 2:g} Hz")
    if args.lag_samples is not None and not 2 <= args.lag_samples < len(u):
        raise UserError(f"--lag-samples must be 2..{len(u) - 1} for {len(u)} samples")
    if len(u) < 64:
        raise UserError(f"{args.recording}: {len(u)} samples are too few (need >= 64)")
    try:
        return plant.identify_plant(
            u,
            y,
            fs,
            args.order,
            args.method,
            args.lag_samples,
            args.lag_window,
            band,
            args.min_coherence,
        )
    except ValueError as exc:
        raise UserError(f"{args.recording}: {exc}") from None


def _validation_data(args: argparse.Namespace, rec, u, y):
    """(u, y, t, label) to validate Ĝ on: --validate's recording, else the estimation data."""
    from fdi_daemon.errors import UserError
    from fdi_daemon.io.recordings import same_rate

    if not args.validate:
        return u, y, rec.t, "estimation data (no --validate given)"
    val_rec, u_val, y_val = load_io(args.validate, args.columns)
    if not same_rate(val_rec.fs, rec.fs):
        raise UserError(
            f"{args.validate}: fs = {val_rec.fs:g} Hz differs from "
            f"{rec.fs:g} Hz of {args.recording}"
        )
    return u_val, y_val, val_rec.t, f"validation: {args.validate}"


def _validate(args: argparse.Namespace, ident, u_val, y_val) -> dict:
    from fdi_daemon.errors import UserError
    from fdi_daemon.ident import plant

    try:
        return plant.validate_plant(ident, u_val, y_val)
    except ValueError as exc:
        raise UserError(f"{args.validate or args.recording}: validation: {exc}") from None


def _provenance(args: argparse.Namespace, ident, check: dict, val_label: str) -> dict:
    """The model file's ``provenance.identify``: source, command, choices and the metrics
    of the fit and its validation."""
    import numpy as np

    from fdi_daemon.ident import provenance

    fit = ident.fit
    metrics = {
        "fit_percent": round(check["fit_percent"], 3),
        "fit_percent_on": val_label,
        "residual_input_xcorr_max": round(check["xcorr"]["max_abs"], 4),
        "residual_input_xcorr_bound_99": round(check["xcorr"]["bound"], 4),
        "band_hz": [round(v, 4) for v in ident.band_hz],
        "band_relative_error": [
            {
                "band_hz": [round(v, 3) for v in row["band_hz"]],
                "rms": round(row["rms_relative_error"], 4),
            }
            for row in check["band_errors"]
        ],
        "weighted_cost": float(fit.cost),
        "rms_relative_error": round(fit.rms_relative_error, 5),
        "coherence_mean_in_band": round(
            float(np.mean(ident.response.coherence[ident.band_mask()])), 4
        ),
    }
    choices = {k: v for k, v in ident.choices.items() if k != "lag_candidates"}
    return {
        **provenance.source_entry(args.recording, provenance.command_line("identify", args)),
        "validation_source": args.validate,
        "order": args.order,
        "choices": choices,
        "metrics": metrics,
    }


def _report(args, ident, check, val_label) -> None:
    import numpy as np

    c = ident.choices
    spec = (
        f"Blackman-Tukey, {c['lag_window']} lag window M = {c['lag_samples']} "
        f"({c['lag_samples_rule']})"
        if c["method"] == "blackman-tukey"
        else f"Welch H1, {c['segment_samples']}-sample segments"
    )
    poles = np.roots(ident.fit.a)
    lines = [
        f"spectral estimate : {spec}",
        f"band              : {ident.band_hz[0]:.3g}-{ident.band_hz[1]:.3g} Hz "
        f"({c['band_rule']}), {c['fit_points']} points",
        f"start             : {c['start']} ({c['sk_iterations']} SK iterations, "
        f"{c['reflected_poles']} pole(s) reflected)",
        f"rms relative error: {100 * ident.fit.rms_relative_error:.2f} % (W = 1/|G|)",
        "poles             : "
        + ", ".join(f"{p:.4f}" for p in poles)
        + f"  (|p| max {np.max(np.abs(poles)):.4f})",
        f"simulation fit    : {check['fit_percent']:.2f} % on {val_label}",
        f"residual-input xcorr: max |r| {check['xcorr']['max_abs']:.3f} "
        f"(99 % band ±{check['xcorr']['bound']:.3f})",
        *xcorr_verdict(
            check["xcorr"],
            args.order,
            args.validate or args.recording,
            args.output,
            args.columns,
        ),
        "band errors       : "
        + ", ".join(
            f"{r['band_hz'][0]:.3g}-{r['band_hz'][1]:.3g} Hz {100 * r['rms_relative_error']:.1f} %"
            for r in check["band_errors"]
        ),
        f"model written     : {args.output}",
    ]
    print("\n".join(lines))
