"""What the gap diagnosis returns: the scored candidates, the diagnosis, and its account in words.

:class:`RankedCandidate` is one catalogue candidate scored on held-out data; :class:`Diagnosis` holds
the verdict, the ranking, the decomposition of the held-out error, the gap map and the parameter-change
test (:func:`dynid.diagnosis.core.diagnose` makes it); :func:`verdict_text` says it in a few lines.
"""

from __future__ import annotations

import math
import shlex
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dynid._io import to_jsonable
from dynid.diagnosis.candidates import Candidate, describe_hyper, excitation_hint, settling_motion
from dynid.validation.metrics import NoiseFloor

__all__ = [
    "QUIET_EXCESS",
    "Diagnosis",
    "RankedCandidate",
    "heldout_needed",
    "settling_excitation",
    "undecided_joints",
    "verdict_text",
]


@dataclass(frozen=True, eq=False)
class RankedCandidate:
    """A scored candidate: the best variant of one effect on one joint (or joint pair).

    Attributes
    ----------
    candidate : Candidate
        Effect, joint(s) and tuned hyper-parameters.
    gain : float
        Reduction of the held-out loss ``sum_j r_j^2 / sigma_j^2`` per sample (in noise variances), on
        the joints it acts on (the tested figure).
    gain_all : float
        The same reduction summed over every joint: an effect that the shared base parameters spread to
        other joints also mends them there.  Like ``gain``, on the footing that decided the candidate
        (``refit["footing"]``); the choice among acceptable candidates uses the training footing's.
    closure : float
        ``sum_j (MSE_before_j - MSE_after_j) / noise_j`` over ``sum_j (MSE_before_j - noise_j) / noise_j``
        on its joint(s), held-out (per joint, in noise variances).
    p_value, p_holm : float
        One-sided Diebold-Mariano p-value and its value adjusted for the candidates tested (Holm in two
        families: :func:`dynid.diagnosis.stats.screened_holm`).
    significant : bool
        ``p_holm < alpha`` and the gain is relevant (``gain >= min_gain``).
    round : int
        Selection round in which it was scored (0: on the baseline).
    accepted : bool
        Part of the verdict.
    confounded_with : list of str
        Candidates whose columns are nearly parallel to its own (not separable with this excitation).
    angle_deg : float or None
        Smallest principal angle (degrees) to the nearest other candidate.
    training_evidence : float
        Log p-value of the Wald test of its coefficients on the training residual (block covariance):
        how strongly the training data alone point at it (:func:`dynid.diagnosis.stats.wald_logp`).
    training_rank : int or None
        Its rank (1: first) by that evidence, in the round it was scored.
    """

    candidate: Candidate
    gain: float
    closure: float
    p_value: float
    p_holm: float = 1.0
    significant: bool = False
    round: int = 0
    accepted: bool = False
    confounded_with: list[str] = field(default_factory=list)
    angle_deg: float | None = None
    mse_joint: NDArray[np.float64] | None = None
    refit: dict[str, Any] = field(default_factory=dict)
    loss: NDArray[np.float64] | None = field(default=None, repr=False)  # (m, n): per sample and joint
    n_columns: int = 0
    gain_all: float = float("nan")
    training_evidence: float = 0.0
    training_rank: int | None = None

    def to_dict(self) -> dict[str, Any]:
        c = self.candidate
        return {
            "effect": c.effect,
            "joint": (c.joint + 1)
            if c.joint is not None
            else ([j + 1 for j in c.joints] if c.joints else None),
            "closure": _num(self.closure),
            "p_value": _num(self.p_holm),
            "p_raw": _num(self.p_value),
            "significant": bool(self.significant),
            "gain": _num(self.gain),
            "gain_all_joints": _num(self.gain_all),
            "accepted": bool(self.accepted),
            "round": self.round,
            "hyper": {k: float(v) for k, v in c.hyper.items()},
            "confounded_with": list(self.confounded_with),
            "angle_deg": _num(self.angle_deg),
            "refit": self.refit,
            "training_rank": self.training_rank,
        }


def _num(v) -> float | None:
    if v is None:
        return None
    v = float(v)
    return v if math.isfinite(v) else None


@dataclass(eq=False)
class Diagnosis:
    """What :func:`diagnose` found.

    Attributes
    ----------
    verdict : list of str
        Accepted effect names, ``["none"]`` or ``["unexplained"]``.
    accepted : list of RankedCandidate
        The accepted effects, in the order they were selected.
    ranking : list of RankedCandidate
        Every candidate scored on the baseline (round 0), best first.
    decomposition : dict
        Held-out MSE per joint (N^2 m^2): ``model`` (as given), ``refit`` (baseline re-identified),
        ``after`` (with the accepted effects), ``noise``; and the parts ``parametric``, ``attributed``,
        ``unexplained``; ``closure`` per joint and ``closure_overall``.
    gap_map : dict
        Residual excess over the noise floor per joint and bin, global flags (see
        :func:`dynid.diagnosis.gapmap.gap_map`).
    parametric : dict
        The parameter-change test.
    noise : NoiseFloor
        Held-out noise floor.
    excess : dict
        Excess of the baseline over the noise floor: ``ratio`` (per joint and overall), ``p_value``,
        ``significant``.
    notes : list of str
        Confounded candidates and the motion that would separate them; other remarks.
    provisional : bool
        The verdict is ``"unexplained"`` on a noise floor estimated from the spectrum (the held-out data do
        not repeat a period), a lower bound when the noise is coloured, so the excess may be overstated,
        and the check that does not rest on the floor (``remainder``) does not confirm it.  "None" and
        accepted effects are not provisional on such a floor: a lower floor can only overstate the gap.
    undecided : list of RankedCandidate
        When no effect is accepted: candidates that would close at least ``min_closure`` of their
        joints' gap and pass the test on their own (raw p below ``alpha``) but not once every candidate
        tested is accounted for, or not by ``min_gain``; most promising first (at most three).  The
        held-out run has too little of the motion that shows them: a recording of that motion decides.
    remainder : dict or None
        What a flexible state model, fitted without each held-out fold, predicts of the final model's
        residual there (:mod:`dynid.diagnosis.remainder`: ``p_joint``, ``share``, ``gain``,
        ``predictable_joint``): evidence that does not rest on the noise floor.  Computed when the verdict
        is ``"unexplained"`` or the floor is not measured; None otherwise.
    consistency : dict or None
        Whether the training and held-out runs agree on the baseline's parameters
        (:mod:`dynid.diagnosis.consistency`: ``cost``, ``null_mean``, ``p_joint`` (Holm-adjusted across
        the joints), ``p_raw`` (per joint), ``lead_joint``, ``lead_cost``, ``noise_source``): a joint in
        ``lead_joint`` makes the verdict "unexplained" when no effect is accepted; evidence that does not
        rest on the noise floor.
    lack_of_fit : dict or None
        Whether the training refit's residual repeats across the training run's periods beyond noise
        (:mod:`dynid.diagnosis.lack_of_fit`: ``ratio``, ``null_mean``, ``misfit`` (noise variances),
        ``p_raw``, ``p_joint``, ``state_estimation``, ``quantisation_factor``, ``lead_joint``,
        ``lead_misfit``, ``periods``, ``curve`` (the residual over the period, for the report)): a joint in
        ``lead_joint``
        makes the verdict "unexplained" when no effect is accepted; evidence on the training run alone.
        None when the training run does not repeat two whole periods.
    """

    verdict: list[str]
    accepted: list[RankedCandidate]
    ranking: list[RankedCandidate]
    decomposition: dict[str, Any]
    gap_map: dict[str, Any]
    parametric: dict[str, Any]
    noise: NoiseFloor
    excess: dict[str, Any]
    notes: list[str]
    joint_names: list[str]
    settings: dict[str, Any]
    residuals: dict[str, Any] = field(default_factory=dict, repr=False)
    provisional: bool = False
    undecided: list[RankedCandidate] = field(default_factory=list)
    remainder: dict[str, Any] | None = None
    consistency: dict[str, Any] | None = None
    lack_of_fit: dict[str, Any] | None = None

    def to_dict(self) -> dict[str, Any]:
        """The JSON-ready figures (``gap_map``, ``ranking``, ``verdict``, ``parametric``, and more)."""
        return to_jsonable(
            {
                "verdict": list(self.verdict),
                "provisional": self.provisional,
                "ranking": [r.to_dict() for r in self.ranking],
                "accepted": [r.to_dict() for r in self.accepted],
                "undecided": [r.to_dict() for r in self.undecided],
                "remainder": self.remainder,
                "consistency": self.consistency,
                "lack_of_fit": self.lack_of_fit,
                "gap_map": self.gap_map,
                "parametric": self.parametric,
                "decomposition": self.decomposition,
                "noise_floor": {
                    "std": self.noise.std.tolist(),
                    "method": self.noise.method,
                    "detail": self.noise.detail,
                    # The floor's own precision: None where unknown (a spectral lower bound).
                    "rel_se": None if self.noise.rel_se is None else self.noise.rel_se,
                    "std_interval_95": [v.tolist() for v in self.noise.std_interval(0.95)],
                },
                "excess": self.excess,
                "notes": list(self.notes),
                "joint_names": list(self.joint_names),
                "settings": self.settings,
            }
        )

    def summary(self) -> str:
        """The verdict and the gap in plain words."""
        return verdict_text(self)


def _describe_refit(r: RankedCandidate) -> str:
    """The fitted physical parameters of an accepted effect, in words."""
    eff = r.refit.get("effective")
    if not eff:
        return describe_hyper(r.candidate)
    e = r.candidate.effect
    if e == "delay":
        return f"delay {1000 * eff['d']:.2g} ms"
    if e == "elasticity":
        bound = (
            ", at an end of the searched range: the data do not pin the resonance down"
            if r.refit.get("at_bound")
            else ""
        )
        return (
            f"stiffness {r.refit['stiffness']:.3g} N m/rad, resonance {r.refit['frequency_hz']:.3g} Hz{bound}"
        )
    if "h" in eff:
        teeth = (
            f", in teeth of stiffness {r.refit['stiffness']:.3g} N m/rad, resonating at {r.refit['frequency_hz']:.3g} Hz"
            if "stiffness" in r.refit
            else ""
        )
        # The filtered torque sees when the teeth change sides, not how far they travel: the half gap and
        # the stiffness trade off (a 0.5 mrad half gap on a simulated UR5 wrist was fitted as 0.09 mrad).
        return (
            f"effective half gap {1000 * eff['a']:.2g} mrad, the teeth changing sides {1000 * eff['d']:.2g} ms "
            f"after the transmitted torque passes {eff['h']:.2g} N m{teeth}"
        )
    return f"half gap {1000 * eff['a']:.2g} mrad"


def heldout_needed(d: Diagnosis) -> float | None:
    """Seconds of held-out data of the same kind that would make the best undecided candidate significant.

    An undecided candidate (:attr:`Diagnosis.undecided`) would close enough of its joints' gap but is not
    significant once every candidate tested is accounted for.  Its held-out gain grows with the length of
    the run and its standard deviation with the square root, so its z-score grows as ``sqrt(T)``: the run
    that reaches the threshold of the top candidate of its family (``alpha / 2K`` among the ``K``
    candidates the training data rank first, else ``alpha / 2m`` among all ``m``; one-sided) is
    ``T (z_needed / z_now)^2``, with a margin of 1.5 for the chance that this run's z-score was lucky.
    None when there is no undecided candidate, or when its gain per sample is below ``min_gain``: no run
    of the same motion raises it, only a motion that shows the effect more
    (:func:`~dynid.diagnosis.candidates.settling_motion`).
    """
    from scipy.stats import norm

    if not d.undecided or not d.ranking:
        return None
    top = d.undecided[0]
    if top.gain < float(d.settings.get("min_gain", 0.15)):
        return None
    t = np.asarray(d.residuals.get("t", ()), dtype=float)
    if t.size < 2 or not (0 < top.p_value < 0.5):
        return None
    alpha = float(d.settings.get("alpha", 0.05))
    z_now = float(norm.isf(top.p_value))
    # The threshold of the family it is tested in: the candidates the training data rank first, or all
    # (each family at half the level, :func:`dynid.diagnosis.stats.screened_holm`).
    k = int(d.settings.get("screen_top", 0))
    if k <= 0:
        family = len(d.ranking)
    else:
        screened = top.training_rank is not None and top.training_rank <= k
        family = 2 * (k if screened else len(d.ranking))
    z_needed = float(norm.isf(alpha / family))
    return _seconds_to_significance(t, z_now, z_needed)


def _seconds_to_significance(t: NDArray[np.float64], z_now: float, z_needed: float) -> float:
    """Seconds of a run of the same kind as ``t`` at which a z-score of ``z_now`` on it reaches ``z_needed``:
    it grows as the square root of the run's length; a margin of 1.5 for the chance that this run's was lucky."""
    return float((t[-1] - t[0]) * max(1.0, (z_needed / z_now) ** 2) * 1.5)


def _tested_and_allowed(d: Diagnosis) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Each joint's held-out error as the excess test saw it and what the test allows for, both in noise
    variances (``1 + tolerance + state estimation``: the floor, the refit's misfit, quantised angles)."""
    ex = d.excess
    tested = np.asarray(ex.get("ratio_tested", ex.get("ratio", ())), dtype=float)
    zeros = np.zeros(tested.size)
    allow = 1 + np.asarray(ex.get("tolerance", zeros), dtype=float)
    allow = allow + np.asarray(ex.get("state_estimation", zeros), dtype=float)
    return tested, allow


QUIET_EXCESS = 0.5
"""Noise variances of held-out excess, beyond what the test allows for, that a joint may show without a
significant test and without a word: above it the summary says the gap there is not decided by this run."""


def undecided_joints(d: Diagnosis) -> list[int]:
    """Joints (0-based) whose held-out error stands above what noise explains by more than
    :data:`QUIET_EXCESS` noise variances, but not significantly, and that no accepted or undecided
    candidate accounts for: a gap this held-out run can neither confirm nor dismiss."""
    ratio, allow = _tested_and_allowed(d)
    if ratio.size == 0 or d.provisional:  # a floor that is only a lower bound inflates every ratio
        return []
    sig = np.asarray(d.excess.get("significant_joint", np.zeros(ratio.size, dtype=bool)), dtype=bool)
    covered: set[int] = set()
    for r in (*d.accepted, *d.undecided):
        covered.update(int(j) for j in (r.candidate.joints or range(ratio.size)))
    return [
        j
        for j in range(ratio.size)
        if not sig[j] and ratio[j] > allow[j] + QUIET_EXCESS and j not in covered
    ]


def _quiet_seconds(d: Diagnosis, joints: list[int]) -> float | None:
    """Seconds of held-out data of the same kind at which the largest such joint's excess would test
    significant (its z-score grows as the square root of the run's length), with a margin of 1.5."""
    from scipy.stats import norm

    t = np.asarray(d.residuals.get("t", ()), dtype=float)
    p = np.asarray(d.excess.get("p_joint", ()), dtype=float)
    if t.size < 2 or p.size == 0:
        return None
    z_now = max(float(norm.isf(min(max(p[j], 1e-300), 1.0))) for j in joints)
    if not z_now > 0.5:  # no sign of it in the test: no length of the same run is sure to show it
        return None
    z_needed = float(norm.isf(float(d.settings.get("alpha", 0.05)) / max(p.size, 1)))
    return _seconds_to_significance(t, z_now, z_needed)


def settling_excitation(
    d: Diagnosis, *, robot: str, dq_max, rate: float, out: str = "heldout_excitation"
) -> dict[str, Any] | None:
    """The ``dynid excite`` command whose recording, held out, would settle an undecided or provisional
    verdict; None when the verdict is neither.

    An undecided candidate (:attr:`Diagnosis.undecided`, the first) gets the motion that shows it
    (:func:`~dynid.diagnosis.candidates.settling_motion`: Stribeck friction a slow joint, a temperature
    drift a long run), for at least three periods and at least :func:`heldout_needed`; a provisional
    verdict gets three periods of a new excitation, so that the noise floor is measured.

    Parameters
    ----------
    d : Diagnosis
    robot : str
        The robot as ``dynid excite --robot`` takes it (a built-in name or a description file).
    dq_max : array_like, shape (n,)
        The robot's speed limits (rad/s).
    rate : float
        Sample rate of the recording (Hz): the controller rate of the excitation's CSV.
    out : str
        Stem of the excitation's files (``out.json``, ``out.csv``).

    Returns
    -------
    dict or None
        ``reason`` (one sentence), ``heldout_seconds`` (or None), ``candidate`` (its key, or None),
        ``excite`` (the command), ``csv`` (the file to play on the robot) and ``play`` (how, as a comment
        line).
    """
    lead = d.undecided[0] if d.undecided else None
    quiet = undecided_joints(d) if lead is None else []
    if lead is None and not d.provisional and not quiet:
        return None
    need = heldout_needed(d) if lead is not None else (_quiet_seconds(d, quiet) if quiet else None)
    options: dict[str, Any] = {}
    if lead is None and quiet:
        names = ", ".join(d.joint_names[j] for j in quiet)
        reason = (
            f"Not decided: {names} show more error than the noise floor explains, not significantly on this "
            "held-out run and closed by no candidate; a held-out run of a new motion decides"
            + (f" (at least {need:.0f} s of it)." if need else ".")
        )
    elif lead is not None:
        cutoff = (d.settings.get("preprocessing") or {}).get("cutoff_hz")
        options, why = settling_motion(lead.candidate, dq_max, cutoff_hz=cutoff, period=10.0)
        # A motion aimed at the effect decides it; a new run of the default kind only may.
        verb = "would decide" if options else "may decide"
        reason = f"Undecided: {lead.candidate.label}. A held-out run with {why} {verb}" + (
            f" (or about {need:.0f} s of held-out data of the same kind)." if need else "."
        )
    else:
        reason = "Provisional: the held-out data do not repeat a period, so the noise floor is a lower bound."
    base_freq = float(options.get("base_freq", 0.1))  # excite's default: a 10 s period
    periods = max(3, int(options.get("periods", 3)), math.ceil((need or 0.0) * base_freq))
    extra = ""
    if "dq_max" in options:
        extra += " --dq-max " + ",".join(_at_most(v) for v in options["dq_max"])
    if "harmonics" in options:
        extra += f" --harmonics {int(options['harmonics'])}"
    csv = f"{out}.csv"
    excite = (
        f"dynid excite --robot {shlex.quote(robot)} --criterion cond --seed 11 --base-freq {base_freq:g}{extra} "
        f"--out {shlex.quote(out + '.json')} --csv {shlex.quote(csv)} --rate {rate:.6g} --periods {periods}"
    )
    return {
        "reason": reason,
        "heldout_seconds": need,
        "candidate": lead.candidate.key if lead is not None else None,
        "excite": excite,
        "csv": csv,
        "play": f"# play {csv} on the robot (it rests 2 s at home at both ends); log t, q_i, tau_i to heldout.csv",
    }


def _at_most(v: float) -> str:
    """A limit printed with six digits, never above ``v`` (a rounded-up speed limit would be refused)."""
    text = f"{v:.6g}"
    return text if float(text) <= v else f"{math.floor(v * 1e5) / 1e5:.6g}"


def _share(closure: float) -> str:
    """What a candidate would close, in words: above 1 the joints' gap is smaller than what it removes."""
    if closure <= 1.0:
        return f"{100 * closure:.0f} % of the gap on its joint(s)"
    return f"more than the whole gap on its joint(s) ({100 * closure:.0f} %: that gap is small)"


def _undecided_text(d: Diagnosis) -> list[str]:
    """One line per undecided candidate: what it would close, and why it is not taken."""
    lines = []
    min_gain = float(d.settings.get("min_gain", 0.15))
    for r in d.undecided:
        why = (
            f"its gain, {r.gain:.2g} noise variances per sample, is below the {min_gain:g} asked of an effect"
            if r.gain < min_gain
            else f"not once the {len(d.ranking)} candidates tested are accounted for (adjusted p = "
            f"{r.p_holm:.2g})"
        )
        lines.append(
            f"Undecided: {r.candidate.label} would close {_share(r.closure)} and "
            f"passes the test on its own (p = {r.p_value:.2g}), but {why}.  The held-out run has too little of "
            f"the motion that shows it ({excitation_hint(r.candidate)}): a recording of that motion decides"
            + (
                f"; about {need:.0f} s of the same kind would too."
                if r is d.undecided[0] and (need := heldout_needed(d))
                else "."
            )
        )
    return lines


def _sensitivity_text(d: Diagnosis) -> list[str]:
    """What "none" means at this run's sensitivity, where a joint's error stands visibly above the floor
    but within what the tests allow for (the floor's own error, the refit's misfit, quantised angles)."""
    tested, allow = _tested_and_allowed(d)
    if tested.size == 0:
        return []
    covered = {j for r in d.undecided for j in (r.candidate.joints or range(tested.size))}
    covered.update(undecided_joints(d))
    near = [j for j in range(tested.size) if 1.25 < tested[j] <= allow[j] and j not in covered]
    if not near:
        return []
    names = ", ".join(
        f"{d.joint_names[j]} ({tested[j]:.2g} noise variances of held-out error, {allow[j]:.2g} allowed)" for j in near
    )
    return [
        f"At this run's sensitivity \"none\" leaves room for a small effect: {names} "
        f"{'stands' if len(near) == 1 else 'stand'} above the floor but "
        "within what the tests allow for (the floor's own error, the refit's misfit, quantised angles), and an "
        "effect that small is not told apart from them.  More held-out periods (a better-measured floor) "
        "narrow the allowance."
    ]


def verdict_text(d: Diagnosis) -> str:
    """Plain-words account of a diagnosis (a few lines)."""
    dec = d.decomposition
    lines = []
    ratio = d.excess["ratio_overall"]
    if d.verdict == ["none"]:
        lines.append(
            f"No significant gap: the re-identified model's held-out error is {ratio:.2f} times the noise floor "
            f"(p = {d.excess['p_value']:.2g}; mean squared error over the noise variance, samples near zero speed "
            "left out)."
        )
        lines.extend(_sensitivity_text(d))
    elif d.verdict == ["unexplained"]:
        if d.excess["significant"]:
            evidence = (
                f"the held-out error is {ratio:.2f} times the noise floor (significant; mean squared error over "
                "the noise variance, samples near zero speed left out)"
            )
        else:
            parts = []
            for doc, what in (
                (d.consistency, "the training and held-out runs disagree on the parameters of {}"),
                (d.lack_of_fit, "the training refit's residual repeats across the training periods on {}"),
            ):
                lead = [n for n, hit in zip(d.joint_names, (doc or {}).get("lead_joint", []), strict=False) if hit]
                if lead:
                    parts.append(what.format(", ".join(lead)))
            evidence = (
                " and ".join(parts) + " (evidence that does not rest on the noise floor; the held-out excess "
                "test, which lets the parameters move, is not significant)"
            )
        lines.append(
            f"Unexplained gap: {evidence}, and no candidate effect of the catalogue both closes enough of it and "
            "passes the significance test."
        )
        if d.ranking and not d.undecided:
            top = d.ranking[0]
            lines.append(
                f"The closest candidate, {top.candidate.label}, would close {100 * max(top.closure, 0):.0f} % of "
                "its joints' gap; that is not taken as the cause."
            )
    else:
        for r in d.accepted:
            hyper = _describe_refit(r)
            lines.append(
                f"{r.candidate.label}{' (' + hyper + ')' if hyper else ''}: closes {100 * r.closure:.0f} % of the "
                f"gap on its joint(s) (adjusted p = {r.p_holm:.2g})."
            )
        lines.append(
            f"Together the accepted effects close {100 * dec['closure_overall']:.0f} % of the gap overall."
        )
    lines.extend(_undecided_text(d))
    quiet = undecided_joints(d)
    if quiet:
        ratio, _ = _tested_and_allowed(d)
        need = _quiet_seconds(d, quiet)
        names = ", ".join(f"{d.joint_names[j]} ({ratio[j]:.2g} noise variances)" for j in quiet)
        lines.append(
            f"Not decided here: {names} show more error than the noise floor and the tests' allowances "
            "explain, but not significantly on this held-out run, and no candidate of the catalogue closes it. "
            "It may be an effect this run shows too little of (Stribeck friction needs slow motion, a "
            "temperature drift a long run): a held-out run of a new motion decides"
            + (f", at least {need:.0f} s of it" if need else "")
            + " (dynid diagnose prints the excitation that records it)."
        )
    est = np.asarray(d.excess.get("estimation", ()), dtype=float)
    # On a joint where the two runs disagree on the parameters, what the refit on the other folds
    # predicts is an effect the parameters absorb, not their uncertainty: said in the consistency note.
    disagree = (d.consistency or {}).get("lead_joint") or [False] * est.size
    loud = [j for j in range(est.size) if est[j] >= 0.25 and not disagree[j]]
    if loud:
        names = ", ".join(f"{d.joint_names[j]} ({est[j]:.2g})" for j in loud)
        lines.append(
            "The training data leave some parameters uncertain: their error adds, in noise variances, "
            f"{names} to the held-out error (the baseline refitted with the rest of the held-out run predicts "
            "it), and the tests allow for it.  An excitation designed for identification (dynid excite) "
            "would sharpen the diagnosis there."
        )
    state = np.asarray(d.excess.get("state_estimation", ()), dtype=float)
    if state.size and np.any(state >= 0.25):
        names = ", ".join(
            f"{d.joint_names[j]} ({state[j]:.2g})" for j in range(state.size) if state[j] >= 0.25
        )
        lines.append(
            "The angles are quantised (an encoder's step, read from their increments): velocities and "
            f"accelerations differentiated from them add, in noise variances, {names} to the held-out error; "
            "the excess test counts it as noise.  Angles logged at a finer resolution would sharpen the "
            "diagnosis."
        )
    sources = d.excess.get("explainable")
    if sources:
        lines.append("Counted as noise in the excess test: " + "; ".join(sources) + ".")
    par = d.parametric
    if par.get("finding") not in (None, "none"):
        lines.append(par["text"])
    lines.extend(d.notes)
    return "\n".join(lines)
