"""The parameter-change test: what re-identification absorbed, against structured hypotheses.

The re-identified minus the nominal base parameters, with the refit's block (HAC) covariance, are fitted
by generalised least squares to structured hypotheses (a common drive gain, a torque gain on one joint,
a payload on the last link, an armature per joint, a tilt of the base) and chosen by BIC
(:func:`dynid.diagnosis.stats.structured_change_test`); then the model's own torque offsets and
armatures are tested against their nominal values.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import stats

from dynid.diagnosis import stats as st
from dynid.diagnosis.fitting import WeightedFit
from dynid.identify.columns import ColumnSet, compiled_base_regressor

__all__ = ["JACKKNIFE_GROUPS", "parameter_change_test"]

#: Contiguous chunks of the training rows whose delete-one spread gives the per-joint tests' errors.
JACKKNIFE_GROUPS = 20


def _absorbed_armature(cols: ColumnSet) -> NDArray[np.float64]:
    """Base-parameter change (n_b, n) that an armature of 1 kg m^2 on each joint causes once absorbed.

    The column ``ddq_j`` of an armature projected on the base regressor over random states.
    """
    from dynid.symbolic.base import random_states

    robot = cols.robot
    n, nb = robot.n, cols.n_base
    rng = np.random.default_rng(0)
    m = max(200, 40 * n)
    q, dq, ddq = random_states(robot, m, rng)
    Yb = compiled_base_regressor(robot, q, dq, ddq).reshape(m * n, nb)
    out = np.zeros((nb, n))
    for j in range(n):
        col = np.zeros((m, n))
        col[:, j] = ddq[:, j]
        out[:, j] = np.linalg.lstsq(Yb, col.reshape(-1), rcond=None)[0]
    return out


@dataclass(frozen=True)
class _Change:
    """The tested base parameters (indices), their nominal values, their change and its covariance."""

    idx: NDArray[np.intp]
    x_nom: NDArray[np.float64]
    delta: NDArray[np.float64]
    C: NDArray[np.float64]


@dataclass(frozen=True)
class _Finding:
    """What the test names, the joint it names (or None) and the sentence that says it."""

    finding: str
    joint: int | None
    text: str


def parameter_change_test(
    ddq_train: NDArray[np.float64],
    cols: ColumnSet,
    fit: WeightedFit,
    x: NDArray[np.float64],
    robot,
    block: int,
    alpha: float,
    sigma: NDArray[np.float64],
    gain_dirs: dict[int, NDArray[np.float64]] | None = None,
    chi2_per_dof: float = 5.0,
    tilt_dirs: NDArray[np.float64] | None = None,
    beside: Sequence[str] = (),
) -> dict[str, Any]:
    """Identified minus nominal parameters against structured hypotheses (chi^2, BIC).

    ``gain_dirs`` maps a joint (0-based) to the parameter change (k, 1) that a torque gain error on that
    joint alone leaves in the refit (the regression of its predicted torque on the baseline columns); a
    gain on one joint is partly absorbed (for most joints nearly all of it): its residual part is scored
    as a candidate, the absorbed part here.  ``tilt_dirs`` (k, 2) is the same for the gravity direction:
    the parameter change that a tilt of the base by 1 rad about each of two horizontal axes leaves in the
    refit (a tilt shows in the gravity columns, so re-identification absorbs part of it and the
    nominal parameters look "off" when it is not a hypothesis).  ``beside`` names the effects whose
    columns ``fit`` holds after the baseline's (the verdict's): the change is what is left beside them.

    A structured hypothesis is the finding when it has the lowest BIC, the nominal parameters are
    rejected clearly (chi^2 per degree of freedom above ``2 chi2_per_dof``) and what it leaves is
    within ``chi2_per_dof`` per degree of freedom (the block covariance underestimates the spread of
    filtered, coloured residuals by a few times: an exact chi^2 test would reject every model).
    """
    # The block sums alone, without their lags: the allowances (chi2_per_dof, twice it for a clear
    # rejection) were set on that covariance.  With the lags it is wider on coloured noise, and on the
    # field UR5 a drive gain on joint 5 and a payload (1x and 3x each) then came out "unstructured".
    cov = fit.covariance(block, lags=False)
    change = _nominal_change(cols, x, robot, cov)
    # An armature cannot be negative (identify keeps it at zero or above): its change is at least minus
    # the nominal one.
    nominal_armature = np.maximum(np.asarray(robot.armature, dtype=float), 0.0)
    hyp, lower = _hypotheses(cols, robot, change, nominal_armature, gain_dirs, tilt_dirs)
    fits = st.structured_change_test(change.delta, change.C, hyp, n_obs=fit.shape[0], lower=lower)
    h0 = next(f for f in fits if f.name == "none")
    last_mass = float(robot.params[-10])
    out = _hypotheses_record(fits, h0, len(change.idx), last_mass)
    # A payload is a body: it adds a mass the change determines and that is positive beyond its error.
    # A change of the last link's inertia with no mass (a friction the refit put there) is no payload.
    best = next(f for f in fits if f.name != "payload" or _a_body(f, last_mass))
    found = _structured_finding(best, h0, alpha, chi2_per_dof, nominal_armature, robot)
    # Per-joint parameters the model holds: torque offsets (nominal 0) and armatures (nominal: the URDF's).
    # Each is tested alone, with the jackknife's spread over chunks of the training run: the block
    # sandwich's standard errors were about half of it on field-like runs (noise correlated over 0.1 s,
    # small model errors that differ along the motion), and an offset traded against gravity then looked
    # "changed" on effect-free robots.
    jack = fit.jackknife_covariance(JACKKNIFE_GROUPS)
    out["per_joint_covariance"] = f"delete-a-chunk jackknife over {JACKKNIFE_GROUPS} chunks of the training data"
    ddq_rms = np.sqrt(np.mean(ddq_train**2, axis=0))
    flagged = []
    for kind, unit in (("offset", "N m"), ("armature", "kg m^2")):
        rows = _per_joint_rows(kind, cols, x, robot, jack, ddq_rms, sigma)
        if not rows:
            continue
        out[kind + "s"] = rows
        # A stricter level than alpha: with enough data a small model error makes any parameter "changed".
        flagged += [(kind, unit, r) for r in rows if r["p_value"] < min(alpha, 1e-3) and r["relevant"]]
    if flagged and found.finding in ("none", "unstructured"):
        found = _per_joint_finding(flagged)
    out["finding"] = found.finding
    out["joint"] = found.joint
    out["beside"] = list(beside)
    out["text"] = found.text
    if beside:
        out["text"] = f"With {', '.join(beside)} in the refit: {found.text[0].lower()}{found.text[1:]}"
    return out


def _nominal_change(cols: ColumnSet, x: NDArray[np.float64], robot, cov: NDArray[np.float64]) -> _Change:
    """The link and armature parameters with a finite variance: identified minus nominal, and covariance."""
    n = robot.n
    k_all = len(x)
    link = np.array([k in ("link", "armature") for k in cols.kinds] + [False] * (k_all - len(cols.kinds)))
    link_idx = np.flatnonzero(link)
    phi = np.concatenate([robot.params, robot.armature, np.zeros(3 * n)])
    x_nom = np.zeros(k_all)
    x_nom[: cols.p] = cols.P @ phi
    idx = link_idx[np.isfinite(np.diag(cov))[link_idx]]
    delta = x[idx] - x_nom[idx]
    C = cov[np.ix_(idx, idx)]
    return _Change(idx=idx, x_nom=x_nom, delta=delta, C=C)


def _hypotheses(
    cols: ColumnSet,
    robot,
    change: _Change,
    nominal_armature: NDArray[np.float64],
    gain_dirs: dict[int, NDArray[np.float64]] | None,
    tilt_dirs: NDArray[np.float64] | None = None,
) -> tuple[dict[str, NDArray[np.float64]], dict[str, float]]:
    """The structured hypotheses' directions on the tested parameters, and their lower bounds."""
    n, nb = robot.n, cols.n_base
    idx, x_nom = change.idx, change.x_nom
    k_all = len(x_nom)
    hyp: dict[str, NDArray[np.float64]] = {"drive_gain": x_nom[idx].reshape(-1, 1)}
    last = robot.n - 1
    Bl = np.zeros((k_all, 10))
    Bl[:nb] = cols.base.matrix[:, 10 * last : 10 * last + 10]
    hyp["payload"] = Bl[idx]
    Aa = np.zeros((k_all, n))
    if cols.armature:
        # Each joint's armature maps to its own parameter, or into the base parameter it duplicates.
        Aa[: cols.p] = cols.P[:, 10 * n : 11 * n]
    else:
        Aa[:nb] = _absorbed_armature(cols)
    lower: dict[str, float] = {}
    for j in range(n):
        if np.linalg.norm(Aa[idx, j]) > 0:
            hyp[f"armature@{j + 1}"] = Aa[idx, j : j + 1]
            lower[f"armature@{j + 1}"] = -float(nominal_armature[j])
    # a direction the refit does not see (its columns are in the fit already) is no hypothesis
    seen = 1e-8 * max(float(np.linalg.norm(x_nom[idx])), 1e-300)
    for j, d in (gain_dirs or {}).items():
        if np.linalg.norm(d[idx]) > seen:
            hyp[f"drive_gain@{j + 1}"] = d[idx]
    if tilt_dirs is not None and np.linalg.norm(tilt_dirs[idx]) > seen:
        hyp["base_tilt"] = tilt_dirs[idx]
    return hyp, lower


def _hypotheses_record(fits, h0, n_parameters: int, last_mass: float) -> dict[str, Any]:
    """The hypotheses' fits and the nominal parameters' test, as the result's first entries."""
    return {
        "hypotheses": [
            {
                "name": f.name,
                "k": f.k,
                "chi2": f.chi2,
                "dof": f.dof,
                "p_value": f.p_value,
                "bic": f.bic,
                "theta": f.theta.tolist(),
                "at_bound": f.at_bound,
                "theta_se": [None if not np.isfinite(v) else float(v) for v in (f.theta_se if f.theta_se is not None else [])],
                "a_body": _a_body(f, last_mass) if f.name == "payload" else None,
            }
            for f in fits
        ],
        "chi2_nominal": h0.chi2,
        "dof_nominal": h0.dof,
        "p_nominal": h0.p_value,
        "n_parameters": n_parameters,
        "covariance": "block (HAC) sandwich over blocks of the training data",
    }


def _structured_finding(
    best, h0, alpha: float, chi2_per_dof: float, nominal_armature: NDArray[np.float64], robot
) -> _Finding:
    """The structured hypothesis found (or none, or an unstructured change), and its sentence."""
    finding, joint = "none", None
    text = "The re-identified base parameters show no structured change from the nominal ones."
    clear = h0.p_value < alpha and h0.chi2 / h0.dof > 2 * chi2_per_dof
    if clear and best.name != "none" and best.chi2 / best.dof <= chi2_per_dof:
        finding = best.name.split("@")[0]
        if best.name == "drive_gain":
            g = 1.0 + float(best.theta[0])
            text = (
                f"Parameter change: every base parameter is scaled by {g:.3f} (a common drive gain or torque "
                "constant error), which re-identification absorbs."
            )
        elif best.name.startswith("drive_gain@"):
            joint = int(best.name.split("@")[1])
            text = (
                f"Parameter change: the base parameters changed as a torque gain of {1.0 + float(best.theta[0]):.3f} "
                f"on joint {joint} alone (its drive's torque constant or current sensor) would change them; "
                "re-identification absorbs most of it."
            )
        elif best.name == "base_tilt":
            text = _tilt_sentence(best.theta, robot.gravity)
        elif best.name == "payload":
            se = float(best.theta_se[0]) if best.theta_se is not None else float("nan")
            text = (
                "Parameter change: the base parameters changed as a payload on the last link would change them "
                f"(mass change {float(best.theta[0]):.3g} +- {se:.2g} kg), which re-identification absorbs."
            )
        else:
            joint = int(best.name.split("@")[1])
            change = float(best.theta[0])
            total = float(nominal_armature[joint - 1]) + change
            text = (
                f"Parameter change: an armature (rotor inertia) change of {change:.3g} kg m^2 on joint {joint} "
                f"(to {total:.3g} kg m^2"
                + (", its lower bound: an armature is never negative" if best.at_bound else "")
                + "), absorbed by the base parameters."
            )
    elif clear:
        finding = "unstructured"
        text = (
            "Parameter change: the re-identified base parameters differ from the nominal ones, and no structured "
            "hypothesis (common or one-joint gain, payload, armature, base tilt) explains the change: the description's "
            "inertial parameters are off, or an effect the refit does not hold is absorbed into them (the verdict "
            "and the ranking say which effects were tried)."
        )
    return _Finding(finding=finding, joint=joint, text=text)


def _a_body(fit, nominal_mass: float) -> bool:
    """A payload hypothesis' fit is a body added (or taken off): its mass change determined by the change,
    beyond twice its error, and the last link's mass still positive.  The error is widened by the fit's
    chi^2 per degree of freedom (the block covariance understates the spread a few times)."""
    se = fit.theta_se
    if se is None or len(fit.theta) == 0 or not np.isfinite(se[0]):
        return False
    widen = np.sqrt(max(1.0, fit.chi2 / max(fit.dof, 1)))
    return bool(abs(fit.theta[0]) > 2.0 * widen * se[0] and nominal_mass + fit.theta[0] > 0)


def _tilt_sentence(theta: NDArray[np.float64], gravity: NDArray[np.float64]) -> str:
    """The base tilt that the change fits: its angle, and the axis it turns about in the base frame."""
    from dynid.identify.effect_builders import tilt_axes

    a1, a2 = tilt_axes(gravity)
    rot = float(theta[0]) * a1 + float(theta[1]) * a2  # gravity's small rotation in the base frame (rad)
    axis = -rot / max(float(np.linalg.norm(rot)), 1e-300)  # the base turned the other way
    return (
        f"Parameter change: the base parameters changed as a tilt of the robot's base by "
        f"{np.degrees(np.linalg.norm(rot)):.2g} degrees about the axis [{axis[0]:.2f}, {axis[1]:.2f}, "
        f"{axis[2]:.2f}] of the base frame would change them (gravity not along the description's "
        "vertical), which re-identification absorbs in part.  Level the base, or give the gravity "
        "direction in the description."
    )


def _per_joint_rows(
    kind: str,
    cols: ColumnSet,
    x: NDArray[np.float64],
    robot,
    jack: NDArray[np.float64],
    ddq_rms: NDArray[np.float64],
    sigma: NDArray[np.float64],
) -> list[dict[str, Any]]:
    """Each of the model's ``kind`` parameters (offset or armature) tested alone against its nominal value."""
    idx_k = [k for k, kd in enumerate(cols.kinds) if kd == kind]
    if not idx_k:
        return []
    joints_k = [int(cols.joints[k]) for k in idx_k]
    nominal = np.zeros(len(idx_k)) if kind == "offset" else np.array([robot.armature[j - 1] for j in joints_k])
    change = x[idx_k] - nominal
    if kind == "armature":
        # The refit here is unconstrained; an armature is not negative (identify keeps it at zero or
        # above), so a change below minus the nominal armature is the bound's, no more: a refit that
        # goes below zero shows something else (a delay, a gain) taking the ddq column, not a rotor.
        nominal = np.maximum(nominal, 0.0)
        change = np.maximum(change, -nominal)
    sd = np.sqrt(np.maximum(np.diag(jack)[idx_k], 1e-300))
    p_holm = st.holm(2 * stats.t.sf(np.abs(change) / sd, JACKKNIFE_GROUPS - 1))
    torque = np.abs(change) * (1.0 if kind == "offset" else ddq_rms[np.array(joints_k) - 1])
    return [
        {
            "joint": jt,
            "value": float(v),
            "nominal": float(nm),
            "change": float(dc),
            "at_bound": bool(v < nm + dc),
            "std": float(d),
            "p_value": float(p),
            "size_noise": float(tq / sigma[jt - 1]),
            "relevant": bool(tq >= 0.5 * sigma[jt - 1]),
        }
        for jt, v, nm, dc, d, p, tq in zip(joints_k, x[idx_k], nominal, change, sd, p_holm, torque, strict=True)
    ]


def _per_joint_finding(flagged: list[tuple[str, str, dict[str, Any]]]) -> _Finding:
    """The kind of per-joint parameter that changed most (in noise units), its joint(s) and its sentence."""
    kind = max(flagged, key=lambda f: f[2]["size_noise"])[0]
    sig = [f for f in flagged if f[0] == kind]
    joint = sig[0][2]["joint"] if len(sig) == 1 else None
    what = "torque offsets" if kind == "offset" else "armatures (rotor inertias)"
    text = (
        f"Absorbed by the model's {kind} parameters: {what} "
        + ", ".join(f"joint {r['joint']}: {r['change']:.3g} +- {r['std']:.2g} {unit}" for _, unit, r in sig)
        + " (change from nominal)."
    )
    return _Finding(finding=kind, joint=joint, text=text)
