"""Effects as regressor columns: the one set of column builders that identify and the diagnosis share.

Each effect of the catalogue (the simulator's :mod:`dynid.sim.effects` injects the same names; the
table of columns is in :mod:`dynid.identify.effect_builders`) becomes one or a few columns per joint, linear
in their coefficients, built at full rate from the states of a dataset (:class:`FeatureSource`) and
then low-passed with the torque's filter like every regressor column (parallel filtering).

``identify(..., effects="coupled_friction@5+6,stribeck@3")`` (:func:`parse_effect_terms`) adds them to
the identified parameters (:class:`dynid.identify.columns.ColumnSet` kind ``effect``), refitted with the
base parameters; the diagnosis screens the same columns as candidates.  Effects whose columns need the
model's own torque (load friction, drive gain, delay, elasticity, backlash) use the torque of a first
fit without the effects, which the model keeps (``effect_reference``) to predict with.  Delay,
elasticity and backlash are not linear in their physical parameters: identify takes their refit forms
with the hyper-parameters given or tuned on the training data (the diagnosis refines them further).

This module is identify's side (the terms of ``--effects``, their coefficients' names, the model file's
form, the tuning of their hyper-parameters) and gives every public name of the catalogue's columns;
the signals, the candidate and the column builders themselves are :mod:`dynid.identify.effect_builders`.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dynid.exceptions import UsageError
from dynid.identify.effect_builders import (
    BUILDERS,
    COMMON_EFFECTS,
    EFFECT_GRIDS,
    Candidate,
    FeatureSource,
    backlash_grid,
    candidate_columns,
    cogging_grid,
    common_term,
    relay,
    stribeck_grid,
    temperature_grid,
)

__all__ = [
    "BUILDERS",
    "COMMON_EFFECTS",
    "EFFECT_GRIDS",
    "TAU_EFFECTS",
    "TIME_EFFECTS",
    "Candidate",
    "EffectColumns",
    "FeatureSource",
    "backlash_grid",
    "candidate_columns",
    "coefficient_names",
    "cogging_grid",
    "common_term",
    "effect_from_dict",
    "effect_to_dict",
    "effect_values",
    "needs_time",
    "needs_torque",
    "parse_effect_terms",
    "relay",
    "stribeck_grid",
    "temperature_grid",
    "term_variants",
    "tune_terms",
]


# ---------------------------------------------------------------------------- identify's side
TAU_EFFECTS = ("load_friction", "delay", "drive_gain", "elasticity", "backlash")
"""Effects whose columns need the model's own torque (a first fit without the effects)."""

TIME_EFFECTS = ("temperature", "delay", "elasticity", "backlash")
"""Effects whose columns need time (derivatives or a warm-up along the run): predicted from a dataset."""

_DELAYS_S = (0.0005, 0.001, 0.002, 0.004, 0.008, 0.016)  # grid of the delay's refit form (s)
_WHOLE_ARM = ("base_tilt",)
_PAIR = ("coupled_friction",)
_COEF_NAMES = {
    "offset": ("fo",),
    "armature": ("ia",),
    "stribeck": ("fs",),
    "load_friction": ("mu", "mu_drive"),  # mu_drive: files written with the two columns (asymmetric)
    "temperature": ("fc_T", "fv_T"),
    "cogging": ("a1", "b1", "a2", "b2"),
    "elasticity": ("c",),
    "backlash": ("a_b", "c", "b"),
    "delay": ("g",),
    "drive_gain": ("g",),
    "base_tilt": ("ax", "ay"),
    "coupled_friction": ("fc", "fv"),
    "nonlinear_viscous": ("fv2", "fv3"),
}
_ITEM = re.compile(r"^(?P<name>[a-z_]+)(@(?P<joints>[0-9+\-]+|all))?(:(?P<hyper>.+))?$")


def coefficient_names(term: Candidate, width: int) -> tuple[str, ...]:
    """Names of a term's coefficients (``coupled_friction@5+6.fc``), ``width`` of them."""
    base = _COEF_NAMES.get(term.effect, ())
    names = [base[k] if k < len(base) else f"c{k + 1}" for k in range(width)]
    return tuple(f"{term.key}.{name}" for name in names)


def _joint_list(text: str, n: int, item: str) -> list[int]:
    """0-based joints of ``J``, ``J-K`` or ``J+K`` (1-based in the text)."""
    try:
        if "-" in text:
            a, b = (int(v) for v in text.split("-"))
            js = list(range(a, b + 1))
        else:
            js = [int(v) for v in text.split("+")]
    except ValueError:
        js = []
    if not js or any(not 1 <= j <= n for j in js) or len(set(js)) != len(js):
        raise UsageError(
            f"the joints of the effect '{item}' are '{text}'; give joints in 1..{n} as J, J-K (a range) or "
            "A+B (a coupled pair), e.g. stribeck@3 or coupled_friction@5+6"
        )
    return [j - 1 for j in js]


def _positive(v: float) -> bool:
    return math.isfinite(v) and v > 0


def _flag(v: float) -> bool:
    return v in (0.0, 1.0)


# Hyper-parameters a user may give, per effect: key -> (rule, its text).
_HYPER_RULES: dict[str, dict[str, tuple[Callable[[float], bool], str]]] = {
    "stribeck": {"vs": (_positive, "a positive Stribeck speed in rad/s (or m/s)")},
    "temperature": {"T": (_positive, "a positive warm-up time constant in s")},
    "cogging": {
        "N": (lambda v: math.isfinite(v) and 1 <= v <= 1e4, "the ripple cycles per revolution, 1 to 10000")
    },
    "backlash": {
        "eps": (_positive, "a positive torque scale of the dead zone in N m"),
        "h": (_positive, "a positive hysteresis, a fraction of the torque's spread"),
        "a": (math.isfinite, "a finite half-gap in rad"),
        "d": (lambda v: math.isfinite(v) and 0 <= v < 1, "a crossing time from 0 to 1 s"),
        "w": (_positive, "a positive natural frequency in rad/s"),
        "z": (lambda v: math.isfinite(v) and v >= 0, "a damping ratio of at least 0"),
        "motor": (_flag, "0 or 1"),
    },
    "elasticity": {
        "w": (_positive, "a positive natural frequency in rad/s"),
        "z": (lambda v: math.isfinite(v) and v >= 0, "a damping ratio of at least 0"),
        "motor": (_flag, "0 or 1"),
    },
    "delay": {
        "d": (
            lambda v: math.isfinite(v) and 0 < abs(v) < 1,
            "a delay in s, non-zero and within +-1 s (the diagnosis measures a sensor that leads as negative)",
        )
    },
    "coupled_friction": {
        "sign": (lambda v: v in (1.0, -1.0), "the coupling sign, 1 or -1"),
        "mix": (
            lambda v: math.isfinite(v) and 0 <= v <= 1,
            "the weight of the first joint's speed, from 0 (the second joint's own output stage) to 1 (the "
            "coupled motor's speed)",
        ),
    },
    "load_friction": {"asymmetric": (_flag, "0 or 1")},
}


def _check_hyper(name: str, key: str, value: float, item: str) -> str:
    """The canonical spelling of a hyper-parameter of ``name``, its value checked; else a UsageError."""
    rules = _HYPER_RULES.get(name, {})
    canonical = {k.lower(): k for k in rules}.get(key.lower())
    if canonical is None:
        known = ", ".join(rules) if rules else "none"
        raise UsageError(
            f"the effect '{item}' has the hyper-parameter '{key}', which {name} does not take (it takes: "
            f"{known}); remove it or fix its name"
        )
    ok, rule = rules[canonical]
    if not ok(value):
        raise UsageError(
            f"the hyper-parameter {canonical} of the effect '{item}' is {value:g}; give {rule}, or leave it out "
            + ("(the default 1)" if canonical == "mix" else "to have it tuned on the data")  # a mix is not tuned
        )
    return canonical


def parse_effect_terms(spec: str | Sequence[str] | None, n: int) -> tuple[Candidate, ...]:
    """Read ``NAME[@JOINTS][:KEY=VALUE;...],...`` into effect terms (hyper-parameters left out are tuned).

    Parameters
    ----------
    spec : str or sequence of str or None
        ``"coupled_friction@5+6,stribeck@3,offset"``: a per-joint effect on every joint when no joint is
        given, on ``J`` or on each joint of ``J-K``; ``coupled_friction`` on a pair ``A+B`` (default the
        last two joints); hyper-parameters such as ``stribeck@3:vs=0.05``, ``cogging@2:N=100``,
        ``delay@1:d=0.002``, ``coupled_friction@5+6:sign=-1``.
    n : int
        Number of joints.

    Returns
    -------
    tuple of Candidate
        One term per (effect, joint or pair), in the order given.

    Raises
    ------
    UsageError
        Unknown effect (the message lists the catalogue), malformed joints or hyper-parameters, a term
        given twice, or ``payload`` (re-identification absorbs it whole: there is nothing to add).
    """
    if spec is None:
        return ()
    items = [p.strip().replace(" ", "") for p in spec.split(",")] if isinstance(spec, str) else list(spec)
    items = [p for p in items if p and p.lower() not in ("none", "off")]
    out: list[Candidate] = []
    for item in items:
        match = _ITEM.match(str(item).lower())
        if match is None:
            raise UsageError(
                f"the effect '{item}' is not of the form NAME[@JOINTS][:KEY=VALUE]; write e.g. "
                "'coupled_friction@5+6', 'stribeck@3' or 'cogging@2:N=100'"
            )
        name = match["name"]
        if name == "payload":
            raise UsageError(
                "the effect 'payload' is a rigid mass on the last link, which the base parameters take in whole; "
                "identify again on data with the payload instead of adding it"
            )
        if name not in BUILDERS:
            raise UsageError(
                f"unknown effect '{name}'; the catalogue's effects with model terms are {', '.join(BUILDERS)}"
            )
        hyper: dict[str, float] = {}
        hyper_text = str(item).partition(":")[2]  # its keys keep their case (N, T)
        for part in hyper_text.split(";"):
            if not part:
                continue
            key, _, value = part.partition("=")
            try:
                number = float(value)
            except ValueError:
                raise UsageError(
                    f"the hyper-parameter '{part}' of the effect '{item}' is not KEY=NUMBER; write e.g. "
                    f"{name}:vs=0.05"
                ) from None
            key = _check_hyper(name, key, number, item)
            hyper[key] = number
        if name == "delay" and hyper:
            hyper["exact"] = 1.0
        joints_text = match["joints"]
        if joints_text == "all" and name not in _WHOLE_ARM:
            if name not in COMMON_EFFECTS:
                raise UsageError(
                    f"the effect '{item}' has no form common to all joints (those that do: "
                    f"{', '.join(COMMON_EFFECTS)}); give its joints as J or J-K"
                )
            terms = [common_term(name, n, hyper)]
        elif name in _WHOLE_ARM:
            if joints_text:
                raise UsageError(f"the effect '{name}' acts on the whole arm; give it without @JOINTS")
            terms = [Candidate(name, None, tuple(range(n)), hyper, "base tilt (gravity direction)")]
        elif name in _PAIR:
            pair = _joint_list(joints_text, n, item) if joints_text else [n - 2, n - 1]
            if len(pair) != 2 or n < 2:
                raise UsageError(
                    f"the effect '{item}' couples two joints; give a pair such as coupled_friction@5+6"
                )
            terms = [
                Candidate(
                    name,
                    None,
                    (pair[0], pair[1]),
                    hyper,
                    f"coupled friction of joints {pair[0] + 1} and {pair[1] + 1}"
                    + ("" if hyper.get("mix", 1.0) == 1.0 else f" on joint {pair[1] + 1}'s output stage"),
                )
            ]
        else:
            js = _joint_list(joints_text, n, item) if joints_text else list(range(n))
            if joints_text and "+" in joints_text:
                raise UsageError(
                    f"the effect '{name}' acts on one joint at a time; give J or J-K, not '{joints_text}'"
                )
            terms = [Candidate(name, j, (j,), dict(hyper), f"{name} on joint {j + 1}") for j in js]
        for term in terms:
            if any(t.key == term.key for t in out):
                raise UsageError(f"the effect '{term.key}' is given twice; give it once")
            out.append(term)
    return tuple(out)


def effect_to_dict(term: Candidate) -> dict[str, Any]:
    """A term as JSON: effect, joints (from 1), hyper-parameters."""
    return {
        "name": term.effect,
        "key": term.key,
        "joint": None if term.joint is None else term.joint + 1,
        "joints": [j + 1 for j in term.joints],
        "hyper": {k: float(v) for k, v in term.hyper.items()},
        "label": term.label,
    }


def effect_from_dict(doc: dict[str, Any]) -> Candidate:
    """The term written by :func:`effect_to_dict` (with its coefficients, as a model file lists it).

    A load friction written with two coefficients (``mu``, ``mu_drive``: the form before its second
    column, which is the drive gain's, was dropped) keeps its two columns (``asymmetric``)."""
    joint = doc.get("joint")
    hyper = {str(k): float(v) for k, v in doc.get("hyper", {}).items()}
    if doc["name"] == "load_friction" and "mu_drive" in (doc.get("coefficients") or {}):
        hyper["asymmetric"] = 1.0
    return Candidate(
        str(doc["name"]),
        None if joint is None else int(joint) - 1,
        tuple(int(j) - 1 for j in doc["joints"]),
        hyper,
        str(doc.get("label", "")),
    )


def term_variants(src: FeatureSource, term: Candidate) -> list[Candidate]:
    """The hyper-parameter variants to tune a term among (the term itself when nothing is left to tune)."""
    name = term.effect
    if name == "coupled_friction" and "sign" not in term.hyper:
        return [
            Candidate(name, None, term.joints, {**term.hyper, "sign": s}, term.label) for s in (1.0, -1.0)
        ]
    if name == "delay" and "d" not in term.hyper:
        return [
            Candidate(name, term.joint, term.joints, {"exact": 1.0, "d": d}, term.label) for d in _DELAYS_S
        ]
    grid = EFFECT_GRIDS.get(name)
    if grid is None or term.joint is None:
        return [term]
    variants = [g for g in grid(src, term.joint) if not set(g) <= set(term.hyper)]
    if not variants or set(variants[0]) <= set(term.hyper):
        return [term]
    return [Candidate(name, term.joint, term.joints, {**g, **term.hyper}, term.label) for g in variants]


def needs_time(terms: Sequence[Candidate]) -> bool:
    """Whether some term needs time stamps (see :data:`TIME_EFFECTS`)."""
    return any(t.effect in TIME_EFFECTS for t in terms)


def needs_torque(terms: Sequence[Candidate]) -> bool:
    """Whether some term needs the model's own torque (see :data:`TAU_EFFECTS`)."""
    return any(t.effect in TAU_EFFECTS for t in terms)


@dataclass(frozen=True, eq=False)
class EffectColumns:
    """Effect terms with their columns on one dataset, for :func:`dynid.identify.linear_system.build_system`.

    Attributes
    ----------
    terms : tuple of Candidate
        The terms (hyper-parameters resolved).
    names : tuple of str
        One name per coefficient (:func:`coefficient_names`).
    values : ndarray, shape (M, n, k)
        Their columns at full rate on the prepared grid, unfiltered (the system filters them like the torque).
    """

    terms: tuple[Candidate, ...]
    names: tuple[str, ...]
    values: NDArray[np.float64]


def effect_values(src: FeatureSource, terms: Sequence[Candidate]) -> tuple[NDArray[np.float64], list[int]]:
    """Full-rate columns of the terms side by side, (M, n, k), and the width of each term."""
    blocks = [candidate_columns(src, t) for t in terms]
    widths = [b.shape[2] for b in blocks]
    if not blocks:
        return np.zeros((src.m, src.n, 0)), widths
    return np.concatenate(blocks, axis=2), widths


def tune_terms(
    src: FeatureSource,
    terms: Sequence[Candidate],
    residual: NDArray[np.float64],
    treat: Callable[[NDArray[np.float64]], NDArray[np.float64]],
) -> tuple[Candidate, ...]:
    """Pick each term's hyper-parameters among its variants: the one whose columns, fitted by least
    squares to the first fit's residual, leave the least of it.

    Parameters
    ----------
    src : FeatureSource
        Training signals at full rate.
    terms : sequence of Candidate
        Terms, some without hyper-parameters.
    residual : ndarray, shape (m, n)
        Residual of the first fit at the kept rows (treated like the torque).
    treat : callable
        ``(M, n) -> (m, n)``: the torque's filter and the kept rows.
    """
    out = []
    for term in terms:
        variants = term_variants(src, term)
        if len(variants) == 1:
            out.append(variants[0])
            continue
        best, best_rss = variants[0], np.inf
        for v in variants:
            C = candidate_columns(src, v)
            A = np.stack([treat(C[:, :, k]) for k in range(C.shape[2])], axis=2).reshape(-1, C.shape[2])
            b = residual.reshape(-1)
            coef, *_ = np.linalg.lstsq(A, b, rcond=1e-10)
            rss = float(np.sum((b - A @ coef) ** 2))
            # a later variant must do better than rounding: where the data cannot tell two apart (an output
            # stage's sign, when the joint's own friction takes its other joint's part) the first is kept
            if rss < best_rss * (1.0 - 1e-9):
                best, best_rss = v, rss
        out.append(best)
    return tuple(out)
