"""What an identified model puts into a simulator description: bodies, armature, damping, frictionloss.

A simulator needs every link as a real body (positive mass, positive definite pseudo-inertia); an
identified model holds base parameters, which fix only combinations of the standard ones.
:func:`simulator_parameters` returns one physically consistent standard set per link:

* a model fitted with ``method="consistent"`` already carries one (``info["consistency"]``): it is
  used as it is, and the armature folded into a base parameter (joint 1 of a vertical first axis) is
  read back from the base parameters;
* any other model: the consistent set closest to the identified parameters in the Mahalanobis
  distance of their covariance, :func:`dynid.identify.consistent.consistent_solution` (a convex
  barrier method).  The directions the data cannot see (the null space of the base-parameter map)
  are pulled toward the template's bodies, so a standard parameter that no base parameter holds
  keeps the template's value where that value is consistent.

Friction is mapped per joint onto what simulators have, a viscous coefficient (``damping``, N m s/rad)
and a Coulomb level (``frictionloss``, N m): a linear model's own, and for a shape they cannot hold the
line closest to it at the training speeds the model file keeps (``speed_quantiles``,
:meth:`dynid.identify.friction.FrictionModel.simulator_line`); whatever the friction model holds beyond that (offset,
Stribeck hump, direction-dependent levels, higher-order viscous terms, a sigmoid's shift) is listed in
:attr:`SimParameters.not_carried`.  Each friction model says what a simulator holds of it
(:meth:`dynid.identify.friction.FrictionModel.simulator_terms`); a registered model that does not is
written as no damping and no frictionloss and listed whole.  Listed too are the mixture correction,
effect terms and a coupled transmission.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dynid.exceptions import ModelFileError
from dynid.identify.consistent import consistent_solution, is_consistent
from dynid.identify.model import IdentifiedModel

__all__ = ["SimParameters", "simulator_parameters", "unidentifiable_directions"]

_STORED_TOLERANCE = 1e-9  # relative gap within which stored standard parameters reproduce the base ones


@dataclass(frozen=True)
class SimParameters:
    """The parameters a simulator description receives.

    Attributes
    ----------
    standard : ndarray, shape (10 n,)
        Consistent standard parameters per joint body, Pinocchio's order (kg, kg m, kg m^2), about the
        joint frame.
    armature : ndarray, shape (n,)
        Rotor inertia reflected to each joint (kg m^2).
    damping : ndarray, shape (n,)
        Viscous friction (N m s/rad).
    frictionloss : ndarray, shape (n,)
        Coulomb friction level (N m).
    identified : ndarray, shape (p,)
        The identified parameters these values reproduce exactly (``P @ phi``; equal to the model's
        for a consistent model).
    source : str
        ``"consistent fit"`` or ``"closest consistent set"``.
    projection : dict
        How far the consistent set moved from the identified parameters (``relative``,
        ``mahalanobis``) and the solver's report.
    unidentifiable : dict
        The standard-parameter directions the data cannot see, pulled toward the template
        (:func:`unidentifiable_directions`).
    not_carried : list of dict
        What the simulator parameters leave out: ``{"what", "joints", "detail"}``.
    """

    standard: NDArray[np.float64]
    armature: NDArray[np.float64]
    damping: NDArray[np.float64]
    frictionloss: NDArray[np.float64]
    identified: NDArray[np.float64]
    source: str
    projection: dict[str, Any] = field(default_factory=dict)
    unidentifiable: dict[str, Any] = field(default_factory=dict)
    not_carried: list[dict[str, Any]] = field(default_factory=list)


def unidentifiable_directions(model: IdentifiedModel) -> dict[str, Any]:
    """The standard-parameter (and armature) directions the identified parameters do not fix.

    Parameters
    ----------
    model : IdentifiedModel
        The model.

    Returns
    -------
    dict
        ``dimension`` (of the null space of the base-parameter map over the standard parameters and
        the armature), ``unseen`` (names of the single parameters no identified parameter holds:
        ``m1``, ``Ixx1``, ...), ``combinations`` (how many further directions are combinations of
        parameters that are seen only together, e.g. the split of joint 1's armature and link
        inertia), ``regrouped`` (names of the parameters that take part in those combinations).
    """
    cols = model.columns
    n = cols.n
    P = cols.P[~cols.effect_mask]
    active = np.concatenate([np.ones(10 * n, dtype=bool), cols.enabled_extras[:n]])
    names = [*model.robot.param_names, *(f"ia{j + 1}" for j in range(n))]
    A = P[:, : 11 * n][:, active]
    labels = [nm for nm, a in zip(names, active, strict=True) if a]
    seen = np.any(np.abs(A) > 0, axis=0)
    s = np.linalg.svd(A, compute_uv=False)
    rank = int(np.sum(s > 1e-10 * s[0])) if s.size else 0
    dimension = A.shape[1] - rank
    unseen = [lab for lab, v in zip(labels, seen, strict=True) if not v]
    # parameters that appear in a null direction although some identified parameter holds them
    _, _, Vt = np.linalg.svd(A[:, seen], full_matrices=True)
    null = Vt[rank:]
    seen_labels = [lab for lab, v in zip(labels, seen, strict=True) if v]
    regrouped = [lab for k, lab in enumerate(seen_labels) if null.size and np.abs(null[:, k]).max() > 1e-9]
    return {
        "dimension": int(dimension),
        "unseen": unseen,
        "combinations": int(dimension - len(unseen)),
        "regrouped": regrouped,
    }


def _whitened_factor(cov: NDArray[np.float64]) -> NDArray[np.float64]:
    """Upper-triangular ``R`` with ``R^T R = cov^-1`` (eigenvalues floored: a singular block stays usable)."""
    w, V = np.linalg.eigh(0.5 * (cov + cov.T))
    top = float(w.max(initial=0.0))
    if not top > 0:
        return np.eye(len(cov))
    w = np.maximum(w, 1e-12 * top)
    inv = (V / w) @ V.T
    L = np.linalg.cholesky(0.5 * (inv + inv.T))
    return L.T


def _friction(model: IdentifiedModel, n: int) -> tuple[np.ndarray, np.ndarray, list[dict[str, Any]]]:
    """Per-joint (damping, frictionloss) from the friction model, and what the two leave out.

    Each model says what a simulator holds of it (:meth:`dynid.identify.friction.FrictionModel.simulator_terms`);
    a model that does not say is left out whole, and listed.
    """
    damping, loss = np.zeros(n), np.zeros(n)
    left: list[dict[str, Any]] = []
    if model.friction is None:
        return damping, loss, left
    models = model.friction.models_
    coefs = model.friction.to_dict()["joints"]

    def leave(what: str, joints: list[int], detail: str) -> None:
        if joints:
            left.append({"what": what, "joints": joints, "detail": detail})

    outside: list[tuple[str, ...]] = []
    items: dict[str, str] = {}
    speeds = model.info.get("speed_quantiles")  # files written before it: the models' own terms
    fitted_line = []
    for j, mdl in enumerate(models):
        damping[j], loss[j], out = mdl.simulator_terms()
        if set(out) - {"friction offset"} and speeds is not None and len(speeds) == n:  # not a line already
            # a shape a simulator cannot hold: the line closest to it at the training speeds instead of
            # its linear coefficients (a seed model's kv1 alone left 3 times the model's held-out error)
            damping[j], loss[j] = mdl.simulator_line(speeds[j])
            fitted_line.append(j + 1)
        outside.append(out)
        items.update(type(mdl).simulator_items())
    negative = [j + 1 for j, c in enumerate(coefs) if c.get("fc", 0.0) < 0 or c.get("fv", 0.0) < 0]
    leave(
        "negative Coulomb or viscous coefficient",
        negative,
        "identified below zero (an unconstrained fit); a simulator needs >= 0, so 0 was written",
    )
    for what, detail in items.items():
        leave(what, [j + 1 for j, out in enumerate(outside) if what in out], detail)
    line = "damping and frictionloss are the straight line closest to the identified friction at the training speeds"
    for item in left:
        if fitted_line and set(item["joints"]) <= set(fitted_line) and item["what"] not in (
            "negative Coulomb or viscous coefficient", "friction offset"
        ):
            whole = "no damping and frictionloss were written for it"  # a model of one's own (its default terms)
            item["detail"] = item["detail"].replace(whole, line) if whole in item["detail"] else f"{item['detail']}; {line}"
    return damping, loss, left


def simulator_parameters(
    model: IdentifiedModel,
    reference=None,
    *,
    reference_weight: float = 0.0,
) -> SimParameters:
    """Consistent bodies, armature and linear friction of an identified model, for a simulator.

    Parameters
    ----------
    model : IdentifiedModel
        The identified model.
    reference : RobotModel, optional
        The bodies the unidentifiable directions are pulled toward (the template's; default the robot
        the model was identified on).  Same kinematics as the model's robot.
    reference_weight : float
        Weight of the log-det pull toward the reference bodies in every direction (0: only the
        directions the data cannot see are pulled, by a vanishing weight).

    Returns
    -------
    SimParameters

    Raises
    ------
    ModelFileError
        Standard parameters that are not a physical body after all (a damaged file).
    """
    robot = model.robot
    cols = model.columns
    n = cols.n
    ref = robot if reference is None else reference
    kinds = np.array(cols.kinds)
    mask = np.isin(kinds, ("link", "armature"))
    x = np.asarray(model.params, dtype=np.float64)
    bodies, note = _stored_bodies(model, mask, x)
    if bodies is None:
        bodies = _closest_bodies(model, ref, mask, x, reference_weight, note)
    standard, armature = bodies.standard, bodies.armature
    _check_physical(standard)
    phi_full = np.concatenate([standard, armature, np.zeros(3 * n)])
    identified = np.where(mask, cols.P @ phi_full, 0.0)

    damping, loss, left = _friction(model, n)
    not_carried = list(left) + _extras_not_carried(model, n)
    return SimParameters(
        standard=standard,
        armature=armature,
        damping=damping,
        frictionloss=loss,
        identified=identified,
        source=bodies.source,
        projection=bodies.projection,
        unidentifiable=unidentifiable_directions(model),
        not_carried=not_carried,
    )


@dataclass(frozen=True)
class _Bodies:
    """Consistent standard parameters and armature, where they come from, and how far they moved."""

    standard: NDArray[np.float64]
    armature: NDArray[np.float64]
    source: str
    projection: dict[str, Any]


def _stored_bodies(
    model: IdentifiedModel, mask: NDArray[np.bool_], x: NDArray[np.float64]
) -> tuple[_Bodies | None, str | None]:
    """The consistent fit's stored bodies if they reproduce the base parameters, else None and why (or no note)."""
    cols = model.columns
    n = cols.n
    cons = model.info.get("consistency") or {}
    stored = cons.get("standard_params")
    if stored is None or len(stored) != 10 * n:
        return None, None
    standard = np.asarray(stored, dtype=np.float64)
    # the armature: alone where it has a column, else read back from the base parameter it was folded in
    arm_cols = cols.P[mask][:, 10 * n : 11 * n]
    resid = x[mask] - cols.P[mask][:, : 10 * n] @ standard
    used = np.any(arm_cols != 0, axis=0)
    armature = np.zeros(n)
    if used.any():
        armature[used] = np.linalg.lstsq(arm_cols[:, used], resid, rcond=None)[0]
    armature = np.maximum(armature, 0.0)
    phi = np.concatenate([standard, armature, np.zeros(3 * n)])
    gap = float(np.abs(cols.P[mask] @ phi - x[mask]).max() / max(np.abs(x[mask]).max(), 1e-300))
    if gap <= _STORED_TOLERANCE and is_consistent(standard).all():
        projection = {"relative": 0.0, "mahalanobis": 0.0, "solver": cons.get("solver")}
        return _Bodies(standard, armature, "consistent fit", projection), None
    note = (
        f"the model's stored standard parameters miss its base parameters by {gap:.2g} (relative); "
        "the closest consistent set was computed instead"
    )
    return None, note


def _closest_bodies(
    model: IdentifiedModel,
    ref,
    mask: NDArray[np.bool_],
    x: NDArray[np.float64],
    reference_weight: float,
    note: str | None,
) -> _Bodies:
    """The consistent set closest to the identified parameters (Mahalanobis), pulled toward ``ref``'s bodies."""
    cols = model.columns
    n = cols.n
    sub = model.cov[np.ix_(mask, mask)]
    R = _whitened_factor(sub)
    phi, solver = consistent_solution(ref, cols, x, R, 1.0, mask=mask, reference_weight=reference_weight)
    standard = phi[: 10 * n]
    armature = np.maximum(phi[10 * n : 11 * n], 0.0)
    x_c = cols.P[mask] @ phi
    projection = {
        "relative": float(np.linalg.norm(x_c - x[mask]) / max(np.linalg.norm(x[mask]), 1e-300)),
        "mahalanobis": float(np.linalg.norm(R @ (x_c - x[mask]))),
        "solver": solver,
    }
    if note is not None:
        projection["note"] = note
    return _Bodies(standard, armature, "closest consistent set", projection)


def _check_physical(standard: NDArray[np.float64]) -> None:
    """Raise :class:`ModelFileError` naming the links whose standard parameters are no physical body."""
    if not is_consistent(standard).all():
        bad = ", ".join(str(j + 1) for j in np.flatnonzero(~is_consistent(standard)))
        raise ModelFileError(
            f"the standard parameters of link(s) {bad} are not a physical body; identify again with "
            "--method consistent"
        )


def _extras_not_carried(model: IdentifiedModel, n: int) -> list[dict[str, Any]]:
    """What beyond friction a simulator leaves out: the mixture correction, effect terms, a coupled transmission."""
    cols = model.columns
    not_carried: list[dict[str, Any]] = []
    if model.gmr is not None and np.any(model.gmr.active_):
        joints = [j + 1 for j in range(n) if model.gmr.active_[j]]
        not_carried.append(
            {"what": "GMM correction", "joints": joints, "detail": "the mixture-regression residual (layer 3)"}
        )
    if cols.effects:
        pattern = cols.pattern[:, cols.effect_mask]
        for i, term in enumerate(cols.effects):
            reach = pattern[:, cols.effect_owner == i].any(axis=1)
            not_carried.append(
                {
                    "what": f"effect term {term.key}",
                    "joints": [int(j) + 1 for j in np.flatnonzero(reach)],
                    "detail": f"the identified {term.effect} term",
                }
            )
    if getattr(model.robot, "transmission", None) is not None:
        T = np.asarray(model.robot.transmission)
        coupled = [i + 1 for i in range(n) if np.count_nonzero(T[i]) > 1]
        not_carried.append(
            {
                "what": "coupled transmission",
                "joints": coupled,
                "detail": "armature and friction of a motor that turns with several joints are written on "
                "its own joint only; the cross terms are left out",
            }
        )
    return not_carried
