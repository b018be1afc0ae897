"""Simulated withheld-effect cases: their excitation and the size of the effects injected into them.

A case of the gap diagnosis (:mod:`dynid.diagnosis.cases`) simulates one truth robot on two random
periodic excitations (:func:`case_excitation`) with effects injected at a size calibrated in
multiples of the torque noise (:func:`calibrate_value`, measured by :func:`effect_contribution`).
These functions only simulate; the diagnosis of the case is :func:`dynid.diagnosis.cases.run_case`.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from dynid.optim.trajectory import FourierTrajectory
from dynid.sim.effects import EFFECTS
from dynid.sim.simulator import NoiseModel, SimulationResult, build_truth, simulate
from dynid.sim.synthetic import random_fourier

__all__ = [
    "CASE_POSTURES",
    "NOISE_STD",
    "calibrate_value",
    "case_centre",
    "case_excitation",
    "effect_contribution",
]

NOISE_STD = math.hypot(NoiseModel().torque, NoiseModel().coloured)
"""Standard deviation of the simulator's default torque noise, as a fraction of each joint's torque scale."""

CASE_POSTURES: dict[str, tuple[float, ...]] = {
    "ur5": (0.0, -1.2, 1.0, -1.0, 0.5, 0.0),
    "ur10": (0.0, -1.2, 1.0, -1.0, 0.5, 0.0),
}
"""Centre posture (rad) of the case excitations, per built-in robot.

The UR arms' joints range over +-2 pi, so the middle of the range (all zeros) is the arm stretched out
horizontally; the cases swing about a folded posture instead (shoulder lifted, elbow bent, wrist
turned).  A robot not listed swings about the middle of each joint's range (clipped to +-pi)."""

_ITERATED = ("delay", "elasticity", "backlash", "temperature", "base_tilt")  # not proportional to VALUE


def case_centre(robot) -> NDArray[np.float64] | None:
    """The centre posture (rad) of ``robot``'s case excitations from :data:`CASE_POSTURES`, or None.

    Parameters
    ----------
    robot : RobotModel
        Looked up by its name; a posture of another joint count is not used.
    """
    posture = CASE_POSTURES.get(robot.name)
    if posture is None or len(posture) != robot.n:
        return None
    return np.array(posture, dtype=float)


def case_excitation(
    robot, seed: int, *, base_freq: float = 0.2, harmonics: int = 5, fraction: float = 0.6
) -> FourierTrajectory:
    """The random Fourier excitation of a case: :func:`~dynid.sim.synthetic.random_fourier` scaled as one arm.

    One factor for all joints brings the motion to ``fraction`` of the tightest speed and acceleration
    limit; the angles stay within 1.2 rad (and 80 % of the half-range) of :func:`case_centre`.

    Parameters
    ----------
    robot : RobotModel
        The robot (its limits and centre posture).
    seed : int
        Seed of the coefficients (the generator ``np.random.default_rng([seed, 7])``).
    base_freq : float
        Base frequency (Hz); the period is its inverse.
    harmonics : int
        Number of harmonics.
    fraction : float
        Fraction of the tightest speed and acceleration limit used.
    """
    return random_fourier(
        robot,
        np.random.default_rng([seed, 7]),
        harmonics=harmonics,
        base_freq=base_freq,
        fraction=fraction,
        centre=case_centre(robot),
        scaling="arm",
    )


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
        new = max(new, EFFECTS[effect].min_value)
        if abs(new - value) < 0.05 * value:
            value = new
            break
        value = new
    return value, achieved * (value / max(value, 1e-12))
