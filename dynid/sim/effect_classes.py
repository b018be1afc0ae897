"""The catalogue of the simulator's unmodelled effects: the base class with its hooks, one class per effect.

:class:`Effect` is what the simulator calls (by role: ``model``, ``drive``, ``transmission``,
``friction``, ``sensor``); each subclass realises one effect for a robot with :meth:`Effect.build` from
an :class:`EffectContext` (sizes relative to the robot's scales s_j, I_j, v_j: :mod:`dynid.sim.effects`)
and says how the diagnosis reads it (``selectable``: per joint or of the whole arm; ``excites``: the
motion that shows it).  :data:`EFFECTS` is the catalogue, name -> class, in the order below;
:data:`EFFECT_NAMES` its built-in names; :func:`register_effect` adds an effect kept outside dynid
(its class here, its column builder in :data:`dynid.identify.effect_builders.BUILDERS`).
:mod:`dynid.sim.effects` re-exports these names and holds the ``--effects`` parser.

Effects (``VALUE`` multiplies the size; random choices use the truth generator, so the seed repeats them):

=================  ============================================================================  ==========
name               model (default size at VALUE = 1)                                             joints
=================  ============================================================================  ==========
offset             constant torque-sensor offset ``o_j``, ``|o_j|`` = 2 % of s_j times a random    any
                   factor in [0.5, 1], random sign
armature           rotor inertia ``I_a ddq`` missing from the nominal model, I_a = 5 % of I_j      any
stribeck           low-speed bump ``(Fs - Fc) exp(-(dq / vs)^2) sign(dq)``, Fs - Fc = 2.5 % of     any
                   s_j, vs = 2 % of dq_max
load_friction      Coulomb growing with the drive torque, ``mu |tau_m| sign(dq)``, mu = 0.05 when   any
                   driving (dq tau_m > 0), 0.025 when back-driven
temperature        the truth friction (above) scaled by ``1 - delta (1 - exp(-t / 60 s))``, delta   any
                   = 0.3 (warming lowers friction along the run); needs a friction other than none
cogging            ``sum_k a_k sin(k N x + phi_k)``, N = 100 (gear ratio), k = 1, 2, a_1 = 1 %,    any
                   a_2 = 0.5 % of s_j, random phases; x the drive-side angle
elasticity         joint spring between motor and link: motor inertia B, ``tau_s = K (theta -     any
                   q) + D (dtheta - dq)``; K = I_j (2 pi 10 Hz)^2 / VALUE, D for 5 % damping,
                   B = the truth armature or at least 50 % of I_j; the encoder reads theta
backlash           dead zone of total width 1 mrad (0.5 mrad either way) in the transmission,      any
                   stiffness I_j (2 pi 20 Hz)^2 (or the elasticity's K on the same joint)
delay              the measured torque lags the applied one by d = 4 ms                           any
drive_gain         measured torque = g_j times applied, g_j = 1 +- 5 % times a random factor in     any
                   [0.5, 1] (random sign per joint: a common gain would be invisible)
payload            point mass of 5 % of the arm's mass, 5 cm along the tool z axis                 none
base_tilt          gravity rotated by 1 degree about a random horizontal axis                     none
coupled_friction   friction on the velocity ``w = dq_a + dq_b`` of the last two joints (a          none
                   coupled wrist): ``Fc tanh(w / eps) + Fv w`` on both joints, Fc = 5 % and Fv
                   v = 3 % of min(s_a, s_b)
nonlinear_viscous  ``kv2 dq|dq| + kv3 dq^3``, kv2 v_j^2 = 2 %, kv3 v_j^3 = 1 % of s_j              any
=================  ============================================================================  ==========

The motor inertia B of a flexible (elastic or backlashed) joint is not in the nominal model: it shows in
the measured torque as ``B ddtheta`` like an armature, which re-identification with armature columns
absorbs.  It is at least 50 % of I_j (reflected rotor inertias of geared arms are of that order) because
the controller's derivative action, sized for the whole joint, must stay well inside the stability limit
of the 1 kHz sampled loop on the motor alone (above the spring's resonance the controller sees only B);
at 2 % and 10 % the drives chattered.
"""

from __future__ import annotations

import inspect
import math
import re
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from dynid.exceptions import UsageError
from dynid.identify.effect_builders import Builder, Grid, register_builder, unregister_builder
from dynid.sim.scales import RobotScales
from dynid.sim.truth_friction import (
    COULOMB,
    SMOOTHING,
    STRIBECK_BUMP,
    STRIBECK_SPEED,
    VISCOUS,
    TruthFriction,
    smooth_sign,
)
from dynid.symbolic.robot import RobotModel, standard_from_com

__all__ = [
    "EFFECTS",
    "EFFECT_NAMES",
    "ROLES",
    "Armature",
    "Backlash",
    "BaseTilt",
    "Cogging",
    "CoupledFriction",
    "Delay",
    "DriveGain",
    "Effect",
    "EffectContext",
    "Elasticity",
    "LoadFriction",
    "NonlinearViscous",
    "Offset",
    "Payload",
    "Stribeck",
    "Temperature",
    "effect_names",
    "register_effect",
    "unregister_effect",
]


@dataclass(frozen=True, eq=False)
class EffectContext:
    """What an effect needs to size itself: the nominal robot, its scales and the truth friction."""

    robot: RobotModel
    scales: RobotScales
    friction: TruthFriction


@dataclass(frozen=True, eq=False)
class Effect:
    """Base class of the effects: a realised effect with its sizes, and the hooks the simulator calls.

    Roles: ``model`` effects change the truth robot (:meth:`apply_model`), ``drive`` effects add a
    torque on the drive side (:meth:`drive`), ``transmission`` effects make a joint flexible (the
    simulator reads their attributes), ``friction`` effects scale the truth friction (temperature:
    ``factor(t)``), ``sensor`` effects change the measured torque (:meth:`measure`).

    Class attributes: ``name`` (the catalogue's), ``role``, ``selectable`` (takes a joint selector
    ``@J``; the diagnosis then tests it per joint, else once for the arm), ``max_value`` / ``min_value``
    with their reasons (``why_limit``, ``why_min``), ``summary`` (its words in ``simulate --help``) and
    ``excites`` (the motion that would show it, ``{j}`` its joint, for the diagnosis' notes).

    Attributes
    ----------
    value : float
        The size multiplier asked for.
    joints : tuple of int
        The joints it acts on, numbered from 0.
    """

    name: ClassVar[str] = ""
    role: ClassVar[str] = ""
    selectable: ClassVar[bool] = True
    max_value: ClassVar[float | None] = 100.0
    why_limit: ClassVar[str] = "100 times the documented default size, far beyond a real arm's"
    min_value: ClassVar[float] = 0.0
    why_min: ClassVar[str] = ""
    summary: ClassVar[str] = ""
    excites: ClassVar[str] = "a richer excitation of joint {j}"

    value: float
    joints: tuple[int, ...]

    @classmethod
    def build(
        cls, ctx: EffectContext, value: float, joints: tuple[int, ...], rng: np.random.Generator
    ) -> Effect:
        """Realise the effect for one robot (sizes from the context, random choices from ``rng``)."""
        raise NotImplementedError

    def mask(self, n: int) -> np.ndarray:
        """Boolean mask of shape (n,) of the joints it acts on."""
        out = np.zeros(n, dtype=bool)
        out[list(self.joints)] = True
        return out

    def apply_model(
        self, params: np.ndarray, armature: np.ndarray, gravity: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Change the truth's standard parameters (10n,), armature (n,) and gravity (3,)."""
        return params, armature, gravity

    def drive(
        self, t: float, x: np.ndarray, dx: np.ndarray, tau_m: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Drive-side torque (N m, opposing the drive like friction) and its derivative in dx.

        Parameters
        ----------
        t : float
            Time (s).
        x, dx : ndarray, shape (n,)
            Drive-side angles (rad) and speeds (rad/s).
        tau_m : ndarray, shape (n,)
            Torque the drive applies (N m).

        Returns
        -------
        f : ndarray, shape (n,)
        J : ndarray, shape (n,) (diagonal) or (n, n)
            ``d f / d dx``.
        """
        raise NotImplementedError

    def measure(self, t: np.ndarray, tau: np.ndarray) -> np.ndarray:
        """Measured torque (m, n) from the torque (m, n) at times ``t`` (m,) (s)."""
        raise NotImplementedError

    def details(self) -> dict:
        """The realised sizes, for the truth file."""
        return {}

    def to_dict(self) -> dict:
        return {
            "name": self.name,
            "role": self.role,
            "value": self.value,
            "joints": [j + 1 for j in self.joints],
            **{k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in self.details().items()},
        }


def _per_joint(values: np.ndarray, joints: tuple[int, ...]) -> np.ndarray:
    out = np.zeros_like(values, dtype=float)
    out[list(joints)] = values[list(joints)]
    return out


def _random_signed(rng: np.random.Generator, n: int) -> np.ndarray:
    """Random sign times a factor in [0.5, 1], shape (n,)."""
    return rng.choice([-1.0, 1.0], size=n) * rng.uniform(0.5, 1.0, size=n)


@dataclass(frozen=True, eq=False)
class Offset(Effect):
    """Constant torque-sensor offset: ``tau_meas = tau + o``."""

    name: ClassVar[str] = "offset"
    role: ClassVar[str] = "sensor"
    summary: ClassVar[str] = "torque-sensor offset, 2% of the joint's torque scale"
    excites: ClassVar[str] = "both directions of motion at every speed (a constant does not change sign)"
    offset: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @classmethod
    def build(cls, ctx, value, joints, rng):
        o = 0.02 * value * ctx.scales.torque * _random_signed(rng, ctx.robot.n)
        return cls(value, joints, offset=_per_joint(o, joints))

    def measure(self, t, tau):
        return tau + self.offset

    def details(self):
        return {"offset": self.offset, "units": "N m"}


@dataclass(frozen=True, eq=False)
class DriveGain(Effect):
    """Per-joint scale of the current-to-torque constant: ``tau_meas = g tau``."""

    name: ClassVar[str] = "drive_gain"
    role: ClassVar[str] = "sensor"
    summary: ClassVar[str] = "measured torque scaled by 1 +- 5% per joint"
    excites: ClassVar[str] = "large torques on joint {j} at several speeds"
    max_value: ClassVar[float | None] = 20.0
    why_limit: ClassVar[str] = "the gain 1 - 0.05 VALUE must stay positive"
    gain: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @classmethod
    def build(cls, ctx, value, joints, rng):
        g = 0.05 * value * _random_signed(rng, ctx.robot.n)
        return cls(value, joints, gain=1.0 + _per_joint(g, joints))

    def measure(self, t, tau):
        return tau * self.gain

    def details(self):
        return {"gain": self.gain}


@dataclass(frozen=True, eq=False)
class Delay(Effect):
    """The measured torque lags: ``tau_meas(t) = tau(t - d)`` (linear interpolation, first value held)."""

    name: ClassVar[str] = "delay"
    role: ClassVar[str] = "sensor"
    summary: ClassVar[str] = "4 ms on the measured torque"
    excites: ClassVar[str] = "faster excitation of joint {j} (a delay grows with frequency)"
    max_value: ClassVar[float | None] = 250.0
    why_limit: ClassVar[str] = "a delay of 4 ms VALUE must stay below 1 s, far beyond any torque sensor's lag"
    delay: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @classmethod
    def build(cls, ctx, value, joints, rng):
        return cls(value, joints, delay=_per_joint(np.full(ctx.robot.n, 0.004 * value), joints))

    def measure(self, t, tau):
        out = np.array(tau, dtype=float, copy=True)
        for j in self.joints:
            out[:, j] = np.interp(t - self.delay[j], t, tau[:, j])
        return out

    def details(self):
        return {"delay": self.delay, "units": "s"}


@dataclass(frozen=True, eq=False)
class Armature(Effect):
    """Rotor inertia ``I_a ddq`` that the nominal model lacks."""

    name: ClassVar[str] = "armature"
    role: ClassVar[str] = "model"
    summary: ClassVar[str] = "rotor inertia, 5% of the joint inertia"
    excites: ClassVar[str] = "large accelerations of joint {j}"
    inertia: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @classmethod
    def build(cls, ctx, value, joints, rng):
        return cls(value, joints, inertia=_per_joint(0.05 * value * ctx.scales.inertia, joints))

    def apply_model(self, params, armature, gravity):
        return params, armature + self.inertia, gravity

    def details(self):
        return {"inertia": self.inertia, "units": "kg m^2"}


@dataclass(frozen=True, eq=False)
class Payload(Effect):
    """A point mass on the last link (the tool frame's body), 5 cm along the tool z axis."""

    name: ClassVar[str] = "payload"
    role: ClassVar[str] = "model"
    summary: ClassVar[str] = "5% of the arm's mass on the last link"
    excites: ClassVar[str] = "several tool orientations under gravity"
    selectable: ClassVar[bool] = False
    mass: float = 0.0
    link: int = 0
    position: np.ndarray = field(default_factory=lambda: np.zeros(3))
    params: np.ndarray = field(default_factory=lambda: np.zeros(10))

    @classmethod
    def build(cls, ctx, value, joints, rng):
        robot = ctx.robot
        total = float(np.sum(robot.params[0::10]))
        mass = 0.05 * value * total
        link = robot.tool_parent - 1
        position = np.asarray(robot.tool_translation) + np.asarray(robot.tool_rotation) @ np.array(
            [0.0, 0.0, 0.05]
        )
        return cls(
            value,
            (link,),
            mass=mass,
            link=link,
            position=position,
            params=standard_from_com(mass, position, np.zeros((3, 3))),
        )

    def apply_model(self, params, armature, gravity):
        params = np.array(params, dtype=float)
        params[10 * self.link : 10 * self.link + 10] += self.params
        return params, armature, gravity

    def details(self):
        return {
            "mass": self.mass,
            "link": self.link + 1,
            "position": self.position,
            "standard_params": self.params,
            "units": "kg, m in the link's joint frame",
        }


@dataclass(frozen=True, eq=False)
class BaseTilt(Effect):
    """Gravity rotated by a small angle about a random horizontal axis."""

    name: ClassVar[str] = "base_tilt"
    role: ClassVar[str] = "model"
    summary: ClassVar[str] = "gravity turned 1 degree"
    excites: ClassVar[str] = "full turns of joint 1 in several arm configurations"
    selectable: ClassVar[bool] = False
    max_value: ClassVar[float | None] = 90.0
    why_limit: ClassVar[str] = "a tilt of 90 degrees or more is no longer a small tilt"
    angle: float = 0.0
    axis: np.ndarray = field(default_factory=lambda: np.zeros(3))
    gravity: np.ndarray = field(default_factory=lambda: np.zeros(3))

    @classmethod
    def build(cls, ctx, value, joints, rng):
        g = np.asarray(ctx.robot.gravity, dtype=float)
        gn = np.linalg.norm(g)
        up = g / gn if gn > 0 else np.array([0.0, 0.0, -1.0])
        axis = rng.normal(size=3)
        axis -= up * (axis @ up)
        axis /= np.linalg.norm(axis)
        angle = math.radians(1.0 * value)
        rot = _rotation(axis, angle)
        return cls(value, tuple(range(ctx.robot.n)), angle=angle, axis=axis, gravity=rot @ g)

    def apply_model(self, params, armature, gravity):
        return params, armature, self.gravity

    def details(self):
        return {"angle": self.angle, "axis": self.axis, "gravity": self.gravity, "units": "rad, m/s^2"}


def _rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rodrigues' rotation matrix (3, 3) about a unit axis."""
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k


@dataclass(frozen=True, eq=False)
class Stribeck(Effect):
    """Low-speed friction bump ``(Fs - Fc) exp(-(dq / vs)^2) sign(dq)``."""

    name: ClassVar[str] = "stribeck"
    role: ClassVar[str] = "drive"
    summary: ClassVar[str] = "low-speed bump, 2.5%"
    excites: ClassVar[str] = "slow motion and many velocity reversals of joint {j}"
    bump: np.ndarray = field(default_factory=lambda: np.zeros(0))
    speed: np.ndarray = field(default_factory=lambda: np.zeros(0))
    eps: float = SMOOTHING

    @classmethod
    def build(cls, ctx, value, joints, rng):
        bump = STRIBECK_BUMP * COULOMB * value * ctx.scales.torque
        return cls(
            value,
            joints,
            bump=_per_joint(bump, joints),
            speed=STRIBECK_SPEED * np.asarray(ctx.robot.dq_max, dtype=float),
            eps=ctx.friction.eps,
        )

    def drive(self, t, x, dx, tau_m):
        s, ds = smooth_sign(dx, self.eps)
        e = np.exp(-((dx / self.speed) ** 2))
        return self.bump * s * e, self.bump * e * (ds - 2 * s * dx / self.speed**2)

    def details(self):
        return {"Fs_minus_Fc": self.bump, "vs": self.speed, "units": "N m, rad/s"}


@dataclass(frozen=True, eq=False)
class LoadFriction(Effect):
    """Coulomb friction growing with the drive torque: ``mu |tau_m| sign(dq)``, mu larger when driving."""

    name: ClassVar[str] = "load_friction"
    role: ClassVar[str] = "drive"
    summary: ClassVar[str] = "Coulomb + 5% of |drive torque|, 2.5% back-driven"
    excites: ClassVar[str] = "large loads on joint {j}, both driving and back-driven"
    mu_drive: np.ndarray = field(default_factory=lambda: np.zeros(0))
    mu_back: np.ndarray = field(default_factory=lambda: np.zeros(0))
    eps: float = SMOOTHING

    @classmethod
    def build(cls, ctx, value, joints, rng):
        n = ctx.robot.n
        return cls(
            value,
            joints,
            mu_drive=_per_joint(np.full(n, 0.05 * value), joints),
            mu_back=_per_joint(np.full(n, 0.025 * value), joints),
            eps=ctx.friction.eps,
        )

    def drive(self, t, x, dx, tau_m):
        # mu = mu_back + (mu_drive - mu_back) (1 + s sign(tau_m)) / 2, s the smooth sign of dx.
        s, ds = smooth_sign(dx, self.eps)
        a = np.abs(tau_m)
        half = 0.5 * (self.mu_drive - self.mu_back)
        sig = np.sign(tau_m)
        mean = self.mu_back + half
        return a * (mean * s + half * sig * s * s), a * ds * (mean + 2 * half * sig * s)

    def details(self):
        return {"mu_drive": self.mu_drive, "mu_back": self.mu_back}


@dataclass(frozen=True, eq=False)
class Temperature(Effect):
    """The truth friction scaled by ``1 - delta (1 - exp(-t / time_constant))`` on the joints chosen."""

    name: ClassVar[str] = "temperature"
    role: ClassVar[str] = "friction"
    summary: ClassVar[str] = "friction drops by 30% with a 60 s warm-up"
    excites: ClassVar[str] = "a longer run (minutes) so that friction drift and motion part"
    max_value: ClassVar[float | None] = 1.0 / 0.3
    why_limit: ClassVar[str] = "the friction drop 0.3 VALUE must stay below 100 %"
    drop: np.ndarray = field(default_factory=lambda: np.zeros(0))
    time_constant: float = 60.0

    @classmethod
    def build(cls, ctx, value, joints, rng):
        if not ctx.friction.active:
            raise UsageError(
                "the effect 'temperature' drifts the friction coefficients, and the friction model is 'none'; "
                "choose --friction linear, seed or stribeck."
            )
        return cls(value, joints, drop=_per_joint(np.full(ctx.robot.n, 0.3 * value), joints))

    def factor(self, t: float | np.ndarray) -> np.ndarray:
        """Friction scale at time(s) t: shape (n,) for a scalar t, (m, n) for t of shape (m,)."""
        t = np.asarray(t, dtype=float)
        warm = 1.0 - np.exp(-t / self.time_constant)
        return 1.0 - np.multiply.outer(warm, self.drop)

    def details(self):
        return {"drop": self.drop, "time_constant": self.time_constant, "units": "fraction, s"}


@dataclass(frozen=True, eq=False)
class Cogging(Effect):
    """Position ripple ``sum_k a_k sin(k N x + phi_k)`` with a gear ratio N."""

    name: ClassVar[str] = "cogging"
    role: ClassVar[str] = "drive"
    summary: ClassVar[str] = "1% + 0.5% ripple at 100 and 200 cycles/rev"
    excites: ClassVar[str] = "slow constant-speed sweeps of joint {j} over several gear periods"
    ratio: float = 100.0
    amplitude: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    phase: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))

    @classmethod
    def build(cls, ctx, value, joints, rng):
        n = ctx.robot.n
        amp = np.outer(ctx.scales.torque, [0.01, 0.005]) * value
        phase = rng.uniform(0.0, 2 * math.pi, size=(n, 2))
        return cls(value, joints, ratio=100.0, amplitude=_per_joint(amp, joints), phase=phase)

    def drive(self, t, x, dx, tau_m):
        k = np.arange(1, self.amplitude.shape[1] + 1)
        arg = self.ratio * np.multiply.outer(x, k) + self.phase
        return np.sum(self.amplitude * np.sin(arg), axis=-1), np.zeros_like(dx)

    def details(self):
        return {
            "gear_ratio": self.ratio,
            "amplitude": self.amplitude,
            "phase": self.phase,
            "harmonics": list(range(1, self.amplitude.shape[1] + 1)),
            "units": "N m, rad",
        }


@dataclass(frozen=True, eq=False)
class CoupledFriction(Effect):
    """Friction on ``w = m dq_a + dq_b`` felt by both joints: a coupled wrist's motor (``m = 1``), or with
    ``m = 0`` the output stage of joint b that the same motor drives."""

    name: ClassVar[str] = "coupled_friction"
    role: ClassVar[str] = "drive"
    summary: ClassVar[str] = "friction on dq_a + dq_b of the last two joints"
    excites: ClassVar[str] = "wrist joints moving in equal and opposite directions"
    selectable: ClassVar[bool] = False
    coulomb: float = 0.0
    viscous: float = 0.0
    eps: float = SMOOTHING
    mix: float = 1.0

    @classmethod
    def build(cls, ctx, value, joints, rng):
        n = ctx.robot.n
        if n < 2:
            raise UsageError(
                "the effect 'coupled_friction' couples the last two joints; the robot has one joint."
            )
        a, b = n - 2, n - 1
        s = min(ctx.scales.torque[a], ctx.scales.torque[b])
        v = min(ctx.scales.speed[a], ctx.scales.speed[b])
        return cls(
            value, (a, b), coulomb=COULOMB * value * s, viscous=VISCOUS * value * s / v, eps=ctx.friction.eps
        )

    def drive(self, t, x, dx, tau_m):
        a, b = self.joints
        w = self.mix * dx[a] + dx[b]
        s, ds = smooth_sign(w, self.eps)
        g = self.coulomb * s + self.viscous * w
        dg = self.coulomb * ds + self.viscous
        n = dx.shape[-1]
        f = np.zeros(n)
        f[a] = f[b] = g
        J = np.zeros((n, n))
        J[a, a] = J[b, a] = self.mix * dg
        J[a, b] = J[b, b] = dg
        return f, J

    def details(self):
        return {
            "Fc": self.coulomb,
            "Fv": self.viscous,
            "coupling": "w = dq_a + dq_b" if self.mix == 1.0 else f"w = {self.mix:g} dq_a + dq_b",
            "units": "N m, N m s/rad",
        }


@dataclass(frozen=True, eq=False)
class NonlinearViscous(Effect):
    """Viscous friction that grows faster than the speed: ``kv2 dq|dq| + kv3 dq^3``."""

    name: ClassVar[str] = "nonlinear_viscous"
    role: ClassVar[str] = "drive"
    summary: ClassVar[str] = "dq|dq| and dq^3 terms"
    excites: ClassVar[str] = "high speeds of joint {j}"
    kv2: np.ndarray = field(default_factory=lambda: np.zeros(0))
    kv3: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @classmethod
    def build(cls, ctx, value, joints, rng):
        s, v = ctx.scales.torque, ctx.scales.speed
        return cls(
            value,
            joints,
            kv2=_per_joint(0.02 * value * s / v**2, joints),
            kv3=_per_joint(0.01 * value * s / v**3, joints),
        )

    def drive(self, t, x, dx, tau_m):
        a = np.abs(dx)
        return self.kv2 * dx * a + self.kv3 * dx**3, 2 * self.kv2 * a + 3 * self.kv3 * dx**2

    def details(self):
        return {"kv2": self.kv2, "kv3": self.kv3, "units": "N m s^2/rad^2, N m s^3/rad^3"}


@dataclass(frozen=True, eq=False)
class Elasticity(Effect):
    """A spring between motor and link: extra motor states, ``tau_s = K (theta - q) + D (dtheta - dq)``."""

    name: ClassVar[str] = "elasticity"
    role: ClassVar[str] = "transmission"
    summary: ClassVar[str] = "joint spring, 10 Hz locked-motor resonance, motor encoder"
    excites: ClassVar[str] = "fast torque changes on joint {j} (harmonics near its resonance)"
    min_value: ClassVar[float] = 0.01
    why_min: ClassVar[str] = (
        "the locked-motor resonance 10 Hz / sqrt(VALUE) must stay at or below 100 Hz: a stiffer spring is a rigid "
        "joint at a 1 kHz control rate, and its integration steps would grow without bound"
    )
    stiffness: np.ndarray = field(default_factory=lambda: np.zeros(0))
    frequency: float = 10.0

    @classmethod
    def build(cls, ctx, value, joints, rng):
        f0 = 10.0
        k = ctx.scales.inertia * (2 * math.pi * f0) ** 2 / value
        return cls(value, joints, stiffness=_per_joint(k, joints), frequency=f0 / math.sqrt(value))

    def details(self):
        return {"stiffness": self.stiffness, "locked_motor_frequency": self.frequency, "units": "N m/rad, Hz"}


@dataclass(frozen=True, eq=False)
class Backlash(Effect):
    """A dead zone of total width ``gap`` in the transmission (no torque while the teeth are apart)."""

    name: ClassVar[str] = "backlash"
    role: ClassVar[str] = "transmission"
    summary: ClassVar[str] = "1 mrad dead zone"
    excites: ClassVar[str] = "torque reversals of joint {j} at low speed"
    gap: np.ndarray = field(default_factory=lambda: np.zeros(0))
    stiffness: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @classmethod
    def build(cls, ctx, value, joints, rng):
        n = ctx.robot.n
        k = ctx.scales.inertia * (2 * math.pi * 20.0) ** 2
        return cls(
            value, joints, gap=_per_joint(np.full(n, 1e-3 * value), joints), stiffness=_per_joint(k, joints)
        )

    def details(self):
        return {"gap": self.gap, "stiffness": self.stiffness, "units": "rad (total width), N m/rad"}


# ---------------------------------------------------------------------------- the catalogue
EFFECTS: dict[str, type[Effect]] = {
    cls.name: cls
    for cls in (
        Offset,
        Armature,
        Stribeck,
        LoadFriction,
        Temperature,
        Cogging,
        Elasticity,
        Backlash,
        Delay,
        DriveGain,
        Payload,
        BaseTilt,
        CoupledFriction,
        NonlinearViscous,
    )
}
"""Effect name -> class, in the order of DESIGN.md (the built-in effects), then the registered ones."""

EFFECT_NAMES: tuple[str, ...] = tuple(EFFECTS)
"""The built-in catalogue's effect names, in catalogue order (DESIGN.md): what ``simulate --effects``
injects, ``identify --effects`` models and ``diagnose`` tests.  Every other list of built-in effects is
this one; :func:`effect_names` adds the registered effects."""

ROLES = ("model", "drive")
"""The roles an effect kept outside dynid may take: the simulator calls their hooks (:meth:`Effect.apply_model`,
:meth:`Effect.drive`) for any effect; the sensor, friction and transmission effects it applies by name."""

_NAME = re.compile(r"^[a-z_]+$")


def effect_names() -> tuple[str, ...]:
    """The catalogue's effect names now: :data:`EFFECT_NAMES`, then the registered effects in their order."""
    return tuple(EFFECTS)


def register_effect(
    cls: type[Effect], builder: Builder | None, *, grid: Grid | None = None, replace: bool = False
) -> type[Effect]:
    """Add an effect kept outside dynid to the catalogue: its simulation class and its column builder.

    Afterwards ``dynid simulate --effects NAME`` injects it, ``dynid identify --effects NAME`` models it
    and ``dynid diagnose`` tests it (by default; ``--effects NAME`` alone), in this process.

    Parameters
    ----------
    cls : type
        A subclass of :class:`Effect` with its ``name`` (lower case letters and ``_``), its ``role``
        (:data:`ROLES`), :meth:`Effect.build` and the role's hook (``apply_model`` or ``drive``);
        ``selectable``, ``summary`` and ``excites`` as it needs.
    builder : callable
        ``(FeatureSource, Candidate) -> (M, n, k)`` columns (:data:`dynid.identify.effect_builders.Builder`):
        what ``identify --effects`` fits and the diagnosis screens.
    grid : callable, optional
        ``(FeatureSource, j) -> [hyper, ...]``: the hyper-parameter variants (``Candidate.hyper``) to tune
        the builder among, scaled from the data (:data:`dynid.identify.effect_builders.Grid`).
    replace : bool
        Replace an effect registered before under the same name (a built-in effect is never replaced).

    Returns
    -------
    type
        ``cls``.

    Raises
    ------
    UsageError
        What the catalogue cannot use, in one sentence: not an Effect subclass, no builder, a name,
        role or hook missing, a built-in name, or a name taken without ``replace``.
    """
    if not (isinstance(cls, type) and issubclass(cls, Effect)) or cls is Effect:
        raise UsageError(
            f"{getattr(cls, '__name__', repr(cls))} is not an effect; subclass dynid.sim.effects.Effect."
        )
    what = cls.__name__
    name = cls.name
    if not isinstance(name, str) or not _NAME.match(name) or name in ("none", "off", "all"):
        raise UsageError(
            f"the effect {what} has the name {name!r}; give it a name of lower case letters and '_' "
            "(not none, off or all)."
        )
    if builder is None or not callable(builder):
        raise UsageError(
            f"the effect '{name}' has no column builder; give register_effect({what}, builder) a function "
            "(FeatureSource, Candidate) -> (M, n, k) columns."
        )
    if cls.role not in ROLES:
        raise UsageError(
            f"the effect '{name}' has the role {cls.role!r}; an effect of one's own acts through the model or "
            "the drive (role 'model' or 'drive'), the simulator applies the others by name."
        )
    hook = "apply_model" if cls.role == "model" else "drive"
    for method in ("build", hook):
        if inspect.getattr_static(cls, method) is inspect.getattr_static(Effect, method):
            raise UsageError(
                f"the effect '{name}' ({what}) does not define {method}; a {cls.role} effect needs it."
            )
    if name in EFFECT_NAMES:
        raise UsageError(f"the effect name '{name}' is a built-in effect's; give {what} a name of its own.")
    if name in EFFECTS and EFFECTS[name] is not cls and not replace:
        raise UsageError(
            f"the effect name '{name}' is taken by {EFFECTS[name].__name__}; choose another name or pass "
            "replace=True."
        )
    register_builder(name, builder, grid=grid, replace=True)
    EFFECTS[name] = cls
    return cls


def unregister_effect(name: str) -> None:
    """Forget a registered effect (its class and its builder); a built-in effect stays.  Unknown: no change."""
    if name in EFFECT_NAMES:
        raise UsageError(f"the effect '{name}' is built in; only registered effects can be forgotten.")
    EFFECTS.pop(name, None)
    unregister_builder(name)
