"""What the diagnosis concludes from its stages: the verdict, whether it is provisional, its notes, the
candidates the held-out run cannot decide, and the decomposition of the held-out error.

:func:`dynid.diagnosis.core.diagnose` runs the stages (the method, step 5, is described there); these
functions turn their records into the result's verdict and words.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dynid.diagnosis import baseline as bl
from dynid.diagnosis.candidates import excitation_hint
from dynid.diagnosis.consistency import Consistency
from dynid.diagnosis.lack_of_fit import LackOfFit
from dynid.diagnosis.refinement import fitted_delay
from dynid.diagnosis.remainder import Remainder
from dynid.diagnosis.result import RankedCandidate
from dynid.diagnosis.screening import Context, confound_note
from dynid.diagnosis.selection import Selection
from dynid.diagnosis.settings import DiagnosisSettings
from dynid.validation.metrics import NoiseFloor

__all__ = [
    "MEASURED_FLOORS",
    "UNDECIDED_SHOWN",
    "consistency_notes",
    "decomposition",
    "lack_of_fit_notes",
    "provisional_status",
    "remainder_notes",
    "small_candidate_notes",
    "undecided_candidates",
    "verdict_and_notes",
]


def consistency_notes(c: Consistency, alpha: float, joint_names: list[str], excess: bool) -> list[str]:
    """Under an "unexplained" verdict: the joints on which the two runs disagree on the baseline's
    parameters (:mod:`.consistency`), and what that says."""
    lead = np.flatnonzero(c.leads(alpha))
    if not lead.size:
        return []
    joints = ", ".join(
        f"{joint_names[j]} ({100 * c.cost[j]:.0f} % of its training residual, {c.cost[j] / c.null_mean[j]:.1f} "
        f"times what torque noise gives (noise modelled on the {c.noise_source}), p = {c.p_raw[j]:.2g}, "
        f"{c.p_joint[j]:.2g} adjusted across the joints)"
        for j in lead
    )
    return [
        "The training and held-out runs disagree on the baseline's parameters: refitted with the held-out "
        f"run, they fit the training run worse on {joints}.  An effect the model lacks, absorbed differently "
        "on two motions, does that; a parameter the training run leaves uncertain does not"
        + (
            "."
            if excess
            else (
                ", and the cross-fitted excess test, which lets the parameters move, does not see it: this "
                "evidence does not rest on the noise floor.  A floor measured across eight periods would "
                "also let the excess test weigh it: dynid simulate --periods 8, or dynid excite --csv "
                "--periods 8 played on the robot."
            )
        )
    ]


def lack_of_fit_notes(lack: LackOfFit | None, alpha: float, joint_names: list[str]) -> list[str]:
    """Under an "unexplained" verdict: the joints whose training residual repeats across the training
    periods beyond noise (:mod:`.lack_of_fit`), and what that says."""
    if lack is None:
        return []
    lead = np.flatnonzero(lack.leads(alpha))
    if not lead.size:
        return []
    joints = ", ".join(
        f"{joint_names[j]} ({lack.misfit[j]:.2g} noise variances, p = {lack.p_raw[j]:.2g}, "
        f"{lack.p_joint[j]:.2g} adjusted across the joints)"
        for j in lead
    )
    return [
        f"The training run holds {lack.periods:.2g} periods of its excitation, and the baseline refitted on it "
        f"leaves a residual that repeats with them on {joints}: what repeats is what the robot's state determines, and "
        "noise does not repeat (a lack-of-fit test against the spread across the periods).  Something the "
        "model lacks is in the training run; no catalogue effect was accepted for it.  This evidence rests on "
        "neither the held-out run nor the noise floor."
    ]


UNDECIDED_SHOWN = 3
"""Most undecided candidates a diagnosis reports."""


def undecided_candidates(
    ctx: Context, base: bl.Baseline, ranking: list[RankedCandidate], settings: DiagnosisSettings
) -> list[RankedCandidate]:
    """Candidates the held-out run cannot decide: they would close at least ``min_closure`` of their
    joints' gap and pass the test on their own (raw p below ``alpha``), but not after the correction for
    every candidate tested or not by ``min_gain``; largest gain first, as the ranking.  A timing mismatch shorter than one
    sample is the state estimation's (see :func:`~dynid.diagnosis.refinement.fitted_delay`), not a lead."""
    out = []
    for r in ranking:  # best gain first
        if len(out) == UNDECIDED_SHOWN:
            break
        if (
            r.significant
            or r.p_value >= settings.alpha
            or not r.gain > 0
            or not r.closure >= settings.min_closure
        ):
            continue
        if r.candidate.effect == "delay":
            d = fitted_delay(ctx, base.fit, r, ctx.tr.columns(r.candidate))
            if abs(d) < ctx.min_delay:
                continue
        out.append(r)
    return out


MEASURED_FLOORS = ("periods", "training periods")
"""Noise-floor methods that measure the noise (not a lower bound): a verdict on them is not provisional."""


def verdict_and_notes(
    sel: Selection,
    excess: dict[str, Any],
    consistency: Consistency,
    lack: LackOfFit | None,
    noise: NoiseFloor,
    base: bl.Baseline,
    settings: DiagnosisSettings,
    joint_names: list[str],
) -> tuple[list[str], list[str]]:
    """The verdict and the notes that go with it."""
    notes: list[str] = []
    if not base.settled:
        notes.append(
            f"The baseline refit's joint weights still moved by more than 5 % after {base.passes} reweighting "
            "passes: the split of the gap between joints is uncertain."
        )
    notes.extend(sel.notes)
    disagree = consistency.leads(settings.alpha)
    misfit = np.zeros_like(disagree) if lack is None else lack.leads(settings.alpha)
    if sel.accepted:
        verdict = [a.candidate.effect for a in sel.accepted]
    elif excess["significant"] or disagree.any() or misfit.any():
        verdict = ["unexplained"]
        notes.extend(consistency_notes(consistency, settings.alpha, joint_names, excess["significant"]))
        notes.extend(lack_of_fit_notes(lack, settings.alpha, joint_names))
        partial = [r for r in sel.ranking if r.significant]
        if partial:
            notes.append(
                "Significant but partial candidates ("
                + ", ".join(f"{r.candidate.label}: {100 * max(r.closure, 0):.0f} %" for r in partial[:3])
                + f" of the gap on their joints) close less than {100 * settings.min_closure:.0f} % of it: none "
                "is taken as the cause."
            )
    else:
        verdict = ["none"]
        notes.extend(small_candidate_notes(sel, excess, settings))
        _, high = noise.std_interval(0.95)
        reach = np.square(high / np.maximum(noise.std, 1e-300))
        if np.isfinite(reach).any():
            j = int(np.nanargmax(reach))
            notes.append(
                f"The floor is itself measured, from the spread across periods: its 95 % interval reaches "
                f"{reach[j]:.2g} times its variance (joint {j + 1}), so a held-out error up to about that "
                "many times the floor can be the floor's own error, not an effect; the excess test allows for "
                "it, so an effect of about that size can hide in it.  More periods narrow it: on simulated "
                "field recordings, eight periods measured it about twice as precisely as three "
                "(dynid simulate --periods, dynid excite --csv --periods)."
            )
    if noise.method == "training periods":
        notes.insert(
            0,
            "The held-out data do not repeat a period, so the noise floor is the training run's spread "
            "across its periods, at the same rate and through the same filter: this assumes the torque noise "
            "of the robot did not change between the two recordings.",
        )
    notes.extend(confound_note(a) for a in sel.accepted if a.confounded_with)
    return verdict, notes


def small_candidate_notes(sel: Selection, excess: dict[str, Any], settings: DiagnosisSettings) -> list[str]:
    """Under a "none" verdict: the candidates significant on their own that close too little to be named.

    A candidate can lower the held-out error beyond chance and still close less of its joints' gap than
    a cause must (``min_closure``, and half where no joint's excess is significant): a verdict of none
    beside a significant finding says why it is not named, and which motion would show it larger.
    """
    significant_joint = np.asarray(excess["significant_joint"], dtype=bool)
    notes = []
    for r in [r for r in sel.ranking if r.significant][:UNDECIDED_SHOWN]:
        joints = list(r.candidate.scored or range(significant_joint.size))
        on_significant = bool(significant_joint[joints].any())
        need = settings.min_closure if on_significant else max(settings.min_closure, 0.5)
        notes.append(
            f"{r.candidate.label} lowers the held-out error beyond chance (adjusted p = {r.p_holm:.2g}) but "
            f"closes {100 * max(r.closure, 0.0):.0f} % of the gap to the floor on its joints, less than the "
            f"{100 * need:.0f} % a cause must close"
            + ("" if on_significant else " where no joint's excess is significant")
            + ": it is not named.  If it is there, a recording with "
            + excitation_hint(r.candidate)
            + " would show it larger."
        )
    return notes


def provisional_status(
    verdict: list[str],
    measured: bool,
    remainder: Remainder | None,
    sel: Selection,
    excess: dict[str, Any],
    settings: DiagnosisSettings,
    mse_refit: NDArray[np.float64],
    floor_free: NDArray[np.bool_],
) -> tuple[bool, str]:
    """Does the verdict rest on a floor that is only a lower bound?  The answer, and why, in a clause.

    A spectral floor can only understate the noise, so the excess, and each joint's gap, are if anything
    overstated.

    * "None" stands: the excess is not significant even so.
    * Accepted effects stand when, on the joints they act on, they remove at least ``min_closure`` of the
      whole held-out error, each joint's error its own unit: that error bounds the joint's noise from
      above, so no floor enters (and their gain in noise variances is then at least ``min_closure``, above
      ``min_gain``).  The figures computed on the floor (the share of the gap, the gain) would otherwise
      rest on it, joint by joint.
    * "Unexplained" stands when the check that does not rest on the floor (:mod:`.remainder`) finds the
      residual predictable on a joint whose excess is significant, or evidence that no floor enters finds
      a joint (``floor_free``: the two runs disagree on its parameters, :mod:`.consistency`, or the training
      residual repeats across the training periods, :mod:`.lack_of_fit`), and no significant candidate
      was turned down for closing too little (the share it closes is understated on a lower floor: it might
      close enough).
    """
    if measured or verdict == ["none"]:
        return False, ""
    if sel.accepted:
        n = len(sel.mse)
        acting = sorted({j for a in sel.accepted for j in (a.candidate.joints or range(n))})
        before = np.maximum(mse_refit[acting], 1e-300)
        share = float(np.mean((before - sel.mse[acting]) / before))
        if share < settings.min_closure:
            return True, (
                f"on the joints they act on, the accepted effects remove {100 * share:.0f} % of the whole held-out "
                f"error, less than the {100 * settings.min_closure:.0f} % that would hold whatever the floor"
            )
        return False, ""
    partial = [r for r in sel.ranking if r.significant]
    if partial:
        return True, (
            f"{partial[0].candidate.label} is significant but closes too little of a gap that the floor may "
            "overstate"
        )
    confirmed = bool(np.any(floor_free)) or (
        remainder is not None
        and bool(np.any(remainder.predictable & np.asarray(excess["significant_joint"], dtype=bool)))
    )
    if not confirmed:
        return True, "the check that does not rest on the floor does not confirm the excess"
    return False, ""


def remainder_notes(
    verdict: list[str],
    measured: bool,
    provisional: tuple[bool, str],
    remainder: Remainder | None,
    joint_names: Sequence[str],
) -> list[str]:
    """What the floor-free check says, and why the verdict is or is not provisional."""
    notes = []
    if remainder is not None:
        hit = np.flatnonzero(remainder.predictable)
        after = "After the accepted effects, a" if verdict not in (["none"], ["unexplained"]) else "A"
        model = (
            f"{after} flexible state model (trees on q, dq, ddq), fitted for each held-out fold on the training "
            "run and the other folds, "
        )
        if hit.size:
            parts = ", ".join(
                f"{joint_names[j]} {100 * remainder.share[j]:.0f} % (adjusted p = {remainder.p_joint[j]:.2g})"
                for j in hit
            )
            tail = {
                "unexplained": "  Something the state predicts remains that no catalogue effect was accepted for.",
                "none": "  Something the state predicts remains, within what the excess test allows.",
            }.get(verdict[0], "  Something the state predicts remains beyond the accepted effects.")
            notes.append(model + f"predicts part of that fold's residual: {parts}." + tail)
        else:
            notes.append(
                model
                + "predicts no joint's residual significantly"
                + (
                    ": what is left behaves as noise or drift (a time-varying effect, or noise the floor "
                    "misses), or the held-out run is too short to show more (the check is less sensitive than "
                    "the excess test)."
                    if verdict == ["unexplained"]
                    else "."
                )
            )
    if measured:
        return notes
    is_provisional, why = provisional
    if is_provisional:
        notes.insert(
            0,
            "Provisional: the held-out data do not repeat a period, so the noise floor comes from the "
            "spectrum's high-frequency level, a lower bound when the noise is coloured, and the verdict may "
            f"rest on it ({why}).  Hold out at least three periods of a periodic excitation for a measured "
            "floor.",
        )
    elif verdict == ["unexplained"]:
        notes.insert(
            0,
            "The held-out data do not repeat a period, so the noise floor is the spectrum's lower bound.  "
            "The verdict does not rest on its level: a state model predicts the residual of a joint with a "
            "significant excess on held-out data it did not see.",
        )
    elif verdict == ["none"]:
        notes.insert(
            0,
            "The held-out data do not repeat a period, so the noise floor is the spectrum's lower bound.  A "
            "lower floor can only overstate the gap, and the excess is not significant even so: the verdict "
            "stands.",
        )
    else:
        notes.insert(
            0,
            "The held-out data do not repeat a period, so the noise floor is the spectrum's lower bound.  The "
            "verdict does not rest on its level: on the joints they act on, the accepted effects remove at "
            "least half of the whole held-out error (each joint's error its own unit, which bounds its noise "
            "from above).",
        )
    return notes


def decomposition(
    held: bl.HeldOutBaseline, sel: Selection, sigma: NDArray[np.float64], mask: NDArray[np.float64]
) -> dict[str, Any]:
    """Held-out MSE per joint of the model, the refit and the accepted effects, and the closure."""
    mse_base, L_base = held.mse, held.loss
    noise_var = sigma**2
    n = len(sigma)
    gap = mse_base - noise_var
    with np.errstate(divide="ignore", invalid="ignore"):
        closure_joint = np.where(gap > 0.05 * noise_var, (mse_base - sel.mse) / gap, np.nan)
    excess_base = float(np.mean(L_base) - np.mean(np.sum(mask, axis=1)))
    closure_all = (
        (float(np.mean(L_base)) - float(np.mean(sel.loss))) / excess_base if excess_base > 0 else float("nan")
    )
    accepted = bool(sel.accepted)
    mse_after = sel.mse if accepted else mse_base
    return {
        "mse_model": held.mse_model,
        "mse_refit": mse_base,
        "mse_after": mse_after,
        "noise": noise_var,
        "parametric": held.mse_model - mse_base,
        "attributed": mse_base - mse_after,
        "unexplained": np.maximum(mse_after - noise_var, 0.0),
        "closure": closure_joint if accepted else np.zeros(n),
        "closure_overall": closure_all if accepted else 0.0,
        "units": "N^2 m^2 (mean squared torque error on the filtered held-out data)",
    }
