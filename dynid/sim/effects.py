"""The simulator's truth friction and its catalogue of unmodelled effects.

The simulator (:mod:`dynid.sim.simulator`) drives a *truth* robot that differs from the nominal
model the way a real arm does.  This module holds the physics of those differences:

* :class:`TruthFriction`, the joint friction of the truth (``--friction {none,linear,seed,stribeck}``);
* :data:`EFFECTS`, the catalogue of the effects that ``--effects NAME[@JOINTS][:VALUE],...`` injects,
  one class each, with a documented default size that ``VALUE`` scales (1.0 by default).

Sizes are relative to the robot, so that an effect weighs the same on a 0.2 N m wrist as on a 60 N m
shoulder.  Two per-joint scales, computed once per robot by :func:`robot_scales` from 1000 random
states drawn with a fixed generator (so they depend on the robot only, never on the seed or the
trajectory):

* the torque scale ``s_j`` (N m): the 95th percentile of ``|rnea_j(q, dq, ddq)|`` of the nominal model,
  with q uniform within the limits (clipped to +-pi), dq uniform in +-dq_max/2, ddq in +-ddq_max/2;
* the inertia scale ``I_j`` (kg m^2): the median of the diagonal entry ``M_jj(q)`` of the nominal mass matrix;

and the reference speed ``v_j = dq_max_j / 2`` (rad/s).

Truth friction (METHOD.md section 2), the torque a joint loses to friction, positive along the motion:

==========  =====================================================================================
kind        model and default size
==========  =====================================================================================
none        0
linear      ``Fc sign(dq) + Fv dq``; Fc = 5 % of s_j, Fv such that Fv v_j = 3 % of s_j
seed        the paper's model: ``kc+`` (dq > 0) = 1.1 Fc, ``kc-`` (dq < 0) = 0.9 Fc, ``kv1 dq + kv2 dq|dq|
            + kv3 dq^3`` with kv1 = Fv, kv2 v_j^2 = 1 % and kv3 v_j^3 = 0.5 % of s_j above ``lambda`` = 3 %
            of dq_max; below it a straight line in |dq| from the static level ``kc+- + ks`` at zero speed
            to the high-speed curve at +-lambda (continuous there), ks = 0.5 Fc: a negative slope at low
            speed.  The same form as :class:`dynid.identify.friction.SeedFriction` with its static
            levels ``ks+- = kc+- + ks``
stribeck    ``(Fc + (Fs - Fc) exp(-(dq / vs)^2)) sign(dq) + Fv dq``; Fs - Fc = 0.5 Fc, vs = 2 % of dq_max
==========  =====================================================================================

``sign`` is smoothed as ``tanh(dq / eps)`` with ``eps = 1e-3`` rad/s: the friction torque is then a
continuous function whose steep slope near zero speed the integrator treats implicitly (see
:mod:`dynid.sim.simulator`), so a velocity reversal neither chatters nor needs tiny steps.  Real
sticking (zero speed held over a finite time) is not reproduced.

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

Syntax of one effect: ``NAME`` (all joints it applies to, size 1), ``NAME:VALUE``, ``NAME@J`` (joint J
only, joints numbered from 1), ``NAME@J-K`` (joints J..K), ``NAME@J:VALUE``; several effects are
separated by commas, e.g. ``offset,elasticity@3:2,delay:1.5``.  The sensor effects act in the order
drive_gain, delay, offset, whatever the order given.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from dynid.exceptions import UsageError
from dynid.symbolic.robot import RobotModel, standard_from_com

__all__ = [
    "EFFECTS",
    "EFFECT_NAMES",
    "FRICTION_KINDS",
    "Effect",
    "EffectContext",
    "EffectRequest",
    "RobotScales",
    "TruthFriction",
    "parse_effects",
    "robot_scales",
]

FRICTION_KINDS = ("none", "linear", "seed", "stribeck")
"""Friction models of the truth (``--friction``)."""

SMOOTHING = 1e-3
"""Default velocity (rad/s) of the ``tanh(dq / eps)`` that stands for ``sign(dq)``."""

# Default sizes, fractions of the torque scale s_j unless stated.
COULOMB = 0.05
VISCOUS = 0.03  # at the reference speed v_j
SEED_ASYMMETRY = 0.1  # kc+ = (1 + a) Fc, kc- = (1 - a) Fc
SEED_KV2, SEED_KV3 = 0.01, 0.005
SEED_LAMBDA = 0.03  # of dq_max
SEED_KS = 0.5  # of Fc
STRIBECK_BUMP = 0.5  # Fs - Fc, of Fc
STRIBECK_SPEED = 0.02  # of dq_max


# ---------------------------------------------------------------------------- robot scales
@dataclass(frozen=True, eq=False)
class RobotScales:
    """Per-joint sizes that default effect sizes are relative to.

    Attributes
    ----------
    torque : ndarray, shape (n,)
        Torque scale s_j (N m): 95th percentile of ``|rnea_j|`` over random states.
    inertia : ndarray, shape (n,)
        Inertia scale I_j (kg m^2): median of ``M_jj(q)`` over random configurations.
    speed : ndarray, shape (n,)
        Reference speed v_j = dq_max_j / 2 (rad/s).
    """

    torque: np.ndarray
    inertia: np.ndarray
    speed: np.ndarray

    def to_dict(self) -> dict:
        return {
            "torque": self.torque.tolist(),
            "inertia": self.inertia.tolist(),
            "speed": self.speed.tolist(),
        }


def robot_scales(robot: RobotModel, *, samples: int = 1000) -> RobotScales:
    """Torque, inertia and speed scales of a robot (see the module docstring).

    Parameters
    ----------
    robot : RobotModel
        The nominal robot.
    samples : int
        Number of random states; drawn with ``np.random.default_rng(0)`` so the scales depend on the
        robot only.

    Returns
    -------
    RobotScales
    """
    import pinocchio as pin

    model = robot.pin_model
    data = model.createData()
    rng = np.random.default_rng(0)
    lo, hi = np.maximum(robot.q_min, -math.pi), np.minimum(robot.q_max, math.pi)
    lo, hi = np.where(lo < hi, lo, robot.q_min), np.where(lo < hi, hi, robot.q_max)
    q = rng.uniform(lo, hi, size=(samples, robot.n))
    dq = rng.uniform(-0.5, 0.5, size=(samples, robot.n)) * robot.dq_max
    ddq = rng.uniform(-0.5, 0.5, size=(samples, robot.n)) * robot.ddq_max
    tau = np.empty((samples, robot.n))
    diag = np.empty((samples, robot.n))
    for i in range(samples):
        tau[i] = pin.rnea(model, data, q[i], dq[i], ddq[i])
        diag[i] = np.diag(pin.crba(model, data, q[i]))
    torque = np.percentile(np.abs(tau), 95, axis=0)
    inertia = np.median(diag, axis=0)
    # A joint that carries nothing still gets a size (a millionth of the largest), never zero.
    torque = np.maximum(torque, 1e-6 * max(float(torque.max()), 1e-9))
    inertia = np.maximum(inertia, 1e-6 * max(float(inertia.max()), 1e-12))
    return RobotScales(torque=torque, inertia=inertia, speed=0.5 * np.asarray(robot.dq_max, dtype=float))


# ---------------------------------------------------------------------------- smooth sign
def _smooth_sign(dx: np.ndarray, eps: float) -> tuple[np.ndarray, np.ndarray]:
    """``tanh(dx / eps)`` and its derivative with respect to dx."""
    s = np.tanh(dx / eps)
    return s, (1.0 - s * s) / eps


# ---------------------------------------------------------------------------- truth friction
@dataclass(frozen=True, eq=False)
class TruthFriction:
    """Joint friction of the truth model (see the module docstring for the formulas).

    Parameters
    ----------
    kind : {"none", "linear", "seed", "stribeck"}
        Which model.
    kc_pos, kc_neg : ndarray, shape (n,)
        Coulomb friction (N m, both positive) when moving in the positive / negative direction.
    kv1, kv2, kv3 : ndarray, shape (n,)
        Viscous terms ``kv1 dq + kv2 dq|dq| + kv3 dq^3`` (N m s/rad, N m s^2/rad^2, N m s^3/rad^3).
    ks : ndarray, shape (n,)
        Extra friction at zero speed (N m): the low-speed region of ``seed``, ``Fs - Fc`` of ``stribeck``.
    vs : ndarray, shape (n,)
        ``lambda`` of ``seed`` or the Stribeck speed of ``stribeck`` (rad/s).
    eps : float
        Smoothing speed of ``sign`` (rad/s).
    """

    kind: str
    kc_pos: np.ndarray
    kc_neg: np.ndarray
    kv1: np.ndarray
    kv2: np.ndarray
    kv3: np.ndarray
    ks: np.ndarray
    vs: np.ndarray
    eps: float = SMOOTHING

    def __post_init__(self) -> None:
        if self.kind not in FRICTION_KINDS:
            raise UsageError(
                f"the friction model '{self.kind}' is unknown; choose one of {', '.join(FRICTION_KINDS)}."
            )
        if not (self.eps > 0 and math.isfinite(self.eps)):
            raise UsageError(
                f"the friction smoothing speed eps is {self.eps}; give a positive speed in rad/s."
            )
        for name in ("kc_pos", "kc_neg", "kv1", "kv2", "kv3", "ks", "vs"):
            value = np.array(getattr(self, name), dtype=float)
            value.setflags(write=False)
            object.__setattr__(self, name, value)

    @classmethod
    def default(
        cls, kind: str, scales: RobotScales, dq_max: np.ndarray, *, eps: float = SMOOTHING
    ) -> TruthFriction:
        """The default friction of each kind, sized by the robot's scales (module docstring).

        Parameters
        ----------
        kind : {"none", "linear", "seed", "stribeck"}
        scales : RobotScales
        dq_max : ndarray, shape (n,)
            Joint speed limits (rad/s).
        eps : float
            Smoothing speed of ``sign`` (rad/s).
        """
        if kind not in FRICTION_KINDS:
            raise UsageError(
                f"the friction model '{kind}' is unknown; choose one of {', '.join(FRICTION_KINDS)}."
            )
        s, v = scales.torque, scales.speed
        zero = np.zeros_like(s)
        fc, fv = COULOMB * s, VISCOUS * s / v
        dq_max = np.asarray(dq_max, dtype=float)
        if kind == "none":
            return cls(kind, zero, zero, zero, zero, zero, zero, zero, eps)
        if kind == "linear":
            return cls(kind, fc, fc, fv, zero, zero, zero, zero, eps)
        if kind == "seed":
            return cls(
                kind,
                (1 + SEED_ASYMMETRY) * fc,
                (1 - SEED_ASYMMETRY) * fc,
                fv,
                SEED_KV2 * s / v**2,
                SEED_KV3 * s / v**3,
                SEED_KS * fc,
                SEED_LAMBDA * dq_max,
                eps,
            )
        return cls(kind, fc, fc, fv, zero, zero, STRIBECK_BUMP * fc, STRIBECK_SPEED * dq_max, eps)

    @property
    def active(self) -> bool:
        return self.kind != "none"

    def torque(self, dq: np.ndarray, factor: np.ndarray | float = 1.0) -> tuple[np.ndarray, np.ndarray]:
        """Friction torque and its derivative with respect to the speed.

        Parameters
        ----------
        dq : ndarray, shape (n,) or (m, n)
            Joint speeds (rad/s).
        factor : float or ndarray, shape (n,)
            Scale of every coefficient (the temperature effect), 1 by default.

        Returns
        -------
        f, df : ndarray, same shape as dq
            Torque (N m, along the motion) and ``d f / d dq`` (N m s/rad).
        """
        s, ds = _smooth_sign(dq, self.eps)
        pos = s >= 0
        kc = np.where(pos, self.kc_pos, self.kc_neg)
        a = np.abs(dq)
        f = kc * s + self.kv1 * dq
        df = kc * ds + self.kv1
        if self.kind == "seed":
            # Magnitude g(|dq|): kc + kv(|dq|) above lambda; below, the line from kc + ks (at 0) to
            # kc + kv(lambda) (at lambda).  f = s g, with s the smooth sign.
            lam = self.vs
            kv_lam = self.kv1 * lam + self.kv2 * lam**2 + self.kv3 * lam**3
            inside = a < lam
            r = a / lam
            g = np.where(
                inside,
                kc + (1.0 - r) * self.ks + r * kv_lam,
                kc + self.kv1 * a + self.kv2 * a * a + self.kv3 * a**3,
            )
            dg = np.where(
                inside, (kv_lam - self.ks) / lam, self.kv1 + 2 * self.kv2 * a + 3 * self.kv3 * a * a
            )
            f = s * g
            df = ds * g + np.abs(s) * dg
        elif self.kind == "stribeck":
            e = np.exp(-((dq / self.vs) ** 2))
            f = f + self.ks * s * e
            df = df + self.ks * e * (ds - 2 * s * dq / self.vs**2)
        return f * factor, df * factor

    def to_dict(self) -> dict:
        out: dict[str, Any] = {"kind": self.kind, "eps": self.eps}
        names = {
            "linear": {"kc_pos": "Fc", "kv1": "Fv"},
            "seed": {
                "kc_pos": "kc_pos",
                "kc_neg": "kc_neg",
                "kv1": "kv1",
                "kv2": "kv2",
                "kv3": "kv3",
                "ks": "ks",
                "vs": "lambda",
            },
            "stribeck": {"kc_pos": "Fc", "ks": "Fs_minus_Fc", "vs": "vs", "kv1": "Fv"},
        }.get(self.kind, {})
        for attr, label in names.items():
            out[label] = getattr(self, attr).tolist()
        if self.kind == "seed":
            out["ks_pos"] = (self.kc_pos + self.ks).tolist()  # static levels, as SeedFriction names them
            out["ks_neg"] = (self.kc_neg + self.ks).tolist()
        out["units"] = "N m, rad/s (kv1 N m s/rad, kv2 N m s^2/rad^2, kv3 N m s^3/rad^3)"
        return out


# ---------------------------------------------------------------------------- requests
@dataclass(frozen=True)
class EffectRequest:
    """One item of ``--effects``: a name, a size multiplier and optional joints (numbered from 1)."""

    name: str
    value: float = 1.0
    joints: tuple[int, ...] | None = None

    def __str__(self) -> str:
        sel = ""
        if self.joints is not None:
            j = self.joints
            sel = f"@{j[0]}" if len(j) == 1 else f"@{j[0]}-{j[-1]}"
        return f"{self.name}{sel}" + ("" if self.value == 1.0 else f":{self.value:g}")


_ITEM = re.compile(r"^(?P<name>[A-Za-z_]+)(?:@(?P<j0>[^:\-]*)(?:-(?P<j1>[^:]*))?)?(?::(?P<value>.*))?$")


def parse_effects(spec: str | Sequence[str | EffectRequest] | None) -> tuple[EffectRequest, ...]:
    """Read ``NAME[@J|@J-K][:VALUE],...`` into effect requests.

    Parameters
    ----------
    spec : str or sequence of (str or EffectRequest) or None
        ``"offset,elasticity@3:2"``, a list of such items, or None / ``""`` / ``"none"`` for no effect.

    Returns
    -------
    tuple of EffectRequest

    Raises
    ------
    UsageError
        Unknown name (the message lists the known ones), a VALUE that is not a positive number, a
        malformed joint selector, an effect given twice, or a selector on an effect that takes none.
    """
    if spec is None:
        return ()
    items: list[str | EffectRequest]
    if isinstance(spec, str):
        if spec.strip().lower() in ("", "none", "off"):
            return ()
        items = [part for part in spec.split(",") if part.strip()]
    else:
        items = list(spec)
    out: list[EffectRequest] = []
    for item in items:
        req = item if isinstance(item, EffectRequest) else _parse_item(str(item))
        _check_request(req)
        if any(r.name == req.name for r in out):
            raise UsageError(
                f"the effect '{req.name}' is given twice; give it once (with a joint range if needed)."
            )
        out.append(req)
    return tuple(out)


def _parse_item(text: str) -> EffectRequest:
    item = text.strip().replace(" ", "")
    match = _ITEM.match(item)
    if match is None:
        raise UsageError(
            f"the effect '{item}' is not of the form NAME[@J|@J-K][:VALUE]; write e.g. 'offset', "
            "'elasticity@3:2' or 'delay:1.5'."
        )
    name = match["name"].lower()
    _check_name(name)
    value = 1.0
    if match["value"] is not None:
        try:
            value = float(match["value"])
        except ValueError:
            raise UsageError(
                f"the size of the effect '{item}' is '{match['value']}', not a number; give a positive number "
                f"such as {name}:2.0 (1.0 is the documented default size)."
            ) from None
    joints = None
    if match["j0"] is not None:
        try:
            j0 = int(match["j0"])
            j1 = int(match["j1"]) if match["j1"] is not None else j0
        except ValueError:
            raise UsageError(
                f"the joint selector of the effect '{item}' is not @J or @J-K with joint numbers from 1; "
                f"write e.g. {name}@3 or {name}@2-4."
            ) from None
        if j0 < 1 or j1 < j0:
            raise UsageError(
                f"the joint selector of the effect '{item}' selects no joint; joints are numbered from 1, "
                f"write e.g. {name}@3 or {name}@2-4."
            )
        joints = tuple(range(j0, j1 + 1))
    return EffectRequest(name=name, value=value, joints=joints)


def _check_name(name: str) -> None:
    if name not in EFFECTS:
        raise UsageError(f"unknown effect '{name}'; the known effects are {', '.join(EFFECTS)}.")


def _check_request(req: EffectRequest) -> None:
    _check_name(req.name)
    if not (isinstance(req.value, (int, float)) and math.isfinite(req.value) and req.value > 0):
        raise UsageError(
            f"the size of the effect '{req.name}' is {req.value}; give a finite positive number "
            "(1.0 is the documented default size)."
        )
    limit = EFFECTS[req.name].max_value
    if limit is not None and req.value >= limit:
        raise UsageError(
            f"the size of the effect '{req.name}' is {req.value:g}; it must stay below {limit:g} "
            f"({EFFECTS[req.name].why_limit})."
        )
    low = EFFECTS[req.name].min_value
    if req.value < low:
        raise UsageError(
            f"the size of the effect '{req.name}' is {req.value:g}; it must be at least {low:g} "
            f"({EFFECTS[req.name].why_min})."
        )
    if req.joints is not None and not EFFECTS[req.name].selectable:
        raise UsageError(
            f"the effect '{req.name}' acts on the whole arm and takes no joint selector; write '{req.name}' "
            f"or '{req.name}:VALUE'."
        )


# ---------------------------------------------------------------------------- the catalogue
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
        s, ds = _smooth_sign(dx, self.eps)
        e = np.exp(-((dx / self.speed) ** 2))
        return self.bump * s * e, self.bump * e * (ds - 2 * s * dx / self.speed**2)

    def details(self):
        return {"Fs_minus_Fc": self.bump, "vs": self.speed, "units": "N m, rad/s"}


@dataclass(frozen=True, eq=False)
class LoadFriction(Effect):
    """Coulomb friction growing with the drive torque: ``mu |tau_m| sign(dq)``, mu larger when driving."""

    name: ClassVar[str] = "load_friction"
    role: ClassVar[str] = "drive"
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
        s, ds = _smooth_sign(dx, self.eps)
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
    """Friction on ``w = dq_a + dq_b`` (a coupled wrist's motor) felt by both joints."""

    name: ClassVar[str] = "coupled_friction"
    role: ClassVar[str] = "drive"
    selectable: ClassVar[bool] = False
    coulomb: float = 0.0
    viscous: float = 0.0
    eps: float = SMOOTHING

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
        w = dx[a] + dx[b]
        s, ds = _smooth_sign(w, self.eps)
        g = self.coulomb * s + self.viscous * w
        dg = self.coulomb * ds + self.viscous
        n = dx.shape[-1]
        f = np.zeros(n)
        f[a] = f[b] = g
        J = np.zeros((n, n))
        J[a, a] = J[a, b] = J[b, a] = J[b, b] = dg
        return f, J

    def details(self):
        return {
            "Fc": self.coulomb,
            "Fv": self.viscous,
            "coupling": "w = dq_a + dq_b",
            "units": "N m, N m s/rad",
        }


@dataclass(frozen=True, eq=False)
class NonlinearViscous(Effect):
    """Viscous friction that grows faster than the speed: ``kv2 dq|dq| + kv3 dq^3``."""

    name: ClassVar[str] = "nonlinear_viscous"
    role: ClassVar[str] = "drive"
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
"""Effect name -> class, in the order of DESIGN.md."""

EFFECT_NAMES: tuple[str, ...] = tuple(EFFECTS)
"""The catalogue's effect names, in catalogue order (DESIGN.md): what ``simulate --effects`` injects,
``identify --effects`` models and ``diagnose`` tests.  Every other list of effects is this one."""
