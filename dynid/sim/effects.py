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

The code is split by responsibility: :mod:`dynid.sim.scales` (the robot's scales),
:mod:`dynid.sim.truth_friction` (the truth friction and the default friction sizes),
:mod:`dynid.sim.effect_classes` (the effect classes); this module holds the catalogue
(:data:`EFFECTS`, :data:`EFFECT_NAMES`) and the ``--effects`` parser (:func:`parse_effects`) and
re-exports the others' names, which import from here as before.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass

from dynid.exceptions import UsageError
from dynid.sim.effect_classes import (
    Armature,
    Backlash,
    BaseTilt,
    Cogging,
    CoupledFriction,
    Delay,
    DriveGain,
    Effect,
    EffectContext,
    Elasticity,
    LoadFriction,
    NonlinearViscous,
    Offset,
    Payload,
    Stribeck,
    Temperature,
)
from dynid.sim.scales import RobotScales, robot_scales
from dynid.sim.truth_friction import COULOMB as COULOMB
from dynid.sim.truth_friction import FRICTION_KINDS, TruthFriction
from dynid.sim.truth_friction import SEED_ASYMMETRY as SEED_ASYMMETRY
from dynid.sim.truth_friction import SEED_KS as SEED_KS
from dynid.sim.truth_friction import SEED_KV2 as SEED_KV2
from dynid.sim.truth_friction import SEED_KV3 as SEED_KV3
from dynid.sim.truth_friction import SEED_LAMBDA as SEED_LAMBDA
from dynid.sim.truth_friction import SMOOTHING as SMOOTHING
from dynid.sim.truth_friction import STRIBECK_BUMP as STRIBECK_BUMP
from dynid.sim.truth_friction import STRIBECK_SPEED as STRIBECK_SPEED
from dynid.sim.truth_friction import VISCOUS as VISCOUS

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
# The effect classes and the default sizes (``COULOMB``, ``SMOOTHING``, ...; imported as themselves, so
# re-exported) also import from here, as before the split.


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
