"""The catalogue of candidate effects of the gap diagnosis: their feature columns.

Each effect of the catalogue (DESIGN.md; the simulator's :mod:`dynid.sim.effects` injects the
same names) is a :class:`Candidate`: a rule that turns the states of a dataset into extra regressor
columns, one or a few per joint, that are refitted *together with* the base parameters (so what
re-identification absorbs is never credited to the effect).  Columns are computed at full rate, from
the same states as the base regressor, and then low-passed with the torque's filter (parallel
filtering, DIAGNOSIS.md section 3).

The table of the columns, effect by effect, is :mod:`dynid.identify.effect_builders`' (shared with
``identify --effects``); what the diagnosis reads of an effect beside them (per joint or of the whole arm,
the motion that excites it) is its simulation class's (:mod:`dynid.sim.effect_classes`), so that
:data:`CANDIDATES` follows the catalogue, effects registered with
:func:`dynid.sim.effects.register_effect` included.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass

from dynid.identify.effect_terms import BUILDERS as _BUILDERS  # noqa: F401 (the builders, by effect)
from dynid.identify.effect_terms import (
    COMMON_EFFECTS,
    EFFECT_GRIDS,
    Candidate,
    FeatureSource,
    candidate_columns,
    common_term,
)
from dynid.identify.effect_terms import relay as _relay  # noqa: F401 (the backlash dead-zone relay)
from dynid.sim.effects import (
    EFFECT_NAMES,  # the catalogue: one list for simulate, identify, diagnose
    EFFECTS,
    effect_names,
)

__all__ = [
    "CANDIDATES",
    "EFFECT_NAMES",
    "PARAMETRIC_EFFECTS",
    "Candidate",
    "FeatureSource",
    "candidate_columns",
    "describe_hyper",
    "effect_names",
    "enumerate_candidates",
    "excitation_hint",
    "settling_motion",
]

PARAMETRIC_EFFECTS = ("drive_gain", "payload", "offset")
"""Effects that re-identification can absorb, tested on the change of the base parameters."""


@dataclass(frozen=True)
class _Spec:
    per_joint: bool
    grid: Callable[[FeatureSource, int], list[dict[str, float]]] | None
    excites: str


class _Candidates(Mapping[str, _Spec]):
    """Effect name -> what the diagnosis reads of it: per joint or not (the class's ``selectable``), its
    hyper-parameter grid (:data:`dynid.identify.effect_terms.EFFECT_GRIDS`) and the motion that excites it
    (the class's ``excites``); read from the catalogue when asked, so a registered effect is in it."""

    def __getitem__(self, name: str) -> _Spec:
        cls = EFFECTS[name]
        return _Spec(bool(cls.selectable), EFFECT_GRIDS.get(name), cls.excites)

    def __iter__(self) -> Iterator[str]:
        return iter(effect_names())

    def __len__(self) -> int:
        return len(EFFECTS)


CANDIDATES: Mapping[str, _Spec] = _Candidates()
"""Effect name -> ``per_joint``, ``grid``, ``excites``: the candidates of the catalogue, in its order."""


def excitation_hint(cand: Candidate) -> str:
    """Words for the motion that excites a candidate."""
    if cand.joint is None and cand.effect in COMMON_EFFECTS:
        return CANDIDATES[cand.effect].excites.replace("of joint {j}", "of every joint")
    j = cand.joint + 1 if cand.joint is not None else (cand.joints[0] + 1 if cand.joints else 1)
    return CANDIDATES[cand.effect].excites.format(j=j)


def settling_motion(
    cand: Candidate, dq_max: Sequence[float], *, cutoff_hz: float | None = None, period: float = 10.0
) -> tuple[dict[str, object], str]:
    """Changes to a default excitation (``dynid excite``) whose recording would show a candidate.

    The default excitation uses every joint's whole speed range, so it passes through the low speeds
    where Stribeck friction, backlash and cogging live in a few milliseconds per reversal: such an effect
    can be real and still too small, on that run, to pass the tests.  The settling run slows the joint
    down instead (Stribeck: below five times the candidate's Stribeck speed; backlash: a tenth of the
    limit; cogging: the gear harmonic below half the torque filter's cut-off, 10 Hz without a filter), runs longer (temperature:
    three of the candidate's time constants) or richer (elasticity: more harmonics; a delay: a higher base
    frequency).  Other effects get a new excitation of the same kind.

    Parameters
    ----------
    cand : Candidate
        The undecided candidate (tuned hyper-parameters).
    dq_max : sequence of float, shape (n,)
        The robot's speed limits (rad/s).
    cutoff_hz : float, optional
        Cut-off of the torque filter the diagnosis used (Hz).
    period : float
        Period of the default excitation (s).

    Returns
    -------
    options : dict
        ``dq_max`` (a full per-joint list, rad/s), ``periods``, ``harmonics`` or ``base_freq``: the
        ``dynid excite`` options that differ from its defaults; empty for a new excitation of the same kind.
    why : str
        The motion in words.
    """
    limits = [float(v) for v in dq_max]
    j = cand.joint
    options: dict[str, object] = {}
    slow = None
    if j is not None and cand.effect == "stribeck" and "vs" in cand.hyper:
        slow = 5.0 * float(cand.hyper["vs"])
    elif j is not None and cand.effect == "backlash":
        slow = 0.1 * limits[j]
    elif j is not None and cand.effect == "cogging" and "N" in cand.hyper:
        slow = math.pi * (cutoff_hz if cutoff_hz else 10.0) / float(cand.hyper["N"])
    if slow is not None and j is not None:
        limits[j] = min(limits[j], slow)
        options["dq_max"] = limits
        why = f"joint {j + 1} kept below {limits[j]:.3g} rad/s ({excitation_hint(cand)})"
    elif cand.effect == "temperature" and "T" in cand.hyper:
        options["periods"] = max(3, min(60, math.ceil(3.0 * float(cand.hyper["T"]) / period)))
        why = f"{options['periods']} periods ({excitation_hint(cand)})"
    elif cand.effect == "elasticity":
        options["harmonics"] = 10
        why = f"10 harmonics ({excitation_hint(cand)})"
    elif cand.effect == "delay":
        options["base_freq"] = 0.2
        why = f"a 5 s period ({excitation_hint(cand)})"
    else:
        why = f"a new excitation of the same kind (the effect shows with {excitation_hint(cand)})"
    return options, why


def enumerate_candidates(
    src: FeatureSource, effects: Sequence[str], *, skip: Sequence[str] = (), motor_inertia: bool = False
) -> list[list[Candidate]]:
    """Every candidate of the catalogue on every joint, each as its list of hyper-parameter variants.

    Parameters
    ----------
    src : FeatureSource
        Training signals (the grids of hyper-parameters are scaled from them).
    effects : sequence of str
        Effects to consider.
    skip : sequence of str
        Effects that the model already holds (their columns would duplicate the model's).
    motor_inertia : bool
        Give elasticity and backlash a motor-inertia column ``ddq_j`` (when the model has no armature).

    Returns
    -------
    list of list of Candidate
        One inner list per (effect, joint): the variants to tune among.
    """
    n = src.n
    out: list[list[Candidate]] = []
    for name in effects:
        if name in skip or name == "payload":
            continue
        spec = CANDIDATES[name]
        if spec.per_joint:
            for j in range(n):
                grid = spec.grid(src, j) if spec.grid else [{}]
                if name in ("elasticity", "backlash") and motor_inertia:
                    grid = [{**g, "motor": 1.0} for g in grid]
                label = f"{name} on joint {j + 1}"
                out.append([Candidate(name, j, (j,), g, label) for g in grid])
            if name in COMMON_EFFECTS and n >= 2:
                # One cause on every joint (a delay of the torques against the angles) is one candidate
                # with one parameter beside the per-joint ones: accepted whole, not joint by joint up to
                # the cap of max_effects.
                out.append([common_term(name, n)])
        elif name == "base_tilt":
            out.append([Candidate(name, None, tuple(range(n)), {}, "base tilt (gravity direction)")])
        elif name == "coupled_friction" and n >= 2:
            wrist = list(range(max(0, n - 3), n))
            for ia, a in enumerate(wrist):
                for b in wrist[ia + 1 :]:
                    out.append(
                        [
                            Candidate(
                                name,
                                None,
                                (a, b),
                                {"sign": sgn},
                                f"coupled friction of joints {a + 1} and {b + 1}",
                            )
                            for sgn in (1.0, -1.0)
                        ]
                    )
    return out


def describe_hyper(cand: Candidate) -> str:
    """Hyper-parameters in words (``vs = 0.05 rad/s``)."""
    units = {"vs": "rad/s", "T": "s", "N": "", "eps": "N m", "sign": ""}
    parts = []
    for k, v in cand.hyper.items():
        if k in ("motor", "exact", "asymmetric", "mix"):
            continue
        if k == "sign":
            mix = cand.hyper.get("mix", 1.0)
            a = "dq_a" if mix == 1.0 else ("" if mix == 0.0 else f"{mix:g} dq_a")
            b = ("+ dq_b" if v > 0 else "- dq_b") if a else ("dq_b" if v > 0 else "-dq_b")
            parts.append(f"w = {a} {b}".replace("  ", " ").strip() + ("" if a else " (felt by both joints)"))
        else:
            parts.append(f"{k} = {v:.3g}{(' ' + units[k]) if units.get(k) else ''}")
    return ", ".join(parts)


def nominal_gear_period(N: float) -> float:
    """Angle (rad) of one gear period for a ratio N."""
    return 2 * math.pi / N
