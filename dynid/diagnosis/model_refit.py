"""From diagnosis to model: the identified model refitted with the effects the diagnosis accepted.

``dynid diagnose ... --out M2.json`` writes it.  The effects become model terms
(:mod:`dynid.identify.effect_terms`) identified with the link parameters, under the same settings as
the model (method, friction model, mixture, preprocessing, bounds), with the hyper-parameters the
diagnosis tuned.  Terms that the model already identifies (an offset or armature of its linear
friction and armature columns) and effects without a model term (a payload, which the base
parameters take in whole) are left out, and a note says so.

A delay goes in at the delay the diagnosis measured (its refit column's shift times its coefficient),
so that the term's coefficient is 1 where the refit agrees with the diagnosis; a refit whose
coefficient moves the delay by more than a quarter says so and why.

With the held-out data, an effect goes in only if it mends the model (:func:`refit_with_effects`):

1. cross-fitted, as the diagnosis scores its candidates (:class:`~dynid.diagnosis.crossfold.CrossFold`:
   the model's structure refitted on the training run and the other held-out folds, each fold predicted
   by the fit that did not see it), the term's columns *as the refit holds them* must lower the
   held-out error on the joints it acts on and raise no joint's RMS by more than ``max_rise``;
2. the refitted model itself must not raise any joint's held-out RMS by more than ``max_rise`` over the
   model before it; where it does, the effect acting on that joint (else the one whose removal mends
   it most) is left out and the model refitted, until none is raised or none is left (then the model
   stays as it is).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dynid.data.dataset import Dataset
from dynid.data.preparation import Preprocessing
from dynid.identify.effect_terms import Candidate
from dynid.identify.model import IdentifiedModel, identify

__all__ = ["MAX_RISE", "effect_spec", "identify_settings", "refit_with_effects"]

MAX_RISE = 0.02
"""Largest rise of any joint's held-out RMS (relative) that a refit with effects may cause."""

_MOVED = 0.25  # a refit coefficient further than this from 1 moves a measured delay: a note says so

_NOT_LINEAR_FORMS = (
    "elasticity",
    "backlash",
)  # their exact refit forms need the model's torque at other states


def identify_settings(model: IdentifiedModel) -> dict[str, Any]:
    """The keyword arguments of :func:`dynid.identify.model.identify` that made ``model`` (as far as the
    model file records them).

    Parameters
    ----------
    model : IdentifiedModel
        The model.
    """
    if model.friction_source == "layer1":
        friction = "linear"
    elif model.friction is None:
        friction = "none"
    else:
        friction = model.friction.model
    gmm: str | int = "off"
    gmm_mode = "position"
    if model.gmr is not None:
        gmm = "auto" if model.gmr.n_components == "auto" else int(model.gmr.n_components)
        gmm_mode = model.gmr.mode
    info = model.info
    return {
        "method": model.method,
        "friction": friction,
        "gmm": gmm,
        "gmm_mode": gmm_mode,
        "preprocessing": Preprocessing.from_settings(model.preprocessing),
        "armature": bool(model.columns.armature),
        "rounds": int(info.get("refinement", {}).get("rounds", 2)),
        "physical": bool(info.get("bounds", {}).get("physical", True)),
    }


def _measured_delay(effect: Any) -> float | None:
    """The delay (s) the diagnosis measured for an accepted delay (a RankedCandidate's refit), else None."""
    if getattr(effect, "candidate", effect).effect != "delay":
        return None
    refit = getattr(effect, "refit", None) or {}
    d = (refit.get("effective") or {}).get("d")
    return None if d is None or not math.isfinite(float(d)) else float(d)


def _as_term(effect: Any, notes: list[str]) -> Candidate:
    """The model term of an accepted effect (a Candidate, or a RankedCandidate with its refit figures)."""
    cand: Candidate = getattr(effect, "candidate", effect)
    hyper = dict(cand.hyper)
    if cand.effect in _NOT_LINEAR_FORMS:
        hyper.pop("exact", None)  # the first-order columns (tuned again on the training data)
        for key in ("w", "z", "h", "a", "d"):
            hyper.pop(key, None)
        notes.append(f"{cand.key}: identified through its first-order columns")
    elif cand.effect == "delay":
        d = _measured_delay(effect)
        if d is not None:
            # The diagnosis' refit column tau(t - theta) - tau(t) has a free coefficient c; the delay it
            # measured is theta c.  The term takes that delay, so its coefficient is 1 where the refit agrees.
            hyper = {"exact": 1.0, "d": d}
    return Candidate(cand.effect, cand.joint, cand.joints, hyper, cand.label)


def _delay_notes(refitted: IdentifiedModel, measured: set[str]) -> list[str]:
    """Where the refit's coefficient moves a delay the diagnosis measured (terms ``measured``, by key), by
    how much and why."""
    notes = []
    for fig in refitted.figures().get("effects", []):
        if fig["key"] not in measured:
            continue
        d = float(fig["hyper"]["d"])
        g = float(fig["coefficients"].get("g", 1.0))
        if abs(g - 1.0) <= _MOVED:
            notes.append(f"{fig['key']}: kept at the measured delay, {1000 * d:.3g} ms (coefficient {g:.2f})")
            continue
        notes.append(
            f"{fig['key']}: the diagnosis measured {1000 * d:.3g} ms; the refit's coefficient on the delayed "
            f"torque is {g:.2f}, so the model's delay is about {1000 * d * g:.3g} ms: identify sizes the term "
            "together with the link parameters under the model's own settings (method, joint weights, filter, "
            "its first fit's torque), which read the lag differently from the diagnosis' weighted refit"
        )
    return notes


def _heldout_rms(model: IdentifiedModel, heldout: Dataset) -> NDArray[np.float64]:
    """Held-out RMS per joint (N m), as ``dynid validate`` and ``diagnose --out`` print it."""
    import warnings

    from dynid.validation.validate import validate

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        v = validate(model, heldout)
    return np.sqrt(np.mean((v.tau - v.tau_pred) ** 2, axis=0))


def _crossfit_gate(
    model: IdentifiedModel,
    train: Dataset,
    heldout: Dataset,
    held: Sequence[Candidate],
    new: Sequence[Candidate],
    max_rise: float,
) -> tuple[list[Candidate], list[str]]:
    """The new terms that, cross-fitted beside one another, lower the held-out error on their joints, and
    notes on the others.

    The model's structure as the diagnosis refits it (:mod:`.baseline`), with the terms the model holds
    already, cross-fitted on the held-out folds as the diagnosis does (:class:`~dynid.diagnosis.crossfold.CrossFold`:
    training rows weighted as the baseline refit weighs them, held-out rows by the inverse noise floor);
    the new terms' columns, built as the refit holds them, are added beside it.  Backward elimination:
    while some term does not lower the mean square on the joints it acts on against the same set without
    it, the one that lowers it least is left out.  The terms are judged together, not one by one: through
    the shared link parameters one term can shift the error of a joint that another term mends (a delay on
    every joint: its joint-4 term alone raised joint 1's cross-fitted error by 15 %, beside joint 1's own
    term it did not).  What the refitted model does to the other joints is checked on the model itself
    (:func:`refit_with_effects`).
    """
    from dynid.diagnosis import baseline as bl
    from dynid.diagnosis.core import heldout_noise_floor
    from dynid.diagnosis.crossfold import CrossFold
    from dynid.diagnosis.fitting import mse, predict
    from dynid.diagnosis.settings import DiagnosisSettings
    from dynid.exceptions import DataError

    settings = DiagnosisSettings()
    structure = bl.model_structure(model, None, train, heldout)
    tr_s = bl.sample(structure, train, settings)
    ho_s = bl.sample(structure, heldout, settings)
    base = bl.refit_baseline(tr_s)
    tr = bl.side(tr_s, structure, base.x)
    ho = bl.side(ho_s, structure, base.x)
    n = ho.y.shape[1]
    try:
        sigma = np.asarray(heldout_noise_floor(tr.prep, ho.prep, None).std, dtype=float)
    except DataError:  # no floor: the baseline's held-out level weighs the joints instead
        sigma = np.sqrt(mse(ho.y - predict(ho.X0, base.x, None, None), ho.moving))
    sigma = np.maximum(sigma, 1e-12)
    cf = CrossFold(tr.X0, tr.y, base.weights, ho.X0, ho.y, ho.moving / sigma[None, :], bl.FOLDS)
    cols = {id(t): (tr.columns(t), ho.columns(t)) for t in [*held, *new]}

    def error(terms: Sequence[Candidate]) -> NDArray[np.float64]:
        if not terms:
            return mse(cf.residual(), ho.moving)
        C_tr = np.concatenate([cols[id(t)][0] for t in terms], axis=2)
        C_ho = np.concatenate([cols[id(t)][1] for t in terms], axis=2)
        return mse(cf.residual(C_tr, C_ho), ho.moving)

    def joints(t: Candidate) -> list[int]:
        return list(t.scored or range(n))

    kept = list(new)
    notes: list[str] = []
    while kept:
        now = error([*held, *kept])
        own = {}
        for t in kept:
            without = np.maximum(error([*held, *(u for u in kept if u is not t)]), 1e-300)
            own[id(t)] = float(np.mean(now[joints(t)] / without[joints(t)]))
        idle = max(kept, key=lambda t: own[id(t)])
        if own[id(idle)] < 1.0:
            break
        beside = ", ".join(t.key for t in kept if t is not idle)
        where = ", ".join(str(j + 1) for j in joints(idle))
        notes.append(
            f"{idle.key}: left out: cross-fitted on the held-out folds"
            + (f" beside {beside}" if beside else "")
            + f", its columns as the refit holds them do not lower the error on joint(s) {where} "
            f"({100 * (math.sqrt(own[id(idle)]) - 1):+.1f} % RMS)"
        )
        kept.remove(idle)
    return kept, notes


def refit_with_effects(
    model: IdentifiedModel,
    train: Dataset,
    effects: Sequence[Any],
    *,
    heldout: Dataset | None = None,
    max_rise: float = MAX_RISE,
) -> tuple[IdentifiedModel, list[str]]:
    """Identify the model again on its training data with ``effects`` added as model terms.

    Parameters
    ----------
    model : IdentifiedModel
        The model the diagnosis was run on.
    train : Dataset
        Its training data.
    effects : sequence of RankedCandidate or Candidate
        The accepted effects (``Diagnosis.accepted``, or their ``.candidate``), with their tuned
        hyper-parameters; from a RankedCandidate a delay takes the delay the diagnosis measured.
    heldout : Dataset, optional
        The held-out data of the diagnosis.  With them, an effect goes in only if it lowers the
        cross-fitted held-out error on its joints and the refitted model raises no joint's held-out RMS
        by more than ``max_rise`` over ``model`` (see the module docstring); without them every effect
        goes in.
    max_rise : float
        Largest relative rise of a joint's held-out RMS allowed (0.02: 2 %).

    Returns
    -------
    (IdentifiedModel, list of str)
        The refitted model (``model`` itself when nothing is added) and notes on the effects left out
        or moved.
    """
    settings = identify_settings(model)
    layer1_friction = settings["friction"] != "none"
    terms: list[Candidate] = [*model.effects]
    notes: list[str] = []
    if settings["method"] == "consistent":
        settings["method"] = "irls"
        notes.append(
            "the refit uses irls with non-negative armature and friction (consistent takes no effect terms)"
        )
    new: list[Candidate] = []
    for effect in effects:
        cand = getattr(effect, "candidate", effect)
        if cand.effect == "payload" or (cand.effect == "offset" and layer1_friction):
            notes.append(f"{cand.key}: the model identifies it already (re-identification absorbs it)")
            continue
        if cand.effect == "armature" and settings["armature"]:
            notes.append(f"{cand.key}: the model identifies the armature already")
            continue
        if any(t.key == cand.key for t in terms):
            notes.append(f"{cand.key}: the model carries it already (an effect term refitted with the links)")
            continue
        if any(t.key == cand.key for t in new):
            continue
        new.append(_as_term(effect, notes))
    measured = {getattr(e, "candidate", e).key for e in effects if _measured_delay(e) is not None}
    if not new:
        return model, notes
    if heldout is None:
        refitted = identify(model.robot, train, random_state=0, effects=(*terms, *new), **settings)
        return refitted, notes + _delay_notes(refitted, measured)
    new, gate_notes = _crossfit_gate(model, train, heldout, terms, new, max_rise)
    notes.extend(gate_notes)
    before = np.maximum(_heldout_rms(model, heldout), 1e-300)
    tried: tuple[list[Candidate], NDArray[np.float64]] | None = None  # the first refit, for the last note
    while new:
        refitted = identify(model.robot, train, random_state=0, effects=(*terms, *new), **settings)
        ratio = _heldout_rms(refitted, heldout) / before
        tried = tried or (list(new), ratio)
        if not np.any(ratio > 1.0 + max_rise):
            return refitted, notes + _delay_notes(refitted, measured)
        raised = np.flatnonzero(ratio > 1.0 + max_rise)
        on_raised = [t for t in new if set(t.scored or range(model.robot.n)) & set(raised.tolist())]
        if on_raised:
            drop = on_raised[-1]  # the last accepted of those acting on a raised joint
        else:
            # No term acts there: the shared link parameters carry the harm; leave out the term whose
            # removal raises the worst joint least.
            trials = []
            for t in new:
                rest = [u for u in new if u is not t]
                if rest:
                    m = identify(model.robot, train, random_state=0, effects=(*terms, *rest), **settings)
                    trials.append((float(np.max(_heldout_rms(m, heldout) / before)), t))
                else:
                    trials.append((1.0, t))
            drop = min(trials, key=lambda s: s[0])[1]
        joints = ", ".join(f"{j + 1} by {100 * (ratio[j] - 1):.1f} %" for j in raised)
        notes.append(
            f"{drop.key}: left out: the model refitted with {', '.join(t.key for t in new)} raised the held-out "
            f"RMS of joint(s) {joints} over the model before it (more than {100 * max_rise:g} %)"
        )
        new = [t for t in new if t is not drop]
    if tried is not None:
        first, ratio = tried
        change = ", ".join(f"{100 * (r - 1):+.1f} %" for r in ratio)
        notes.append(
            "no accepted effect is added: every refit tried raised some joint's held-out RMS by more than "
            f"{100 * max_rise:g} % over the model before it, so the model stays as it is.  The refit with "
            f"{', '.join(t.key for t in first)} changed joints 1-{len(ratio)} by {change}; to take it anyway, "
            f"identify with --effects '{effect_spec(first)}'"
        )
    return model, notes


def effect_spec(terms: Sequence[Candidate]) -> str:
    """``--effects`` text of terms with their hyper-parameters (``delay@5:d=0.0049,stribeck@3:vs=0.05``)."""
    items = []
    for t in terms:
        where = "" if t.joint is None and t.effect == "base_tilt" else "@" + t.key.split("@", 1)[1].split(":", 1)[0]
        hyper = ";".join(f"{k}={v!r}" if k == "mix" else f"{k}={v:.6g}" for k, v in t.hyper.items() if k != "exact")
        items.append(t.effect + where + (f":{hyper}" if hyper else ""))
    return ",".join(items)
