"""Withheld-effect cases for checking the gap diagnosis (DIAGNOSIS.md section 4).

A case simulates one truth robot (closed-loop tracking, quantised encoders, coloured torque noise;
:func:`dynid.sim.simulator.simulate`) on two different periodic excitations, one for training
and one held out (:func:`dynid.sim.cases.case_excitation`), with effects injected at a size
calibrated in multiples of the torque noise (:func:`dynid.sim.cases.calibrate_value`); identifies a
model that lacks those effects; and diagnoses it.  The benchmark
(``benchmarks/diagnosis_benchmark.py``) and the tests share these functions; :func:`simulate_runs` (the
two runs) and :func:`truth_labels` (what was injected, as :func:`classify` reads it) are the field
cases' (:mod:`dynid.diagnosis.field_cases`) too.

>>> case = run_case(load_robot("ur5"), ["stribeck@3"], level=1.0, seed=1)
>>> case["verdict"], case["correct"]
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from dynid.sim.cases import calibrate_value, case_excitation
from dynid.sim.effects import effect_names, parse_effects
from dynid.sim.simulator import SimulationResult, simulate

__all__ = ["CaseRuns", "case_record", "classify", "run_case", "simulate_runs", "truth_labels"]


def case_record(d, injected, truth_injected, *, level, seed, values, achieved) -> dict[str, Any]:
    """The figures every withheld-effect case reports (lab and field): what was injected, the verdict.

    Parameters
    ----------
    d : Diagnosis
        The case's diagnosis.
    injected : sequence of str
        The effects injected, as given.
    truth_injected : list of (str, int or None)
        The injected effects the catalogue can name, with their joints (:func:`truth_labels`).
    level, seed, values, achieved
        The case's size, seed, effect values and the size it reached.
    """
    return {
        "injected": list(injected),
        "truth": [f"{e}@{j}" if j else e for e, j in truth_injected],
        "level": level,
        "seed": seed,
        "values": values,
        "achieved_level": achieved,
        "verdict": list(d.verdict),
        "excess": [float(v) for v in d.excess["ratio"]],
    }


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
    structured = par in ("payload", "drive_gain", "offset", "armature", "base_tilt")
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


@dataclass(frozen=True, eq=False)
class CaseRuns:
    """The two simulated runs of a case, with the effects injected into both.

    Attributes
    ----------
    train, heldout : SimulationResult
        The training and held-out runs (one truth robot: the held-out run's truth seed is the case's).
    specs : list of str
        The injected effects with their values (``NAME@J:VALUE`` or ``NAME:VALUE``).
    values : list of float
        Their values (calibrated, or as given).
    achieved : list of float
        The level each calibrated value reached on the training excitation, in the units of the
        calibration's ``level`` (NaN for a value given).
    """

    train: SimulationResult
    heldout: SimulationResult
    specs: list[str]
    values: list[float]
    achieved: list[float]


def simulate_runs(
    robot,
    injected: Sequence[str],
    train_traj,
    held_traj,
    *,
    level: float,
    seed: int,
    calibration_seconds: float,
    train_seconds: float,
    heldout_seconds: float,
    friction: str,
    armature: bool,
    noise=None,
) -> CaseRuns:
    """Calibrate the injected effects on the training excitation and simulate both runs with them.

    Parameters
    ----------
    robot : RobotModel
    injected : sequence of str
        Effects as ``NAME`` or ``NAME@J`` (VALUE calibrated to ``level``), or with ``:VALUE`` (used as given).
    train_traj, held_traj : Trajectory
        The training and held-out motions.
    level : float
        RMS contribution of each calibrated effect, in the lab noise's standard deviations
        (:func:`dynid.sim.cases.calibrate_value`).
    seed : int
        Seed of the truth and the training run's noise (the held-out run's: ``seed + 100_000``).
    calibration_seconds : float
        Length (s) of the noise-free training run the calibration measures.
    train_seconds, heldout_seconds : float
        Lengths (s) of the two runs.
    friction : str
        Truth friction.
    armature : bool
        Whether the model will identify an armature (the calibration leaves the motor inertia out then).
    noise : NoiseModel, optional
        The sensor model of both runs; the simulator's default when None.

    Returns
    -------
    CaseRuns
    """
    specs, values, achieved = [], [], []
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
                duration=calibration_seconds,
                seed=seed,
                friction=friction,
                armature=armature,
            )
        specs.append(f"{req.name}@{joint}:{value:.6g}" if joint else f"{req.name}:{value:.6g}")
        values.append(value)
        achieved.append(got)
    effects = ",".join(specs) or None
    tr = simulate(
        robot, train_traj, duration=train_seconds, friction=friction, effects=effects, seed=seed, noise=noise
    )
    ho = simulate(
        robot,
        held_traj,
        duration=heldout_seconds,
        friction=friction,
        effects=effects,
        seed=seed + 100_000,
        truth_seed=seed,
        noise=noise,
    )
    return CaseRuns(train=tr, heldout=ho, specs=specs, values=values, achieved=achieved)


def truth_labels(injected: Sequence[str], catalogue: Sequence[str]) -> list[tuple[str, int | None]]:
    """What was injected, as :func:`classify` takes it: ``(effect, joint or None)`` per effect (joint
    1-based), an effect outside ``catalogue`` named ``"unknown:" + name``."""
    labels = []
    for req in parse_effects(list(injected)):
        joint = req.joints[0] if req.joints else None
        labels.append((req.name if req.name in catalogue else f"unknown:{req.name}", joint))
    return labels


def run_case(
    robot,
    injected: Sequence[str],
    *,
    level: float,
    seed: int,
    catalogue: Sequence[str] | None = None,
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
    catalogue : sequence of str, optional
        Effects the diagnosis is told about (drop one to make it an unknown effect); default the whole
        catalogue (:func:`dynid.sim.effects.effect_names`).
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

    runs = simulate_runs(
        robot,
        injected,
        case_excitation(robot, 2 * seed, base_freq=base_freq),
        case_excitation(robot, 2 * seed + 1, base_freq=base_freq),
        level=level,
        seed=seed,
        calibration_seconds=min(train_seconds, 10.0),
        train_seconds=train_seconds,
        heldout_seconds=heldout_seconds,
        friction=friction,
        armature=armature,
    )
    catalogue = effect_names() if catalogue is None else tuple(catalogue)
    truth_injected = truth_labels(injected, catalogue)
    train, held = runs.train.to_dataset(), runs.heldout.to_dataset()
    model = identify(robot, train, method="ols", friction=model_friction, gmm="off", armature=armature)
    d = diagnose(model, train, held, effects=tuple(catalogue), **(diagnose_options or {}))
    cls = classify(d, truth_injected)
    return {
        **case_record(
            d, injected, truth_injected, level=level, seed=seed, values=runs.values, achieved=runs.achieved
        ),
        "realised": [e.to_dict() for e in runs.train.truth.effects],
        "diagnosis": d,
        **cls,
    }
