"""Withheld-effect cases for checking the gap diagnosis (DIAGNOSIS.md section 4).

A case simulates one truth robot (closed-loop tracking, quantised encoders, coloured torque noise;
:func:`dynid.sim.simulator.simulate`) on two different periodic excitations, one for training
and one held out, with effects injected at a size calibrated in multiples of the torque noise;
identifies a model that lacks those effects; and diagnoses it.  The benchmark
(``benchmarks/diagnosis_benchmark.py``) and the tests share these functions.

>>> case = run_case(load_robot("ur5"), ["stribeck@3"], level=1.0, seed=1)
>>> case["verdict"], case["correct"]
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dynid.diagnosis.candidates import EFFECT_NAMES
from dynid.optim.trajectory import FourierTrajectory
from dynid.sim.effects import EFFECTS, parse_effects
from dynid.sim.simulator import NoiseModel, SimulationResult, build_truth, simulate

__all__ = [
    "NOISE_STD",
    "calibrate_value",
    "classify",
    "effect_contribution",
    "random_fourier",
    "run_case",
]

NOISE_STD = math.hypot(NoiseModel().torque, NoiseModel().coloured)
"""Standard deviation of the simulator's default torque noise, as a fraction of each joint's torque scale."""

_ITERATED = ("delay", "elasticity", "backlash", "temperature", "base_tilt")  # not proportional to VALUE


def random_fourier(
    robot, seed: int, *, base_freq: float = 0.2, harmonics: int = 5, fill: float = 0.6
) -> FourierTrajectory:
    """A random Fourier excitation scaled to ``fill`` of the speed and acceleration limits.

    Parameters
    ----------
    robot : RobotModel
        The robot (its limits).
    seed : int
        Seed of the coefficients.
    base_freq : float
        Base frequency (Hz); the period is its inverse.
    harmonics : int
        Number of harmonics.
    fill : float
        Fraction of the tightest speed and acceleration limit used; the angles stay within 1.2 rad of
        the middle of their range.
    """
    rng = np.random.default_rng([seed, 7])
    n = robot.n
    a = rng.normal(size=(harmonics, n))
    b = rng.normal(size=(harmonics, n))
    lo, hi = np.maximum(robot.q_min, -math.pi), np.minimum(robot.q_max, math.pi)
    c = 0.5 * (lo + hi)
    if robot.name.startswith("ur"):
        c = np.array([0.0, -1.2, 1.0, -1.0, 0.5, 0.0])[:n] if n == 6 else c
    half = np.minimum(0.5 * (hi - lo) * 0.8, 1.2)
    traj = FourierTrajectory(a=a, b=b, c=c, base_freq=base_freq)
    q, dq, ddq = traj.evaluate(np.linspace(0.0, 1.0 / base_freq, 4000))
    s = min(
        float(np.min(fill * robot.dq_max / np.max(np.abs(dq), axis=0))),
        float(np.min(fill * robot.ddq_max / np.max(np.abs(ddq), axis=0))),
        float(np.min(half / np.max(np.abs(q - c), axis=0))),
    )
    return FourierTrajectory(a=a * s, b=b * s, c=c, base_freq=base_freq)


def effect_contribution(
    result: SimulationResult, *, friction: str = "linear", motor_inertia: bool = True
) -> NDArray[np.float64]:
    """Torque (m, n) that the injected effects add to what the measured torque would be without them.

    The run should be noise-free (``NoiseModel.off()``): measured torque minus the effect-free truth
    (same perturbation and friction) evaluated at the drive-side states the encoders read.

    Parameters
    ----------
    result : SimulationResult
        A noise-free simulation with the effects.
    friction : str
        The truth friction of that run.
    motor_inertia : bool
        Leave out the motor inertia of flexible joints (``B ddtheta``), which a model with armature
        parameters absorbs.
    """
    import pinocchio as pin

    base = build_truth(
        result.truth.nominal,
        effects=None,
        friction=friction,
        perturb=result.truth.perturb,
        truth_seed=result.truth.truth_seed,
    )
    model = base.robot.pin_model
    data = model.createData()
    tau = np.array(
        [
            pin.rnea(model, data, q, dq, ddq)
            for q, dq, ddq in zip(result.theta, result.dtheta, result.ddtheta, strict=True)
        ]
    )
    f, _ = base.friction.torque(result.dtheta)
    out = result.tau - tau - f
    tm = result.truth.transmission
    if tm is not None and motor_inertia:
        # The motor inertia of a flexible joint acts like an armature, which the model identifies.
        for j, b in zip(tm.joints, tm.motor_inertia, strict=True):
            out[:, j] -= (b - base.robot.armature[j]) * result.ddtheta[:, j]
    return out


def _size(contribution: NDArray[np.float64], scales: NDArray[np.float64], joints) -> float:
    rms = np.sqrt(np.mean(contribution**2, axis=0)) / (NOISE_STD * scales)
    return float(np.max(rms[list(joints)]) if joints else np.max(rms))


def calibrate_value(
    robot,
    trajectory,
    effect: str,
    joint: int | None,
    level: float,
    *,
    duration: float,
    seed: int,
    friction: str = "linear",
    armature: bool = True,
) -> tuple[float, float]:
    """The VALUE at which an effect's RMS torque contribution is ``level`` times the noise std.

    Parameters
    ----------
    robot : RobotModel
    trajectory : FourierTrajectory
        The training excitation (the size is measured on it, noise-free).
    effect : str
        Catalogue name.
    joint : int or None
        Joint (1-based) of a per-joint effect, None for a whole-arm effect.
    level : float
        Wanted RMS contribution in noise standard deviations (on the effect's joint, or the largest
        over the joints for a whole-arm effect).
    duration : float
        Simulated time (s).
    seed : int
        Truth seed.
    friction : str
        Truth friction.
    armature : bool
        Whether the model identifies armature (then a flexible joint's motor inertia is not counted).

    Returns
    -------
    (value, achieved) : tuple of float
        The VALUE and the level it reaches (VALUE is capped below the effect's limit).
    """
    limit = EFFECTS[effect].max_value
    joints = (joint - 1,) if joint else ()
    value = 1.0
    achieved = 0.0
    for _ in range(3 if effect in _ITERATED else 2):
        spec = f"{effect}@{joint}:{value:.6g}" if joint else f"{effect}:{value:.6g}"
        res = simulate(
            robot,
            trajectory,
            duration=duration,
            friction=friction,
            effects=spec,
            seed=seed,
            noise=NoiseModel.off(),
        )
        contribution = effect_contribution(res, friction=friction, motor_inertia=armature)
        achieved = _size(contribution, res.truth.scales.torque, joints)
        if achieved <= 0:
            break
        new = value * level / achieved
        if limit is not None:
            new = min(new, 0.95 * limit)
        if abs(new - value) < 0.05 * value:
            value = new
            break
        value = new
    return value, achieved * (value / max(value, 1e-12))


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

    train_traj = random_fourier(robot, 2 * seed, base_freq=base_freq)
    held_traj = random_fourier(robot, 2 * seed + 1, base_freq=base_freq)
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
