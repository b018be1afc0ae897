"""The catalogue of candidate effects of the gap diagnosis: their feature columns.

Each effect of the catalogue (DESIGN.md; the simulator's :mod:`dynid.sim.effects` injects the
same names) is a :class:`Candidate`: a rule that turns the states of a dataset into extra regressor
columns, one or a few per joint, that are refitted *together with* the base parameters (so what
re-identification absorbs is never credited to the effect).  Columns are computed at full rate, from
the same states as the base regressor, and then low-passed with the torque's filter (parallel
filtering, DIAGNOSIS.md section 3).

========================  ===================================================  ===================
effect                    columns on joint j (``s = sign``)                    hyper-parameter
========================  ===================================================  ===================
offset                    1                                                    -
armature                  ddq_j                                                -
stribeck                  s(dq_j) exp(-(|dq_j| / vs)^2)                        vs
load_friction             s(dq_j) |tau_j|                                      -
temperature               h(t) s(dq_j),  h(t) dq_j;  h = 1 - exp(-t / T)       T
cogging                   sin(k N q_j), cos(k N q_j), k = 1, 2                 N (gear ratio)
elasticity                M(q)[:, j] d^2 tau_j / dt^2 (all joints; first      -
                          order of q_j = theta_j - tau_j / K)
backlash                  M(q)[:, j] d^2 b_j / dt^2, M(q)[:, j] d^2 tau_j /    eps
                          dt^2 (all joints), b_j; b_j = tanh(tau_j / eps)
delay                     d tau_j / dt (first order of tau(t - d))             -
drive_gain                tau_j                                                -
base_tilt                 d g(q) / d alpha about two horizontal axes (all j)   -
coupled_friction          s(w), w on joints a and b, w = dq_a +- dq_b          pair and sign
nonlinear_viscous         dq_j |dq_j|,  dq_j^3                                 -
payload                   (absorbed by the base parameters: parametric test)   -
========================  ===================================================  ===================

A delay also has a form common to all joints (``delay@all``, :func:`dynid.identify.effect_terms.common_term`): the delay column on
every joint with one coefficient, so that one lag of the torques against the angles is one candidate.
``tau`` is the identified model's predicted torque (the "first fit"); for backlash its links' share,
which the transmission carries (the motor's armature and friction act before the gear).
No two candidates on a joint span the same columns: a load friction that differs between driving and
back-driven motion has no column of its own for the difference, ``s(dq_j) |tau_j| s(dq_j tau_j)`` being
``tau_j`` itself, the drive gain's column (the simulator's load friction, 0.05 driving and 0.025
back-driven, is a load friction of 0.0375 and a drive gain of 0.0125 on its joint).  Candidates whose
columns contain a simpler one's by design (the motor-inertia column of elasticity and backlash is the
armature's; backlash holds the teeth's stiffness, elasticity's column) are told apart by the
simpler-candidate test (:func:`dynid.diagnosis.screening.parsimonious`).
The column builders live in :mod:`dynid.identify.effect_terms`, shared with ``identify --effects``.
Elasticity, backlash and delay are not linear in their parameters: the screen uses the first-order
columns above, the refit (:mod:`dynid.diagnosis.refinement`) fits their physical parameters (for
backlash a dead zone whose sides change once the torque has reversed beyond a threshold, a crossing
time later).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from dynid.identify.effect_terms import BUILDERS as _BUILDERS  # noqa: F401 (the builders, by effect)
from dynid.identify.effect_terms import (
    COMMON_EFFECTS,
    Candidate,
    FeatureSource,
    backlash_grid,
    candidate_columns,
    cogging_grid,
    common_term,
    stribeck_grid,
    temperature_grid,
)
from dynid.identify.effect_terms import relay as _relay  # noqa: F401 (the backlash dead-zone relay)
from dynid.sim.effects import EFFECT_NAMES  # the catalogue: one list for simulate, identify, diagnose

__all__ = [
    "CANDIDATES",
    "EFFECT_NAMES",
    "PARAMETRIC_EFFECTS",
    "Candidate",
    "FeatureSource",
    "candidate_columns",
    "describe_hyper",
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


CANDIDATES: dict[str, _Spec] = {
    "offset": _Spec(True, None, "both directions of motion at every speed (a constant does not change sign)"),
    "armature": _Spec(True, None, "large accelerations of joint {j}"),
    "stribeck": _Spec(True, stribeck_grid, "slow motion and many velocity reversals of joint {j}"),
    "load_friction": _Spec(True, None, "large loads on joint {j}, both driving and back-driven"),
    "temperature": _Spec(
        True, temperature_grid, "a longer run (minutes) so that friction drift and motion part"
    ),
    "cogging": _Spec(True, cogging_grid, "slow constant-speed sweeps of joint {j} over several gear periods"),
    "elasticity": _Spec(True, None, "fast torque changes on joint {j} (harmonics near its resonance)"),
    "backlash": _Spec(True, backlash_grid, "torque reversals of joint {j} at low speed"),
    "delay": _Spec(True, None, "faster excitation of joint {j} (a delay grows with frequency)"),
    "drive_gain": _Spec(True, None, "large torques on joint {j} at several speeds"),
    "payload": _Spec(False, None, "several tool orientations under gravity"),
    "base_tilt": _Spec(False, None, "full turns of joint 1 in several arm configurations"),
    "coupled_friction": _Spec(False, None, "wrist joints moving in equal and opposite directions"),
    "nonlinear_viscous": _Spec(True, None, "high speeds of joint {j}"),
}


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
        if k in ("motor", "exact", "asymmetric"):
            continue
        if k == "sign":
            parts.append("w = dq_a + dq_b" if v > 0 else "w = dq_a - dq_b")
        else:
            parts.append(f"{k} = {v:.3g}{(' ' + units[k]) if units.get(k) else ''}")
    return ", ".join(parts)


def nominal_gear_period(N: float) -> float:
    """Angle (rad) of one gear period for a ratio N."""
    return 2 * math.pi / N
