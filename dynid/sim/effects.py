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

Effects: the catalogue :data:`EFFECTS` and its table (names, models, default sizes) are in
:mod:`dynid.sim.effect_classes`, beside the classes; :func:`register_effect` adds one kept outside dynid.

Syntax of one effect: ``NAME`` (all joints it applies to, size 1), ``NAME:VALUE``, ``NAME@J`` (joint J
only, joints numbered from 1), ``NAME@J-K`` (joints J..K), ``NAME@J:VALUE``; several effects are
separated by commas, e.g. ``offset,elasticity@3:2,delay:1.5``.  The sensor effects act in the order
drive_gain, delay, offset, whatever the order given.

The code is split by responsibility: :mod:`dynid.sim.scales` (the robot's scales),
:mod:`dynid.sim.truth_friction` (the truth friction and the default friction sizes),
:mod:`dynid.sim.effect_classes` (the effect classes and their catalogue, :data:`EFFECTS`,
:data:`EFFECT_NAMES`, :func:`register_effect`); this module holds the ``--effects`` parser
(:func:`parse_effects`) and re-exports the others' names, which import from here as before.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass

from dynid.exceptions import UsageError
from dynid.sim.effect_classes import (
    EFFECT_NAMES,
    EFFECTS,
    ROLES,
    Effect,
    EffectContext,
    effect_names,
    register_effect,
    unregister_effect,
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
    "ROLES",
    "Effect",
    "EffectContext",
    "EffectRequest",
    "RobotScales",
    "TruthFriction",
    "effect_names",
    "parse_effects",
    "register_effect",
    "robot_scales",
    "unregister_effect",
]
# The default sizes (``COULOMB``, ``SMOOTHING``, ...; imported as themselves, so re-exported) also import
# from here, as before the split; the effect classes from dynid.sim.effect_classes.


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
