"""``export_model``: an identified model written into a URDF or an MJCF, reload-checked before it is kept.

>>> result = export_model(load_model("M.json"), "mjcf", "robot.xml")
>>> result.figures()["checks"]          # each reload check with its error and tolerance

The file is written to a temporary path beside ``out``, read back by Pinocchio (URDF) or MuJoCo (MJCF)
and checked (:mod:`dynid.simmodel.checks`); only when every check passes is it renamed into place.  A
failing check raises :class:`dynid.exceptions.IdentificationError` and leaves nothing behind.
"""

from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from dynid._io import atomic_path
from dynid.exceptions import IdentificationError, UsageError
from dynid.identify.registry import FRICTION_MODELS
from dynid.simmodel.checks import check_mjcf, check_urdf
from dynid.simmodel.parameters import SimParameters, simulator_parameters
from dynid.simmodel.urdf import match_template, read_template, robot_urdf, write_urdf

__all__ = ["FORMATS", "ExportResult", "default_template", "export_model"]

FORMATS = ("urdf", "mjcf")


@dataclass
class ExportResult:
    """What :func:`export_model` wrote and checked.

    Attributes
    ----------
    path : Path
        The file written.
    format : str
        ``urdf`` or ``mjcf``.
    template : Path
        The URDF the file was built from (a modified-DH table: the table, from which one was written).
    params : SimParameters
        The values written.
    checks : list of dict
        The reload checks (each with ``passed``).
    not_carried : list of dict
        What the format leaves out, with its share of the training error where the model file tells it.
    locked : list of str
        Joints of the template the model does not move (kept, at their neutral position in the checks).
    heldout : dict or None
        Held-out RMS of the model, of the export and of the model without each part the export loses
        (:func:`dynid.simmodel.shares.heldout_shares`), when held-out data were given.
    """

    path: Path
    format: str
    template: Path
    params: SimParameters
    checks: list[dict[str, Any]] = field(default_factory=list)
    not_carried: list[dict[str, Any]] = field(default_factory=list)
    locked: list[str] = field(default_factory=list)
    heldout: dict[str, Any] | None = None

    def figures(self) -> dict[str, Any]:
        """JSON-ready figures: ``checks``, ``not_carried`` and the values written."""
        p = self.params
        n = len(p.armature)
        return {
            "out": str(self.path),
            "format": self.format,
            "template": str(self.template),
            "inertials": p.source,
            "projection": p.projection,
            "unidentifiable": p.unidentifiable,
            "locked_joints": self.locked,
            "joints": [
                {
                    "joint": j + 1,
                    "armature": float(p.armature[j]),
                    "damping": float(p.damping[j]),
                    "frictionloss": float(p.frictionloss[j]),
                    "mass": float(p.standard[10 * j]),
                }
                for j in range(n)
            ],
            "checks": self.checks,
            "not_carried": self.not_carried,
            "heldout": self.heldout,
        }


def default_template(robot) -> Path:
    """The URDF a robot was loaded from (a built-in name: the file of example-robot-data).

    Raises
    ------
    UsageError
        A robot from a modified-DH table (no URDF to copy).
    """
    from dynid.symbolic.robot import BUILTIN_ROBOTS, example_robot_data_dir

    source = str(robot.source)
    if source.lower() in BUILTIN_ROBOTS and not Path(source).exists():
        return example_robot_data_dir() / BUILTIN_ROBOTS[source.lower()]["urdf"]
    path = Path(source)
    if path.suffix.lower() == ".urdf":
        if not path.is_file():
            raise UsageError(
                f"the model was identified on '{source}', which is not here any more; give --template with the "
                "robot's URDF"
            )
        return path
    raise UsageError(
        f"the model was identified on '{source}', not on a URDF, so there is no description to copy; give "
        "--template with a URDF of the same robot"
    )


def _friction_items() -> set[str]:
    """The ``what`` of every friction item :func:`simulator_parameters` may leave out: each registered
    friction model's (:meth:`dynid.identify.friction.FrictionModel.simulator_items`) and negative ones."""
    return {"negative Coulomb or viscous coefficient"} | {
        what for name in FRICTION_MODELS for what in FRICTION_MODELS[name].simulator_items()
    }


def _measured(heldout: dict[str, Any], item: dict[str, Any]) -> str | None:
    """The held-out share of a part left out, from :func:`heldout_shares`; None when not measured."""
    what = item["what"]
    friction_items = _friction_items()
    for part in heldout["parts"]:
        name = part["part"]
        hit = (
            (what in friction_items and name.startswith("friction beyond"))
            or (what == "GMM correction" and name == "GMM correction")
            or (what == name)
            or (what in ("armature", "coupled transmission") and name.startswith("rigid body"))
        )
        if hit:
            without, full = float(np.mean(part["rms_without"])), float(heldout["rms_full_mean"])
            if what in friction_items:  # one figure for all of them: they are removed together
                return (
                    f"held-out RMS {without:.4g} N m without the friction terms the file cannot carry (all of "
                    f"them together, not this one alone), {full:.4g} N m with them (mean over joints)"
                )
            together = ""
            if what in ("armature", "coupled transmission"):
                together = " (with the rest of the rigid-body change: consistency projection, armature)"
            return f"held-out RMS {without:.4g} N m without it{together}, {full:.4g} N m with it (mean over joints)"
    return None


def _shares(
    model, items: list[dict[str, Any]], fmt: str, params: SimParameters, heldout: dict[str, Any] | None = None
) -> list[dict[str, Any]]:
    """Add to each item left out its share of the error: held-out if measured, else training where the
    model file holds it, else a sentence saying it cannot be computed."""
    out = []
    layers = model.rms_layers or {}
    for item in items:
        item = dict(item)
        measured = None if heldout is None else _measured(heldout, item)
        if measured is not None:
            item["share"] = measured
        elif heldout is not None:
            item["share"] = "none on the held-out data (its torque there is zero to rounding)"
        elif item["what"] == "GMM correction" and "gmm" in layers and "friction" in layers:
            before = np.asarray(layers["friction"], dtype=float)
            after = np.asarray(layers["gmm"], dtype=float)
            item["training_rms_without"] = before.tolist()
            item["training_rms_with"] = after.tolist()
            item["share"] = (
                f"training RMS {after.mean():.4g} N m with it, {before.mean():.4g} N m without (mean over joints)"
            )
        else:
            item["share"] = (
                "cannot be computed from the model file (its training states are not stored); give "
                "--heldout data to measure it"
            )
        out.append(item)
    if fmt == "urdf" and np.any(params.armature > 0):
        arm = {
            "what": "armature",
            "joints": [j + 1 for j in range(len(params.armature)) if params.armature[j] > 0],
            "detail": "URDF has no armature field (Pinocchio's model.armature, MuJoCo's joint armature); "
            "values: " + ", ".join(f"{a:.6g}" for a in params.armature) + " kg m^2 (in this comment only)",
        }
        measured = None if heldout is None else _measured(heldout, arm)
        arm["share"] = measured or "kept in the MJCF export"
        out.append(arm)
    if fmt == "mjcf":
        out.append(
            {
                "what": "visual and collision geometry",
                "joints": [],
                "detail": "MuJoCo's URDF importer cannot resolve package:// meshes, so the MJCF has bodies, "
                "joints, limits and inertials only; the URDF export keeps them",
                "share": "none (geometry does not enter the joint torque)",
            }
        )
    return out


def _comment(model_name: str, fmt: str, params: SimParameters, items: list[dict[str, Any]], locked) -> str:
    u = params.unidentifiable
    lines = [
        f" dynid export ({fmt}) of {model_name}.",
        f" Link inertials: {params.source}, physically consistent (positive definite pseudo-inertias).",
        f" {u.get('dimension', 0)} standard-parameter directions are not identifiable from joint torques and were "
        "pulled toward the template's values"
        + (f"; parameters never seen: {', '.join(u['unseen'])}" if u.get("unseen") else "")
        + ".",
    ]
    if locked:
        lines.append(f" Joints not in the model (locked at neutral when identified): {', '.join(locked)}.")
    if items:
        lines.append(" Not carried by this format:")
        for it in items:
            joints = ",".join(str(j) for j in it.get("joints", []))
            lines.append(f"  - {it['what']} (joints {joints}): {it['detail']}; share: {it['share']}.")
    text = "\n".join(lines).replace("--", "- -")
    return text + "\n"


def export_model(
    model,
    fmt: str,
    out: str | os.PathLike[str],
    *,
    template: str | os.PathLike[str] | None = None,
    model_name: str = "the model",
    reference_weight: float = 0.0,
    heldout=None,
) -> ExportResult:
    """Write an identified model into a copy of a robot description and check it by reloading it.

    Parameters
    ----------
    model : IdentifiedModel
        The identified model.
    fmt : {"urdf", "mjcf"}
        Format written.
    out : str or path-like
        The file to write (its folder must exist).
    template : str or path-like, optional
        The URDF to copy (default: the one the model was identified on, :func:`default_template`; for
        a modified-DH table, a URDF written from it by :func:`dynid.simmodel.urdf.robot_urdf`).
    model_name : str
        How the model is named in the file's comment.
    reference_weight : float
        Pull toward the template's bodies in every direction (see :func:`simulator_parameters`).
    heldout : Dataset, optional
        Held-out data on which the share of each part the format leaves out is measured
        (:func:`dynid.simmodel.shares.heldout_shares`).

    Returns
    -------
    ExportResult

    Raises
    ------
    UsageError
        Unknown format, a template that is not a URDF or not of this robot.
    IdentificationError
        A reload check failed (nothing is written).
    """
    if fmt not in FORMATS:
        raise UsageError(f"unknown format {fmt!r}; choose one of {', '.join(FORMATS)}")
    robot = model.robot
    if template is not None and Path(template).suffix.lower() in (".xml", ".mjcf"):
        return _export_into_mjcf(model, fmt, Path(out), Path(template), model_name, reference_weight, heldout)
    if template is None and Path(str(robot.source)).suffix.lower() == ".toml":
        # a modified-DH table has no URDF: one is written from the robot's canonical tree
        with tempfile.TemporaryDirectory() as folder:
            generated = Path(folder) / f"{robot.name}.urdf"
            generated.write_text(robot_urdf(robot), encoding="utf-8")
            root = read_template(generated)
            match = match_template(root, generated, robot)
        tpl = Path(str(robot.source))
    else:
        tpl = default_template(robot) if template is None else Path(template)
        root = read_template(tpl)
        match = match_template(root, tpl, robot)
    reference = robot.with_params(match.template_params)
    params = simulator_parameters(model, reference, reference_weight=reference_weight)
    shares = None
    if heldout is not None:
        from dynid.simmodel.shares import heldout_shares

        shares = heldout_shares(model, params, fmt, heldout)
    items = _shares(model, params.not_carried, fmt, params, shares)
    comment = _comment(model_name, fmt, params, items, match.locked)
    text = write_urdf(root, match, robot, params, comment, payload=model.info.get("payload"))
    if fmt == "mjcf":
        from dynid.simmodel.mjcf import build_mjcf

        text = build_mjcf(text, robot, params, comment)
    out = Path(out)
    checks = _write_checked(out, fmt, text, model, params)
    return ExportResult(
        path=out,
        format=fmt,
        template=tpl,
        params=params,
        checks=checks,
        not_carried=items,
        locked=list(match.locked),
        heldout=shares,
    )


def _write_checked(out: Path, fmt: str, text: str, model, params: SimParameters) -> list[dict[str, Any]]:
    """Write ``text`` to ``out`` only if the reload checks pass (see :func:`export_model`)."""
    with atomic_path(out) as tmp:
        tmp.write_text(text, encoding="utf-8")
        checks = [check_urdf(tmp, model, params)] if fmt == "urdf" else check_mjcf(tmp, model, params)
        failed = [c for c in checks if not c["passed"]]
        if failed:
            what = "; ".join(f"{c['check']}: error {c.get('relative_error', 'see joints')}" for c in failed)
            raise IdentificationError(
                f"the exported {fmt.upper()} does not reproduce the identified model when reloaded ({what}); "
                f"nothing was written to {out}: report this with the model file"
            )
    return checks


def _export_into_mjcf(model, fmt, out: Path, template: Path, model_name, reference_weight, heldout) -> ExportResult:
    """An MJCF template filled through MuJoCo's MjSpec (:func:`dynid.simmodel.mjcf.write_into_mjcf`)."""
    from dynid.simmodel.mjcf import write_into_mjcf
    from dynid.symbolic.robot import load_robot

    if fmt != "mjcf":
        raise UsageError(
            f"--template '{template}' is an MJCF; a URDF is written from a URDF template: give the robot's URDF, "
            "or --format mjcf"
        )
    if not template.is_file():
        raise UsageError(f"the template '{template}' does not exist; give the robot's MuJoCo .xml")
    robot = model.robot
    described = load_robot(template)
    if described.n != robot.n:
        raise UsageError(
            f"the template '{template}' has {described.n} joint(s) ({', '.join(described.joint_names[:10])}), but "
            f"the model's robot '{robot.name}' has {robot.n} ({', '.join(robot.joint_names[:10])}); give the MJCF "
            "of the robot the model was identified for"
        )
    reference = robot.with_params(described.params)
    params = simulator_parameters(model, reference, reference_weight=reference_weight)
    shares = None
    if heldout is not None:
        from dynid.simmodel.shares import heldout_shares

        shares = heldout_shares(model, params, fmt, heldout)
    items = _shares(model, params.not_carried, "mjcf-template", params, shares)
    text = write_into_mjcf(template, robot, params, _comment(model_name, fmt, params, items, []))
    checks = _write_checked(out, fmt, text, model, params)
    return ExportResult(
        path=out, format=fmt, template=template, params=params, checks=checks, not_carried=items, heldout=shares
    )
