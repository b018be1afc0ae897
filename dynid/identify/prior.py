"""The user's description as a prior: how strongly it holds, chosen from the recording.

Joint torques determine only some combinations of the links' inertial parameters, and some of those
only weakly: a least-squares fit then puts 60 kg on a 0.65 kg link, 28 times an arm's mass, and still
predicts the joint torque well.  dynid keeps the robot's description (URDF or DH table) in every
direction the recording does not determine, by the pull of the physically consistent fit
(:func:`dynid.identify.consistent.consistent_solution`),

    || R (x - x_hat) ||^2 / sigma^2  +  w  sum_l D(J_l || J_l,ref),

with ``D`` the entropic (log-det) divergence of each link's pseudo-inertia from its description
(Lee and Wensing's geometric prior; unit-free, zero only at the description).  The data term is in
squared standard deviations, so ``w`` says how many of them a body may cost.

How strong?  :func:`choose_prior` decides from the training recording alone, by blocked
cross-validation: the recording is cut into :data:`FOLDS` contiguous blocks, each block is predicted
by a fit on the others (a motion the fit has not seen), for ``w = lambda * m`` on a grid of
``lambda`` (``m`` the fit's samples, so the balance does not move with the recording's length).
For speed the folds use the quadratic form of the divergence at the description (its Hessian: the
Euclidean pull-back of the same metric) and ordinary least squares with linear friction, all in
p x p normal matrices.  The strongest prior whose cross-validated error stays within
:data:`TOLERANCE` of the best on every joint is taken: the description stands wherever the data do
not measurably predict better without it.

The same quadratic model gives, per link, how much of its uncertainty the data removed
(``data_share``: 1 - posterior / prior variance of the link's parameters in the prior's metric; 0:
the description decided it alone, 1: the data did).

References: T. Lee, P. M. Wensing, F. C. Park, "Geometric robot dynamic identification: a convex
programming approach", IEEE T-RO 2020; P. M. Wensing, S. Kim, J.-J. E. Slotine, "Linear matrix
inequalities for physically consistent inertial parameter identification", RA-L 2018.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dynid._progress import advance
from dynid.identify.columns import ColumnSet
from dynid.identify.consistent import pseudo_inertia
from dynid.identify.estimators import long_run_factor

__all__ = [
    "FOLDS",
    "GRID",
    "STAYED",
    "TOLERANCE",
    "PriorChoice",
    "choose_prior",
    "link_report",
    "prior_precision",
]

FOLDS = 3
"""Contiguous blocks of the training recording in the cross-validation of the prior's strength."""

GRID = (0.0, 3.0, 10.0, 30.0, 100.0, 300.0)
"""Candidate weights of the pull, in effective samples per unit of divergence."""

TOLERANCE = 0.02
"""The strongest pull is taken whose cross-validated score is within this fraction of the best."""

STAYED = 0.1
"""Largest divergence from the description of a body the description decided (share of the data under 0.1).

About a body scaled as a whole by 1.25 or 0.8 (``4 (r - ln r - 1)``).  A body that moved further while
the data removed little of its uncertainty was moved by the few combinations the data do see, which it
shares with other links (``decided_by`` ``shared``): a Kinova Gen3 given another arm's recording put its
third link at 13 times its mass with a data share of 8 %, and was said to be decided by the description."""

_E = pseudo_inertia(np.eye(10))  # (10, 4, 4): J = sum_i params_i _E[i]
_FLOOR = 1e-9  # relative weight that keeps the unseen directions at the description when lambda = 0


@dataclass(frozen=True)
class PriorChoice:
    """The strength of the pull toward the description, as cross-validation chose it.

    Attributes
    ----------
    weight : float
        ``w`` of the consistent fit on the whole recording, against a data term in effective samples
        (squared standard deviations with the residual's long-run variance factor).
    kappa : float
        That factor (mean over joints): a data term in plain squared standard deviations takes the
        weight ``w * kappa``.
    strength : float
        ``lambda = w / m``.
    grid : tuple of float
        The strengths tried.
    cv_rms : ndarray, shape (len(grid), n)
        Cross-validated RMS per joint (N m) at each strength.
    data_share : ndarray, shape (n,)
        Per link, the share of its prior uncertainty the data removed at the chosen strength.
    rule : str
        One sentence on how the strength was chosen.
    """

    weight: float
    kappa: float
    strength: float
    grid: tuple[float, ...]
    cv_rms: NDArray[np.float64] = field(repr=False)
    data_share: NDArray[np.float64] = field(repr=False)
    rule: str

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready record (the model file keeps it)."""
        return {
            "weight": float(self.weight),
            "kappa": float(self.kappa),
            "strength": float(self.strength),
            "grid": [float(g) for g in self.grid],
            "cv_rms": np.round(self.cv_rms, 6).tolist(),
            "data_share": [float(v) for v in self.data_share],
            "rule": self.rule,
        }


def prior_precision(robot, cols: ColumnSet) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The description and the quadratic form of the divergence at it, over the physical vector.

    Parameters
    ----------
    robot : RobotModel
        Its bodies are the description.
    cols : ColumnSet
        The identified parameters.

    Returns
    -------
    phi_ref : ndarray, shape (14 n,)
        The described physical vector (bodies, armature; friction and offsets 0).
    Lam : ndarray, shape (14 n, 14 n)
        ``D(J || J_ref) ~ dphi^T Lam dphi`` per link (``Lam_ik = tr(Jr^-1 E_i Jr^-1 E_k) / 2``); the
        extras get a vanishing weight relative to their scale.
    """
    n = cols.n
    phi_ref = np.concatenate([robot.params, robot.armature, np.zeros(3 * n)])
    Lam = np.zeros((14 * n, 14 * n))
    J_ref = pseudo_inertia(robot.params.reshape(n, 10))
    for link in range(n):
        w, V = np.linalg.eigh(J_ref[link])
        w = np.maximum(w, 1e-6 * max(float(w.max()), 1e-9))
        Jinv = (V / w) @ V.T
        T = np.einsum("ab,kbc->kac", Jinv, _E)  # Jr^-1 E_k
        block = 0.5 * np.einsum("iab,kba->ik", T, T)
        Lam[10 * link : 10 * link + 10, 10 * link : 10 * link + 10] = block
    return phi_ref, Lam


def _extras_precision(cols: ColumnSet, H: NDArray[np.float64], scale: float) -> NDArray[np.float64]:
    """A vanishing weight on the extras (armature, friction, offsets), relative to their data curvature."""
    n = cols.n
    out = np.zeros(4 * n)
    P = cols.P
    for k in range(4 * n):
        col = P[:, 10 * n + k]
        if np.any(col):
            out[k] = max(float(col @ H @ col), scale) * 1e-9
        else:
            out[k] = 1.0
    return out


def _block_moments(system) -> tuple[NDArray[np.float64], NDArray[np.intp]]:
    """Per block and joint, the (p+1) x (p+1) moment matrix of ``[W_j, tau_j]`` over the block's rows."""
    Z = system.data_matrix()  # the kept rows, in time order
    p, n = system.p, system.n
    edges = np.linspace(0, Z.shape[0], FOLDS + 1).round().astype(int)
    reg = system.z_param >= 0
    T = []
    for j in range(n):
        Tj = np.zeros((len(system.z_joint), p + 1))
        on = reg & (system.z_joint == j)
        Tj[np.flatnonzero(on), system.z_param[on]] = 1.0
        Tj[np.flatnonzero(~reg & (system.z_joint == j)), p] = 1.0
        T.append(Tj)
    M = np.zeros((FOLDS, n, p + 1, p + 1))
    for b in range(FOLDS):
        G = np.zeros((Z.shape[1], Z.shape[1]))
        for a in range(edges[b], edges[b + 1], 4096):
            chunk = Z[a : min(a + 4096, edges[b + 1])]
            G += chunk.T @ chunk
        for j in range(n):
            M[b, j] = T[j].T @ G @ T[j]
    return M, edges


def choose_prior(robot, system, *, grid: tuple[float, ...] = GRID, tolerance: float = TOLERANCE) -> PriorChoice:
    """The strength of the pull toward the description, chosen by blocked cross-validation.

    Each of :data:`FOLDS` contiguous blocks of the recording is predicted by the physically
    consistent ordinary least-squares fit of the other blocks (the system's own columns: links,
    armature, linear friction), pulled toward the description with each weight of ``grid``; the
    weights are in effective samples (the data term divided by the residual's long-run variance
    factor), so that they mean the same on every recording.  Score of a weight: the mean over joints
    of its cross-validated RMS over the joint's best.  Chosen: the strongest weight whose score is
    within ``tolerance`` of the best score.

    Parameters
    ----------
    robot : RobotModel
        The robot (its bodies are the description).
    system : LinearSystem
        The training recording's identification system, with its data matrix (before ``release``).
    grid : tuple of float
        Weights to try, increasing.
    tolerance : float
        How much worse than the best score the chosen weight may be.

    Returns
    -------
    PriorChoice
    """
    from dynid.identify.consistent import consistent_projection

    cols = system.columns
    n, p = cols.n, cols.p
    M, edges = _block_moments(system)
    total = M.sum(axis=(0, 1))

    def ols(T):
        H, g = T[:p, :p], T[:p, p]
        x = np.linalg.lstsq(H, g, rcond=None)[0]
        sse = float(T[p, p] - 2 * g @ x + x @ H @ x)
        ridge = 1e-12 * max(float(np.trace(H)) / max(p, 1), 1e-300)
        R = np.linalg.cholesky(H + ridge * np.eye(p)).T
        # noise-free (simulated) data fit to rounding: the residual is floored at 1e-6 of the torque's RMS,
        # so that the data term in squared standard deviations stays finite
        return x, R, max(sse, 1e-12 * float(T[p, p]), 1e-300)

    x_all, _, sse_all = ols(total)
    # the residual's long-run variance factor: the data term in effective samples, as the joint refit's
    # consistency step measures it, so that one weight means the same in every path
    resid = system.tau() - system.predict(x_all)
    kappa = float(np.mean(long_run_factor(resid, float(system.prepared.noise_correlation))[0]))
    sq = np.zeros((len(grid), n))
    for k in range(FOLDS):
        T = M[np.arange(FOLDS) != k].sum(axis=(0, 1))
        x_hat, R, sse = ols(T)
        m_train = system.m - (edges[k + 1] - edges[k])
        scale2 = sse / max(m_train * n - p, 1) * kappa
        for gi, w in enumerate(grid):
            x, _, _ = consistent_projection(
                robot, cols, x_hat, R, scale2, reference_weight=float(w), tol=1e-6, describe=False
            )
            for j in range(n):
                Mj = M[k, j]
                sq[gi, j] += Mj[p, p] - 2 * Mj[:p, p] @ x + x @ Mj[:p, :p] @ x
            advance(k * len(grid) + gi + 1, FOLDS * len(grid))
    cv = np.sqrt(np.maximum(sq, 0.0) / max(system.m, 1))
    score = np.mean(cv / np.maximum(cv.min(axis=0), 1e-300), axis=1)
    ok = score <= (1 + tolerance) * score.min() + 1e-12
    pick = int(np.flatnonzero(ok).max())
    w = float(grid[pick])

    # how much of each link's prior uncertainty the data removed, at the chosen weight (the quadratic
    # form of the divergence at the description; the data term in effective samples)
    _, Lam = prior_precision(robot, cols)
    sigma2 = sse_all / max(system.m * n - p, 1) * kappa
    H_all = total[:p, :p]
    Lam[10 * n :, 10 * n :] = np.diag(_extras_precision(cols, H_all / sigma2, 1.0))
    floor = _FLOOR * float(np.trace(Lam[: 10 * n, : 10 * n])) / max(10 * n, 1)
    A = cols.P.T @ H_all @ cols.P / sigma2 + (w + floor) * Lam
    cov_post = np.linalg.pinv(A, hermitian=True)
    share = np.zeros(n)
    for link in range(n):
        blk = slice(10 * link, 10 * link + 10)
        prior_var = 10.0 / (w + floor)  # tr(Lam_l C0_l) with C0 = ((w + floor) Lam)^-1
        post = float(np.trace(Lam[blk, blk] @ cov_post[blk, blk]))
        share[link] = float(np.clip(1.0 - post / prior_var, 0.0, 1.0))
    rule = (
        f"{FOLDS}-fold blocked cross-validation on the training recording: the strongest pull whose mean "
        f"relative fold error is within {100 * tolerance:g} % of the best (weight {w:g}; {len(grid)} weights tried, "
        f"{', '.join(f'{g:g}' for g in grid)})"
    )
    return PriorChoice(
        weight=w,
        kappa=kappa,
        strength=w / max(system.m, 1),
        grid=tuple(float(g) for g in grid),
        cv_rms=cv,
        data_share=share,
        rule=rule,
    )


def link_report(robot, standard: NDArray[np.float64], data_share: NDArray[np.float64] | None = None) -> list[dict]:
    """How far each identified body moved from its description, and what decided it.

    Parameters
    ----------
    robot : RobotModel
        The robot (its bodies are the description).
    standard : ndarray, shape (n, 10) or (10 n,)
        The identified bodies' standard parameters.
    data_share : ndarray, shape (n,), optional
        Share of each link's prior uncertainty the data removed (:class:`PriorChoice`).

    Returns
    -------
    list of dict
        Per link: ``link``, ``mass`` and ``mass_description`` (kg), ``mass_ratio``, ``com_shift`` (m),
        ``divergence`` (entropic, 0 at the description), ``data_share`` and ``decided_by``
        ("data", "description", "both", or "shared": moved beyond :data:`STAYED` by the combinations
        the data see with other links while they removed under 10 % of its uncertainty).
    """
    phi = np.asarray(standard, dtype=np.float64).reshape(-1, 10)
    ref = robot.params.reshape(-1, 10)
    out = []
    for link, (v, r) in enumerate(zip(phi, ref, strict=True)):
        J, Jr = pseudo_inertia(v), pseudo_inertia(r)
        try:
            M = np.linalg.solve(Jr, J)
            sign, logdet = np.linalg.slogdet(M)
            div = float(np.trace(M) - logdet - 4) if sign > 0 else float("inf")
        except np.linalg.LinAlgError:
            div = float("nan")
        c = v[1:4] / v[0] if v[0] > 0 else np.zeros(3)
        cr = r[1:4] / r[0] if r[0] > 0 else np.zeros(3)
        share = None if data_share is None else float(data_share[link])
        if share is None:
            decided = None
        elif share > 0.9:
            decided = "data"
        elif share >= 0.1:
            decided = "both"
        else:  # the data removed little of its uncertainty: the description decided it, if it stayed there
            decided = "description" if not div > STAYED else "shared"
        out.append(
            {
                "link": robot.joint_names[link] if link < len(robot.joint_names) else str(link + 1),
                "mass": float(v[0]),
                "mass_description": float(r[0]),
                "mass_ratio": float(v[0] / r[0]) if r[0] > 0 else None,
                "com_shift": float(np.linalg.norm(c - cr)),
                "divergence": div,
                "data_share": share,
                "decided_by": decided,
            }
        )
    return out
