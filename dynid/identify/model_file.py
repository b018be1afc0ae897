"""The model file: :func:`save_model` and :func:`load_model` (``M.json`` and ``M.npz``).

>>> save_model(model, "M.json")                 # M.json (figures, readable) + M.npz (arrays)
>>> model = load_model("M.json")

``M.json`` holds everything a person reads (robot, parameters with their standard
deviations, preprocessing, friction coefficients, condition number, RMS per layer) and the name and
SHA-256 of ``M.npz``, which holds the arrays (covariance, mixture).  The JSON is the pair's manifest:
both files are written in full to temporary files first, then renamed into place, the arrays first and
the JSON last, so the pair is valid exactly when the JSON's checksum names the arrays beside it.  An
interrupted write (Ctrl-C, SIGTERM, an error) removes its temporary files and leaves the old pair; a
process killed outright between the two renames leaves a pair that :func:`load_model` refuses in one
sentence (never a model with another model's arrays).
"""

from __future__ import annotations

import glob
import hashlib
import io
import json
import os
import warnings
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dynid._io import atomic_path, dumps_json
from dynid.exceptions import DynidError, ModelFileError
from dynid.identify.columns import column_set
from dynid.identify.effect_terms import effect_from_dict
from dynid.identify.estimators import IdentificationWarning
from dynid.identify.friction import FrictionLayer
from dynid.identify.gmr import GMRCorrection
from dynid.identify.identified import IdentifiedModel

__all__ = ["FORMAT", "VERSION", "load_model", "save_model"]

FORMAT = "dynid-model"
VERSION = 5
"""Model file version: 2 adds effect terms and a coupled transmission; 3 the links' consistent standard
parameters (``links``: mass, centre of mass and inertia of each body, as a URDF inertial takes them) and the
links held at the consistency bound; 4 a coupled friction's ``mix`` (an output stage's friction, which a
version-3 reader would take for the motor's) and the ``seed_shared`` friction; 5 a seed model's fastest
training speed ``vmax`` (beyond it its square and cube go on as secants) and a mixture's ``rest_speed``
(no correction at rest), which a version-4 reader would ignore and so predict otherwise.  A file is
written at the lowest version that holds it, so older readers refuse what they would misread and read
the rest; version-1 to -4 files still load."""


def _file_version(model: IdentifiedModel) -> int:
    """The lowest version that holds the model (see :data:`VERSION`)."""
    friction = getattr(model, "friction", None)
    models = getattr(friction, "models_", None) or ()
    gmr = getattr(model, "gmr", None)
    if any(np.isfinite(getattr(m, "vmax_", np.inf)) for m in models) or any(
        int(mdl.get("rest_speed", -1)) >= 0 for mdl in (getattr(gmr, "models_", None) or ())
    ):
        return 5
    terms = getattr(model, "effects", None) or ()
    shared = getattr(friction, "model", None) == "seed_shared"
    return 4 if shared or any(t.hyper.get("mix", 1.0) != 1.0 for t in terms) else 3


def _recorded_robot(info_robot: dict[str, Any], path: Path, name: str, load_robot) -> Any:
    """The robot a model file names, the first of these that is that robot (its key and joint count):
    a built-in name or an absolute path as recorded; the description found from the model's folder; the
    path as given, from the current folder; where it was."""
    source = info_robot["source"]
    tried = []
    relative = info_robot.get("source_from_model")
    if isinstance(relative, str):
        tried.append(str(path.parent / relative))
    tried.append(source)
    if isinstance(info_robot.get("source_path"), str):
        tried.append(info_robot["source_path"])
    first: DynidError | None = None
    other = None
    for candidate in dict.fromkeys(tried):
        if candidate != source and not Path(candidate).is_file():
            continue
        try:
            base = robot = load_robot(candidate)
            if info_robot.get("transmission") is not None:
                robot = robot.with_transmission(info_robot["transmission"])
        except DynidError as err:
            first = first or err
            continue
        if robot.key == info_robot.get("key") and robot.n == info_robot.get("n"):
            return base
        other = other or base
    if other is not None:
        return other  # load_model names the mismatch
    raise ModelFileError(
        f"{name} was identified for the robot '{info_robot.get('name')}' from '{info_robot.get('source')}', "
        f"which cannot be loaded here ({first}); give the robot it was identified for (--robot, where the "
        "command has it), or run the command from the folder the model was identified in"
    ) from None


def save_model(model: IdentifiedModel, path: str | os.PathLike[str]) -> tuple[Path, Path]:
    """Write a model to ``path`` (JSON) and the arrays beside it (same name, ``.npz``), all or nothing.

    Parameters
    ----------
    model : IdentifiedModel
        The model.
    path : str or path-like
        The JSON file to write (its folder must exist).

    Returns
    -------
    (Path, Path)
        The JSON and the arrays file.
    """
    path = Path(path)
    if not path.parent.is_dir():
        raise ModelFileError(
            f"cannot write {path.name}: the folder {path.parent} does not exist; create it first"
        )
    arrays_path = path.with_suffix(".npz")
    arrays: dict[str, NDArray[Any]] = {"params": model.params, "cov": model.cov}
    if model.gmr is not None:
        arrays.update(model.gmr.to_arrays("gmr"))
    if model.columns.n_effect:
        arrays["effect_pattern"] = model.columns.pattern[:, model.columns.effect_mask]
        if model.effect_reference is not None:
            arrays["effect_reference"] = np.asarray(model.effect_reference, dtype=np.float64)
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    blob = buf.getvalue()
    figures = model.figures()
    source = Path(str(model.robot.source))
    if source.is_file():  # found again from another folder: beside the model, or where it was
        figures["robot"]["source_path"] = str(source.resolve())
        figures["robot"]["source_from_model"] = os.path.relpath(source.resolve(), path.parent.resolve())
    doc = {
        "format": FORMAT,
        "version": _file_version(model),
        **figures,
        "arrays": arrays_path.name,
        "arrays_sha256": hashlib.sha256(blob).hexdigest(),
    }
    text = dumps_json(doc)
    # The old arrays are kept under a name their own sha256 gives until the new JSON is in place: a save
    # killed between the two renames leaves the old JSON beside them (load_model finds them there), one
    # interrupted in Python puts them back.
    backup = _keep_old_arrays(arrays_path)
    # Both files are written before either is renamed; the blocks close inner first, so the arrays
    # replace theirs before the JSON that names them (and carries their sha256) does.
    try:
        with atomic_path(path) as tmp_json, atomic_path(arrays_path) as tmp_arrays:
            tmp_arrays.write_bytes(blob)
            tmp_json.write_text(text, encoding="utf-8")
    except BaseException:
        if backup is not None and backup.exists() and _json_sha(path) != doc["arrays_sha256"]:
            os.replace(backup, arrays_path)  # the old JSON stands: its arrays go back beside it
        raise
    finally:
        if backup is not None:
            backup.unlink(missing_ok=True)
    for stale in arrays_path.parent.glob(f"{glob.escape(arrays_path.name)}.*.old"):  # an earlier killed save's
        stale.unlink(missing_ok=True)
    return path, arrays_path


def _old_arrays_name(arrays_path: Path, sha: str) -> Path:
    """Where a model's previous arrays wait while a save replaces them (named by their sha256)."""
    return arrays_path.with_name(f"{arrays_path.name}.{sha[:16]}.old")


def _keep_old_arrays(arrays_path: Path) -> Path | None:
    """Link (or copy) the arrays file about to be replaced under :func:`_old_arrays_name`; None if none."""
    try:
        blob = arrays_path.read_bytes()
    except OSError:
        return None
    backup = _old_arrays_name(arrays_path, hashlib.sha256(blob).hexdigest())
    backup.unlink(missing_ok=True)
    try:
        os.link(arrays_path, backup)
    except OSError:
        backup.write_bytes(blob)
    return backup


def _json_sha(path: Path) -> str | None:
    """The arrays checksum the model JSON at ``path`` names (None if it cannot be read)."""
    try:
        return json.loads(path.read_text(encoding="utf-8")).get("arrays_sha256")
    except (OSError, ValueError, AttributeError):
        return None


def load_model(path: str | os.PathLike[str], robot=None) -> IdentifiedModel:
    """Read a model written by :func:`save_model` (or ``dynid identify``).

    Parameters
    ----------
    path : str or path-like
        The model's JSON file.
    robot : RobotModel, optional
        The robot to use; it must be the one the model was identified for.  Default: loaded from the
        source recorded in the file (a built-in name or a URDF / table path).

    Returns
    -------
    IdentifiedModel

    Raises
    ------
    ModelFileError
        Missing or corrupt file, arrays that do not match, another robot.
    """
    path = Path(path)
    name = path.name
    if not path.is_file():
        raise ModelFileError(f"no model file at {path}; give the JSON written by 'dynid identify --out'")
    doc, info_robot, arrays_path = _read_manifest(path, name)
    robot = _model_robot(robot, info_robot, path, name)
    blob = _read_arrays(arrays_path, name, doc, renamed=path.with_suffix(".npz"))
    try:
        return _model_from(doc, blob, robot, name)
    except ModelFileError:
        raise
    except (ValueError, KeyError, TypeError, OSError) as err:
        raise ModelFileError(
            f"{name} or its arrays are malformed ({type(err).__name__}: {err}); write them again with 'dynid identify'"
        ) from None


def _read_manifest(path: Path, name: str) -> tuple[dict[str, Any], dict[str, Any], Path]:
    """The model JSON at ``path`` (its format and version checked), its ``robot`` entry and the arrays file
    it names."""
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
        if not isinstance(doc, dict) or doc.get("format") != FORMAT:
            raise ValueError("no 'format: dynid-model' field")
        version = doc.get("version", 1)
        if isinstance(version, bool) or not isinstance(version, int) or version < 1:
            raise ModelFileError(
                f"{name} says it is model file version {version!r}; dynid writes whole versions 1 to {VERSION}: "
                "write it again with 'dynid identify'"
            )
        if version > VERSION:
            raise ModelFileError(
                f"{name} is a version-{version} model file; this dynid reads up to version {VERSION}: upgrade dynid"
            )
        info_robot = doc["robot"]
        if not isinstance(info_robot, dict) or not isinstance(info_robot.get("source"), str):
            raise ValueError("its 'robot' entry has no 'source'")
        arrays_path = path.parent / doc["arrays"]
    except ModelFileError:
        raise
    except (ValueError, KeyError, TypeError, UnicodeDecodeError) as err:
        raise ModelFileError(
            f"{name} is not a readable dynid model file ({type(err).__name__}: {err}); write it again with 'dynid identify'"
        ) from None
    return doc, info_robot, arrays_path


def _model_robot(robot, info_robot: dict[str, Any], path: Path, name: str) -> Any:
    """The robot of the model: ``robot`` as given, or the one the file records; checked to be the robot
    the model was identified for (with the recorded transmission)."""
    recorded = robot is None
    if robot is None:
        from dynid.symbolic.robot import load_robot

        robot = _recorded_robot(info_robot, path, name, load_robot)
    if info_robot.get("transmission") is not None:
        try:
            robot = robot.with_transmission(info_robot["transmission"])
        except DynidError as err:
            raise ModelFileError(
                f"{name} records a transmission that does not fit its robot ({err})"
            ) from None
    changed = robot.key != info_robot.get("key") and (robot.name, robot.n) == (info_robot.get("name"), info_robot.get("n"))
    if recorded and changed:  # the description the model names, edited since
        raise ModelFileError(
            f"{name} was identified on the description '{info_robot.get('source')}', which has changed since (its "
            f"bodies, joints, armature or tool frame: key {robot.key} now, {info_robot.get('key')} then); identify again "
            "on the description as it is, or restore the file the model was identified on"
        )
    if robot.key != info_robot.get("key") or robot.n != info_robot.get("n"):
        raise ModelFileError(
            f"{name} was identified for the robot '{info_robot.get('name')}' ({info_robot.get('n')} joints, key "
            f"{info_robot.get('key')}), not for '{robot.name}' ({robot.n} joints, key {robot.key}); use the model "
            "identified on this robot, or identify one"
        )
    return robot


def _read_arrays(arrays_path: Path, name: str, doc: dict[str, Any], renamed: Path | None = None) -> bytes:
    """The bytes of the arrays file the model JSON ``doc`` was written with (those a killed save left
    under :func:`_old_arrays_name` if the file beside it is another's), checked against its checksum.

    ``renamed`` is the arrays file a pair renamed together would have (the JSON's own name with ``.npz``):
    ``arm.json`` and ``arm.npz``, renamed from ``M.json`` and ``M.npz``, are read as the pair they are,
    whose JSON still names ``M.npz``.
    """
    sha = doc.get("arrays_sha256")
    renamed = None if renamed == arrays_path else renamed  # the pair's own name: nothing else to look for

    def read(p: Path | None) -> bytes | None:
        try:
            return None if p is None else p.read_bytes()
        except OSError:
            return None

    def matches(b: bytes | None) -> bool:
        return b is not None and hashlib.sha256(b).hexdigest() == sha

    blob, other = read(arrays_path), read(renamed)
    for found in (blob, other):
        if matches(found):
            return found  # type: ignore[return-value]
    # a save killed between its renames leaves the old arrays beside the old JSON, under their checksum
    kept = _old_arrays_name(arrays_path, str(sha))
    old_blob = read(kept)
    if blob is not None and matches(old_blob):
        warnings.warn(
            f"{name}: a save was interrupted after it replaced {arrays_path.name}; the arrays {name} was "
            f"written with were read from {kept.name} (save the model again to tidy up)",
            IdentificationWarning,
            stacklevel=3,  # the caller of load_model
        )
        return old_blob  # type: ignore[return-value]
    if blob is None:
        raise ModelFileError(
            f"{name} keeps its arrays in {arrays_path.name}, which is missing"
            + ("" if other is None else f", and {renamed.name} beside it is another model's arrays (checksum differs)")
            + f"; copy {arrays_path.name} beside {name}"
            + ("" if renamed is None else f" (or as {renamed.name}, if the pair was renamed)")
            + " or identify again"
        )
    also = "" if other is None else f" (nor is {renamed.name}, the name a pair renamed together would give it)"
    raise ModelFileError(
        f"{arrays_path.name} is not the arrays file {name} was written with (checksum differs){also}: the pair "
        "was copied or renamed apart, or its writing was interrupted; copy the two files together or identify again"
    )


def _model_from(doc: dict[str, Any], blob: bytes, robot, name: str) -> IdentifiedModel:
    """The model that a checked model JSON (``doc``, the file ``name``) and its arrays' bytes describe, for
    ``robot``."""
    with np.load(io.BytesIO(blob), allow_pickle=False) as npz:
        arrays = {k: npz[k] for k in npz.files}
    layer1 = doc["layer1"]
    cols = column_set(robot, friction=bool(layer1["friction"]), armature=bool(layer1["armature"]))
    effect_docs = doc.get("effects") or []
    effect_reference = None
    if effect_docs:
        terms = tuple(effect_from_dict(e) for e in effect_docs)
        eff_names = tuple(
            f"{t.key}.{coef}"
            for t, e in zip(terms, effect_docs, strict=True)
            for coef in e["coefficients"]
        )
        cols = cols.with_effects(terms, eff_names, np.asarray(arrays["effect_pattern"], dtype=bool))
        if "effect_reference" in arrays:
            effect_reference = np.asarray(arrays["effect_reference"], dtype=np.float64)
    names = [p["name"] for p in doc["parameters"]]
    if names != list(cols.names):
        raise ModelFileError(
            f"{name} lists the parameters {', '.join(names[:4])}...; this dynid derives "
            f"{', '.join(cols.names[:4])}... for '{robot.name}' (another base-parameter split): identify again"
        )
    params = np.asarray(arrays["params"], dtype=np.float64)
    cov = np.asarray(arrays["cov"], dtype=np.float64)
    if params.shape != (cols.p,) or cov.shape != (cols.p, cols.p):
        raise ValueError(f"params {params.shape} / cov {cov.shape} do not fit {cols.p} parameters")
    fr = doc["friction"]
    friction = (
        None
        if fr["model"] == "none"
        else FrictionLayer.from_dict({"model": fr["model"], "joints": fr["joints"]})
    )
    gmr = None
    if doc.get("gmm") is not None:
        gmr = GMRCorrection.from_arrays(arrays, "gmr", mode=doc["gmm"]["mode"])
        gmr.fallback_ = doc["gmm"].get("fallback")
    info = {
        k: v
        for k, v in doc.items()
        if k
        in (
            "n_samples",
            "notes",
            "reference",
            "irls",
            "consistency",
            "refinement",
            "bounds",
            "physical_check",
            "prior",
            "pipeline",
            "torque_range",
            "speed_quantiles",
            "payload",
            "data_sha256",
            "data_parts_sha256",
        )
    }
    if doc.get("gmm") is not None:
        info["gmm_validation_rms"] = doc["gmm"].get("validation_rms")
    return IdentifiedModel(
        robot=robot,
        columns=cols,
        params=params,
        cov=cov,
        method=str(doc["method"]),
        preprocessing=dict(doc["preprocessing"]),
        friction=friction,
        friction_source=str(fr["source"]),
        gmr=gmr,
        cond=float(doc["cond"]),
        rms=np.asarray(doc["rms"], dtype=np.float64),
        rms_layers=dict(doc["rms_layers"]),
        info=info,
        layers_filtered=bool(doc.get("layers_filtered", False)),
        effect_reference=effect_reference,
    )
