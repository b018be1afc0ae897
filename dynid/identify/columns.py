"""The identified parameters of a robot (the column set) and the torque of the linear model.

Layer 1 of the identification (METHOD.md section 4) solves ``tau = W x`` with ``x`` the identified
parameters: the base parameters of the links, optionally the armature and the linear friction of
each joint (Coulomb, viscous, offset: the columns of ``friction_columns``).  :func:`column_set`
names those parameters and maps them to the physical ones (:class:`ColumnSet`);
:func:`linear_torque` evaluates ``W(q, dq, ddq) x`` through the compiled batch regressor
(:func:`dynid.symbolic.export.compiled_functions`).

A coupled transmission (:attr:`RobotModel.transmission`, e.g. the TX40's wrist, where motor 6 also
turns with joint 5) moves the armature and the Coulomb and viscous friction to the motor side: the
motor of joint ``i`` turns (in joint units) by ``u_i = R[i] . q``, its inertia and friction act on
``u_i``, and the torque they cost reaches joint ``j`` as ``R[i, j]`` times theirs (power balance:
``tau = R^T tau_motor``).  Without a transmission ``R`` is the identity and the columns are the
joint's own.

Armature columns that duplicate a base column (joint 1 of an arm whose first axis is vertical:
its armature acts exactly like ``Izz1R``) are not given a column of their own; their parameter is
folded into the base parameter it duplicates and a note says so (:attr:`ColumnSet.notes`).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dynid._rest import direction
from dynid._threads import single_blas_thread
from dynid.exceptions import DataError, ShapeError, UsageError

__all__ = [
    "CHUNK_SAMPLES",
    "EXTRA_KINDS",
    "ColumnSet",
    "column_set",
    "compiled_base_regressor",
    "coupled_pairs",
    "linear_torque",
    "robot_coupling",
]

EXTRA_KINDS = ("armature", "coulomb", "viscous", "offset")
"""Kinds of the extra (non-link) parameters, in the order of the physical vector ``phi``."""
CHUNK_SAMPLES = 16384
"""Samples per call of the compiled regressor (and per block of the QR of the linear system)."""
_EXTRA_PREFIX = {"armature": "ia", "coulomb": "fc", "viscous": "fv", "offset": "fo"}
_DEPENDENT_TOL = 1e-8  # relative residual below which an extra column lies in the span of the others


@dataclass(frozen=True, eq=False)
class ColumnSet:
    """The identified parameters of a robot: base parameters plus optional armature and friction.

    The physical parameter vector is ``phi = [pi (10 n), ia (n), fc (n), fv (n), fo (n)]``: standard
    link parameters, armature (kg m^2), Coulomb (N m), viscous (N m s/rad) and offset (N m) per joint.
    The identified vector is ``x = P @ phi`` (p values): the base parameters, then the extras that have
    a column of their own.

    Attributes
    ----------
    robot : RobotModel
    base : BaseParameters
    friction, armature : bool
        Whether linear friction and armature columns are part of the system.
    names, kinds, expressions : tuple of str, length p
        Name (``Izz1R``, ``ia2``, ``fc3``...), kind (``link`` or one of :data:`EXTRA_KINDS`) and
        expression in the physical parameters of each identified parameter.
    joints : ndarray of int, shape (p,)
        Link (for a link parameter, the link of its leading standard parameter) or joint (extras) it
        belongs to, numbered from 1.
    extras : ndarray of int, shape (p - n_b,)
        Index into the 4 n extras of ``phi`` of each extra column kept.
    P : ndarray, shape (p, 14 n)
        ``x = P @ phi``.
    pattern : ndarray of bool, shape (n, p)
        Structurally non-zero entries of the identified regressor.
    notes : tuple of str
        What was folded where (duplicated columns).
    coupling : ndarray, shape (n, n), optional
        Motor angles in joint units per joint angle, ``u = R q`` (unit diagonal); None for the identity
        (every motor on its own joint).
    effects : tuple
        Effect terms (:mod:`dynid.identify.effect_terms`) whose coefficients close ``x`` (kind
        ``effect``, zero rows of ``P``: they are no physical parameter of the links).
    """

    robot: Any
    base: Any
    friction: bool
    armature: bool
    names: tuple[str, ...]
    kinds: tuple[str, ...]
    expressions: tuple[str, ...]
    joints: NDArray[np.intp]
    extras: NDArray[np.intp]
    P: NDArray[np.float64]
    pattern: NDArray[np.bool_]
    notes: tuple[str, ...]
    coupling: NDArray[np.float64] | None = None
    effects: tuple[Any, ...] = ()

    @property
    def n(self) -> int:
        """Number of joints."""
        return int(self.robot.n)

    @property
    def p(self) -> int:
        """Number of identified parameters."""
        return len(self.names)

    @property
    def n_base(self) -> int:
        """Number of base link parameters (the first ``n_base`` entries of ``x``)."""
        return int(self.base.n_base)

    @cached_property
    def link_mask(self) -> NDArray[np.bool_]:
        """Parameters of the rigid-body model: base parameters and armature (no friction), the friction of
        coupled motors (:attr:`coupled_mask`) and the effect terms (refitted with them)."""
        return np.array([k in ("link", "armature", "effect") for k in self.kinds]) | self.coupled_mask

    @cached_property
    def coupled_mask(self) -> NDArray[np.bool_]:
        """Coulomb and viscous friction of motors that turn with several joints (a coupled transmission):
        a friction model per joint cannot take them over, so they stay with the link parameters."""
        out = np.zeros(self.p, dtype=bool)
        if self.coupling is None:
            return out
        nb = self.n_base
        for k in range(len(self.extras)):
            if (
                self.kinds[nb + k] in ("coulomb", "viscous")
                and np.count_nonzero(self.extra_weights[:, k]) > 1
            ):
                out[nb + k] = True
        return out

    @cached_property
    def effect_mask(self) -> NDArray[np.bool_]:
        """Coefficients of the effect terms (the last ones of ``x``)."""
        return np.array([k == "effect" for k in self.kinds])

    @property
    def n_effect(self) -> int:
        """Number of effect coefficients."""
        return int(np.count_nonzero(self.effect_mask))

    @cached_property
    def effect_owner(self) -> NDArray[np.intp]:
        """Index into :attr:`effects` of each effect coefficient."""
        owner: list[int] = []
        for name in self.names[self.p - self.n_effect :]:
            key = name.rsplit(".", 1)[0]
            owner.append(next(i for i, t in enumerate(self.effects) if t.key == key))
        return np.array(owner, dtype=np.intp)

    def with_effects(self, terms, names, pattern) -> ColumnSet:
        """The column set with effect terms added after the extras.

        Parameters
        ----------
        terms : sequence
            The effect terms (:class:`dynid.identify.effect_terms.Candidate`).
        names : sequence of str
            One name per coefficient, ``KEY.coef`` (:func:`dynid.identify.effect_terms.coefficient_names`).
        pattern : ndarray of bool, shape (n, k)
            Joints each coefficient's column reaches.
        """
        k = len(names)
        pattern = np.asarray(pattern, dtype=bool).reshape(self.n, k)
        first = [int(np.flatnonzero(pattern[:, c])[0]) + 1 if pattern[:, c].any() else 1 for c in range(k)]
        return ColumnSet(
            robot=self.robot,
            base=self.base,
            friction=self.friction,
            armature=self.armature,
            names=self.names + tuple(names),
            kinds=self.kinds + ("effect",) * k,
            expressions=self.expressions + tuple(names),
            joints=np.concatenate([self.joints, np.array(first, dtype=np.intp)]),
            extras=self.extras,
            P=np.vstack([self.P, np.zeros((k, self.P.shape[1]))]),
            pattern=np.hstack([self.pattern, pattern]),
            notes=self.notes,
            coupling=self.coupling,
            effects=tuple(terms),
        )

    @cached_property
    def friction_mask(self) -> NDArray[np.bool_]:
        """Linear friction parameters (Coulomb, viscous, offset) of the joints (not of coupled motors)."""
        return np.array([k in ("coulomb", "viscous", "offset") for k in self.kinds]) & ~self.coupled_mask

    @property
    def extra_names(self) -> tuple[str, ...]:
        """Names of the 4 n extras of ``phi`` (``ia1..ia_n, fc1.., fv1.., fo1..``)."""
        n = self.n
        return tuple(f"{_EXTRA_PREFIX[k]}{j + 1}" for k in EXTRA_KINDS for j in range(n))

    @property
    def enabled_extras(self) -> NDArray[np.bool_]:
        """Which of the 4 n extras are part of the model (identified alone or folded into another)."""
        n = self.n
        return np.concatenate([np.full(n, self.armature), np.full(3 * n, self.friction)])

    def extra_columns(self, dq: NDArray[np.float64], ddq: NDArray[np.float64]) -> NDArray[np.float64]:
        """Values of the kept extra columns: (m, p - n_b); column k reaches joint j times ``extra_weights[j, k]``.

        Armature ``ddu_i``, Coulomb ``sign(du_i)``, viscous ``du_i``, offset ``1``, with ``u = R q`` the
        motor angles in joint units (``u = q`` without a coupled transmission: then these are
        ``friction_columns`` / ``armature_columns`` of :mod:`dynid.symbolic.functions`).

        Parameters
        ----------
        dq, ddq : ndarray, shape (m, n)
            Joint velocities (rad/s) and accelerations (rad/s^2).
        """
        n = self.n
        du, ddu = (dq, ddq) if self.coupling is None else (dq @ self.coupling.T, ddq @ self.coupling.T)
        out = np.empty((len(dq), len(self.extras)))
        for k, e in enumerate(self.extras):
            kind, j = EXTRA_KINDS[e // n], e % n
            if kind == "armature":
                out[:, k] = ddu[:, j]
            elif kind == "coulomb":
                out[:, k] = direction(du[:, j])
            elif kind == "viscous":
                out[:, k] = du[:, j]
            else:
                out[:, k] = 1.0
        return out

    @cached_property
    def extra_weights(self) -> NDArray[np.float64]:
        """(n, p - n_b): how much of each kept extra column reaches each joint (``R[i, j]`` for the
        motor-side kinds of motor i, 1 on its own joint for an offset or without a coupling)."""
        return _extra_weights(self.n, self.extras, self.coupling)

    @property
    def extra_joint(self) -> NDArray[np.intp]:
        """Joint (0-based) each kept extra column belongs to (its motor's joint for a coupled one)."""
        return (self.extras % self.n).astype(np.intp)


def _extra_weights(n: int, extras, coupling) -> NDArray[np.float64]:
    W = np.zeros((n, len(extras)))
    for k, e in enumerate(extras):
        kind, j = EXTRA_KINDS[e // n], e % n
        if coupling is None or kind == "offset":
            W[j, k] = 1.0
        else:
            W[:, k] = coupling[j]
    return W


def robot_coupling(robot) -> NDArray[np.float64] | None:
    """The robot's coupled transmission ``R`` (n, n), or None when every motor drives its own joint."""
    R = getattr(robot, "transmission", None)
    if R is None:
        return None
    R = np.asarray(R, dtype=np.float64)
    if np.array_equal(R, np.eye(robot.n)):
        return None
    return R


def coupled_pairs(R: ArrayLike) -> list[tuple[int, int]]:
    """``(a, b)`` (0-based) for each motor ``b`` of the transmission ``R`` that turns with exactly its own
    joint ``b`` and one other, ``a`` (the TX40's wrist: motor 6 with joints 5 and 6)."""
    pairs = []
    for b, row in enumerate(np.asarray(R, dtype=np.float64)):
        moved = np.flatnonzero(np.abs(row) > 1e-12).tolist()
        if len(moved) == 2 and b in moved:
            pairs.append((moved[0] if moved[1] == b else moved[1], b))
    return pairs


_COLUMN_CACHE: dict[tuple[str, bool, bool, bytes], ColumnSet] = {}
_BASE_CACHE: dict[str, Any] = {}


def _base_and_lib(robot):
    from dynid.symbolic.base import base_parameters
    from dynid.symbolic.export import compiled_functions
    from dynid.symbolic.functions import robot_functions

    # compiled_functions recomputes the base parameters on each call: keep both per robot.
    if robot.key not in _BASE_CACHE:
        with single_blas_thread():
            _BASE_CACHE[robot.key] = (base_parameters(robot_functions(robot)), compiled_functions(robot))
    return _BASE_CACHE[robot.key]


def compiled_base_regressor(robot, q, dq, ddq) -> NDArray[np.float64]:
    """Base regressor ``Y_b`` of a batch through the compiled path: (m, n, n_b)."""
    _, lib = _base_and_lib(robot)
    return lib.base_regressor(q, dq, ddq)


def column_set(robot, *, friction: bool = True, armature: bool = True) -> ColumnSet:
    """The identified parameters of ``robot`` (cached per robot and options).

    Parameters
    ----------
    robot : RobotModel
        The robot.
    friction : bool
        Identify linear friction (Coulomb, viscous, offset per joint) with the link parameters.
    armature : bool
        Identify the armature (rotor inertia) of each joint with the link parameters.

    Returns
    -------
    ColumnSet
    """
    R = robot_coupling(robot)
    key = (robot.key, bool(friction), bool(armature), b"" if R is None else R.tobytes())
    cached = _COLUMN_CACHE.get(key)
    if cached is not None:
        return cached
    with single_blas_thread():
        out = _column_set(robot, friction, armature)
    _COLUMN_CACHE[key] = out
    return out


def _column_set(robot, friction: bool, armature: bool) -> ColumnSet:
    from dynid.symbolic.base import random_states

    base, lib = _base_and_lib(robot)
    n, nb = robot.n, base.n_base
    rng = np.random.default_rng(0)
    m = max(200, 40 * n)
    q, dq, ddq = random_states(robot, m, rng)
    Yb = lib.base_regressor(q, dq, ddq)  # (m, n, nb)
    coupling = robot_coupling(robot)
    du, ddu = (dq, ddq) if coupling is None else (dq @ coupling.T, ddq @ coupling.T)
    pattern_b = np.any(Yb != 0.0, axis=0)
    enabled = np.concatenate([np.full(n, bool(armature)), np.full(3 * n, bool(friction))])
    extra_names = [f"{_EXTRA_PREFIX[k]}{j + 1}" for k in EXTRA_KINDS for j in range(n)]
    P = np.zeros((nb, 14 * n))
    P[:, : 10 * n] = base.matrix
    kept_cols = [Yb.reshape(m * n, nb)]
    kept_extra: list[int] = []
    expressions = list(base.expressions)
    notes = []
    ones = np.ones(m)
    for e in np.flatnonzero(enabled):
        kind, j = EXTRA_KINDS[e // n], e % n
        values = {"armature": ddu[:, j], "coulomb": direction(du[:, j]), "viscous": du[:, j], "offset": ones}[
            kind
        ]
        col = values[:, None] * _extra_weights(n, [e], coupling)[:, 0][None, :]
        col = col.reshape(m * n, 1)
        W = np.hstack(kept_cols)
        coef, *_ = np.linalg.lstsq(W, col, rcond=None)
        resid = np.linalg.norm(col - W @ coef) / max(np.linalg.norm(col), 1e-300)
        if resid < _DEPENDENT_TOL:
            coef = coef.ravel()
            coef[np.abs(coef) < 1e-9 * max(1.0, np.abs(coef).max())] = 0.0
            rows = np.flatnonzero(coef)
            P_col = np.zeros(P.shape[0])
            P_col[rows] = coef[rows]
            P[:, 10 * n + e] = P_col
            targets = []
            for r in rows:
                if r < nb:
                    c = coef[r]
                    term = extra_names[e] if abs(c - 1) < 1e-12 else f"{c:.6g}*{extra_names[e]}"
                    expressions[r] += f" + {term}"
                    targets.append(base.names[r])
                else:
                    targets.append(extra_names[kept_extra[r - nb]])
            notes.append(
                f"the {kind} column of joint {j + 1} ({extra_names[e]}) duplicates the column of "
                f"{', '.join(targets)}; {extra_names[e]} is identified inside {', '.join(targets)} "
                "instead of alone"
            )
            continue
        kept_cols.append(col)
        kept_extra.append(int(e))
        row = np.zeros((1, 14 * n))
        row[0, 10 * n + e] = 1.0
        P = np.vstack([P, row])
        expressions.append(extra_names[e])
    extras = np.array(kept_extra, dtype=np.intp)
    pattern_x = _extra_weights(n, extras, coupling) != 0.0
    link_of = (base.independent // 10 + 1).astype(np.intp)
    return ColumnSet(
        robot=robot,
        base=base,
        friction=bool(friction),
        armature=bool(armature),
        names=tuple(base.names) + tuple(extra_names[e] for e in extras),
        kinds=("link",) * nb + tuple(EXTRA_KINDS[e // n] for e in extras),
        expressions=tuple(expressions),
        joints=np.concatenate([link_of, extras % n + 1]).astype(np.intp),
        extras=extras,
        P=P,
        pattern=np.hstack([pattern_b, pattern_x]),
        notes=tuple(notes),
        coupling=coupling,
    )


def linear_torque(
    columns: ColumnSet,
    x: ArrayLike,
    q: ArrayLike,
    dq: ArrayLike,
    ddq: ArrayLike,
    *,
    mask: NDArray[np.bool_] | None = None,
    effect_values: NDArray[np.float64] | None = None,
) -> NDArray[np.float64]:
    """Torque of the linear model ``W(q, dq, ddq) x`` for a batch, through the compiled regressor.

    Parameters
    ----------
    columns : ColumnSet
        The identified parameters.
    x : array_like, shape (p,)
        Their values.
    q, dq, ddq : array_like, shape (m, n)
        States (rad, rad/s, rad/s^2).
    mask : ndarray of bool, shape (p,), optional
        Use only these parameters (e.g. ``columns.link_mask``: the rigid-body part).
    effect_values : ndarray, shape (m, n, k), optional
        The columns of the effect terms at these states (:func:`dynid.identify.effect_terms.effect_values`);
        needed when the column set has effect terms in use.

    Returns
    -------
    ndarray, shape (m, n)
        Joint torques (N m).
    """
    robot = columns.robot
    q, dq, ddq = (robot.check_state(label, v) for label, v in (("q", q), ("dq", dq), ("ddq", ddq)))
    for label, v in (("q", q), ("dq", dq), ("ddq", ddq)):
        if not np.all(np.isfinite(v)):
            row = int(np.argmax(~np.all(np.isfinite(v), axis=1)))
            raise DataError(
                f"{label} holds a non-finite value at row {row}; give finite states (drop or interpolate that row)"
            )
    if not (q.shape == dq.shape == ddq.shape):
        raise ShapeError(
            f"q, dq and ddq have shapes {q.shape}, {dq.shape}, {ddq.shape}; give three (m, n) arrays of one shape"
        )
    x = np.asarray(x, dtype=np.float64)
    if mask is not None:
        x = np.where(mask, x, 0.0)
    nb = columns.n_base
    m = len(q)
    out = np.zeros((m, robot.n))
    xb = x[:nb]
    for a in range(0, m, CHUNK_SAMPLES):
        s = slice(a, min(a + CHUNK_SAMPLES, m))
        out[s] = compiled_base_regressor(robot, q[s], dq[s], ddq[s]) @ xb
    k_eff = columns.n_effect
    if k_eff:
        xf = x[columns.p - k_eff :]
        if np.any(xf != 0):
            if effect_values is None or np.shape(effect_values) != (m, robot.n, k_eff):
                raise UsageError(
                    f"the model has {k_eff} effect coefficients ({', '.join(columns.names[-k_eff:][:3])}...) and "
                    "their columns were not given; predict through IdentifiedModel.predict, which builds them"
                )
            out += np.einsum("mnk,k->mn", effect_values, xf)
    if len(columns.extras):
        xe = x[nb : columns.p - k_eff]
        used = xe != 0
        if used.any():
            weights = columns.extra_weights[:, used].T
            for a in range(0, m, CHUNK_SAMPLES):  # a block at a time: the columns of a long run are large
                s = slice(a, min(a + CHUNK_SAMPLES, m))
                out[s] += (columns.extra_columns(dq[s], ddq[s])[:, used] * xe[used]) @ weights
    return out
