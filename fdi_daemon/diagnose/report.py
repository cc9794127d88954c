"""The diagnose report (`--json`, DESIGN.md) and its one-screen text summary."""

from __future__ import annotations

from typing import Any

from fdi_daemon.diagnose.effects import BASE_TERMS, MODE_LINES
from fdi_daemon.diagnose.mode_lines import LINES
from fdi_daemon.diagnose.select import ALPHA
from fdi_daemon.diagnose.signals import nrmse
from fdi_daemon.io.plain import json_data


def build_report(result, source: str = "") -> dict[str, Any]:
    """``{effect, gap_before, gap_after, gap_metric, ranking, params, regions, ...}``."""
    ctx = result.ctx
    test = ctx.split.test
    y = result.y_measured
    named = [e for e in result.selection.chosen if e.name not in BASE_TERMS]
    rounds = []
    for candidates in result.selection.rounds:
        rows = []
        for c in candidates:
            gap = nrmse(y[test], (ctx.y0 + c.prediction)[test])
            rows.append(c.ranking_entry(gap))
        rounds.append(rows)
    where = result.where_before
    report = {
        "effect": named[0].named_as if named else None,
        "gap_before": result.gap_before,
        "gap_after": result.gap_after,
        "gap_metric": "nrmse",
        "ranking": rounds[0] if rounds else [],
        "params": dict(named[0].physical) if named else {},
        "regions": where["regions"],
        "effects": [
            {"effect": e.named_as, "form": e.name, "params": dict(e.physical)} for e in named
        ],
        "rounds": rounds,
        "test": {
            "held_out_from_s": ctx.split.train_end / ctx.fs_hz,
            "samples": ctx.split.n - ctx.split.train_end,
            "alpha": ALPHA,
            "score": "n_eff ln(SSE1/SSE0) + k ln(n_eff) on held-out data; F-test p < alpha",
        },
        "localization": {
            "whiteness_before": where["whiteness"],
            "whiteness_after": result.where_after["whiteness"],
            "cross_correlation_before": {
                k: v for k, v in where["cross_correlation"].items() if k not in ("lags", "r")
            },
            "cross_correlation_after": {
                k: v
                for k, v in result.where_after["cross_correlation"].items()
                if k not in ("lags", "r")
            },
        },
        "model": {
            "baseline": result.info["baseline"],
            "baseline_refit": "numerator of the nominal model refitted with every "
            "candidate (effect linear_refit in the model file)",
            "output_kind": ctx.output_kind,
            "highpass_hz": result.info["highpass_hz"],
            "fs": ctx.fs_hz,
        },
        "source": source,
        # how the effects were tested (issue 14): the form, the noise floor, the dead time
        "form": result.info["form"],
        "form_reason": result.info["form_reason"],
        "noise_floor": result.info["noise_floor"],
        "gap_before_to_floor": _ratio(result.gap_before, result.info["noise_floor"]),
        "gap_after_to_floor": _ratio(result.gap_after, result.info["noise_floor"]),
        "dead_time": {
            "by_correlation_s": result.info.get("dead_time_by_correlation_s"),
            # the force balance's: the measured motion behind its input (`inverse.baseline`)
            "motion_lag_s": result.info.get("inverse_lag_s"),
            "named_s": next(
                (e.physical.get("dead_time_s") for e in named if e.name == "dead_time"), None
            ),
        },
        "linear_check": result.selection.linear,
        "spring_check": result.selection.spring,
        "held_by_later": result.selection.held_by_later,
        # rounds whose best candidate did not beat another by the margin (`select.margin`)
        "ambiguous": result.selection.ambiguous,
    }
    spring = [e.physical for e in result.selection.chosen if e.name == "loop_stiffness"]
    if spring:  # the force loop's spring in the base: what it does to the mode (§4.3)
        report["loop_spring"] = spring[0]
    if "inverse_baseline" in result.info:  # mass, damping [, stiffness]: refitted if named
        refit = [e.physical for e in result.selection.chosen if e.name == "force_balance"]
        report["force_balance"] = refit[0] if refit else dict(result.info["inverse_baseline"])
    return json_data(report)


def _ratio(gap: float, floor: dict):
    return gap / floor["floor"] if floor.get("floor") else None


def _explanation(name: str) -> str:
    """A linear explanation of the refit in words: a mode line by the effect it stands for."""
    line = MODE_LINES.get(name)
    return name if line is None else f"{LINES[line]} (the mode's {line} line)"


def summary_lines(report: dict[str, Any]) -> list[str]:
    """A short human-readable summary for the terminal: the baseline and the form of the
    test, the refit check, the effects named, the gap and the ranking, where the error sat."""
    return (
        _baseline_lines(report)
        + _linear_check_lines(report)
        + _effect_lines(report)
        + _gap_lines(report)
        + [_where_line(report["regions"])]
    )


def _baseline_lines(report: dict[str, Any]) -> list[str]:
    """The baseline, the form of the test and the noise floor."""
    lines = [
        f"baseline: {report['model']['baseline']}  "
        f"(output {report['model']['output_kind']}, held out from "
        f"t = {report['test']['held_out_from_s']:.3g} s)"
    ]
    lines.append(f"form: {report['form']} ({report['form_reason']})")
    floor = report["noise_floor"]
    if floor.get("floor") is not None:
        lines.append(
            f"noise floor (NRMSE): {floor['floor']:.4g} ({floor['method']})"
            + ("  -- the nominal model is at the floor" if floor["at_floor"] else "")
        )
    else:
        lines.append(f"noise floor (NRMSE): unknown ({floor['method']})")
    return lines


def _linear_check_lines(report: dict[str, Any]) -> list[str]:
    """What the numerator refit's check found (`select.linear_round`), where it matters."""
    lines = []
    check = report["linear_check"]
    if check.get("matching"):
        held = check.get("held_by")
        lines.append(
            f"the numerator refit is mostly a {_explanation(check['matching'])}"
            + (
                f", held by {', '.join(held)}"
                if held
                else ", held by the named effects"
                if report["effect"]
                else ""
            )
            + ": not named (see linear_check)"
        )
    elif check.get("named") and check.get("on_top_of"):
        lines.append(
            f"the numerator refit is mostly a {_explanation(check['named'])}, also "
            f"on top of {', '.join(check['on_top_of'])}: named"
        )
    if report["linear_check"].get("unexplained"):
        lines.append(
            "the numerator refit alone is significant (a missing effect's linear "
            "part, or a numerator that is off) and is neither a gain change, a "
            "dead time nor a change of one parameter of the mode: it stays in the "
            "base"
        )
    return lines


def _effect_lines(report: dict[str, Any]) -> list[str]:
    """The effects named with their parameters (or none), the rounds that were ambiguous,
    the effects a later one holds, and what the force loop's spring does to the mode."""
    lines = []
    if report["effect"] is None:
        lines.append("no significant missing effect")
    else:
        for e in report["effects"]:
            params = ", ".join(
                f"{k}={v:.4g}"
                + (f" {e['params'][k + '_unit']}" if k + "_unit" in e["params"] else "")
                for k, v in e["params"].items()
                if isinstance(v, (int, float)) and not isinstance(v, bool)
            )
            form = f"fitted as {e['form']}: " if e["form"] != e["effect"] else ""
            lines.append(f"missing effect: {e['effect']}  ({form}{params})")
    for tie in report.get("ambiguous", []):
        (a, b), (gap_a, gap_b) = tie["effects"], tie["gaps"]
        lines.append(
            f"ambiguous: {a} or {b} (held-out gap {gap_a:.4g} against {gap_b:.4g}; "
            f"{a} gains {tie['block_gain']:.3g} of the held-out error per block over {b}, "
            f"less than the blocks' spread {tie['block_spread']:.3g})"
        )
    for held in report["held_by_later"]:
        lines.append(
            f"{held['effect']} was named first and is not kept: "
            f"{', '.join(held['held_by'])}, refitted without it, does as well "
            f"(held-out SSE {held['sse_without']:.4g} against {held['sse_with']:.4g})"
        )
    spring = report.get("loop_spring", {})
    if "resonance_hz" in spring:
        lines.append(
            f"the force loop's linear part (its spring, in the base) moves the mode "
            f"{spring['resonance_hz_nominal']:.3g} -> {spring['resonance_hz']:.3g} Hz, "
            f"damping ratio {spring['damping_ratio_nominal']:.2g} -> "
            f"{spring['damping_ratio']:.2g} (stiffness x "
            f"{spring['stiffness_ratio']:.3g}; read as {spring['mode_change']})"
        )
    return lines


def _gap_lines(report: dict[str, Any]) -> list[str]:
    """The held-out gap before and after (also against the noise floor) and the first
    five candidates of the ranking (``*``: accepted)."""
    lines = [
        f"gap (NRMSE, held out): {report['gap_before']:.4g} -> "
        f"{report['gap_after']:.4g}"
        + (
            f"  ({report['gap_before_to_floor']:.3g} -> "
            f"{report['gap_after_to_floor']:.3g} x the floor)"
            if report["gap_before_to_floor"] is not None
            else ""
        )
    ]
    lines.append("ranking:")
    for row in report["ranking"][:5]:
        mark = "*" if row["accepted"] else " "
        name = row["effect"] + (f" ({row['form']} form)" if row["form"] != row["effect"] else "")
        lines.append(
            f" {mark} {name:<18} gap {row['gap_after']:.4g}  "
            f"score {row['score']:.1f}  p {row['p_value']:.2g}"
        )
    return lines


def _where_line(regions: list[dict]) -> str:
    """Where the error sat before: the first time segment, state and frequency band of the
    localisation's ``regions`` (`localize`)."""
    seg = [r for r in regions if r["kind"] == "time"][:1]
    st = [r for r in regions if r["kind"] == "state"][:1]
    fr = [r for r in regions if r["kind"] == "frequency"][:1]
    where = []
    if seg:
        where.append(f"t {seg[0]['t0']:.3g}-{seg[0]['t1']:.3g} s")
    if st:
        where.append(f"{st[0]['variable']} (explains {100 * st[0]['explained']:.0f} %)")
    if fr:
        where.append(
            f"{fr[0]['f0']:.3g}-{fr[0]['f1']:.3g} Hz "
            f"({100 * fr[0]['error_power_fraction']:.0f} % of error power)"
        )
    return "error sat at: " + "; ".join(where)
