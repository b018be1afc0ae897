"""Withheld-effect cases for checking the gap diagnosis (DIAGNOSIS.md section 4).

A case simulates one truth robot (closed-loop tracking, quantised encoders, coloured torque noise;
:func:`dynid.sim.simulator.simulate`) on two different periodic excitations, one for training
and one held out (:func:`dynid.sim.cases.case_excitation`), with effects injected at a size
calibrated in multiples of the torque noise (:func:`dynid.sim.cases.calibrate_value`); identifies a
model that lacks those effects; and diagnoses it.  The benchmark
(``benchmarks/diagnosis_benchmark.py``) and the tests share these functions.

>>> case = run_case(load_robot("ur5"), ["stribeck@3"], level=1.0, seed=1)
>>> case["verdict"], case["correct"]
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from dynid.sim.cases import calibrate_value, case_excitation
from dynid.sim.effects import EFFECT_NAMES, parse_effects
from dynid.sim.simulator import simulate

__all__ = ["classify", "run_case"]


def classify(diagnosis, injected: Sequence[tuple[str, int | None]]) -> dict[str, Any]:
    """What the diagnosis called the case and whether that is right.

    Parameters
    ----------
    diagnosis : Diagnosis
    injected : sequence of (effect, joint or None)
        What was injected (joint 1-based); empty for an effect-free case.  An effect outside the
        diagnosis' catalogue is given as ``("unknown:" + name, joint)``.

    Returns
    -------
    dict
        ``label`` (the confusion-matrix column: an effect name, ``parametric``, ``none`` or
        ``unexplained``), ``parametric`` (the parameter-change finding), ``correct``, ``closure``.
    """
    verdict = list(diagnosis.verdict)
    par = diagnosis.parametric.get("finding", "none")
    par_joint = diagnosis.parametric.get("joint")
    found = [
        (a.candidate.effect, a.candidate.joint + 1 if a.candidate.joint is not None else None)
        for a in diagnosis.accepted
    ]
    structured = par in ("payload", "drive_gain", "offset", "armature")
    if found:
        label = found[0][0]
    elif structured:
        label = "parametric"
    else:
        label = verdict[0]

    def hit(name, joint):
        for e, j in found:
            if e == name and (joint is None or j is None or j == joint):
                return True
        return structured and par == name and (joint is None or par_joint is None or par_joint == joint)

    if not injected:
        correct = verdict == ["none"] and not structured
    elif injected[0][0].startswith("unknown:"):
        correct = verdict == ["unexplained"]
    else:
        correct = all(hit(e, j) for e, j in injected)
    closure = None
    if found:
        closure = float(np.mean([a.closure for a in diagnosis.accepted]))
    return {"label": label, "parametric": par, "correct": bool(correct), "closure": closure, "found": found}


def run_case(
    robot,
    injected: Sequence[str],
    *,
    level: float,
    seed: int,
    catalogue: Sequence[str] = EFFECT_NAMES,
    train_seconds: float = 20.0,
    heldout_seconds: float = 20.0,
    base_freq: float = 0.2,
    friction: str = "linear",
    armature: bool = True,
    model_friction: str = "linear",
    diagnose_options: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Simulate, identify without the effects, diagnose and classify one case.

    Parameters
    ----------
    robot : RobotModel
    injected : sequence of str
        Effects as ``NAME`` or ``NAME@J`` (VALUE calibrated to ``level``), or with ``:VALUE`` (used as given).
    level : float
        RMS contribution of each effect in noise standard deviations.
    seed : int
        Seed of the truth, noise and trajectories.
    catalogue : sequence of str
        Effects the diagnosis is told about (drop one to make it an unknown effect).
    train_seconds, heldout_seconds : float
        Durations (s) of the training and held-out runs (several periods of ``1 / base_freq``).
    base_freq : float
        Base frequency (Hz) of both excitations.
    friction : str
        Truth friction (the model identifies linear friction).
    armature : bool
        Whether the model identifies an armature per joint (dynid's default; an injected armature is
        then absorbed and found by the parameter-change test).
    model_friction : str
        Friction the model identifies (``"linear"``: Coulomb, viscous and offset per joint; ``"none"``).
    diagnose_options : dict, optional
        Extra keyword arguments of :func:`dynid.diagnosis.core.diagnose`.

    Returns
    -------
    dict
        The case, the calibrated values, the realised effects (their truth-file entries: sizes, joints),
        the verdict, the classification and the closure.
    """
    from dynid.diagnosis.core import diagnose
    from dynid.identify.model import identify

    train_traj = case_excitation(robot, 2 * seed, base_freq=base_freq)
    held_traj = case_excitation(robot, 2 * seed + 1, base_freq=base_freq)
    specs, values, achieved, truth_injected = [], [], [], []
    for item, req in zip(injected, parse_effects(list(injected)), strict=True):
        joint = req.joints[0] if req.joints else None
        if ":" in item:  # a VALUE given: no calibration
            value, got = req.value, float("nan")
        else:
            value, got = calibrate_value(
                robot,
                train_traj,
                req.name,
                joint,
                level,
                duration=min(train_seconds, 10.0),
                seed=seed,
                friction=friction,
                armature=armature,
            )
        specs.append(f"{req.name}@{joint}:{value:.6g}" if joint else f"{req.name}:{value:.6g}")
        values.append(value)
        achieved.append(got)
        name = req.name if req.name in catalogue else f"unknown:{req.name}"
        truth_injected.append((name, joint))
    effects = ",".join(specs) or None
    tr = simulate(robot, train_traj, duration=train_seconds, friction=friction, effects=effects, seed=seed)
    ho = simulate(
        robot,
        held_traj,
        duration=heldout_seconds,
        friction=friction,
        effects=effects,
        seed=seed + 100_000,
        truth_seed=seed,
    )
    train, held = tr.to_dataset(), ho.to_dataset()
    model = identify(robot, train, method="ols", friction=model_friction, gmm="off", armature=armature)
    d = diagnose(model, train, held, effects=tuple(catalogue), **(diagnose_options or {}))
    cls = classify(d, truth_injected)
    return {
        "injected": list(injected),
        "truth": [f"{e}@{j}" if j else e for e, j in truth_injected],
        "level": level,
        "seed": seed,
        "values": values,
        "achieved_level": achieved,
        "verdict": list(d.verdict),
        "excess": [float(v) for v in d.excess["ratio"]],
        "realised": [e.to_dict() for e in tr.truth.effects],
        "diagnosis": d,
        **cls,
    }
