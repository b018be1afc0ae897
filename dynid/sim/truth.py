"""The truth robot of the simulator: perturbed parameters, friction, realised effects, flexible joints.

:func:`build_truth` turns the nominal model (the URDF) into the robot the simulator drives: standard
parameters perturbed while every link stays physical (:func:`perturb_params`), the truth friction and
the unmodelled effects of :mod:`dynid.sim.effects` realised with sizes and random choices drawn from
``np.random.default_rng([truth_seed, k])``, one stream per purpose.  Elasticity and backlash make
their joints flexible (:class:`Transmission`): a motor inertia and a spring between motor and link.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from dynid.exceptions import ShapeError, UsageError
from dynid.sim.effects import (
    EFFECTS,
    FRICTION_KINDS,
    Effect,
    EffectContext,
    EffectRequest,
    RobotScales,
    TruthFriction,
    parse_effects,
    robot_scales,
)
from dynid.symbolic.robot import RobotModel, check_simulable, standard_from_com

__all__ = ["Transmission", "Truth", "build_truth", "perturb_params"]

_MOTOR_FLOOR = 0.5  # motor inertia of a flexible joint: at least this fraction of its inertia scale
_SPRING_DAMPING = 0.05  # damping ratio of a flexible joint's spring


@dataclass(frozen=True, eq=False)
class Transmission:
    """Flexible joints of the truth (from the elasticity and backlash effects).

    Attributes
    ----------
    joints : ndarray of int, shape (k,)
        Flexible joints, numbered from 0.
    stiffness : ndarray, shape (k,)
        Spring stiffness K (N m/rad).
    damping : ndarray, shape (k,)
        Spring damping D (N m s/rad), acting while the teeth touch.
    gap : ndarray, shape (k,)
        Total backlash width (rad); 0 for a plain spring.
    motor_inertia : ndarray, shape (k,)
        Motor-side inertia B (kg m^2), joint side.
    """

    joints: np.ndarray
    stiffness: np.ndarray
    damping: np.ndarray
    gap: np.ndarray
    motor_inertia: np.ndarray

    def spring(self, delta: np.ndarray, ddelta: np.ndarray) -> np.ndarray:
        """Transmitted torque (k,) (N m) for a deflection ``theta - q`` and its rate (k,) (rad, rad/s)."""
        half = 0.5 * self.gap
        excess = np.abs(delta) - half
        touch = excess > 0
        return np.where(touch, self.stiffness * np.sign(delta) * excess + self.damping * ddelta, 0.0)

    def to_dict(self) -> dict:
        return {
            "joints": (self.joints + 1).tolist(),
            "stiffness": self.stiffness.tolist(),
            "damping": self.damping.tolist(),
            "gap": self.gap.tolist(),
            "motor_inertia": self.motor_inertia.tolist(),
            "encoder": "motor side (theta) on these joints",
            "units": "N m/rad, N m s/rad, rad, kg m^2",
        }


@dataclass(frozen=True, eq=False)
class Truth:
    """The robot the simulator drives.

    Attributes
    ----------
    nominal : RobotModel
        The model the controller uses (the URDF).
    robot : RobotModel
        Rigid truth: perturbed parameters, plus armature, payload and base tilt effects (its ``gravity``).
    friction : TruthFriction
    effects : tuple of Effect
        Realised effects, in catalogue order.
    scales : RobotScales
        Per-joint sizes the defaults are relative to.
    transmission : Transmission or None
        Flexible joints, if any.
    perturb : float
        Relative perturbation of the standard parameters.
    truth_seed : int
    """

    nominal: RobotModel
    robot: RobotModel
    friction: TruthFriction
    effects: tuple[Effect, ...]
    scales: RobotScales
    transmission: Transmission | None
    perturb: float
    truth_seed: int

    def effect(self, name: str) -> Effect | None:
        """The realised effect of that name, or None."""
        return next((e for e in self.effects if e.name == name), None)

    @property
    def link_robot(self) -> RobotModel:
        """The rigid truth with the armature of flexible joints moved to their motors (zeroed here)."""
        if self.transmission is None:
            return self.robot
        armature = np.array(self.robot.armature)
        armature[self.transmission.joints] = 0.0
        return replace(self.robot.with_params(armature=armature), gravity=np.array(self.robot.gravity))

    def to_dict(self) -> dict:
        return {
            "robot": self.nominal.name,
            "source": self.nominal.source,
            "joint_names": list(self.nominal.joint_names),
            "param_names": list(self.nominal.param_names),
            "params": {"nominal": self.nominal.params.tolist(), "truth": self.robot.params.tolist()},
            "armature": {"nominal": self.nominal.armature.tolist(), "truth": self.robot.armature.tolist()},
            "gravity": {"nominal": self.nominal.gravity.tolist(), "truth": self.robot.gravity.tolist()},
            "perturb": self.perturb,
            "truth_seed": self.truth_seed,
            "scales": self.scales.to_dict(),
            "friction": self.friction.to_dict(),
            "effects": [e.to_dict() for e in self.effects],
            "transmission": None if self.transmission is None else self.transmission.to_dict(),
        }


def perturb_params(params: np.ndarray, fraction: float, rng: np.random.Generator) -> np.ndarray:
    """Perturb standard parameters by a relative ``fraction`` while keeping every link physical.

    Per link: mass ``m (1 + f u)``, centre of mass moved by ``f L u`` (L the larger of |c| and the radius
    of gyration), and the inertia about the centre of mass rebuilt from its second-moment matrix
    ``S = tr(I)/2 - I`` (positive semi-definite exactly when the triangle inequalities hold) with
    eigenvalues scaled by ``1 + f u`` and principal axes turned by up to ``f`` rad; ``u`` uniform in
    [-1, 1].  Bodies of zero mass are left alone.

    Parameters
    ----------
    params : ndarray, shape (10 n,)
        Standard parameters (Pinocchio's order, see :data:`dynid.symbolic.PARAM_NAMES`).
    fraction : float
        ``0 <= fraction <= 0.5``.
    rng : numpy.random.Generator

    Returns
    -------
    ndarray, shape (10 n,)
    """
    if not (math.isfinite(fraction) and 0 <= fraction <= 0.5):
        raise UsageError(f"the perturbation is {fraction}; give a fraction in [0, 0.5] (0.1 = 10 %).")
    params = np.asarray(params, dtype=float)
    out = params.copy()
    if fraction == 0:
        return out
    for i in range(params.size // 10):
        v = params[10 * i : 10 * i + 10]
        u = rng.uniform(-1.0, 1.0, size=10)
        m = v[0]
        if m <= 0:
            continue
        c = v[1:4] / m
        ixx, ixy, iyy, ixz, iyz, izz = v[4:]
        inertia_o = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
        skew = np.array([[0.0, -c[2], c[1]], [c[2], 0.0, -c[0]], [-c[1], c[0], 0.0]])
        inertia_c = inertia_o + m * skew @ skew
        second = 0.5 * np.trace(inertia_c) * np.eye(3) - inertia_c
        sigma, axes = np.linalg.eigh(second)
        sigma = np.clip(sigma, 0.0, None)
        length = max(float(np.linalg.norm(c)), math.sqrt(max(np.trace(inertia_c), 0.0) / m))
        m_new = m * (1 + fraction * u[0])
        c_new = c + fraction * length * u[1:4]
        sigma_new = sigma * (1 + fraction * u[4:7])
        turn = fraction * u[7:10]
        angle = float(np.linalg.norm(turn))
        rot = np.eye(3) if angle == 0 else _rodrigues(turn / angle, angle)
        axes_new = rot @ axes
        second_new = axes_new @ np.diag(sigma_new) @ axes_new.T
        inertia_new = np.trace(second_new) * np.eye(3) - second_new
        out[10 * i : 10 * i + 10] = standard_from_com(m_new, c_new, inertia_new)
    return out


def _rodrigues(axis: np.ndarray, angle: float) -> np.ndarray:
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k


def build_truth(
    robot: RobotModel,
    *,
    effects: str | Sequence[str | EffectRequest] | None = None,
    friction: str | TruthFriction = "linear",
    perturb: float = 0.0,
    truth_seed: int = 0,
    scales: RobotScales | None = None,
) -> Truth:
    """Build the truth robot: perturbed parameters, friction and realised effects.

    Parameters
    ----------
    robot : RobotModel
        The nominal robot.
    effects : str or sequence, optional
        ``"NAME[@J|@J-K][:VALUE],..."`` or requests (see :func:`dynid.sim.effects.parse_effects`).
    friction : {"none", "linear", "seed", "stribeck"} or TruthFriction
        Truth friction: a kind with the default sizes, or explicit coefficients.
    perturb : float
        Relative perturbation of the standard parameters, in [0, 0.5].
    truth_seed : int
        Seed of the truth's random choices.
    scales : RobotScales, optional
        Precomputed :func:`dynid.sim.effects.robot_scales` of ``robot``.

    Returns
    -------
    Truth

    Raises
    ------
    UsageError
        Unknown effect or friction, bad size, joint selector outside the robot.
    RobotModelError
        A joint that carries no mass, inertia or armature (:func:`dynid.symbolic.robot.check_simulable`).
    """
    check_simulable(robot)
    requests = parse_effects(effects)
    if isinstance(friction, str) and friction not in FRICTION_KINDS:
        raise UsageError(
            f"the friction model '{friction}' is unknown; choose one of {', '.join(FRICTION_KINDS)}."
        )
    n = robot.n
    for req in requests:
        if req.joints is not None and max(req.joints) > n:
            raise UsageError(
                f"the effect '{req}' selects joint {max(req.joints)}; the robot '{robot.name}' has joints 1..{n}."
            )
    scales = scales or robot_scales(robot)
    fric = (
        friction
        if isinstance(friction, TruthFriction)
        else TruthFriction.default(friction, scales, robot.dq_max)
    )
    if fric.kc_pos.shape != (n,):
        raise ShapeError(
            f"the truth friction has {fric.kc_pos.size} joints; the robot '{robot.name}' has {n}."
        )
    params = perturb_params(robot.params, float(perturb), np.random.default_rng([int(truth_seed), 0]))
    armature = np.array(robot.armature, dtype=float)
    gravity = np.array(robot.gravity, dtype=float)
    ctx = EffectContext(robot=robot, scales=scales, friction=fric)
    by_name = {req.name: req for req in requests}
    realised: list[Effect] = []
    for k, (name, cls) in enumerate(EFFECTS.items()):
        req = by_name.get(name)
        if req is None:
            continue
        joints = tuple(range(n)) if req.joints is None else tuple(j - 1 for j in req.joints)
        effect = cls.build(ctx, float(req.value), joints, np.random.default_rng([int(truth_seed), 10 + k]))
        params, armature, gravity = effect.apply_model(params, armature, gravity)
        realised.append(effect)
    truth_robot = replace(robot.with_params(params, armature), gravity=gravity)
    transmission = _transmission(realised, armature, scales, n)
    return Truth(
        nominal=robot,
        robot=truth_robot,
        friction=fric,
        effects=tuple(realised),
        scales=scales,
        transmission=transmission,
        perturb=float(perturb),
        truth_seed=int(truth_seed),
    )


def _transmission(
    effects: Sequence[Effect], armature: np.ndarray, scales: RobotScales, n: int
) -> Transmission | None:
    elastic = next((e for e in effects if e.name == "elasticity"), None)
    backlash = next((e for e in effects if e.name == "backlash"), None)
    if elastic is None and backlash is None:
        return None
    flexible = np.zeros(n, dtype=bool)
    stiffness = np.zeros(n)
    gap = np.zeros(n)
    if backlash is not None:
        mask = backlash.mask(n)
        flexible |= mask
        stiffness[mask] = backlash.stiffness[mask]  # type: ignore[attr-defined]
        gap[mask] = backlash.gap[mask]  # type: ignore[attr-defined]
    if elastic is not None:
        mask = elastic.mask(n)
        flexible |= mask
        stiffness[mask] = elastic.stiffness[mask]  # type: ignore[attr-defined]
    idx = np.flatnonzero(flexible)
    motor = np.maximum(armature[idx], _MOTOR_FLOOR * scales.inertia[idx])
    link = scales.inertia[idx]
    reduced = motor * link / (motor + link)
    damping = 2 * _SPRING_DAMPING * np.sqrt(stiffness[idx] * reduced)
    return Transmission(
        joints=idx, stiffness=stiffness[idx], damping=damping, gap=gap[idx], motor_inertia=motor
    )
