"""The thresholds and figures of a three-layer fit (:class:`dynid.identify.three_layer.ThreeLayerModel`).

The limits that guard the mixture correction against taking over physical torque (:data:`MIXTURE_SHARE`,
:data:`TAKEOVER`, :data:`TAKEOVER_SHARE`, :data:`TAKEOVER_GAIN`) and the one that says when a bounded
parameter is held at its bound (:data:`AT_BOUND_STD`), and the helpers that turn a fit into the figures a
model file reports: :func:`cap_mixture` (the mixture switched off where it carries too much),
:func:`consistency_figures`, :func:`bounds_info` and :func:`at_bound`, :func:`layer1_friction` and
:func:`joint_rms`.
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dynid._rest import AT_REST
from dynid.data.preparation import Prepared
from dynid.exceptions import IdentificationWarning
from dynid.identify.columns import ColumnSet, linear_torque
from dynid.identify.consistent import pseudo_inertia
from dynid.identify.gmr import GMRCorrection

__all__ = [
    "AT_BOUND_STD",
    "MIXTURE_SHARE",
    "TAKEOVER",
    "TAKEOVER_GAIN",
    "TAKEOVER_SHARE",
    "at_bound",
    "bounds_info",
    "cap_mixture",
    "consistency_figures",
    "joint_rms",
    "layer1_friction",
    "speed_quantiles",
    "warn_unexplained",
]

UNEXPLAINED = 0.2
"""Largest share of the training torque a fit may leave unexplained without a warning (:func:`warn_unexplained`).

``sqrt(sum_j rms_j^2 / sum_j var(tau_j))``: the residual's power over the torque's, so that the large joints
count by their size and a wrist whose torque is near its noise does not.  Measured with OLS and linear
friction: 0.008-0.03 on the Panda, the LWR4+ and fifteen simulated arms of five kinds; 0.105 on the TX40
without its coupled wrist declared; 0.27 for a Kinova Gen3's description given a KUKA iiwa's recording;
on a simulated UR5, 0.38 and 0.69 with joints 2 and 3 (1 and 2) in each other's columns, 0.91 with joint
2's torque of the other sign.  Not seen: two wrist joints swapped (0.065: their torque is small), a
UR10's recording on the UR5's description (0.008: the base parameters take the other lengths)."""


def warn_unexplained(rms: NDArray[np.float64], tau: NDArray[np.float64]) -> None:
    """Warn, in one sentence, when the fit leaves more than :data:`UNEXPLAINED` of the training torque."""
    spread = float(np.sum(np.var(tau, axis=0)))
    if not spread > 0:
        return
    share = float(np.sqrt(np.sum(np.asarray(rms) ** 2) / spread))
    if share > UNEXPLAINED:
        warnings.warn(
            f"the model leaves {100 * share:.0f} % of the training torque unexplained (the residual's RMS over "
            "the torque's spread, over all joints): check that the description is the arm that was recorded, "
            "its joints in the recording's order, the torques in N m with the description's signs; or an effect "
            "is missing (dynid diagnose names it)",
            IdentificationWarning,
            stacklevel=4,
        )


SPEED_LEVELS = 40
"""Equal-probability samples of each joint's training speed the model file keeps (:func:`speed_quantiles`)."""


def speed_quantiles(dq) -> list[list[float]]:
    """Per joint, :data:`SPEED_LEVELS` quantiles of the training ``|dq|`` (rad/s) at the mid-levels
    ``(k + 0.5) / SPEED_LEVELS``, over the samples where it moves (``|dq| >= AT_REST``; all of them for a
    joint that never does): equal-probability samples of the speeds the friction was fitted at.

    The model file keeps them (``speed_quantiles``) so that what is written for a simulator, which holds
    only a viscous coefficient and a Coulomb level per joint, is the straight line closest to the
    identified friction where the arm was seen moving (:meth:`dynid.identify.friction.FrictionModel.
    simulator_line`), not its linear coefficient alone.
    """
    levels = (np.arange(SPEED_LEVELS) + 0.5) / SPEED_LEVELS
    a = np.abs(np.asarray(dq, dtype=np.float64))
    out = []
    for j in range(a.shape[1]):  # the moving samples: at rest a joint has no friction direction (dynid._rest)
        moving = a[a[:, j] >= AT_REST, j]
        out.append(np.round(np.quantile(moving if moving.size else a[:, j], levels), 9).tolist())
    return out

AT_BOUND_STD = 1e-3
"""A bounded parameter closer to its bound than this many of its standard deviations is held at it."""

MIXTURE_SHARE = 0.25
"""Largest RMS of the mixture's correction on a joint, as a fraction of that joint's torque RMS.

The mixture is for what the physical layers cannot shape (a ripple, a friction's fine structure), a
few per cent of a joint's torque.  A correction of a quarter of it carries physics the link and
friction layers miss: a CAD description's wrong angle (a mixture carried joint 2's gravity: the
physical layers 3.1 N m off held out, the mixture's 0.41), a coupled transmission, an unmodelled
effect.  That joint's correction is switched off, and a note says so and where to look (``dynid
diagnose`` names the effect): a model that predicts well for the wrong reason is not kept silently."""

TAKEOVER = 10.0
"""Largest ratio of the physical layers' RMS in the joint fit to their RMS fitted alone (per joint).

Set between what was measured: a mixture that took over physical torque shows 12-14 (the Panda
filtered at 6 Hz, the whole TX40 recording); a joint fit that generalises well shows up to 5.7 (the
identification benchmark's UR5 with a smooth position-dependent torque, whose held-out error is 0.26x
OLS with the joint fit kept and 0.84x with the physical layers first)."""

TAKEOVER_SHARE = 0.03
"""Largest share of a joint's measured torque power that the mixture may take from the physical layers.

Per joint, ``(rms_joint**2 - rms_alone**2) / mean(tau**2)``: the power the physical layers leave in
the joint fit beyond what they leave fitted alone, over the measured torque's power (filtered as the
fit sees it).  Measured: the whole TX40 recording's joint 2, 0.103 (ratio 5.0: link + friction 10.8
N m in the joint fit, 2.2 N m alone); the identification benchmark's UR5, at most 0.008; the paper
reproduction's UR5 with a smooth position ripple, 0.032 (and there the joint fit predicts held-out data
twice as well).  Past this share, the physical layers come first only if they, with a mixture fitted on
what they leave, fit the training data within :data:`TAKEOVER_GAIN` of the joint fit on every joint."""

TAKEOVER_GAIN = 1.1
"""Largest ratio, on every joint, of the training RMS of the physical layers first (with their own mixture)
to the joint fit's, for a share past :data:`TAKEOVER_SHARE` to put the physical layers first.

Measured: the whole TX40 recording, at most 1.07 (the joint fit bought nothing for the torque its mixture
moved); the paper reproduction's ripple, 1.17 on the joint past the share and 1.7-2.4 on the others; a
1 N m position bump on every joint of a UR5 (tests/identify/test_physical_layers.py), 1.4-3.1."""


def cap_mixture(gmr: GMRCorrection, prep, rms_layers: dict[str, list[float]], info: dict[str, Any]):
    """Switch off the mixture on joints where it carries more than :data:`MIXTURE_SHARE` of the torque.

    Returns the layers' RMS with those joints' full-model figure set to the physical layers' (what the
    model now predicts there); ``info["notes"]`` says which joints and why.
    """
    if not gmr.active_.any():
        return rms_layers
    rows = prep.rows
    u = np.hstack([prep.q, prep.dq])
    correction = prep.filter(gmr.predict(u))[rows]
    share = np.sqrt(np.mean(correction**2, axis=0)) / np.maximum(
        np.sqrt(np.mean(prep.tau_reference**2, axis=0)), 1e-300
    )
    over = gmr.active_ & (share > MIXTURE_SHARE)
    info["mixture_share"] = [float(v) for v in share]
    if not over.any():
        return rms_layers
    gmr.active_ = gmr.active_ & ~over
    full = list(rms_layers["gmm"])
    for j in np.flatnonzero(over):
        full[j] = rms_layers["friction"][j]
    joints = ", ".join(f"{j + 1} ({100 * share[j]:.0f} %)" for j in np.flatnonzero(over))
    note = (
        f"the mixture correction is off on joint(s) {joints}: it would carry that share of the joint's torque "
        f"(RMS), more than {100 * MIXTURE_SHARE:.0f} %: physics the link and friction layers miss (the "
        "description's geometry or inertials, a coupled transmission, an unmodelled effect); dynid diagnose "
        "names the effect"
    )
    info["notes"] = [*info.get("notes", []), note]
    gmr.fallback_ = "; ".join(x for x in (gmr.fallback_, note) if x)
    return {**rms_layers, "gmm": full}


def joint_rms(r: NDArray[np.float64]) -> list[float]:
    """The RMS of each column of ``r`` (per joint), as floats."""
    return [float(v) for v in np.sqrt(np.mean(r**2, axis=0))]


def consistency_figures(
    standard, solver: dict[str, Any], *, relative_distance, mahalanobis, rms_before, rms_after
) -> dict[str, Any]:
    """JSON-ready figures of the consistent projection (``info["consistency"]``).

    ``at_bound`` names the links (1-based) whose consistency constraint held the fit away from the
    unconstrained estimate; ``rms_before`` / ``rms_after`` are the training RMS (N m per joint) of the
    fit before and after the projection (the later layers refitted), ``rms_rise`` their ratio.
    """
    phi = np.asarray(standard, dtype=np.float64)
    J = pseudo_inertia(phi.reshape(-1, 10))
    out: dict[str, Any] = {
        "relative_distance": float(relative_distance),
        "mahalanobis": float(mahalanobis),
        "min_eigenvalues": [float(np.linalg.eigvalsh(j).min()) for j in J],
        "standard_params": [float(v) for v in phi],
        "solver": dict(solver),
        "at_bound": [int(k) for k in solver.get("at_bound", [])],
    }
    if rms_before is not None and rms_after is not None:
        b = np.asarray(rms_before, dtype=np.float64)
        a = np.asarray(rms_after, dtype=np.float64)
        out["rms_before"] = b.tolist()
        out["rms_after"] = a.tolist()
        out["rms_rise"] = (a / np.where(b > 0, b, 1.0)).tolist()
    return out


def bounds_info(
    cols: ColumnSet, x: NDArray[np.float64], lower: NDArray[np.float64] | None, std: NDArray[np.float64]
) -> dict[str, Any]:
    """Whether the fit was bounded and which parameters sit at their bound (JSON-ready): on it, or closer
    to it than :data:`AT_BOUND_STD` of their standard deviation (an interior-point step stops just inside
    a bound: the value there is the bound's, not the data's)."""
    if lower is None:
        return {"physical": False, "active": []}
    finite = np.isfinite(lower)
    gap = np.where(finite, x - np.where(finite, lower, 0.0), np.inf)
    held = at_bound(x, lower) | (finite & (gap <= AT_BOUND_STD * std))
    return {"physical": True, "active": [cols.names[i] for i in np.flatnonzero(held)]}


def at_bound(x: NDArray[np.float64], lower: NDArray[np.float64]) -> NDArray[np.bool_]:
    """Parameters at their lower bound, to 1e-12 of the largest parameter."""
    return np.isfinite(lower) & (x <= lower + 1e-12 * max(1.0, float(np.abs(x).max(initial=0.0))))


def layer1_friction(cols: ColumnSet, x: NDArray[np.float64], prep: Prepared) -> NDArray[np.float64]:
    """The layer-1 linear friction, filtered like the torque, at the kept rows."""
    full = linear_torque(cols, x, prep.q, prep.dq, prep.ddq, mask=cols.friction_mask)
    return prep.filter(full)[prep.rows]
