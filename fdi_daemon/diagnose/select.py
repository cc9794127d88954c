"""Score each candidate effect on held-out data, test its significance, pick the winner(s).

Every candidate is fitted on the training part (its nonlinear parameter by search, its
coefficients by least squares) and judged on the held-out part only:

- effective sample size: the held-out residual e₀ that the candidates have to explain is
  coloured, so its samples are not independent; n_eff = n / τ with τ = 1 + 2 Σ_k ρ_k
  (integrated autocorrelation time, summed up to the first lag where ρ_k < 0.05), the same
  for every candidate of a round (so that their scores compare like with like);
- parsimony: Δ score = n_eff ln(SSE₁/SSE₀) + k ln(n_eff) (BIC difference against the model
  without the candidate, k = its coefficients + its searched parameter); < 0 is better;
- significance: F = ((SSE₀ − SSE₁)/k) / (SSE₁/(n_eff − k_total)), p = P(F_{k, n_eff−k_total} > F).

A candidate is accepted when p < ALPHA, Δ score < 0, it removes at least MIN_REDUCTION of
the held-out error energy (statistically significant but practically void improvements —
a discretisation mismatch of a few per cent, say — are not a missing effect) and its
physical coefficients are plausible (`effects.physical_report`); the best accepted (lowest
score) is named — unless it is one of a nested pair and the nested F-test at ALPHA says
otherwise: the larger only when it is significantly better than the smaller (`_choose`).
Before the rounds, a significant numerator refit is checked for a gain, a shift or a change
of one parameter of the nominal mode that it may be (`linear_round`).
Nested pairs: Stribeck contains Coulomb, a force offset a sensor offset, and every force
effect contains ``stiffness_change``, the loop's free linear force of x that comes with it
(`force.in_the_loop`): a friction, a cubic spring or a constant force is named only where
it does more than a linear change of the mechanics would. That change is named after what
it does to the mechanical mode (`force.mode_shift`): ``stiffness_change`` when the spring
moved, ``mass_change`` (the same fit) when the mass did, ``viscous_friction`` (its own fit)
when damping was added. After each round the spring a named force effect left in the base
is named too when it pays on top of it and the record's linear part moves the mode that
way (`spring_check`: a stiffness change behind a friction, or a damper, fitted in its own
column beside the spring, where that pays). Then
every remaining candidate is tried on top of it (jointly refitted) for a second effect,
with the same test, against the base given the same loop fit (not one that a named effect
contains, nor a fit that stands for an effect already named: a Stribeck form named
``coulomb_friction`` on top of Coulomb friction, `FittedEffect.named_as`); the one named
must also beat the base refitted from its own fit without it (`_beyond_its_start`: a loop's
fit depends on where it starts). After the rounds, an effect named before a force effect
must still pay on top of it, that effect refitted without it (`_each_pays_on_top`: backward
elimination). No accepted candidate: "no significant missing effect".
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from scipy import stats

from fdi_daemon.diagnose.effects import (
    BASE_TERMS,
    MODE_LINES,
    SHARE_RANGE,
    SPECS,
    Context,
    FittedEffect,
    NotApplicable,
    columns,
    effect_coefficients,
    effect_columns,
    fit_effect,
)
from fdi_daemon.diagnose.force import (
    FORCE_EFFECTS,
    LOOPED,
    MECHANICS,
    SPRINGS,
    in_the_loop,
    mechanics_name,
    possible,
)
from fdi_daemon.diagnose.mode_lines import LINES
from fdi_daemon.diagnose.signals import nrmse

#: significance level per test; 10 candidates × 2 rounds keeps the chance of naming an
#: effect in pure noise near 2 %
ALPHA = 1e-3
#: smallest share of the held-out error energy (SSE) an effect must remove to be named
MIN_REDUCTION = 0.05
#: effects that contain another as a special case (Stribeck with no excess is Coulomb)
NESTS = {
    "stribeck_friction": "coulomb_friction",
    # a constant force through the free force path settles to a constant output
    "force_offset": "sensor_offset",
}
#: how many effects are added at most (the first, then one more)
MAX_EFFECTS = 2
#: time blocks of the held-out part for the margin (`margin`)
BLOCKS = 5


def margin(ctx: Context, worse: np.ndarray, better: np.ndarray) -> tuple[bool, float, float]:
    """Does the fit whose contribution is ``better`` beat ``worse`` by more than the spread
    of held-out error across time blocks? The held-out part is cut into BLOCKS contiguous
    blocks; d_b = SSE_worse,b − SSE_better,b per block. It beats it when the mean gain is
    above the blocks' standard deviation of the gain, d̄ > s_d (every block has to agree:
    a t statistic above √BLOCKS ≈ 2.2). Returns (beats, d̄, s_d) as shares of the worse
    fit's held-out SSE."""
    idx = ctx.split.test
    with np.errstate(all="ignore"):
        e_worse = (ctx.target - worse)[idx] ** 2
        e_better = (ctx.target - better)[idx] ** 2
    if not (np.all(np.isfinite(e_worse)) and np.all(np.isfinite(e_better))):
        return bool(np.all(np.isfinite(e_better))), math.nan, math.nan
    total = float(np.sum(e_worse)) or 1.0
    d = np.array(
        [
            np.sum(w) - np.sum(b)
            for w, b in zip(np.array_split(e_worse, BLOCKS), np.array_split(e_better, BLOCKS))
        ]
    ) / (total / BLOCKS)
    mean, spread = float(np.mean(d)), float(np.std(d, ddof=1))
    return bool(mean > spread), mean, spread


@dataclass
class Candidate:
    name: str
    effect: FittedEffect
    base: list[FittedEffect]
    sse_test: float
    sse_reference: float
    n_eff: float
    score: float
    p_value: float
    accepted: bool
    prediction: np.ndarray = field(repr=False, default=None)  # type: ignore[arg-type]  # always given
    k: int = 0  # parameters it adds to the round's reference (its own and new base terms)
    k_total: int = 0  # parameters of the whole fit
    #: held-out SSE of the base refitted from the candidate's own fit, without it (a later
    #: round's check, `_beyond_its_start`; None where not made)
    sse_from_its_start: float | None = None
    #: held-out gain over the round's reference per time block, mean and spread (`margin`)
    block_gain: tuple[float, float] | None = None

    def ranking_entry(self, gap_after: float) -> dict:
        """The candidate as the report ranks it (a linear change of the mechanics by the
        name of the mode it moves, `force.mechanics_name`; a friction form by the friction
        it stands for, `FittedEffect.named_as`)."""
        effect = mechanics_name(self.effect)
        entry = {
            "effect": effect.named_as,
            "form": effect.name,
            "gap_after": gap_after,
            "score": self.score,
            "p_value": self.p_value,
            "accepted": self.accepted,
            "params": dict(self.effect.physical),
        }
        if self.block_gain is not None:
            entry["block_gain"], entry["block_spread"] = self.block_gain
        if self.sse_from_its_start is not None:
            entry["base_from_its_fit_sse_ratio"] = self.sse_from_its_start / self.sse_reference
        return entry


def effective_samples(e: np.ndarray, max_lag: int = 200) -> float:
    """n / τ, τ the integrated autocorrelation time of e."""
    e = np.asarray(e, float) - np.mean(e)
    n = len(e)
    var = float(e @ e)
    if var == 0.0 or n < 4:
        return float(n)
    spec = np.fft.rfft(e, 2 * n)
    acf = np.fft.irfft(spec * np.conj(spec))[: min(max_lag, n - 1) + 1] / var
    tau = 1.0
    for rho in acf[1:]:
        if rho < 0.05:
            break
        tau += 2.0 * rho
    return n / tau


def evaluate(
    name: str,
    ctx: Context,
    base: list[FittedEffect],
    base_cols: np.ndarray | None,
    sse_reference: float,
    n_eff: float,
) -> Candidate:
    """Fit ``name`` on top of ``base`` and judge it on the held-out part (n_eff: effective
    samples of the residual it has to explain, the same for every candidate of a round)."""
    eff, refitted = fit_effect(name, ctx, base, base_cols)
    effects = refitted + [eff]
    if ctx.form == "simulation" and any(e.name in FORCE_EFFECTS for e in effects):
        if SPECS[name].param is not None and name in FORCE_EFFECTS:
            eff = _search_in_the_loop(ctx, effects)
            effects = refitted + [eff]
        effects, prediction = in_the_loop(ctx, effects, base)
        refitted, eff = effects[:-1], effects[-1]
    else:
        x_new = columns(SPECS[name], eff.param, ctx, ctx.regressors(SPECS[name], eff.param))
        xx = x_new if base_cols is None else np.column_stack([base_cols, x_new])
        prediction = xx @ effect_coefficients(effects)
    sse1 = _sse(ctx, prediction, ctx.split.test)  # a force loop that diverges: inf
    k = eff.n_params + sum(e.n_params for e in refitted if e.name not in {b.name for b in base})
    k_total = eff.n_params + sum(b.n_params for b in refitted)
    score, p, pays = _judged(sse_reference, sse1, k, k_total, n_eff)
    map_share(refitted + [eff])
    return Candidate(
        name,
        eff,
        refitted,
        sse1,
        sse_reference,
        n_eff,
        score,
        p,
        pays and possible(refitted + [eff]),
        prediction,
        k,
        k_total,
    )


def _judged(
    sse0: float, sse1: float, k: int, k_total: int, n_eff: float
) -> tuple[float, float, bool]:
    """A fit with held-out SSE ``sse1`` and ``k`` parameters more (``k_total`` in all)
    against one with ``sse0`` (module docstring): (Δ score, F-test p, whether it pays:
    p < ALPHA, Δ score < 0 and at least MIN_REDUCTION of sse0 removed)."""
    dof = n_eff - k_total
    if sse1 <= 0.0:
        score, p = -math.inf, 0.0
    elif math.isinf(sse1):
        score, p = math.inf, 1.0
    else:
        score = n_eff * math.log(sse1 / sse0) + k * math.log(max(n_eff, 2.0))
        p = (
            float(stats.f.sf(((sse0 - sse1) / k) / (sse1 / dof), k, dof))
            if dof > 1 and sse1 < sse0
            else 1.0
        )
    return float(score), p, bool(p < ALPHA and score < 0.0 and sse1 <= (1.0 - MIN_REDUCTION) * sse0)


def _sse(ctx: Context, prediction: np.ndarray, part: np.ndarray) -> float:
    """The SSE of a fit's contribution on a part of the record (``ctx.split.fit`` or
    ``.test``); inf where its loop diverged."""
    with np.errstate(over="ignore", invalid="ignore"):
        e = (ctx.target - prediction)[part]
        sse = float(e @ e)
    return sse if math.isfinite(sse) else math.inf


#: static maps whose φ = N(w) − w must enter with the gain of the signal w they map: the
#: input (a saturation, dead zone, backlash) or the output (a sensor's clip); each with the
#: key of its fitted coefficient in ``physical``
MAPS = {
    "input_saturation": "input_gain",
    "dead_zone": "input_gain",
    "backlash": "input_gain",
    "output_saturation": "gain",
}


def map_share(effects: list[FittedEffect]) -> None:
    """A saturation, dead zone or backlash is the input map N itself: the plant sees
    (1 + r) N(u) = (1 + r) u + (1 + r) [N(u) − u], r the numerator refit's gain
    (``linear_refit``, 0 without it); a sensor that clips maps the output the same way,
    sat((1 + r) ŷ₀) = (1 + r) ŷ₀ + (1 + r) [sat'(ŷ₀) − ŷ₀]. The fitted coefficient c of
    φ = N(w) − w (an input map's referred to the input, `effects.physical_report`) is the
    map's share s = c / (1 + r): 1 for the effect, 0 for none. A share far from 1 is another
    map: s < 0 turns a saturation into a gain that *rises* with amplitude and a dead zone
    into one that falls; 0 < s ≪ 1 is a gain that changes a little with amplitude, not a
    signal that stops (saturation), moves nothing (dead zone) or has play (backlash). The
    effect being added (the last of ``effects``) is plausible only within SHARE_RANGE, the
    tolerance of a dead time's shift share; a map named in an earlier round keeps its name
    when a later effect takes over part of it (its share is reported, in ``physical``, for
    every map). Where the refit reverses the nominal input path (1 + r ≤ 0) no map has a
    share, and a set that holds one is not physically possible: the rig's 3.4 N Coulomb
    friction under 0.4 V kept an input saturation beside the friction on a base whose
    input gain was −0.05 (r = −1.05), a gain that rises with amplitude."""
    r = next((e.physical.get("input_gain", 0.0) for e in effects if e.name == "linear_refit"), 0.0)
    new = effects[-1]
    for e in effects:
        if e.name in MAPS and 1.0 + r <= 0.0:
            e.physical["plausible"] = False  # the refit reversed the input: no map's share
        elif e.name in MAPS and MAPS[e.name] in e.physical:
            share = e.physical[MAPS[e.name]] / (1.0 + r)
            e.physical["map_share"] = share
            if e is new:
                e.physical["plausible"] = bool(
                    e.physical.get("plausible", True) and SHARE_RANGE[0] <= share <= SHARE_RANGE[1]
                )


def _search_in_the_loop(ctx: Context, effects: list[FittedEffect]) -> FittedEffect:
    """The searched parameter of a force effect (the last of ``effects``) again, with the
    motion in the loop: its feed-forward search saw the nominal motion only. Each grid
    value gets a loop fit (a short one misleads; the joint step only at the value chosen,
    in `evaluate`); the lowest training error wins."""
    new = effects[-1]
    spec = SPECS[new.name]
    best = (math.inf, new)
    assert spec.grid is not None and new.param is not None  # a searched effect
    grid = np.append(spec.grid(ctx), new.param)
    for value in grid[np.isfinite(grid) & (grid > 0)]:
        trial = replace(new, param=float(value))
        _, pred = in_the_loop(ctx, effects[:-1] + [trial], joint=False)
        sse = _sse(ctx, pred, ctx.split.fit)  # a diverging loop: inf, not chosen
        if sse < best[0]:
            best = (sse, trial)
    return best[1]


def nested_p_value(larger: Candidate, smaller: Candidate, n_eff: float) -> float:
    """F-test of a candidate against one it contains: do its extra parameters pay?"""
    extra = larger.k - smaller.k
    dof = n_eff - larger.k_total
    if extra <= 0 or dof <= 1 or larger.sse_test >= smaller.sse_test:
        return 1.0
    f_stat = ((smaller.sse_test - larger.sse_test) / extra) / (larger.sse_test / dof)
    return float(stats.f.sf(f_stat, extra, dof))


def nested_in(name: str) -> tuple[str, ...]:
    """The candidates that ``name`` contains (`NESTS`; a force effect: the loop's spring)."""
    inner = (NESTS[name],) if name in NESTS else ()
    return inner + (
        ("stiffness_change",) if name in FORCE_EFFECTS and name != "stiffness_change" else ()
    )


def _beats_nested(ctx: Context, larger: Candidate, smaller: Candidate, n_eff: float) -> bool:
    """The larger of a nested pair is better: its extra numbers pay (nested F-test at ALPHA)
    and it beats the smaller by the margin of the held-out blocks (`margin`)."""
    return (
        nested_p_value(larger, smaller, n_eff) < ALPHA
        and margin(ctx, smaller.prediction, larger.prediction)[0]
    )


def _choose(ctx: Context, results: list[Candidate], n_eff: float) -> Candidate | None:
    """The candidate named in a round (``results`` sorted by score), or None.

    From the best accepted, nested pairs are walked: down to a contained candidate that
    the larger does not beat significantly (nested F-test at ALPHA; BIC alone
    under-rewards extra parameters when n_eff is small, and a larger effect that only
    scores level with the smaller one explains nothing more), up to an accepted one that
    significantly beats it. A linear change of the mechanics that adds damping is viscous
    friction (`force.mode_shift`), whose own fit is named. When the walk ends at a
    candidate that is not accepted, the next best accepted is tried."""
    by_name = {c.name: c for c in results}
    pool = [c for c in results if c.accepted]
    while pool:
        best = pool[0]
        for _ in range(len(results)):
            down = next(
                (
                    by_name[s]
                    for s in nested_in(best.name)
                    if s in by_name and not _beats_nested(ctx, best, by_name[s], n_eff)
                ),
                None,
            )
            up = (
                None
                if down
                else next(
                    (
                        c
                        for c in pool
                        if best.name in nested_in(c.name) and _beats_nested(ctx, c, best, n_eff)
                    ),
                    None,
                )
            )
            if down is None and up is None:
                break
            better = down or up
            assert better is not None
            best = better
        if (
            best.name == "stiffness_change"
            and best.effect.physical.get("mode_change") == "damping"
            and best.effect.physical.get("damping_change_per_s", 0.0) > 0.0
        ):
            best = by_name.get("viscous_friction", best)
        if best.accepted:
            return best
        pool.pop(0)
    return None


@dataclass
class Selection:
    chosen: list[FittedEffect]
    rounds: list[list[Candidate]]
    prediction: np.ndarray  # Σ contributions of the chosen effects (whole record)
    linear: dict = field(default_factory=dict)  # the refit check (`linear_round`)
    spring: dict = field(default_factory=dict)  # the base spring's check (`spring_check`)
    #: effects named in a round that the later ones hold (`_each_pays_on_top`)
    held_by_later: list[dict] = field(default_factory=list)
    #: rounds whose best candidate did not beat another by the margin (`_runner_up`)
    ambiguous: list[dict] = field(default_factory=list)

    @property
    def named(self) -> list[FittedEffect]:
        return [e for e in self.chosen if e.name not in BASE_TERMS]


#: what a significant numerator refit may be: a pure gain change, a pure shift, or a change
#: of one parameter of the nominal mode (`mode_lines`: damping, stiffness, mass)
LINEAR_EXPLANATIONS = ("gain_fault", "dead_time", "mode_damping", "mode_stiffness", "mode_mass")
#: share of the refit's improvement a gain or a shift must account for to be what the refit
#: is (more than half: the refit's main content)
MATCH_SHARE = 0.5
#: the same for a mode line: nearly all of it. The nominal model's own mismatch at another
#: excitation moves the mode too (the rig's fault-free records: the mass line takes 55–68 %
#: of the refit), and so does a heavy friction's describing function (on top of the
#: friction, the damping line takes 56–73 % of what the refit adds on rig variant v1); a
#: real change of the mechanics accounts for the refit (the rig's dampers and payloads on
#: five rig variants: 99–123 %; on top of the seal's friction 97–100 %)
LINE_MATCH_SHARE = 0.9


def match_share(name: str) -> float:
    """The share of the refit's improvement the explanation ``name`` must exceed to match."""
    return LINE_MATCH_SHARE if name in MODE_LINES else MATCH_SHARE


def linear_round(
    ctx: Context, floor_sse: float | None = None, explain: str | None = None
) -> tuple[list[FittedEffect], np.ndarray, dict]:
    """The refit never swallows an effect silently.

    The nominal numerator refit (``linear_refit``) is judged like a candidate. When it is
    significant, a pure gain change (``gain_fault``, y = (1 + g) ŷ₀), a pure shift
    (``dead_time``, ŷ₀(t − τ)) and a change of one parameter of the nominal mode
    (``mode_damping``, ``mode_stiffness``, ``mode_mass``: `mode_lines`) are tried: the
    best one that the refit does not beat
    (nested F-test at ALPHA) and that leaves no more than the noise floor (floor_sse; a
    dead zone or a saturation also looks like a lower gain, but leaves its nonlinear part)
    is named with its value and replaces the refit. Otherwise the refit stays in the base and
    is reported (``linear_check``: ``unexplained``, or the explanations tried, with
    their values).

    An explanation that is accepted like a candidate and accounts for more than
    MATCH_SHARE of what the refit removes (``refit_share``; a mode line LINE_MATCH_SHARE)
    is the refit's main content
    even when the refit beats it (the rest: the nominal model's own imperfection, or a
    nonlinearity of the plant the linear model lacks); it is reported as ``matching``, and
    `select_effects` names it (``explain``: named here, in the refit's place).
    """
    test = ctx.split.test
    e0 = ctx.target[test]
    sse0 = float(e0 @ e0)
    n_eff = effective_samples(e0)
    refit = evaluate("linear_refit", ctx, [], None, sse0, n_eff)
    out: dict[str, Any] = {
        "refit_significant": refit.accepted,
        "refit_p_value": refit.p_value,
        "refit_sse_ratio": refit.sse_test / sse0 if sse0 > 0 else 1.0,
        "explanations": [],
    }
    if not refit.accepted:
        return [refit.effect], refit.prediction, out
    simple, matching = [], []
    removed = sse0 - refit.sse_test
    for name in LINEAR_EXPLANATIONS:
        try:
            c = evaluate(name, ctx, [], None, sse0, n_eff)
        except NotApplicable:
            continue
        p_refit = nested_p_value(refit, c, n_eff)
        share = (sse0 - c.sse_test) / removed if removed > 0 else 0.0
        out["explanations"].append(
            {
                "effect": name,
                "sse_ratio": c.sse_test / sse0,
                "p_value": c.p_value,
                "refit_beats_it_p": p_refit,
                "refit_share": share,
                "params": dict(c.effect.physical),
            }
        )
        if name == explain:
            simple = [c]
            break
        if c.accepted and p_refit >= ALPHA and (floor_sse is None or c.sse_test <= floor_sse):
            simple.append(c)
        elif c.accepted and share > match_share(name):
            matching.append(c)
    if simple:
        best = min(simple, key=lambda c: c.sse_test)
        out["named"] = best.name
        return [best.effect], best.prediction, out
    if matching:
        out["matching"] = min(matching, key=lambda c: c.sse_test).name
    out["unexplained"] = not matching and not any(
        x["p_value"] < ALPHA and x["refit_beats_it_p"] >= ALPHA for x in out["explanations"]
    )
    return [refit.effect], refit.prediction, out


def select_effects(
    ctx: Context,
    max_effects: int = MAX_EFFECTS,
    progress=None,
    refit_linear: bool = False,
    floor_sse: float | None = None,
    explain: str | None = None,
) -> Selection:
    """Rounds of candidate search; see the module docstring.

    refit_linear: the nominal model's numerator is refitted jointly with every candidate
    (``linear_refit``, part of the base: an imperfect Ĝ, or one fitted on data that hold the
    effect, otherwise makes linear stand-ins look significant), after `linear_round` has
    checked that the refit is not a gain change or a dead time; in the inverse-dynamics
    form the force balance's mass and damping (``force_balance``). A base term alone is
    not a missing effect: it is dropped when nothing is named. floor_sse: the held-out SSE
    at the noise floor (`floor`); once the remaining error is there, no further effect is
    looked for.

    When the refit check found a gain, a shift or a mode line that matches the refit
    without replacing it (``matching``), the refit never swallows it:
    - nothing named on top of the refit: the rounds run again with the match named in the
      refit's place (``explain``); the effects then named on top of it are fitted again
      without it (`_without_explanation`), and when it does not pay on top of them it is
      theirs and not named (``held_by``);
    - an effect E named in the first round on top of the refit: right after that round
      the match is named first, E refitted on top of it, where it still matches on top of
      E (`_matching_on_top`); otherwise E holds it and the refit stays in the base.
    """
    chosen, base_cols, prediction, linear = _starting_base(ctx, refit_linear, floor_sse, explain)
    rounds: list[list[Candidate]] = []
    ambiguous: list[dict] = []
    spring: dict = {}
    test = ctx.split.test
    skip = set(LINEAR_EXPLANATIONS) if refit_linear else set()
    while len([e for e in chosen if e.name not in BASE_TERMS]) < max_effects:
        reference, refit_base = _round_reference(ctx, chosen, prediction, bool(rounds))
        e0 = ctx.target[test] - reference[1][test]
        sse0 = float(e0 @ e0)
        if rounds and floor_sse is not None and sse0 <= floor_sse:
            chosen, prediction = reference
            break  # what is left is noise
        n_eff = effective_samples(e0)
        results = _round(ctx, chosen, base_cols, reference, sse0, n_eff, skip, progress)
        rounds.append(results)
        best, reference = _named_in_round(ctx, results, n_eff, reference, refit_base)
        if best is None:
            chosen, prediction = reference
            break
        tie = _runner_up(ctx, results, best)
        if tie is not None:
            ambiguous.append(tie)
        by_mode = [mechanics_name(e) for e in best.base + [best.effect]]
        if linear.get("matching") and explain is None and len(rounds) == 1:
            # the first effect named on top of the refit, whose main content the check found
            # to be a gain, a shift or a mode line (before the base's spring check)
            if _stands_for(linear["matching"]) in {e.named_as for e in by_mode}:
                # the effect named is the change the check found, read by the loop's free
                # path (the loop's spring reading a mass): one effect, one name, read on
                # the line, which has no free numerator to bend the mode with; the base
                # is still the refit alone, so the rounds run again with the line (below)
                break
            held = _matching_on_top(ctx, by_mode, best, linear, floor_sse)
            if held is not None:
                held.rounds = rounds + held.rounds
                return held
        chosen, prediction, check = spring_check(ctx, by_mode, best.prediction, floor_sse, linear)
        spring = check or spring
        base_cols = effect_columns(ctx, chosen)
    if (
        linear.get("matching")
        and explain is None
        and not any(e.name not in BASE_TERMS for e in chosen)
    ):
        # nothing but the refit: name what it matches
        return select_effects(
            ctx, max_effects, progress, refit_linear, floor_sse, explain=linear["matching"]
        )
    return _after_the_rounds(
        ctx, chosen, prediction, rounds, linear, spring, ambiguous, explain, floor_sse
    )


def _starting_base(
    ctx: Context, refit_linear: bool, floor_sse: float | None, explain: str | None
) -> tuple[list[FittedEffect], np.ndarray | None, np.ndarray, dict]:
    """The base the first round starts from (`select_effects`): nothing; with
    ``refit_linear`` the force balance's refit (inverse dynamics) or what `linear_round`
    leaves (the refit or its explanation; ``explain`` named in the refit's place). Returns
    (effects, their columns, their contribution over the record, the refit check)."""
    chosen: list[FittedEffect] = []
    base_cols = None
    prediction = np.zeros_like(ctx.target)
    linear: dict = {}
    if refit_linear and ctx.form == "inverse_dynamics":
        balance, _ = fit_effect("force_balance", ctx)
        chosen = [balance]
    elif refit_linear:
        chosen, prediction, linear = linear_round(ctx, floor_sse, explain)
    if chosen:
        base_cols = effect_columns(ctx, chosen)
        prediction = base_cols @ effect_coefficients(chosen)
    return chosen, base_cols, prediction, linear


def _round_reference(
    ctx: Context, chosen: list[FittedEffect], prediction: np.ndarray, later: bool
) -> tuple[tuple[list[FittedEffect], np.ndarray], bool]:
    """The reference a round's candidates are judged against, (effects, contribution), and
    whether it is the base refitted: in a ``later`` round whose base holds a loop, the base
    given the fit each candidate gets on top of it (its loop refitted from where it stands,
    `in_the_loop`): what the loop's fit reaches by itself is no candidate's. A refit that is
    not physically possible is no base (the effects named stay as their round fitted
    them)."""
    reference = (chosen, prediction)
    refit_base = later and ctx.form == "simulation" and any(e.name in LOOPED for e in chosen)
    if refit_base:
        reference = _possible_or(in_the_loop(ctx, chosen, chosen), reference)
    return reference, refit_base


def _round(
    ctx: Context,
    chosen: list[FittedEffect],
    base_cols: np.ndarray | None,
    reference: tuple[list[FittedEffect], np.ndarray],
    sse0: float,
    n_eff: float,
    skip: set[str],
    progress,
) -> list[Candidate]:
    """One round: every candidate not yet in ``chosen`` (nor contained in an effect there,
    nor in ``skip``; ``stiffness_change`` not where the loop's spring is in) fitted on top
    of it (`evaluate`) and accepted only where it also beats the ``reference`` by the
    margin of the held-out blocks (`margin`) and stands for an effect not named yet.
    Returns the candidates sorted by score (best first)."""
    has_spring = any(e.name in SPRINGS for e in chosen)  # the loop's spring is in
    taken = {e.name for e in chosen} | {NESTS.get(e.name) for e in chosen}
    named_so_far = {e.named_as for e in chosen}
    remaining = [
        c
        for c in ctx.candidates
        if c not in taken and c not in skip and not (has_spring and c == "stiffness_change")
    ]
    results = []
    for name in remaining:
        try:
            results.append(evaluate(name, ctx, chosen, base_cols, sse0, n_eff))
        except NotApplicable:
            pass
        if progress is not None:
            progress(name)
    for c in results:
        beats, gain, spread = margin(ctx, reference[1], c.prediction)
        c.block_gain = (gain, spread)
        c.accepted = c.accepted and beats and c.effect.named_as not in named_so_far
    results.sort(key=lambda c: c.score)
    return results


def _named_in_round(
    ctx: Context,
    results: list[Candidate],
    n_eff: float,
    reference: tuple[list[FittedEffect], np.ndarray],
    refit_base: bool,
) -> tuple[Candidate | None, tuple[list[FittedEffect], np.ndarray]]:
    """The candidate a round names (`_choose`), or None, and the round's reference. Where
    the reference is the base refitted (``refit_base``), the candidate must also pay
    beyond its start (`_beyond_its_start`); where it does not, the base's loop from the
    candidate's start did it: that fit of the base becomes the reference when it fits the
    training part better, the candidate is not accepted and the next one is tried."""
    best = _choose(ctx, results, n_eff)
    while best is not None and refit_base:
        pays, there = _beyond_its_start(ctx, best)
        if pays:
            break
        reference = min(
            reference,
            _possible_or(there, reference),
            key=lambda fit: _sse(ctx, fit[1], ctx.split.fit),
        )
        best.accepted = False
        best = _choose(ctx, results, n_eff)
    return best, reference


def _matching_on_top(
    ctx: Context,
    by_mode: list[FittedEffect],
    best: Candidate,
    linear: dict,
    floor_sse: float | None,
) -> Selection | None:
    """Is the refit's main content, which the check found to be a gain, a shift or a mode
    line (``linear["matching"]``), still that on top of the effects the first round named
    (``by_mode``, named by the mode they move; ``best`` the candidate named)? Asked right
    after the first round, before the base's spring check: that can take a change of the
    mechanics that a mode line reads, and then no room is left for the line. Where it
    still matches on top of them (`_explanation_on_top`), the selection with the match
    named first and the effects refitted on top of it (the refit check's ``named`` and
    ``on_top_of``); None where they hold it (a friction's describing function or a static
    map's Bussgang gain also looks like a gain change): the refit stays in the base."""
    named = [e.name for e in by_mode if e.name not in BASE_TERMS]
    refit = next(e for e in by_mode if e.name == "linear_refit")
    held = _explanation_on_top(
        ctx, named, linear["matching"], best.prediction, refit.n_params, floor_sse
    )
    if held is not None:
        held.linear = {
            **linear,
            "named": linear["matching"],
            "on_top_of": [e.named_as for e in held.named if e.name != linear["matching"]],
        }
        held.linear.pop("matching")
    return held


def _after_the_rounds(
    ctx: Context,
    chosen: list[FittedEffect],
    prediction: np.ndarray,
    rounds: list[list[Candidate]],
    linear: dict,
    spring: dict,
    ambiguous: list[dict],
    explain: str | None,
    floor_sse: float | None,
) -> Selection:
    """The selection after the rounds (`select_effects`): each effect named before a force
    effect must still pay on top of it (`_each_pays_on_top`); effects named on top of an
    explanation of the refit (``explain``) are fitted again without it
    (`_without_explanation`: where it does not pay on top of them it is theirs, not named,
    ``held_by``); nothing named leaves the model as it was (a refit alone is not a missing
    effect); a round's tie is reported while its named effect is kept."""
    held_by_later: list[dict] = []
    if explain is None:
        chosen, prediction, held_by_later = _each_pays_on_top(ctx, chosen, prediction)
    others = [e.name for e in chosen if e.name not in BASE_TERMS and e.name != explain]
    if explain is not None and others:
        alone = _without_explanation(ctx, others, prediction, explain, floor_sse)
        if alone is not None:
            linear["held_by"] = others  # the gain or shift is theirs: not named
            linear["matching"] = linear.pop("named", explain)
            return Selection(alone.chosen, rounds + alone.rounds, alone.prediction, linear)
    if not any(e.name not in BASE_TERMS for e in chosen):
        # nothing named: the model stays as it was (a refit alone is not a missing effect)
        chosen, prediction = [], np.zeros_like(ctx.target)
    # a round's tie is reported while its named effect is kept (`_each_pays_on_top`)
    kept = {mechanics_name(e).named_as for e in chosen}
    ambiguous = [tie for tie in ambiguous if tie["effects"][0] in kept]
    return Selection(chosen, rounds, prediction, linear, spring, held_by_later, ambiguous)


def _runner_up(ctx: Context, results: list[Candidate], best: Candidate) -> dict | None:
    """The round is ambiguous when the best accepted candidate with another name (neither
    containing the other, `nested_in`) is not beaten by ``best`` by the margin (`margin`):
    both are reported, with their held-out gaps; the best is added (the gap shown shrinks),
    its name is not a decision the data made."""
    name = mechanics_name(best.effect).named_as
    for c in results:
        other = mechanics_name(c.effect).named_as
        if (
            c is best
            or not c.accepted
            or other == name
            or c.name in nested_in(best.name)
            or best.name in nested_in(c.name)
        ):
            continue
        beats, gain, spread = margin(ctx, c.prediction, best.prediction)
        if beats:
            return None
        y = ctx.target + ctx.y0
        gaps = [
            float(nrmse(y[ctx.split.test], (ctx.y0 + k.prediction)[ctx.split.test]))
            for k in (best, c)
        ]
        return {"effects": [name, other], "gaps": gaps, "block_gain": gain, "block_spread": spread}
    return None


def _each_pays_on_top(
    ctx: Context, chosen: list[FittedEffect], prediction: np.ndarray
) -> tuple[list[FittedEffect], np.ndarray, list[dict]]:
    """Backward elimination: an effect named before a force effect must still pay on top of
    it, as a candidate would (`_judged`), with the others' loop refitted from where it
    stands without it (`in_the_loop`, as `_beyond_its_start` refits a base). A later
    friction can take over an earlier effect's work: the rig's pure Coulomb friction of
    3.4 N under a small excitation (0.4 V) named an input saturation first, the friction's
    loop alone stuck where it pushes the motion; on top of the map it fitted, and refitted
    from there without the map it does as well (held-out SSE 43.78 against 43.81). Springs
    are the spring check's (`spring_check`). Returns ``chosen`` and its prediction without
    the first effect that does not pay, when its set is physically possible, and what was
    dropped (``held_by_later``)."""
    named = [e for e in chosen if e.name not in BASE_TERMS]
    if ctx.form != "simulation" or not any(e.name in LOOPED for e in named[1:]):
        return chosen, prediction, []
    test = ctx.split.test
    sse_with = _sse(ctx, prediction, test)
    k_total = sum(e.n_params for e in chosen)
    for first in named[:-1]:
        if first.name in SPRINGS:
            continue
        rest = [e for e in chosen if e is not first]
        effects, without = in_the_loop(ctx, rest, rest)
        sse_without = _sse(ctx, without, test)
        if not (math.isfinite(sse_without) and possible(effects)):
            continue
        e0 = ctx.target[test] - without[test]
        _, p, pays = _judged(sse_without, sse_with, first.n_params, k_total, effective_samples(e0))
        if not pays:
            held = {
                "effect": first.named_as,
                "p_value": p,
                "held_by": [e.named_as for e in named if e is not first],
                "sse_with": sse_with,
                "sse_without": sse_without,
            }
            return [mechanics_name(e) for e in effects], without, [held]
    return chosen, prediction, []


def _possible_or(
    fit: tuple[list[FittedEffect], np.ndarray], fallback: tuple[list[FittedEffect], np.ndarray]
) -> tuple[list[FittedEffect], np.ndarray]:
    """``fit`` (effects, contribution) where its effects are physically possible, else
    ``fallback``: a refit of the base whose loop ends where a friction pushes the motion
    is no model of the record, and what a round names must be physically possible."""
    return fit if possible(fit[0]) else fallback


def _stands_for(explanation: str) -> str:
    """The effect an explanation of the refit check (`linear_round`) is named as: a mode
    line the change of the mechanics it reads (`mode_lines.LINES`), a gain or a shift
    itself."""
    return LINES[MODE_LINES[explanation]] if explanation in MODE_LINES else explanation


def _beyond_its_start(
    ctx: Context, cand: Candidate
) -> tuple[bool, tuple[list[FittedEffect], np.ndarray]]:
    """Does ``cand`` pay on top of the base as the candidate's own fit left it? A later
    round's candidate moves the base's loop to another start before the joint fit, and the
    base refitted from there without it (`force.in_the_loop`) may do as well: then what
    the candidate "explains" is the start, not an effect (the same argument as E alone in
    `_explanation_on_top`). The candidate must pass the round's tests (F-test at ALPHA,
    ΔBIC < 0, MIN_REDUCTION) against the better of the round's reference and that refit;
    the held-out SSE of the refit is kept in ``cand.sse_from_its_start``. Returns whether
    it pays, and the base so refitted (effects, contribution)."""
    there = in_the_loop(ctx, cand.base, cand.base)
    cand.sse_from_its_start = _sse(ctx, there[1], ctx.split.test)
    reference = min(cand.sse_reference, cand.sse_from_its_start)
    pays = _judged(reference, cand.sse_test, cand.k, cand.k_total, cand.n_eff)[2]
    # and by the margin of the held-out blocks over that refit too (`margin`)
    return pays and margin(ctx, there[1], cand.prediction)[0], there


def _fit_set(
    ctx: Context, names: list[str], base: list[FittedEffect]
) -> tuple[list[FittedEffect], np.ndarray, float]:
    """``names`` fitted in turn on top of ``base`` (jointly refitted, whatever their
    plausibility): (effects, contribution over the record, held-out SSE)."""
    test = ctx.split.test
    chosen = list(base)
    prediction = np.zeros_like(ctx.target)
    base_cols = None
    if chosen:
        base_cols = effect_columns(ctx, chosen)
        prediction = base_cols @ effect_coefficients(chosen)
    for name in names:
        e0 = ctx.target[test] - prediction[test]
        c = evaluate(name, ctx, chosen, base_cols, float(e0 @ e0), effective_samples(e0))
        chosen = c.base + [c.effect]
        base_cols = effect_columns(ctx, chosen)
        prediction = c.prediction
    e = ctx.target[test] - prediction[test]
    return chosen, prediction, float(e @ e)


def _explanation_on_top(
    ctx: Context,
    named: list[str],
    explain: str,
    prediction: np.ndarray,
    refit_params: int,
    floor_sse: float | None,
) -> Selection | None:
    """Effects ``named`` with the refit in the base (``prediction``; the refit has
    ``refit_params`` numbers), whose refit the check found to be mostly a gain or a shift
    (``explain``): is it still that on top of them? The three nested fits E ⊂ E +
    explanation ⊂ E + refit on the held-out part: the explanation is named (a Selection of
    it and E, E refitted on top of it) when the refit adds to E significantly (F-test at
    ALPHA: a share of next to nothing is no match), and the explanation pays on top of E
    (F-test at ALPHA) and accounts for more than `match_share` of what the refit adds to E
    (MATCH_SHARE; a mode line LINE_MATCH_SHARE, as alone).
    E alone is also E's loop as fitted on top of the explanation, refitted from there
    without it (an explanation that only moved the loop's start explains nothing). E on
    top of the explanation is refitted as the rounds name effects (`_physical_on_top`):
    the larger of a nested pair that is not physically possible there is replaced by the
    smaller (a Stribeck excess that pushes the motion once the gain has taken its part:
    Coulomb friction). The share is always
    of what the refit adds to E as named: the smaller effect with the explanation must
    account for more than that share of the way from E alone to E with the refit (the
    smaller effect alone starts further away and would make any pair look like a match).
    On top of E the explanation must change the model the way it did alone (`_direction`):
    a gain that turns from a loss into a rise is a remainder of E's fit, not the change the
    check found (a dead zone's Bussgang gain: 0.867 alone, 1.018 on top of the map).
    Otherwise (None) E holds the apparent gain or shift (a friction's describing function,
    a static map's Bussgang gain) and the refit stays in the base."""
    test = ctx.split.test
    e_refit = ctx.target[test] - prediction[test]
    sse_refit = float(e_refit @ e_refit)
    try:
        first, _, _ = linear_round(ctx, floor_sse, explain)
        if first[0].name != explain:
            return None
        on_top = _physical_on_top(ctx, named, first)
        if on_top is None:
            return None
        names, chosen, pred, sse_with = on_top
        if _direction(next(e for e in chosen if e.name == explain)) != _direction(first[0]):
            return None  # E took the change the check found, and more: E holds it
        _, _, sse_alone = _fit_set(ctx, names, [])
        sse_named = sse_alone if names == named else _fit_set(ctx, named, [])[2]
    except NotApplicable:
        return None
    if ctx.form == "simulation" and any(e.name in LOOPED for e in chosen):
        # E's loop as fitted on top of the explanation is a fit of E too: refitted from
        # there without it, E must not do as well (a loop's fit depends on where it starts,
        # and an explanation that only moved the start explains nothing)
        rest = [e for e in chosen if e.name != explain]
        sse_there = _sse(ctx, in_the_loop(ctx, rest, rest)[1], test)
        if math.isfinite(sse_there):
            sse_alone = min(sse_alone, sse_there)
            if names == named:
                sse_named = sse_alone
    n_eff = effective_samples(ctx.target[test])
    k = first[0].n_params
    dof = n_eff - sum(e.n_params for e in chosen)
    dof_refit = n_eff - refit_params - sum(e.n_params for e in chosen if e.name != explain)
    if sse_with >= sse_alone or sse_refit >= sse_named or min(dof, dof_refit) <= 1:
        return None  # nothing to explain: the refit adds nothing to E on held-out data
    p_refit = float(
        stats.f.sf(
            ((sse_named - sse_refit) / refit_params) / (sse_refit / dof_refit),
            refit_params,
            dof_refit,
        )
    )
    p = float(stats.f.sf(((sse_alone - sse_with) / k) / (sse_with / dof), k, dof))
    share = (sse_named - sse_with) / (sse_named - sse_refit)
    if p_refit >= ALPHA or p >= ALPHA or share <= match_share(explain):
        return None
    return Selection(chosen, [], pred, {})


def _direction(explanation: FittedEffect) -> float:
    """Which way an explanation of the refit changes the model: a gain up or down, a mode
    line's parameter up or down (+1, −1); a shift is always a delay."""
    if explanation.name == "gain_fault":
        return float(np.sign(explanation.physical["gain_ratio"] - 1.0))
    if explanation.name in MODE_LINES:
        assert explanation.param is not None  # a mode line's ratio
        return float(np.sign(explanation.param - 1.0))
    return 1.0


def _physical_on_top(
    ctx: Context, named: list[str], first: list[FittedEffect]
) -> tuple[list[str], list[FittedEffect], np.ndarray, float] | None:
    """The effects ``named`` refitted on top of ``first`` (`_fit_set`), each the smaller of
    its nested pair (`NESTS`) when the set is not physically possible there (the rounds
    never name an effect that is not): (names, effects, contribution, held-out SSE), or
    None when no such set is possible.
    The explanation ``first`` was judged alone, against the refit (`linear_round`); on top
    it keeps that judgement: its coefficient trades with the effects fitted beside it (a
    shift's c, set by the second-order term of c·(ŷ₀(t − τ) − ŷ₀(t)): a dead time of two
    samples on rig variant v0 read c 1.47 alone, 1.57 beside the seal's friction), and
    whether the refit is still the explanation is the share and the F-tests' question."""
    explanation = first[0]
    smaller = [NESTS.get(n, n) for n in named]
    for names in [named, smaller] if smaller != named else [named]:
        chosen, pred, sse = _fit_set(ctx, names, first)
        if possible([e for e in chosen if e.name != explanation.name]):
            for e in chosen:
                if e.name == explanation.name:
                    e.physical["plausible"] = explanation.physical.get("plausible", True)
            return names, [mechanics_name(e) for e in chosen], pred, sse
    return None


def _without_explanation(
    ctx: Context, names: list[str], prediction: np.ndarray, explain: str, floor_sse: float | None
) -> Selection | None:
    """The effects ``names`` named on top of a gain or a shift (``explain``), fitted again
    without it: a friction's describing function or a map's Bussgang gain also looks like
    a gain change. The selection without the explanation when it names the same effects
    and the explanation does not pay on top of them (F-test at ALPHA, its parameters
    against the held-out SSE); None when it does."""
    alone = select_effects(replace(ctx, candidates=tuple(names)), len(names), floor_sse=floor_sse)
    if sorted(e.name for e in alone.named) != sorted(names):
        return None
    test = ctx.split.test
    e_with = ctx.target[test] - prediction[test]
    e_alone = ctx.target[test] - alone.prediction[test]
    sse_with, sse_alone = float(e_with @ e_with), float(e_alone @ e_alone)
    n_eff = effective_samples(ctx.target[test])
    k = 1 + (SPECS[explain].param is not None)  # a gain: 1; a shift: its share and τ
    k_total = k + sum(e.n_params for e in alone.chosen)
    dof = n_eff - k_total
    if sse_with >= sse_alone or dof <= 1:
        return alone
    f_stat = ((sse_alone - sse_with) / k) / (sse_with / dof)
    return alone if float(stats.f.sf(f_stat, k, dof)) >= ALPHA else None


def spring_check(
    ctx: Context,
    chosen: list[FittedEffect],
    prediction: np.ndarray,
    floor_sse: float | None,
    linear: dict,
) -> tuple[list[FittedEffect], np.ndarray, dict]:
    """The loop's spring never swallows a change of the mechanics silently.

    Every force effect brings the loop's spring (``loop_stiffness``, §4.3), unnamed. After
    a round that leaves it in ``chosen``, the other effects are fitted again without it
    (`force.in_the_loop`, ``spring=False``); when the spring pays on top of them as a
    candidate would (F-test at ALPHA, ΔBIC < 0, at least MIN_REDUCTION of the held-out
    error energy), the error without it is above the noise floor and there is room for one
    more effect (MAX_EFFECTS), it is a change of the mechanics, named as in a round
    (`_choose`): ``viscous_friction`` (its own fit, the spring beside it, as every force
    effect has) when that is physically possible (adds damping, moves the mode by damping)
    and pays on top of the spring's fit; otherwise the spring by what it does to the mode
    (`force.mode_shift`): ``stiffness_change`` or ``mass_change``, when the data's linear
    part moves the mode along that line and the same way (``linear``: the refit check,
    `linear_round`; a spring softer where the stiffness line reads the mode stiffer, or a
    mass where the refit is the damping line that a heavy friction's describing function
    holds, is the friction loop's correction, not a change of the mechanics), and when
    that change is not named already (one effect, one name). With a fitted baseline the
    spring stays in the base, as ``stiffness_change`` is not a candidate there (the
    baseline holds the linear effects). Returns ``chosen`` (the spring renamed, or the
    damper added, when named), its prediction and the figures of the check ({} when there
    was nothing to check)."""
    spring = next((e for e in chosen if e.name == "loop_stiffness"), None)
    if (
        spring is None
        or "stiffness_change" not in ctx.candidates
        or ctx.form != "simulation"
        or len([e for e in chosen if e.name not in BASE_TERMS]) >= MAX_EFFECTS
    ):
        return chosen, prediction, {}
    rest = [e for e in chosen if e is not spring]
    check, judged = _spring_pays(ctx, chosen, spring, prediction, floor_sse)
    if judged is None:
        return chosen, prediction, check
    damper = _damper_beside_the_spring(ctx, rest, *judged)
    if damper is not None:
        check.update(named=True, damper=True)
        return damper[0], damper[1], check
    matching = linear.get("matching")
    change = check["mode_change"]
    check["named"] = (
        change in MECHANICS
        and MECHANICS[change] not in {e.named_as for e in rest}
        and (matching not in MODE_LINES or matching == f"mode_{change}")
    )
    if check["named"]:
        # the refit check's line, where it tried it, must read the change the same way
        check["line_ratio"] = line = _line_ratio(linear, change)
        check["named"] = (
            line is None or (line - 1.0) * (spring.physical[f"{change}_ratio"] - 1.0) > 0.0
        )
    if not check["named"]:
        return chosen, prediction, check
    named = replace(spring, name=MECHANICS[change], physical={**spring.physical, "plausible": True})
    return rest + [named], prediction, check


def _spring_pays(
    ctx: Context,
    chosen: list[FittedEffect],
    spring: FittedEffect,
    prediction: np.ndarray,
    floor_sse: float | None,
) -> tuple[dict, tuple[float, float, int] | None]:
    """Does the loop's ``spring`` pay on top of the other effects of ``chosen``, fitted
    again without it (`force.in_the_loop`, ``spring=False``), as a candidate would
    (`_judged`), with the error without it above the noise floor (``floor_sse``)? Returns
    the check's figures and, where it does, (held-out SSE with it, n_eff, the parameters
    of ``chosen``); None where it does not."""
    rest = [e for e in chosen if e is not spring]
    _, without = in_the_loop(ctx, rest, rest, spring=False)
    test = ctx.split.test
    e0 = ctx.target[test] - without[test]
    e1 = ctx.target[test] - prediction[test]
    sse0, sse1 = float(e0 @ e0), float(e1 @ e1)
    if not (math.isfinite(sse0) and sse1 < sse0):  # without it the loop diverges, or worse
        return {"named": False, "pays": False}, None
    n_eff = effective_samples(e0)
    k_total = sum(e.n_params for e in chosen)
    if n_eff - k_total <= 1:
        return {"named": False, "pays": False}, None
    score, p, pays = _judged(sse0, sse1, spring.n_params, k_total, n_eff)
    check: dict[str, Any] = {
        "p_value": p,
        "score": score,
        "sse_ratio": sse1 / sse0,
        "above_floor": floor_sse is None or sse0 > floor_sse,
        "mode_change": spring.physical.get("mode_change"),
    }
    if not (pays and check["above_floor"]):
        check["named"] = False
        return check, None
    return check, (sse1, n_eff, k_total)


def _line_ratio(linear: dict, change: str) -> float | None:
    """The ratio (``<change>_ratio``) that the refit check (`linear_round`) read on the mode
    line of ``change`` ("stiffness", "mass"), None where it did not try that line."""
    return next(
        (
            x["params"][f"{change}_ratio"]
            for x in linear.get("explanations", [])
            if x["effect"] == f"mode_{change}"
        ),
        None,
    )


def _damper_beside_the_spring(
    ctx: Context, rest: list[FittedEffect], sse_spring: float, n_eff: float, k_total: int
) -> tuple[list[FittedEffect], np.ndarray] | None:
    """``rest`` with a viscous friction in the loop (the spring beside it), when that is
    physically possible and pays on top of the spring's fit (held-out SSE ``sse_spring``,
    ``k_total`` parameters): the spring's free numerator can carry a damper, and the
    friction's free path beside it can bend its mode towards another reading (the rig's
    load damping × 2 read as a mass × 0.835, `git show b57fd1a:docs/diagnose.md` §9)."""
    width = len(ctx.a_dom)
    damper = FittedEffect("viscous_friction", None, [np.zeros(width)], n_linear=width, n_free=width)
    effects, prediction = in_the_loop(ctx, rest + [damper], rest)
    _, _, pays = _judged(
        sse_spring,
        _sse(ctx, prediction, ctx.split.test),
        damper.n_params,
        k_total + damper.n_params,
        n_eff,
    )
    return (effects, prediction) if pays and possible(effects) else None
