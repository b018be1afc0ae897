"""An identified model's torque prediction and regressor as C: ``dynid export-c --model M.json``.

>>> result = export_model_c(load_model("M.json"), "ur5_model_c")
>>> result.not_carried                           # what the C prediction leaves out, each with why
>>> lib = CompiledLibrary("ur5_model_c")         # dynid_loader.py beside it, or dynid.symbolic.export
>>> tau = lib.predict(q, dq, ddq)                # (N, n) N m: IdentifiedModel.predict to 1e-9

The folder is the one of :func:`dynid.symbolic.export.export_c`, with two more functions first:

``predict(q, dq, ddq) -> tau`` (n,)
    The model's torque with its parameters written into the code: the base regressor times the
    identified base parameters, the armature and the linear friction (Coulomb, viscous, offset) that
    layer 1 identifies, and a layer-2 friction model of the built-in kinds (linear, seed, Stribeck,
    sigmoid) at its fitted shape.
``model_regressor(q, dq, ddq) -> W`` (n, k)
    The columns of that prediction: ``predict == model_regressor @ theta``, ``theta`` and the columns'
    names in ``manifest.json["model"]["parameters"]`` (to refit or update the parameters in C).

What C cannot carry as a function of one state is listed, never dropped silently: a layer-3 mixture
correction that is active on some joint, a friction model of one's own (not a built-in kind), effect
terms (they need time histories or the measured torque).  ``manifest.json["model"]["not_carried"]``
names each with its joints and why; the command prints them.

Before the folder is moved into place the compiled library is loaded again and its ``predict``
compared with :meth:`IdentifiedModel.predict` (of the model without what is not carried) on random
states within the robot's limits: the largest difference must stay within :data:`RTOL` of the largest
torque, or nothing is written (:class:`~dynid.exceptions.GeneratorError`).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np
from numpy.typing import NDArray

from dynid._rest import AT_REST
from dynid.exceptions import GeneratorError
from dynid.identify.columns import EXTRA_KINDS, column_set
from dynid.identify.friction import (
    LinearFriction,
    NoFriction,
    SeedFriction,
    SigmoidFriction,
    StribeckFriction,
)
from dynid.identify.model import IdentifiedModel
from dynid.symbolic.base import random_states
from dynid.symbolic.build import Progress, stderr_progress
from dynid.symbolic.export import CompiledLibrary, ExportResult, export_c
from dynid.symbolic.functions import direction_sx

__all__ = [
    "MODEL_FUNCTIONS",
    "RTOL",
    "ModelExportResult",
    "check_prediction",
    "export_model_c",
    "model_functions",
]

RTOL = 1e-9
"""Largest difference between the library's prediction and the model's, relative to the largest torque."""
CHECK_STATES = 200
"""Random states of the reload check."""
MODEL_FUNCTIONS = ("predict", "model_regressor")
"""The functions :func:`export_model_c` always exports, before the robot's."""


@dataclass(frozen=True)
class ModelExportResult:
    """What :func:`export_model_c` wrote and checked.

    Attributes
    ----------
    export : ExportResult
        The paths written.
    carried : list of str
        What the C prediction holds.
    not_carried : list of dict
        What it leaves out: ``what``, ``joints`` (numbered from 1) and ``why``.
    check : dict
        The reload check: ``states``, ``relative_error``, ``tolerance``, ``passed``.
    """

    export: ExportResult
    carried: list[str]
    not_carried: list[dict[str, Any]] = field(default_factory=list)
    check: dict[str, Any] = field(default_factory=dict)

    @property
    def folder(self) -> Path:
        """The folder written."""
        return self.export.folder


# ---------------------------------------------------------------------------- layer-2 friction in CasADi
def _seed(v: ca.SX, lam: float, vmax: float = np.inf) -> list[ca.SX]:
    """The columns of :class:`SeedFriction` at threshold ``lam`` (its ``_seed_rows``, one speed), the square
    and cube continued as secants beyond ``vmax`` (its ``columns``)."""
    a = ca.fabs(v)
    high = a >= lam
    low = a < lam
    r = a / lam
    pos, neg = v >= AT_REST, v <= -AT_REST  # a joint at rest has no direction
    pos_low = ca.logic_and(pos, low)
    neg_low = ca.logic_and(neg, low)
    signed = ca.if_else(pos_low, r, ca.if_else(neg_low, -r, 0.0))
    square, cube = v * a, v**3
    if np.isfinite(vmax):  # beyond the training speeds: their secants (SeedFriction.columns)
        square, cube = ca.if_else(a > vmax, vmax * v, square), ca.if_else(a > vmax, vmax**2 * v, cube)
    return [
        ca.if_else(pos_low, r, ca.if_else(ca.logic_and(pos, high), 1.0, 0.0)),
        ca.if_else(neg_low, -r, ca.if_else(ca.logic_and(neg, high), -1.0, 0.0)),
        ca.if_else(high, v, signed * lam),
        ca.if_else(high, square, signed * lam**2),
        ca.if_else(high, cube, signed * lam**3),
        ca.if_else(pos_low, 1.0 - r, 0.0),
        ca.if_else(neg_low, -(1.0 - r), 0.0),
    ]


def _friction_basis(mdl: Any, v: ca.SX) -> list[tuple[str, ca.SX]] | None:
    """The columns of a fitted single-joint friction model at speed ``v`` (its ``basis``), each with the name
    of its coefficient, or None when it is not a built-in kind (a model of one's own: its form is not known
    here)."""
    kind = type(mdl)
    if kind is NoFriction:
        return []
    if kind is LinearFriction:
        k = len(mdl.linear_coef())
        return list(zip(("fc", "fv", "fo")[:k], [direction_sx(v), v, ca.SX(1.0)][:k], strict=True))
    if issubclass(kind, SeedFriction):  # held or shared static levels share a column (merged)
        cols = mdl.merged(_seed(v, float(mdl.coef_[-1]), mdl.vmax_))
        return list(zip((mdl.coef_names[k] for k in mdl._linear), cols, strict=True))
    if kind is StribeckFriction:
        vs = float(mdl.coef_[-1])
        e = ca.exp(-((v / vs) ** 2))
        sg = direction_sx(v)
        return list(zip(("fc", "fs", "fv", "fo"), [sg * (1.0 - e), sg * e, v, ca.SX(1.0)], strict=True))
    if kind is SigmoidFriction:
        phi2, phi3 = float(mdl.coef_[1]), float(mdl.coef_[2])

        def expit(z):
            return 1.0 / (1.0 + ca.exp(-z))

        return [("phi1", expit(phi2 * (v + phi3)) - expit(phi2 * phi3))]
    return None


# ---------------------------------------------------------------------------- the model's functions
@dataclass(frozen=True)
class _Plan:
    """What the C prediction holds, and the model that predicts exactly that."""

    names: list[str]
    kinds: list[str]
    theta: NDArray[np.float64]
    carried: list[str]
    not_carried: list[dict[str, Any]]
    reference: IdentifiedModel
    friction: dict[str, Any] | None


def _plan(model: IdentifiedModel) -> _Plan:
    cols = model.columns
    n = model.robot.n
    p0 = cols.p - cols.n_effect
    used = np.asarray(model.filtered_mask[:p0], dtype=bool)
    names = [cols.names[k] for k in np.flatnonzero(used)]
    kinds = [cols.kinds[k] for k in np.flatnonzero(used)]
    theta = [float(model.params[k]) for k in np.flatnonzero(used)]
    carried = [f"rigid body ({cols.n_base} base parameters)"]
    for kind, label in (
        ("armature", "armature"),
        ("coulomb", "Coulomb"),
        ("viscous", "viscous"),
        ("offset", "offset"),
    ):
        if kind in kinds:
            carried.append(f"{label} (layer 1)")
    not_carried: list[dict[str, Any]] = []
    if cols.n_effect:
        coefs = model.params[p0:]
        keys = [t.key for i, t in enumerate(cols.effects) if np.any(coefs[cols.effect_owner == i] != 0)]
        if keys:
            joints = sorted({int(j) for j in cols.joints[p0:][coefs != 0]})
            not_carried.append(
                {
                    "what": f"effect terms {', '.join(keys)}",
                    "joints": joints,
                    "why": "they are functions of time histories or of the measured torque, not of one state "
                    "(q, dq, ddq); predict them with dynid (IdentifiedModel.predict on a Dataset)",
                }
            )
    friction_source = model.friction_source
    layer2 = None
    friction = None
    if model.friction is not None and model.friction_source == "layer2":
        fric = model.friction
        bases = [_friction_basis(mdl, ca.SX.sym("v")) for mdl in fric.models_]
        friction = {"model": fric.model, "source": "layer2", "joints": fric.to_dict()["joints"]}
        if all(b is not None for b in bases):
            layer2 = fric
            friction["carried"] = True
            for j, (mdl, basis) in enumerate(zip(fric.models_, bases, strict=True)):
                for (name, _), value in zip(basis, mdl.linear_coef(), strict=True):
                    names.append(f"friction{j + 1}.{name}")
                    kinds.append(f"friction ({fric.model}, layer 2)")
                    theta.append(float(value))
            carried.append(f"{fric.model} friction (layer 2, at its fitted shape)")
        else:
            friction["carried"] = False
            friction_source = "none"
            not_carried.append(
                {
                    "what": f"layer-2 friction ({fric.model})",
                    "joints": list(range(1, n + 1)),
                    "why": f"'{fric.model}' is not a built-in friction model (linear, seed, seed_shared, stribeck, sigmoid), "
                    "so its form is not known to the C generator; add it to the C torque yourself (its "
                    "coefficients are in manifest.json's model.friction)",
                }
            )
    elif model.friction is not None:
        friction = {"model": model.friction.model, "source": model.friction_source, "carried": True}
    gmr = model.gmr
    if gmr is not None and not gmr.active_.any():
        carried.append("layer-3 mixture: inactive on every joint (zero)")
    elif gmr is not None:
        not_carried.append(
            {
                "what": "layer-3 mixture correction (GMR)",
                "joints": [int(j) + 1 for j in np.flatnonzero(gmr.active_)],
                "why": "a Gaussian mixture regression with range guards, not written as C; the C torque is "
                "the physical layers' (dynid's IdentifiedModel.predict adds it)",
            }
        )
    base_cols = column_set(model.robot, friction=cols.friction, armature=cols.armature)
    if tuple(base_cols.names) != tuple(cols.names[:p0]):  # a model file of another column order
        raise GeneratorError(
            "the model's layer-1 columns differ from the robot's column set here; identify the model again "
            "with this version of dynid, then export it"
        )
    info = {k: v for k, v in model.info.items() if k != "torque_range"}  # random states may leave it
    reference = replace(
        model,
        columns=base_cols,
        params=np.asarray(model.params[:p0], dtype=np.float64),
        cov=np.asarray(model.cov[:p0, :p0], dtype=np.float64),
        friction=layer2 if friction_source == "layer2" else model.friction,
        friction_source=friction_source,
        gmr=None,
        info=info,
    )
    return _Plan(names, kinds, np.asarray(theta), carried, not_carried, reference, friction)


def model_functions(model: IdentifiedModel) -> tuple[ca.Function, ca.Function, dict[str, Any]]:
    """The model's ``predict`` and ``model_regressor`` as CasADi functions, and what they carry.

    Parameters
    ----------
    model : IdentifiedModel
        The identified model.

    Returns
    -------
    predict : casadi.Function
        ``predict(q, dq, ddq) -> tau``, (n,) each (rad, rad/s, rad/s^2 -> N m).
    regressor : casadi.Function
        ``model_regressor(q, dq, ddq) -> W``, (n, k): ``tau = W @ theta``.
    description : dict
        ``parameters`` (name, kind, value of each column), ``carried``, ``not_carried``, ``friction``; and,
        under ``_reference``, the model that predicts what the functions carry (for the reload check).
    """
    plan = _plan(model)
    cols = model.columns
    n = model.robot.n
    q, dq, ddq = (ca.SX.sym(s, n) for s in ("q", "dq", "ddq"))
    Yb = cols.base.base_regressor(q, dq, ddq)
    R = cols.coupling
    du = dq if R is None else ca.mtimes(ca.DM(R), dq)
    ddu = ddq if R is None else ca.mtimes(ca.DM(R), ddq)
    p0 = cols.p - cols.n_effect
    used = np.asarray(model.filtered_mask[:p0], dtype=bool)
    columns = [Yb[:, k] for k in np.flatnonzero(used[: cols.n_base])]
    nb = cols.n_base
    for k, e in enumerate(cols.extras):
        if not used[nb + k]:
            continue
        kind, j = EXTRA_KINDS[e // n], e % n
        value = {"armature": ddu[j], "coulomb": direction_sx(du[j]), "viscous": du[j], "offset": ca.SX(1.0)}[kind]
        columns.append(value * ca.DM(cols.extra_weights[:, k]))
    fric = plan.reference.friction if plan.reference.friction_source == "layer2" else None
    if fric is not None:
        for j, mdl in enumerate(fric.models_):
            for _, column in _friction_basis(mdl, dq[j]) or []:
                e_j = np.zeros(n)
                e_j[j] = 1.0
                columns.append(column * ca.DM(e_j))
    W = ca.horzcat(*columns) if columns else ca.SX.zeros(n, 0)
    if W.size2() != len(plan.theta):  # the plan and the columns are built from the same lists
        raise GeneratorError(
            f"{W.size2()} regressor columns for {len(plan.theta)} parameters; report this as a bug"
        )
    tau = ca.mtimes(W, ca.DM(plan.theta)) if len(plan.theta) else ca.SX.zeros(n, 1)
    predict = ca.Function("predict", [q, dq, ddq], [tau], ["q", "dq", "ddq"], ["tau"])
    regressor = ca.Function("model_regressor", [q, dq, ddq], [W], ["q", "dq", "ddq"], ["W"])
    description = {
        "parameters": [
            {"name": a, "kind": b, "value": float(c)}
            for a, b, c in zip(plan.names, plan.kinds, plan.theta, strict=True)
        ],
        "carried": plan.carried,
        "not_carried": plan.not_carried,
        "friction": plan.friction,
        "_reference": plan.reference,
    }
    return predict, regressor, description


# ---------------------------------------------------------------------------- the reload check
def check_prediction(
    folder: str | Path,
    model: IdentifiedModel,
    *,
    states: int = CHECK_STATES,
    rtol: float = RTOL,
    seed: int = 0,
) -> dict[str, Any]:
    """Compare the ``predict`` of a compiled library with ``model.predict`` on random states.

    Parameters
    ----------
    folder : str or Path
        A folder written by :func:`export_model_c` (or being written).
    model : IdentifiedModel
        The model whose prediction the library must reproduce (for :func:`export_model_c`: the model
        without what is not carried).
    states : int
        Random states, drawn uniformly within the robot's position, speed and acceleration limits; the
        speeds of half of them scaled down by up to 1e-4 (a few at rest), where friction models change.
    rtol : float
        Largest ``max |tau_C - tau_model|`` relative to ``max |tau_model|``.
    seed : int
        Seed of the states.

    Returns
    -------
    dict
        ``states``, ``relative_error``, ``regressor_error`` (of ``model_regressor @ theta``),
        ``tolerance``, ``passed`` (True: a failure raises).

    Raises
    ------
    GeneratorError
        When the library does not reproduce the model within ``rtol``.
    """
    lib = CompiledLibrary(folder, threads=1)
    robot = model.robot
    rng = np.random.default_rng(seed)
    q, dq, ddq = random_states(robot, int(states), rng)
    # half of the speeds scaled down to 1e-4 of the limit, a few at rest: the low-speed friction regions
    half = int(states) // 2
    dq[half:] *= 10.0 ** rng.uniform(-4.0, 0.0, size=(int(states) - half, 1))
    dq[half : half + max(1, int(states) // 20)] = 0.0
    want = model.predict(q, dq, ddq)
    got = lib.predict(q, dq, ddq).reshape(want.shape)
    theta = np.array([p["value"] for p in lib.manifest["model"]["parameters"]], dtype=np.float64)
    W = lib.model_regressor(q, dq, ddq)
    via_w = W @ theta if theta.size else np.zeros_like(want)
    scale = max(float(np.max(np.abs(want))), 1e-300)
    error = float(np.max(np.abs(got - want))) / scale
    error_w = float(np.max(np.abs(via_w - want))) / scale
    if not (error <= rtol and error_w <= rtol):
        worst = "predict" if not error <= rtol else "model_regressor @ theta"
        raise GeneratorError(
            f"the compiled {worst} differs from the model's prediction by {max(error, error_w):.3g} (relative to the "
            f"largest torque, {scale:.4g} N m) on {states} random states within the limits; the tolerance is "
            f"{rtol:.0e}: nothing was written (report this as a bug, with the model file)"
        )
    return {
        "what": "predict and model_regressor @ theta against IdentifiedModel.predict (of the layers carried)",
        "states": int(states),
        "relative_error": error,
        "regressor_error": error_w,
        "tolerance": float(rtol),
        "passed": True,
    }


def export_model_c(
    model: IdentifiedModel,
    out: str | Path,
    *,
    functions=(),
    model_file: str | None = None,
    progress: Progress | None = stderr_progress,
) -> ModelExportResult:
    """Write an identified model's prediction and regressor as C, compiled and reload-checked.

    Parameters
    ----------
    model : IdentifiedModel
        The identified model.
    out : str or Path
        The folder to write (see :func:`dynid.symbolic.export.export_c`).
    functions : sequence of str
        Robot functions to export after ``predict`` and ``model_regressor`` (names of
        :data:`dynid.symbolic.export.DEFAULT_EXPORT` and the other exportable functions); none by default,
        since the robot's ``rnea`` and ``gravity`` are the description's, not the identified model's.
    model_file : str, optional
        The model file's name, recorded in the manifest.
    progress : callable, optional
        Receives progress messages.

    Returns
    -------
    ModelExportResult

    Raises
    ------
    GeneratorError
        The compiler failed, or the library does not reproduce the model (nothing is written).
    """
    predict, regressor, description = model_functions(model)
    reference = description.pop("_reference")
    manifest = {
        "model": {
            "file": model_file,
            "method": model.method,
            "prediction": "tau = predict(q, dq, ddq) = model_regressor(q, dq, ddq) @ theta, theta the values of "
            "'parameters' (N m)",
            **description,
        }
    }
    result = export_c(
        model.robot,
        out,
        functions=tuple(f for f in functions if f not in MODEL_FUNCTIONS),
        extra=(predict, regressor),
        manifest=manifest,
        example="predict",
        check=lambda folder: check_prediction(folder, reference),
        progress=progress,
    )
    check = json.loads(result.manifest.read_text())["check"]
    return ModelExportResult(
        export=result, carried=description["carried"], not_carried=description["not_carried"], check=check
    )
