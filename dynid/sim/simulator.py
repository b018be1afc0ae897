"""A robot that follows a trajectory like a real one: synthetic measured data with a known truth.

:func:`simulate` drives a *truth* robot along a commanded trajectory and records what a real arm's
controller would log: quantised encoder angles and the torque the drives apply, read through a noisy,
quantised current sensor.  The truth is the nominal model (URDF) with, optionally,

* its standard parameters perturbed (``perturb``; every link stays physically consistent: mass, centre
  of mass, principal moments and axes of the inertia about the centre of mass are perturbed and the
  link rebuilt from them),
* joint friction (``friction``: none, linear, seed = the paper's model, stribeck; sizes in
  :mod:`dynid.sim.effects`),
* unmodelled effects (``effects``: the catalogue of :mod:`dynid.sim.effects`, e.g.
  ``"offset,elasticity@3:2,delay:1.5"``),

and everything about it (parameters, friction coefficients, effects with their sizes, noise settings,
seed, controller gains) goes to a sidecar ``<out>.truth.json`` written beside the data, never into them.

Loop (per control tick of ``1 / control_rate`` s, 1 kHz by default):

1. the encoders read the drive-side angle (the motor side of an elastic or backlashed joint, else the
   joint angle): the controller reads the motor encoders, ``2^control_bits`` counts per joint revolution
   (2^24 by default: 2^17 counts per motor turn through a 100:1 gear), the log records
   ``2^encoder_bits`` (2^18 by default);
2. a PD + feedforward controller computes the drive torque
   ``tau_m = rnea_nominal(q_d, dq_d, ddq_d) + M_nominal(q_enc) (Kp (q_d - q_enc) + Kd (dq_d - v))``:
   feedforward and PD weighting both use the *nominal* model (never the truth); ``v`` is the backward
   difference of the encoder angle low-pass filtered at 100 Hz; ``Kp = w^2``, ``Kd = 2 zeta w`` with
   ``w = 2 pi 10 Hz``, ``zeta = 0.7``.  Weighting the PD by the mass matrix keeps every motion mode at
   the same bandwidth: gains per joint sized by the diagonal of M make light coupled modes (Panda's
   joints 1 and 3 when their axes align) exceed the stability limit of the 1 kHz sampled loop;
3. the torque is held for the tick (zero-order hold) while the truth moves: forward dynamics of the
   truth (Pinocchio's ``aba`` on the numeric model) with the friction and effect torques entering as
   joint torques, integrated in ``substeps`` steps by semi-implicit Euler (velocity first, then
   position) in which the velocity-dependent torques are *linearly implicit*: the step solves
   ``(M + h df/ddq) a = tau - b - f``, with ``f`` and ``df/ddq`` evaluated at the tick and linearised
   within it.  The diagonal ``h df/ddq`` is added to the armature of the model, so the step is one
   ``aba``; a coupled term (coupled_friction) takes ``crba`` and a solve.  The smoothed
   ``sign(dq) = tanh(dq / eps)`` of the friction has a slope ``Fc / eps`` near zero speed that would
   need sub-microsecond explicit steps; implicitly it is a strong damping the step cannot overshoot,
   so reversals are smooth at any step;
4. the *measured torque* is the drive torque ``tau_m`` (what a current sensor reads), then the sensor
   effects (drive_gain, delay, offset), white + AR(1) coloured noise and the current quantisation.

The recorded true states are the states at the ticks, and the recorded true acceleration is the
instantaneous acceleration of the continuous model there, so that with no friction, effect or noise
``tau = rnea_truth(q_true, dq_true, ddq_true)`` holds to rounding, whatever the step.

Noise settings (``noise=``, or ``--noise key=value,...``; torques are fractions of each joint's torque
scale s_j, see :mod:`dynid.sim.effects`; ``--noise off`` turns all off):

============  =========  =================================================================
key           default    meaning
============  =========  =================================================================
torque        0.01       white torque noise, std as a fraction of s_j
coloured      0.005      AR(1) coloured torque noise, stationary std as a fraction of s_j
colour        0.9        AR(1) coefficient of the coloured noise per control tick, in [0, 1)
encoder_bits  18         resolution of the logged angle, 2^bits counts per joint revolution (0: exact)
control_bits  24         resolution of the angle the controller reads (motor encoders), per joint revolution
current_lsb   0.001      quantisation step of the torque reading, fraction of s_j (0: exact)
============  =========  =================================================================

Seeds: the truth's random choices (perturbation, effect signs and phases) come from
``np.random.default_rng([truth_seed, k])`` (one stream per purpose), the noise from
``np.random.default_rng([seed, 1])``; ``truth_seed`` defaults to ``seed``.  Give two runs the same
``truth_seed`` and different seeds to record one robot on two trajectories with independent noise.
"""

from __future__ import annotations

import json
import math
import os
import tempfile
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from dynid._io import jsonable
from dynid.exceptions import DataError, ShapeError, UsageError
from dynid.identify.dataset import Dataset, save_dataset
from dynid.optim.trajectory import FourierTrajectory, Trajectory
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
from dynid.symbolic.robot import RobotModel, standard_from_com

__all__ = [
    "ControllerGains",
    "NoiseModel",
    "SimulationResult",
    "Transmission",
    "Truth",
    "build_truth",
    "check_output_path",
    "perturb_params",
    "simulate",
    "truth_path",
    "write_simulation",
]

CONTROL_RATE = 1000.0
"""Default control and integration rate (Hz)."""

_SENSOR_ORDER = ("drive_gain", "delay", "offset")
_MOTOR_FLOOR = 0.5  # motor inertia of a flexible joint: at least this fraction of its inertia scale
_SPRING_DAMPING = 0.05  # damping ratio of a flexible joint's spring
_LIMIT_TOL = 1e-6


# ---------------------------------------------------------------------------- noise
@dataclass(frozen=True)
class NoiseModel:
    """Sensor model: torque noise (white and AR(1)), encoder and current quantisation.

    Parameters
    ----------
    torque : float
        White torque noise std, fraction of each joint's torque scale.
    coloured : float
        Stationary std of the AR(1) torque noise, fraction of each joint's torque scale.
    colour : float
        AR(1) coefficient per control tick, ``0 <= colour < 1``.
    encoder_bits : int
        The logged angles have ``2**encoder_bits`` counts per joint revolution; 0 logs exact angles.
    current_lsb : float
        Quantisation step of the torque reading, fraction of each joint's torque scale; 0 for none.
    """

    torque: float = 0.01
    coloured: float = 0.005
    colour: float = 0.9
    encoder_bits: int = 18
    current_lsb: float = 0.001

    control_bits: int = 24

    KEYS = ("torque", "coloured", "colour", "encoder_bits", "current_lsb", "control_bits")

    def __post_init__(self) -> None:
        for key in ("torque", "coloured", "current_lsb"):
            value = getattr(self, key)
            if not (math.isfinite(value) and value >= 0):
                raise UsageError(
                    f"the noise setting {key} is {value}; give a fraction >= 0 of the torque scale."
                )
        if not (math.isfinite(self.colour) and 0 <= self.colour < 1):
            raise UsageError(
                f"the noise setting colour is {self.colour}; give an AR(1) coefficient in [0, 1)."
            )
        for key in ("encoder_bits", "control_bits"):
            value = getattr(self, key)
            if not (math.isfinite(value) and int(value) == value and 0 <= value <= 40):
                raise UsageError(
                    f"the noise setting {key} is {value}; give a whole number of bits in 0..40 (0 for exact angles)."
                )
            object.__setattr__(self, key, int(value))

    @classmethod
    def off(cls) -> NoiseModel:
        """No noise and no quantisation: the measured values are the exact ones."""
        return cls(torque=0.0, coloured=0.0, colour=0.0, encoder_bits=0, current_lsb=0.0, control_bits=0)

    @classmethod
    def parse(cls, spec: str | Mapping[str, float] | NoiseModel | None) -> NoiseModel:
        """Read ``key=value,...`` (keys in :attr:`KEYS`), ``off``/``none``, a mapping, or None (defaults).

        Keys not given keep their default; ``off,torque=0.01`` starts from no noise instead.
        """
        if isinstance(spec, NoiseModel):
            return spec
        if spec is None:
            return cls()
        if isinstance(spec, Mapping):
            items = list(spec.items())
            base = cls()
        else:
            parts = [p.strip() for p in str(spec).split(",") if p.strip()]
            base = cls()
            if parts and parts[0].lower() in ("off", "none"):
                base = cls.off()
                parts = parts[1:]
            items = []
            for part in parts:
                if "=" not in part:
                    raise UsageError(
                        f"the noise setting '{part}' is not key=value; write e.g. --noise torque=0.02,colour=0.8 "
                        f"(keys: {', '.join(cls.KEYS)}) or --noise off."
                    )
                key, _, value = part.partition("=")
                items.append((key.strip().lower().replace("color", "colour"), value.strip()))
        values = {k: getattr(base, k) for k in cls.KEYS}
        for key, value in items:
            if key not in cls.KEYS:
                raise UsageError(f"unknown noise setting '{key}'; the known ones are {', '.join(cls.KEYS)}.")
            try:
                values[key] = float(value)
            except (TypeError, ValueError):
                raise UsageError(
                    f"the noise setting {key} is '{value}', not a number; give e.g. {key}=0.01."
                ) from None
        return cls(**values)

    def to_dict(self) -> dict:
        return {k: getattr(self, k) for k in self.KEYS}


# ---------------------------------------------------------------------------- controller
@dataclass(frozen=True, eq=False)
class ControllerGains:
    """PD + feedforward joint controller: ``rnea_nominal(q_d, dq_d, ddq_d) + M_nominal(q) (kp e + kd de)``.

    Attributes
    ----------
    kp : ndarray, shape (n,)
        Position gains (1/s^2), multiplied by the nominal mass matrix.
    kd : ndarray, shape (n,)
        Velocity gains (1/s), multiplied by the nominal mass matrix.
    bandwidth : float
        Design bandwidth (Hz) with which the gains were chosen.
    damping : float
        Design damping ratio.
    velocity_cutoff : float
        Cut-off (Hz) of the first-order low-pass on the differentiated encoder angle.
    """

    kp: np.ndarray
    kd: np.ndarray
    bandwidth: float = 10.0
    damping: float = 0.7
    velocity_cutoff: float = 100.0

    @classmethod
    def design(cls, n: int, *, bandwidth: float = 10.0, damping: float = 0.7) -> ControllerGains:
        """Gains ``kp = w^2``, ``kd = 2 zeta w`` with ``w = 2 pi bandwidth`` for n joints.

        Parameters
        ----------
        n : int
            Number of joints.
        bandwidth : float
            Closed-loop natural frequency (Hz).
        damping : float
            Damping ratio zeta.
        """
        w = 2 * math.pi * bandwidth
        return cls(kp=np.full(n, w * w), kd=np.full(n, 2 * damping * w), bandwidth=bandwidth, damping=damping)

    def to_dict(self) -> dict:
        return {
            "law": "tau = rnea_nominal(q_d, dq_d, ddq_d) + M_nominal(q_encoder) (kp (q_d - q_encoder) + "
            "kd (dq_d - v_filtered))",
            "kp": self.kp.tolist(),
            "kd": self.kd.tolist(),
            "bandwidth_hz": self.bandwidth,
            "damping": self.damping,
            "velocity_cutoff_hz": self.velocity_cutoff,
            "units": "1/s^2, 1/s (times the nominal mass matrix)",
        }


# ---------------------------------------------------------------------------- truth
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
    """
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


# ---------------------------------------------------------------------------- result
@dataclass(frozen=True, eq=False)
class SimulationResult:
    """What a simulated run gives: the measured data and the truth behind them.

    All arrays have one row per output sample (``rate``); joints in the model's order.

    Attributes
    ----------
    t : ndarray, shape (m,)
        Time (s).
    q : ndarray, shape (m, n)
        Measured angles (rad): the encoders, quantised; drive (motor) side on flexible joints.
    tau : ndarray, shape (m, n)
        Measured torque (N m): drive torque through the sensor effects, noise and quantisation.
    q_true, dq_true, ddq_true : ndarray, shape (m, n)
        True link-side states (rad, rad/s, rad/s^2); ``ddq_true`` is the instantaneous acceleration.
    tau_drive : ndarray, shape (m, n)
        Torque the drives apply (controller output, N m), held until the next control tick.
    q_desired, dq_desired, ddq_desired : ndarray, shape (m, n)
        The commanded trajectory.
    theta, dtheta, ddtheta : ndarray, shape (m, n)
        Drive-side states: the motor on flexible joints, equal to the link states elsewhere.
    components : dict of str to ndarray (m, n)
        Drive-side torque of each term (N m, opposing the drive): ``friction`` and each drive effect.
        On a rigid joint ``tau_drive = rnea_link_truth(true states) + sum(components)``.
    truth : Truth
    noise : NoiseModel
    controller : ControllerGains
    seed : int
    rate, control_rate : float
        Output and control rates (Hz).
    substeps : int
        Integration steps per control tick.
    elapsed : float
        Wall time of the simulation (s).
    """

    t: np.ndarray
    q: np.ndarray
    tau: np.ndarray
    q_true: np.ndarray
    dq_true: np.ndarray
    ddq_true: np.ndarray
    tau_drive: np.ndarray
    q_desired: np.ndarray
    dq_desired: np.ndarray
    ddq_desired: np.ndarray
    theta: np.ndarray
    dtheta: np.ndarray
    ddtheta: np.ndarray
    components: dict[str, np.ndarray]
    truth: Truth
    noise: NoiseModel
    controller: ControllerGains
    seed: int
    rate: float
    control_rate: float
    substeps: int
    elapsed: float
    meta: dict = field(default_factory=dict)

    @property
    def n(self) -> int:
        return self.q.shape[1]

    def to_dataset(self, *, true_states: bool = False) -> Dataset:
        """The measured data as a :class:`Dataset` (``t, q, tau``; ``dq, ddq`` true ones if asked)."""
        extra = {"dq": self.dq_true, "ddq": self.ddq_true} if true_states else {}
        return Dataset(
            self.t,
            self.q,
            self.tau,
            **extra,
            meta={"source": "dynid simulate", "reference": "raw", **self.meta},
        )

    def truth_dict(self) -> dict:
        """Everything about the truth, noise, controller and run, for ``<out>.truth.json``."""
        s = self.truth.scales.torque
        noise = self.noise.to_dict()
        noise["absolute"] = {
            "torque_std": (self.noise.torque * s).tolist(),
            "coloured_std": (self.noise.coloured * s).tolist(),
            "current_lsb": (self.noise.current_lsb * s).tolist(),
            "encoder_step": 0.0 if self.noise.encoder_bits == 0 else 2 * math.pi / 2**self.noise.encoder_bits,
            "units": "N m, rad",
        }
        noise["note"] = "torque, coloured, current_lsb: fractions of the torque scale s_j (scales.torque)"
        err = self.q_true - self.q_desired
        return {
            "format": "dynid-truth 1",
            "seed": self.seed,
            **self.truth.to_dict(),
            "noise": noise,
            "controller": self.controller.to_dict(),
            "sampling": {
                "rate_hz": self.rate,
                "control_rate_hz": self.control_rate,
                "substeps": self.substeps,
                "duration_s": float(self.t[-1] - self.t[0]),
                "samples": int(self.t.size),
                "integrator": "semi-implicit Euler, velocity-dependent torques linearly implicit",
            },
            "tracking_error_rms": np.sqrt(np.mean(err**2, axis=0)).tolist(),
            "sensor_effect_order": list(_SENSOR_ORDER),
            "trajectory": self.meta.get("trajectory"),
        }


# ---------------------------------------------------------------------------- checks
def check_output_path(path: str | os.PathLike[str]) -> Path:
    """Check that a dataset can be written at ``path`` (.csv or .npz, existing folder); return it."""
    path = Path(path)
    if path.suffix.lower() not in (".csv", ".npz"):
        raise DataError(
            f"the output '{path}' has the extension '{path.suffix}'; give a .csv or .npz file name."
        )
    if not path.parent.is_dir():
        raise DataError(
            f"the folder '{path.parent}' for the output does not exist; create it or write elsewhere."
        )
    return path


def truth_path(path: str | os.PathLike[str]) -> Path:
    """Sidecar of a dataset file: ``<file>.truth.json``."""
    path = Path(path)
    return path.with_name(path.name + ".truth.json")


def _check_limits(robot: RobotModel, t: np.ndarray, q, dq, ddq, source: str) -> None:
    for label, values, lo, hi, unit, option in (
        ("q", q, robot.q_min, robot.q_max, "rad", "--q-min/--q-max"),
        ("dq", dq, -robot.dq_max, robot.dq_max, "rad/s", "--dq-max"),
        ("ddq", ddq, -robot.ddq_max, robot.ddq_max, "rad/s^2", "--ddq-max"),
    ):
        tol = _LIMIT_TOL * (1 + np.abs(hi - lo))
        over = (values > hi + tol) | (values < lo - tol)
        if over.any():
            k, j = np.argwhere(over)[0]
            bound = hi[j] if values[k, j] > hi[j] else lo[j]
            raise UsageError(
                f"{source} takes {label}_{j + 1} to {values[k, j]:.4g} {unit} at t = {t[k]:.4g} s, beyond the limit "
                f"{bound:.4g} {unit} of the robot '{robot.name}'; design the trajectory within the limits "
                f"(dynid excite) or override the limit with {option}."
            )


# ---------------------------------------------------------------------------- simulation
def simulate(
    robot: RobotModel,
    trajectory: Trajectory,
    *,
    effects: str | Sequence[str | EffectRequest] | None = None,
    friction: str | TruthFriction = "linear",
    noise: str | Mapping[str, float] | NoiseModel | None = None,
    seed: int = 0,
    truth_seed: int | None = None,
    perturb: float = 0.0,
    rate: float = CONTROL_RATE,
    duration: float | None = None,
    control_rate: float = CONTROL_RATE,
    substeps: int | None = None,
    truth: Truth | None = None,
    controller: ControllerGains | None = None,
    source: str = "the trajectory",
) -> SimulationResult:
    """Run the truth robot along a trajectory under a tracking controller and measure it.

    Parameters
    ----------
    robot : RobotModel
        The nominal robot (the controller's model; the truth is built from it).
    trajectory : FourierTrajectory or SampledTrajectory
        Commanded motion; times from 0.
    effects : str or sequence, optional
        Unmodelled effects, ``"NAME[@J|@J-K][:VALUE],..."`` (see :mod:`dynid.sim.effects`).
    friction : {"none", "linear", "seed", "stribeck"} or TruthFriction
        Truth friction.
    noise : str or mapping or NoiseModel, optional
        Sensor model (default :class:`NoiseModel` ()); ``NoiseModel.off()`` or ``"off"`` for exact values.
    seed : int
        Seed of the noise (and of the truth when ``truth_seed`` is None).
    truth_seed : int, optional
        Seed of the truth's random choices.
    perturb : float
        Relative perturbation of the standard parameters, in [0, 0.5].
    rate : float
        Output rate (Hz); ``control_rate / rate`` must be a whole number.
    duration : float, optional
        Length of the run (s); default the trajectory's.  A Fourier trajectory repeats beyond its period.
    control_rate : float
        Controller (and sensor) rate (Hz).
    substeps : int, optional
        Integration steps per tick; default at least 2 and enough for the stiffest spring.
    truth : Truth, optional
        A truth from :func:`build_truth` (then ``effects``, ``friction``, ``perturb``, ``truth_seed`` are
        not used): the same robot on another trajectory.
    controller : ControllerGains, optional
        Default :meth:`ControllerGains.design` (10 Hz, damping 0.7).
    source : str
        Name of the trajectory in messages.

    Returns
    -------
    SimulationResult

    Raises
    ------
    UsageError
        Bad effect, friction, noise, rate or duration; a trajectory beyond the joint limits.
    ShapeError
        A trajectory for another joint count.
    """
    started = time.perf_counter()
    noise = NoiseModel.parse(noise)
    n = robot.n
    if trajectory.n != n:
        raise ShapeError(
            f"{source} has {trajectory.n} joints; the robot '{robot.name}' has {n}: use a trajectory designed "
            "for this robot."
        )
    if not (math.isfinite(control_rate) and control_rate > 0):
        raise UsageError(f"the control rate is {control_rate}; give a positive rate in Hz.")
    if not (math.isfinite(rate) and 0 < rate <= control_rate):
        raise UsageError(
            f"the output rate is {rate} Hz; give a positive rate up to the control rate {control_rate:g} Hz."
        )
    stride = control_rate / rate
    if abs(stride - round(stride)) > 1e-9 * stride:
        raise UsageError(
            f"the output rate {rate:g} Hz does not divide the control rate {control_rate:g} Hz; give e.g. "
            f"{control_rate:g}, {control_rate / 2:g} or {control_rate / 10:g} Hz."
        )
    stride = round(stride)
    if duration is None:
        duration = float(trajectory.duration)
    if not (math.isfinite(duration) and duration > 0):
        raise UsageError(f"the duration is {duration} s; give a positive duration.")
    if duration > trajectory.duration * (1 + 1e-9) and not isinstance(trajectory, FourierTrajectory):
        raise UsageError(
            f"the duration {duration:g} s is longer than {source} ({trajectory.duration:g} s), which does not "
            "repeat; give at most its duration."
        )
    if substeps is not None and (int(substeps) != substeps or substeps < 1):
        raise UsageError(f"substeps is {substeps}; give a whole number >= 1.")
    seed = int(seed)

    ticks = round(duration * control_rate) + 1
    t_ctrl = np.arange(ticks) / control_rate
    qd, dqd, ddqd = (np.ascontiguousarray(a) for a in trajectory.evaluate(t_ctrl))
    _check_limits(robot, t_ctrl, qd, dqd, ddqd, source)

    if truth is None:
        truth = build_truth(
            robot,
            effects=effects,
            friction=friction,
            perturb=perturb,
            truth_seed=seed if truth_seed is None else int(truth_seed),
        )
    elif truth.nominal.n != n:
        raise ShapeError(f"the truth has {truth.nominal.n} joints; the robot '{robot.name}' has {n}.")
    scales = truth.scales
    if controller is None:
        controller = ControllerGains.design(n)

    run = _Run(truth, controller, noise, control_rate, substeps)
    states = run.integrate(t_ctrl, qd, dqd, ddqd)

    # Sensor chain at the control rate, then decimation.
    tau_meas = states["tau_drive"]
    by_name = {e.name: e for e in truth.effects}
    for name in _SENSOR_ORDER:
        if name in by_name:
            tau_meas = by_name[name].measure(t_ctrl, tau_meas)
    rng = np.random.default_rng([seed, 1])
    tau_meas = tau_meas + _torque_noise(noise, scales.torque, ticks, rng)
    if noise.current_lsb > 0:
        lsb = noise.current_lsb * scales.torque
        tau_meas = np.round(tau_meas / lsb) * lsb

    pick = slice(0, ticks, stride)
    meta = {
        "trajectory": {
            "source": source,
            "type": type(trajectory).__name__,
            "duration": float(trajectory.duration),
            "meta": dict(getattr(trajectory, "meta", {}) or {}),
        },
        "effects": [e.name for e in truth.effects],
    }
    return SimulationResult(
        t=t_ctrl[pick],
        q=states["q_meas"][pick],
        tau=tau_meas[pick],
        q_true=states["q"][pick],
        dq_true=states["dq"][pick],
        ddq_true=states["ddq"][pick],
        tau_drive=states["tau_drive"][pick],
        q_desired=qd[pick],
        dq_desired=dqd[pick],
        ddq_desired=ddqd[pick],
        theta=states["theta"][pick],
        dtheta=states["dtheta"][pick],
        ddtheta=states["ddtheta"][pick],
        components={k: v[pick] for k, v in states["components"].items()},
        truth=truth,
        noise=noise,
        controller=controller,
        seed=seed,
        rate=float(rate),
        control_rate=float(control_rate),
        substeps=run.substeps,
        elapsed=time.perf_counter() - started,
        meta=meta,
    )


def _torque_noise(noise: NoiseModel, scale: np.ndarray, ticks: int, rng: np.random.Generator) -> np.ndarray:
    """White + AR(1) torque noise, shape (ticks, n) (N m)."""
    from scipy.signal import lfilter

    n = scale.size
    white = rng.normal(size=(ticks, n)) * (noise.torque * scale)
    if noise.coloured == 0:
        return white
    rho = noise.colour
    drive = rng.normal(size=(ticks, n))
    first = rng.normal(size=n)  # stationary start
    coloured = lfilter([math.sqrt(1 - rho * rho)], [1.0, -rho], drive, axis=0, zi=(rho * first)[None, :])[0]
    return white + coloured * (noise.coloured * scale)


class _Run:
    """The integration loop (a workspace: Pinocchio model and data, preallocated arrays)."""

    def __init__(
        self,
        truth: Truth,
        controller: ControllerGains,
        noise: NoiseModel,
        control_rate: float,
        substeps: int | None,
    ) -> None:
        import pinocchio as pin

        self.truth = truth
        self.controller = controller
        self.noise = noise
        self.dt = 1.0 / control_rate
        n = truth.nominal.n
        self.n = n
        self.model = pin.Model(truth.link_robot.pin_model)  # a copy: the loop changes its armature
        self.data = self.model.createData()
        self.nominal = truth.nominal.pin_model
        self.nominal_data = self.nominal.createData()
        tr = truth.transmission
        self.flex = np.array([], dtype=int) if tr is None else tr.joints
        self.rigid = np.ones(n, dtype=bool)
        self.rigid[self.flex] = False
        if substeps is None:
            substeps = 2
            if tr is not None:
                link = truth.scales.inertia[self.flex]
                omega = np.sqrt(tr.stiffness * (1 / tr.motor_inertia + 1 / link))
                substeps = max(substeps, math.ceil(float(omega.max()) * self.dt / 0.3))
        self.substeps = int(substeps)
        # Drive-side torque terms: (name, callable(t, x, dx, tau_m) -> (f, J)).
        terms = []
        temperature = truth.effect("temperature")
        if truth.friction.active:
            fric = truth.friction
            if temperature is None:
                terms.append(("friction", lambda t, x, dx, tau: fric.torque(dx)))
            else:
                terms.append(("friction", lambda t, x, dx, tau: fric.torque(dx, temperature.factor(t))))  # type: ignore[attr-defined]
        for effect in truth.effects:
            if effect.role == "drive":
                terms.append((effect.name, effect.drive))
        self.terms = terms
        self.encoder_step = 0.0 if noise.encoder_bits == 0 else 2 * math.pi / 2**noise.encoder_bits
        self.control_step = 0.0 if noise.control_bits == 0 else 2 * math.pi / 2**noise.control_bits

    def _drive(self, t, x, dx, tau_m, store=None):
        n = self.n
        f = np.zeros(n)
        jd = np.zeros(n)
        jfull = None
        for name, term in self.terms:
            fi, ji = term(t, x, dx, tau_m)
            f += fi
            if store is not None:
                store[name] = fi
            if ji.ndim == 1:
                jd += ji
            else:
                jfull = ji if jfull is None else jfull + ji
        return f, jd, jfull

    def integrate(self, t_ctrl, qd, dqd, ddqd) -> dict[str, Any]:
        import pinocchio as pin

        model, data = self.model, self.data
        armature = np.array(model.armature)
        n, dt, ns = self.n, self.dt, self.substeps
        h = dt / ns
        ticks = t_ctrl.size
        tr = self.truth.transmission
        flex, rigid = self.flex, self.rigid
        has_flex = flex.size > 0
        kp, kd = self.controller.kp, self.controller.kd
        alpha = math.exp(-2 * math.pi * self.controller.velocity_cutoff * dt)
        step, cstep = self.encoder_step, self.control_step

        ff = np.empty((ticks, n))
        for k in range(ticks):
            ff[k] = pin.rnea(self.nominal, self.nominal_data, qd[k], dqd[k], ddqd[k])

        out = {
            name: np.empty((ticks, n))
            for name in ("q", "dq", "ddq", "theta", "dtheta", "ddtheta", "q_meas", "tau_drive")
        }
        comps = {name: np.empty((ticks, n)) for name, _ in self.terms}

        q = qd[0].copy()
        dq = dqd[0].copy()
        if has_flex:
            assert tr is not None
            tau_s0 = pin.rnea(model, data, q, dq, ddqd[0])[flex]
            half = 0.5 * tr.gap
            theta = q[flex] + tau_s0 / tr.stiffness + half * np.sign(tau_s0)
            dtheta = dq[flex].copy()
            motor = tr.motor_inertia
        x = q.copy()
        dx = dq.copy()
        v = dqd[0].copy()
        x_prev = None
        diag = slice(None, None, n + 1)
        rigid_f = rigid.astype(float)
        rigid_outer = np.outer(rigid_f, rigid_f)
        store: dict[str, np.ndarray] = {}

        for k in range(ticks):
            if has_flex:
                x[:] = q
                x[flex] = theta
                dx[:] = dq
                dx[flex] = dtheta
            else:
                x, dx = q, dq
            x_ctrl = np.round(x / cstep) * cstep if cstep else x.copy()
            if x_prev is not None:
                v = alpha * v + (1 - alpha) * (x_ctrl - x_prev) / dt
            x_prev = x_ctrl
            weight = pin.crba(self.nominal, self.nominal_data, x_ctrl)
            tau_m = ff[k] + weight @ (kp * (qd[k] - x_ctrl) + kd * (dqd[k] - v))
            out["q_meas"][k] = np.round(x / step) * step if step else x
            out["tau_drive"][k] = tau_m
            # Drive-side torques at the tick, linearised in the speed for the substeps of this tick.
            f0, jd, jfull = self._drive(t_ctrl[k], x, dx, tau_m, store)
            dx0 = dx.copy()
            if self.terms:
                jr = jd * rigid_f if has_flex else jd
                if jfull is not None and has_flex:
                    jfull = jfull * rigid_outer
            for i in range(ns):
                f = (
                    f0
                    if i == 0
                    else f0 + (jd * (dx - dx0) if jfull is None else jd * (dx - dx0) + jfull @ (dx - dx0))
                )
                tau_link = tau_m - f
                if has_flex:
                    tau_s = tr.spring(theta - q[flex], dtheta - dq[flex])
                    tau_link[flex] = tau_s
                    motor_rhs = tau_m[flex] - tau_s - f[flex]
                if i == 0:
                    model.armature = armature
                    ddq = pin.aba(model, data, q, dq, tau_link)
                    out["q"][k] = q
                    out["dq"][k] = dq
                    out["ddq"][k] = ddq
                    for name in comps:
                        comps[name][k] = store[name]
                    out["theta"][k] = x
                    out["dtheta"][k] = dx
                    acc = ddq.copy()
                    if has_flex:
                        acc[flex] = motor_rhs / motor
                    out["ddtheta"][k] = acc
                if jfull is None:
                    # (M + diag(h J)) a = tau - b - f is forward dynamics with h J added to the armature.
                    if self.terms:
                        model.armature = armature + h * jr
                    acc = pin.aba(model, data, q, dq, tau_link)
                else:
                    model.armature = armature
                    mass = pin.crba(model, data, q)
                    mass.flat[diag] += h * jr
                    mass += h * jfull
                    acc = np.linalg.solve(mass, tau_link - pin.nle(model, data, q, dq))
                dq = dq + h * acc
                q = q + h * dq
                if has_flex:
                    dtheta = dtheta + h * motor_rhs / (motor + h * jd[flex])
                    theta = theta + h * dtheta
                    x = q.copy()
                    x[flex] = theta
                    dx = dq.copy()
                    dx[flex] = dtheta
                else:
                    x, dx = q, dq
        out["components"] = comps
        return out


# ---------------------------------------------------------------------------- files
def write_simulation(
    result: SimulationResult, path: str | os.PathLike[str], *, true_states: bool = False
) -> tuple[Path, Path]:
    """Write the measured data and the sidecar ``<path>.truth.json``, both or neither.

    The data go to a temporary file in the target folder, the sidecar is written (atomically), and only
    then the data file takes its name; if any step fails nothing new is left behind.

    Parameters
    ----------
    result : SimulationResult
    path : str or path-like
        ``.csv`` or ``.npz`` file in an existing folder.
    true_states : bool
        Also write the true ``dq_i`` and ``ddq_i`` (for debugging; a real robot gives none).

    Returns
    -------
    (Path, Path)
        The data file and the sidecar.
    """
    path = check_output_path(path)
    sidecar = truth_path(path)
    text = json.dumps(result.truth_dict(), indent=2, default=jsonable) + "\n"
    dataset = result.to_dataset(true_states=true_states)
    fd, tmp_name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=path.suffix)
    os.close(fd)
    tmp = Path(tmp_name)
    sidecar_written = False
    try:
        save_dataset(dataset, tmp)
        os.chmod(tmp, _file_mode(path))
        _write_text_atomic(sidecar, text)
        sidecar_written = True
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        if sidecar_written:
            sidecar.unlink(missing_ok=True)
        raise
    return path, sidecar


def _file_mode(path: Path) -> int:
    """Mode for a new file at ``path``: the existing file's, else 0666 less the umask (not mkstemp's 0600)."""
    if path.exists():
        return path.stat().st_mode & 0o777
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask


def _write_text_atomic(path: Path, text: str) -> None:
    """Write ``text`` through a temporary file in the same folder and a rename: never half written."""
    fd, tmp_name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    tmp = Path(tmp_name)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as handle:
            handle.write(text)
        os.chmod(tmp, _file_mode(path) if not path.is_dir() else 0o644)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


