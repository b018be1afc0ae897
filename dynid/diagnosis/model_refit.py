"""From diagnosis to model: the identified model refitted with the effects the diagnosis accepted.

``dynid diagnose ... --out M2.json`` writes it.  The effects become model terms
(:mod:`dynid.identify.effect_terms`) identified with the link parameters, under the same settings as
the model (method, friction model, mixture, preprocessing, bounds), with the hyper-parameters the
diagnosis tuned.  Terms that the model already identifies (an offset or armature of its linear
friction and armature columns) and effects without a model term (a payload, which the base
parameters take in whole) are left out, and a note says so.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from dynid.data.dataset import Dataset
from dynid.data.preparation import Preprocessing
from dynid.identify.effect_terms import Candidate
from dynid.identify.model import IdentifiedModel, identify

__all__ = ["identify_settings", "refit_with_effects"]

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


def refit_with_effects(
    model: IdentifiedModel, train: Dataset, effects: Sequence[Candidate]
) -> tuple[IdentifiedModel, list[str]]:
    """Identify the model again on its training data with ``effects`` added as model terms.

    Parameters
    ----------
    model : IdentifiedModel
        The model the diagnosis was run on.
    train : Dataset
        Its training data.
    effects : sequence of Candidate
        The accepted effects (``Diagnosis.accepted[i].candidate``), with their tuned hyper-parameters.

    Returns
    -------
    (IdentifiedModel, list of str)
        The refitted model and notes on the effects left out.
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
    for cand in effects:
        if cand.effect == "payload" or (cand.effect == "offset" and layer1_friction):
            notes.append(f"{cand.key}: the model identifies it already (re-identification absorbs it)")
            continue
        if cand.effect == "armature" and settings["armature"]:
            notes.append(f"{cand.key}: the model identifies the armature already")
            continue
        if any(t.key == cand.key for t in terms):
            continue
        hyper = dict(cand.hyper)
        if cand.effect in _NOT_LINEAR_FORMS:
            hyper.pop("exact", None)  # the first-order columns (tuned again on the training data)
            for key in ("w", "z", "h", "a", "d"):
                hyper.pop(key, None)
            notes.append(f"{cand.key}: identified through its first-order columns")
        terms.append(Candidate(cand.effect, cand.joint, cand.joints, hyper, cand.label))
    if not terms:
        return model, notes
    refitted = identify(model.robot, train, random_state=0, effects=tuple(terms), **settings)
    return refitted, notes
