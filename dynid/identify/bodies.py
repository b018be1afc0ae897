"""Links as rigid bodies, through their pseudo-inertias.

A link's ten standard parameters ``[m, mx, my, mz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz]`` (kg, kg m, kg m^2,
about the link frame's origin) map linearly onto its pseudo-inertia

    J = [[Sigma, h], [h^T, m]],   Sigma = tr(I)/2 * 1 - I,   h = m c,

which is positive definite exactly when the parameters describe a real body.  This module holds that
map and its inverse, their derivatives, the log-Cholesky parameters of a body, the checks of
consistency, the bodies as a URDF ``<inertial>`` takes them, and what the consistent fit
(:mod:`dynid.identify.consistent`) shares with :func:`described_bodies`: the margins and described
bodies it keeps to, the scale of the physical vector, and Newton steps on log-det barriers over the
pseudo-inertias.  :func:`described_bodies` picks, among the bodies with the same identified
parameters, those nearest the robot's description.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike, NDArray

from dynid.identify.columns import EXTRA_KINDS, ColumnSet

# pull of the armature and friction toward their description, relative to the links' divergence: a base
# parameter that holds a link's inertia and an armature together (joint 1's axis) leaves the link at its
# description and the armature takes the rest
_EXTRA_PULL = 1e-3
EPS = 1e-6
"""Default smallest eigenvalue (SI, kg m^2) of a consistent pseudo-inertia
(see :class:`~dynid.identify.consistent.ConsistentLS`)."""
__all__ = [
    "EPS",
    "add_link_terms",
    "add_neg_logdet",
    "clip_eigenvalues",
    "described_bodies",
    "is_consistent",
    "link_inertials",
    "log_cholesky",
    "neg_logdet_terms",
    "newton_direction",
    "physical_scale",
    "pseudo_inertia",
    "pseudo_inertia_jacobian",
    "reference_bodies",
    "standard_from_pseudo_inertia",
    "trace_gradient",
]


def pseudo_inertia(params: ArrayLike) -> NDArray[np.float64]:
    """Pseudo-inertia matrices of standard parameters.

    Parameters
    ----------
    params : array_like, shape (10,) or (k, 10)
        ``[m, mx, my, mz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz]`` per link (kg, kg m, kg m^2).

    Returns
    -------
    ndarray, shape (4, 4) or (k, 4, 4)
    """
    p = np.asarray(params, dtype=np.float64)
    single = p.ndim == 1
    p = p.reshape(-1, 10)
    J = (p @ _E_FLAT).reshape(-1, 4, 4)  # J is linear in the parameters: sum_i params_i E_i
    return J[0] if single else J


def _basis() -> NDArray[np.float64]:
    """(10, 4, 4): the pseudo-inertia of each unit standard parameter."""
    E = np.zeros((10, 4, 4))
    for i, (a, b) in enumerate([(3, 3), (0, 3), (1, 3), (2, 3)]):
        E[i, a, b] = E[i, b, a] = 1.0
    # inertia entries [Ixx, Ixy, Iyy, Ixz, Iyz, Izz]: Sigma = tr(I)/2 * 1 - I
    for i, (a, b) in zip(range(4, 10), [(0, 0), (0, 1), (1, 1), (0, 2), (1, 2), (2, 2)], strict=True):
        if a == b:
            E[i, :3, :3] = 0.5 * np.eye(3)
            E[i, a, a] -= 1.0
        else:
            E[i, a, b] = E[i, b, a] = -1.0
    return E


_E = _basis()  # (10, 4, 4): J = sum_i params_i _E[i]
_E_FLAT = _E.reshape(10, 16)


def pseudo_inertia_jacobian(G: ArrayLike, n: int) -> NDArray[np.float64]:
    """Derivatives of the links' pseudo-inertias when their standard parameters are linear in ``v``.

    Parameters
    ----------
    G : array_like, shape (m, k), m >= 10 n
        ``d params / d v``: its first 10 n rows are the standard parameters of links 1..n, in order
        (any rows after them are ignored).
    n : int
        Number of links.

    Returns
    -------
    ndarray, shape (n, k, 4, 4)
        ``dJ_l / dv_k``.
    """
    G = np.asarray(G, dtype=np.float64)
    return np.stack([np.einsum("ik,iab->kab", G[10 * link : 10 * link + 10], _E) for link in range(n)])


def standard_from_pseudo_inertia(J):
    """Standard parameters ``[m, mx, my, mz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz]`` of a pseudo-inertia.

    Works on numpy arrays of shape (4, 4) and on CasADi matrices alike.

    Parameters
    ----------
    J : ndarray or casadi.SX, shape (4, 4)
        Pseudo-inertia.
    """
    S = J[0:3, 0:3]
    tr = S[0, 0] + S[1, 1] + S[2, 2]
    return [
        J[3, 3],
        J[0, 3],
        J[1, 3],
        J[2, 3],
        tr - S[0, 0],
        -S[0, 1],
        tr - S[1, 1],
        -S[0, 2],
        -S[1, 2],
        tr - S[2, 2],
    ]


def log_cholesky(J: ArrayLike) -> NDArray[np.float64]:
    """The 10 log-Cholesky parameters of a positive definite pseudo-inertia (``J = U U^T``).

    Parameters
    ----------
    J : array_like, shape (4, 4)
        Positive definite pseudo-inertia.
    """
    J = np.asarray(J, dtype=np.float64)
    Lf = np.linalg.cholesky(J[::-1, ::-1])
    U = Lf[::-1, ::-1]
    return np.array(
        [
            np.log(U[0, 0]),
            U[0, 1],
            U[0, 2],
            U[0, 3],
            np.log(U[1, 1]),
            U[1, 2],
            U[1, 3],
            np.log(U[2, 2]),
            U[2, 3],
            np.log(U[3, 3]),
        ]
    )


def clip_eigenvalues(J: NDArray[np.float64], floor: float) -> NDArray[np.float64]:
    """Nearest matrix with eigenvalues >= floor (symmetric eigenvalue clipping).

    Parameters
    ----------
    J : ndarray, shape (k, k)
        A matrix (its symmetric part is used).
    floor : float
        Smallest eigenvalue of the result.
    """
    w, V = np.linalg.eigh(0.5 * (J + J.T))
    return (V * np.maximum(w, floor)) @ V.T


def reference_bodies(
    ref_params: NDArray[np.float64], eps: float | ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Per-link margin and described pseudo-inertia, as the consistent fit and its bodies use them.

    The margin is ``eps``, lowered to half the smallest eigenvalue of a thinner URDF body; the described
    pseudo-inertia is the URDF's, lifted to at least twice that margin (and 1e-6 of its size).

    Parameters
    ----------
    ref_params : ndarray, shape (10 n,)
        Standard parameters of the described bodies.
    eps : float or array_like, shape (n,)
        Margin asked for (kg m^2), one for all links or one per link.

    Returns
    -------
    eps_l : ndarray, shape (n,)
    J_ref_pd : ndarray, shape (n, 4, 4)
    """
    J_ref = pseudo_inertia(np.asarray(ref_params, dtype=np.float64).reshape(-1, 10))
    eps_in = np.broadcast_to(np.asarray(eps, dtype=np.float64), (len(J_ref),))
    eps_l = np.empty(len(J_ref))
    J_pd = np.empty_like(J_ref)
    for link, J in enumerate(J_ref):
        w = np.linalg.eigvalsh(J)
        eps_l[link] = min(float(eps_in[link]), 0.5 * float(w.min())) if w.min() > 0 else float(eps_in[link])
        J_pd[link] = clip_eigenvalues(J, max(1e-6 * max(float(w.max()), 1e-6), 2 * eps_l[link]))
    return eps_l, J_pd


def physical_scale(phi_ref: NDArray[np.float64], n: int) -> NDArray[np.float64]:
    """Typical size of each physical parameter (kg, kg m, kg m^2, N m...), for a scaled minimum norm.

    Parameters
    ----------
    phi_ref : ndarray, shape (14 n,)
        A physical vector ``[pi, ia, fc, fv, fo]`` of typical size (the description's).
    n : int
        Number of links.

    Returns
    -------
    ndarray, shape (14 n,)
        Per link, the size of each entry: mass (at least 1 g), first moments (at least 5 % of the
        mass), second moments (at least the mean of ``|Ixx|, |Iyy|, |Izz|``); the armature (at least
        0.01); 1 for friction and offsets.
    """
    out = np.ones(14 * n)
    for link in range(n):
        v = phi_ref[10 * link : 10 * link + 10]
        m = max(abs(v[0]), 1e-3)
        inertia = max(abs(v[4]) + abs(v[6]) + abs(v[9]), 1e-2 * m) / 3
        out[10 * link] = m
        out[10 * link + 1 : 10 * link + 4] = np.maximum(np.abs(v[1:4]), 0.05 * m)
        out[10 * link + 4 : 10 * link + 10] = np.maximum(np.abs(v[4:]), inertia)
    out[10 * n : 11 * n] = np.maximum(np.abs(phi_ref[10 * n : 11 * n]), 1e-2)
    return out


def add_neg_logdet(M, G, coef: float, grad, hess) -> None:
    """Add the derivatives of ``-coef sum_l log det M_l`` (``dM_l / dv_k = sum_i G[10 l + i, k] E_i``) in place.

    In each link's standard parameters the gradient of ``-log det M`` is ``-tr(M^-1 E_i)`` and its
    Hessian ``tr(M^-1 E_i M^-1 E_j)`` (10 x 10, ``E_i`` the pseudo-inertia of unit parameter ``i``);
    ``G`` maps them to the variables.  (Forming ``dM_l / dv_k`` for every variable first, as
    :func:`pseudo_inertia_jacobian` gives it, costs ``k / 10`` times the small products: on the 7-link
    LWR4+ the log-det terms of a Newton step of the consistent fit took 0.32 ms that way, 0.16 ms this way.)

    Parameters
    ----------
    M : ndarray, shape (n, 4, 4)
        Positive definite matrices (pseudo-inertias, or their part above a margin).
    G : ndarray, shape (m, k), m >= 10 n
        ``d params / d v``: its first 10 n rows are the standard parameters of links 1..n, as
        :func:`pseudo_inertia_jacobian` takes them.
    coef : float
        Weight of the barrier.
    grad, hess : ndarray, shapes (k,) and (k, k)
        Gradient and Hessian, added to in place.
    """
    g, H = neg_logdet_terms(M)
    add_link_terms(G, coef * g, coef * H, grad, hess)


def neg_logdet_terms(M) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Gradient and Hessian of ``-log det M_l`` in each link's standard parameters.

    Returns ``(g, H)``: ``g`` (10 n,) stacks ``-tr(M_l^-1 E_i)``, ``H`` (n, 10, 10) holds
    ``tr(M_l^-1 E_i M_l^-1 E_j)``; :func:`add_link_terms` maps them to the variables.
    """
    n = M.shape[0]
    Li = np.linalg.inv(np.linalg.cholesky(M))  # (n, 4, 4), lower triangular: M^-1 = Li^T Li
    S = (Li[:, None] @ _E @ np.swapaxes(Li, 1, 2)[:, None]).reshape(n, 10, 16)  # Li E_i Li^T
    g = -S[:, :, [0, 5, 10, 15]].sum(axis=2).reshape(10 * n)  # -tr(M^-1 E_i)
    return g, S @ np.swapaxes(S, 1, 2)  # (n, 10, 10): tr(M^-1 E_i M^-1 E_j)


def add_link_terms(G, g, H, grad, hess) -> None:
    """Add a gradient ``g`` (10 n,) and block-diagonal Hessian ``H`` (n, 10, 10) in the links' standard
    parameters to ``grad`` and ``hess`` in the variables (``G`` as in :func:`add_neg_logdet`), in place."""
    n = H.shape[0]
    Gl = G[: 10 * n]
    grad += Gl.T @ g
    hess += Gl.T @ (H @ Gl.reshape(n, 10, -1)).reshape(10 * n, -1)


def trace_gradient(A, G) -> NDArray[np.float64]:
    """The gradient of ``sum_l tr(A_l M_l)`` in the variables (``M_l`` as in :func:`add_neg_logdet`).

    Parameters
    ----------
    A : ndarray, shape (n, 4, 4)
    G : ndarray, shape (m, k), m >= 10 n

    Returns
    -------
    ndarray, shape (k,)
    """
    n = A.shape[0]
    return G[: 10 * n].T @ np.einsum("lab,iba->li", A, _E).reshape(10 * n)


def newton_direction(hess, grad):
    """The Newton step ``-hess^-1 grad``, Jacobi-scaled (entries span many decades); least squares if singular.

    Parameters
    ----------
    hess : ndarray, shape (k, k)
        Positive semidefinite Hessian.
    grad : ndarray, shape (k,)
        Gradient.

    Returns
    -------
    ndarray, shape (k,)
    """
    d = 1.0 / np.sqrt(np.maximum(np.diag(hess), 1e-300))
    scaled = hess * np.outer(d, d)
    try:
        c = scipy.linalg.cho_factor(scaled, check_finite=False)
        step = -d * scipy.linalg.cho_solve(c, d * grad, check_finite=False)
        if not np.all(np.isfinite(step)):
            raise np.linalg.LinAlgError
    except (np.linalg.LinAlgError, ValueError):
        step = -d * np.linalg.lstsq(scaled, d * grad, rcond=1e-14)[0]
    return step


def described_bodies(
    robot,
    cols: ColumnSet,
    phi: ArrayLike,
    *,
    mask: NDArray[np.bool_] | None = None,
    eps: float | ArrayLike = EPS,
    max_iter: int = 200,
) -> tuple[NDArray[np.float64], dict[str, Any]]:
    """The bodies nearest the robot's description among those with the same identified parameters.

    Joint torques determine only combinations of the links' standard parameters (the base parameters):
    in every other direction any body is as good as another for the data, and a vanishing pull toward
    an arbitrary start used to decide, which could put 60 kg on a 0.65 kg link.  Here the description
    decides there: among the physical vectors ``phi`` with the same identified parameters (``P phi``
    fixed, so the prediction of every torque is unchanged to rounding) and ``J_l >= eps_l I``, the one
    that minimises the entropic divergence of every body from its description,

        sum_l  tr(J_l,ref^-1 J_l) - log det(J_l - eps_l I)     (Lee and Wensing's log-det divergence,
                                                                with the margin in the log-det)

    plus, for armature and friction in play, ``((e - e_ref) / e_scale)^2`` with a vanishing barrier at
    their lower bounds.  The divergence is unit-free and treats mass, first and second moments alike:
    a change of a base parameter that could go into a link's mass or its inertia goes where it is
    the smaller change relative to that body, and a direction the data do not see stays at the
    description.  A convex problem in the null-space coordinates, solved by damped Newton steps from
    the feasible ``phi``.

    Parameters
    ----------
    robot : RobotModel
        The robot; its URDF/DH bodies are the description.
    cols : ColumnSet
        The identified parameters.
    phi : array_like, shape (14 n,)
        A physical vector with ``J_l - eps_l I`` positive semidefinite.
    mask : ndarray of bool, shape (p,), optional
        Identified parameters held fixed (default all).
    eps : float or array_like
        Consistency margin per link (kg m^2).
    max_iter : int
        Most Newton steps.

    Returns
    -------
    phi : ndarray, shape (14 n,)
        The physical vector with the same identified parameters, nearest the description.
    info : dict
        ``iterations``, ``directions`` (how many directions the data leave to the description) and
        ``divergence`` (the summed divergence before and after).
    """
    phi = np.asarray(phi, dtype=np.float64).copy()
    free = _free_directions(robot, cols, mask)
    info: dict[str, Any] = {"iterations": 0, "directions": int(free.N.shape[1])}
    if free.N.shape[1] == 0:
        return phi, info
    lb, e_scale = _extra_bounds(free, phi)
    phi = _nudged_inside(phi, free, lb, e_scale)
    div = _divergence(robot, free, phi, lb, e_scale, eps)
    w = np.zeros(free.N.shape[1])
    f_start = div.value(w)
    if not np.isfinite(f_start):  # the start sits on the margin: nothing safe to move
        return phi, info
    w, f, info["iterations"] = _newton(div, w, f_start, max_iter)
    n, e_idx = free.n, free.e_idx
    phi[free.act] = _onto_affine(free, div, w)
    phi[10 * n + e_idx] = np.maximum(phi[10 * n + e_idx], lb)
    info["divergence"] = {"start": f_start, "end": f}
    return phi, info


@dataclass(frozen=True)
class _Free:
    """The parameters in play and the directions the identified parameters leave free in them."""

    n: int
    P: NDArray[np.float64]
    e_idx: NDArray[np.intp]
    act: NDArray[np.intp]
    ref: NDArray[np.float64]
    N: NDArray[np.float64]


def _free_directions(robot, cols: ColumnSet, mask: NDArray[np.bool_] | None) -> _Free:
    """The links' and the extras' entries in play, and a scaled basis of the null space of ``P`` in them."""
    n = cols.n
    mask = np.ones(cols.p, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
    P = cols.P[mask]
    enabled = cols.enabled_extras & np.any(P[:, 10 * n :] != 0, axis=0)
    e_idx = np.flatnonzero(enabled)
    act = np.concatenate([np.arange(10 * n), 10 * n + e_idx])
    ref = np.concatenate([robot.params, robot.armature * enabled[:n], np.zeros(3 * n)])
    D = physical_scale(ref, n)[act]
    Pa = P[:, act] * D
    if Pa.size:
        _, sk, Vkt = np.linalg.svd(Pa, full_matrices=True)
        rank = int(np.sum(sk > 1e-10 * sk[0])) if sk.size and sk[0] > 0 else 0
    else:
        Vkt, rank = np.eye(len(act)), 0
    N = D[:, None] * Vkt[rank:].T  # phi_a = phi_a,0 + N w keeps P phi
    return _Free(n=n, P=P, e_idx=e_idx, act=act, ref=ref, N=N)


def _extra_bounds(free: _Free, phi: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Lower bounds of the extras in play (none for offsets) and their scales."""
    n, e_idx = free.n, free.e_idx
    kinds = [EXTRA_KINDS[e // n] for e in e_idx]
    lb = np.array([-np.inf if k == "offset" else 0.0 for k in kinds])
    e_scale = np.maximum(np.abs(phi[10 * n + e_idx]), 1e-6)
    e_scale = np.maximum(e_scale, 1e-2 * float(e_scale.max(initial=1e-6)))
    return lb, e_scale


def _nudged_inside(
    phi: NDArray[np.float64], free: _Free, lb: NDArray[np.float64], e_scale: NDArray[np.float64]
) -> NDArray[np.float64]:
    """``phi`` with the extras sitting on their bound nudged strictly inside (the start must be)."""
    n, e_idx = free.n, free.e_idx
    bounded = np.isfinite(lb)
    phi = phi.copy()
    e0 = phi[10 * n + e_idx]
    phi[10 * n + e_idx] = np.where(bounded & (e0 <= lb + 1e-9 * e_scale), lb + 1e-9 * e_scale, e0)
    return phi


@dataclass(frozen=True)
class _Divergence:
    """The bodies' divergence from their description (plus the extras' pull and barrier) over the free
    coordinates ``w``: ``phi_a = base + N w``."""

    n: int
    base: NDArray[np.float64]
    N: NDArray[np.float64]
    A: NDArray[np.float64]
    shift: NDArray[np.float64]
    lb: NDArray[np.float64]
    bounded: NDArray[np.bool_]
    e_ref: NDArray[np.float64]
    e_scale: NDArray[np.float64]
    trace_grad: NDArray[np.float64]
    kappa: float = 1e-9  # barrier weight of the extras' bounds (relative to the unit pull)

    def parts(self, w: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The links' pseudo-inertias and the extras at ``w``."""
        n = self.n
        pa = self.base + self.N @ w
        return pseudo_inertia(pa[: 10 * n].reshape(n, 10)), pa[10 * n :]

    def value(self, w: NDArray[np.float64]) -> float:
        """The divergence at ``w`` (inf outside the margins or bounds)."""
        lb, bounded, e_scale, kappa = self.lb, self.bounded, self.e_scale, self.kappa
        Js, e = self.parts(w)
        slack = (e - lb)[bounded]
        if np.any(slack <= 0):
            return np.inf
        out = _EXTRA_PULL * float(np.sum(((e - self.e_ref) / e_scale) ** 2)) - kappa * float(
            np.sum(np.log(slack / e_scale[bounded]))
        )
        try:
            L = np.linalg.cholesky(Js - self.shift)
        except np.linalg.LinAlgError:
            return np.inf
        logdet = 2 * float(np.log(np.diagonal(L, axis1=1, axis2=2)).sum())
        return out + float(np.einsum("lab,lba->", self.A, Js)) - logdet

    def derivatives(self, w: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Gradient and Hessian of the divergence at ``w``."""
        e_scale, kappa = self.e_scale, self.kappa
        Ne = self.N[10 * self.n :]
        Js, e = self.parts(w)
        grad = 2 * _EXTRA_PULL * Ne.T @ ((e - self.e_ref) / e_scale**2)
        hess = 2 * _EXTRA_PULL * (Ne.T / e_scale**2) @ Ne
        slack = (e - self.lb)[self.bounded]
        Nb = Ne[self.bounded]
        grad -= kappa * Nb.T @ (1.0 / slack)
        hess += kappa * (Nb.T / slack**2) @ Nb
        grad += self.trace_grad
        add_neg_logdet(Js - self.shift, self.N, 1.0, grad, hess)
        return grad, hess


def _divergence(
    robot,
    free: _Free,
    phi: NDArray[np.float64],
    lb: NDArray[np.float64],
    e_scale: NDArray[np.float64],
    eps: float | ArrayLike,
) -> _Divergence:
    """The divergence from the described bodies, with ``phi`` (inside the bounds) as ``w = 0``."""
    n, N = free.n, free.N
    eps_l, J_ref_pd = reference_bodies(robot.params, eps)
    A = np.linalg.inv(J_ref_pd)  # (n, 4, 4)
    return _Divergence(
        n=n,
        base=phi[free.act].copy(),
        N=N,
        A=A,
        shift=eps_l[:, None, None] * np.eye(4),
        lb=lb,
        bounded=np.isfinite(lb),
        e_ref=free.ref[10 * n + free.e_idx],
        e_scale=e_scale,
        trace_grad=trace_gradient(A, N),  # the gradient of sum_l tr(A_l J_l): constant
    )


def _newton(
    div: _Divergence, w: NDArray[np.float64], f: float, max_iter: int
) -> tuple[NDArray[np.float64], float, int]:
    """Damped Newton steps from ``w`` (value ``f``): the last point, its value and the steps taken."""
    iterations = 0
    for step_count in range(1, max_iter + 1):
        grad, hess = div.derivatives(w)
        step = newton_direction(hess, grad)
        decrement = float(-grad @ step)
        iterations = step_count
        if decrement <= 1e-10 * max(1.0, abs(f)):
            break
        t, f_new = _line_search(div, w, step, f, decrement)
        if t < 1e-12:
            break
        w, f = w + t * step, f_new
    return w, f, iterations


def _line_search(
    div: _Divergence, w: NDArray[np.float64], step: NDArray[np.float64], f: float, decrement: float
) -> tuple[float, float]:
    """Backtracking (Armijo, 1/4) along ``step``: the step length (below 1e-12: none found) and the value there."""
    t = 1.0
    while True:
        f_new = div.value(w + t * step)
        if f_new <= f - 0.25 * t * decrement:
            break
        t *= 0.5
        if t < 1e-12:
            break
    return t, f_new


def _onto_affine(free: _Free, div: _Divergence, w: NDArray[np.float64]) -> NDArray[np.float64]:
    """The entries in play at ``w``, put back onto the affine set exactly (the null space is numerical:
    rounding of its basis)."""
    Pa = free.P[:, free.act]
    target = Pa @ div.base
    moved = div.base + div.N @ w
    moved += np.linalg.lstsq(Pa, target - Pa @ moved, rcond=None)[0]
    return moved


def link_inertials(standard: ArrayLike) -> list[dict[str, Any]]:
    """Mass, centre of mass and inertia about it of every link, as a URDF ``<inertial>`` takes them.

    Parameters
    ----------
    standard : array_like, shape (10 n,)
        Standard parameters ``[m, mx, my, mz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz]`` per link, about the
        link frame's origin (kg, kg m, kg m^2).

    Returns
    -------
    list of dict
        Per link: ``mass`` (kg), ``com`` (m, link frame), ``inertia_com`` ``[ixx, ixy, ixz, iyy, iyz,
        izz]`` (kg m^2, about the centre of mass, link-frame axes; URDF's order), ``standard`` (the
        10 values given) and ``min_eigenvalue`` of the pseudo-inertia (kg m^2; > 0: a real body).
    """
    p = np.asarray(standard, dtype=np.float64).reshape(-1, 10)
    out = []
    for v in p:
        m = float(v[0])
        c = v[1:4] / m if m > 0 else np.zeros(3)
        Io = np.array([[v[4], v[5], v[7]], [v[5], v[6], v[8]], [v[7], v[8], v[9]]])
        Ic = Io - m * (float(c @ c) * np.eye(3) - np.outer(c, c))
        out.append(
            {
                "mass": m,
                "com": [float(a) for a in c],
                "inertia_com": [
                    float(Ic[0, 0]),
                    float(Ic[0, 1]),
                    float(Ic[0, 2]),
                    float(Ic[1, 1]),
                    float(Ic[1, 2]),
                    float(Ic[2, 2]),
                ],
                "standard": [float(a) for a in v],
                "min_eigenvalue": float(np.linalg.eigvalsh(pseudo_inertia(v)).min()),
            }
        )
    return out


def is_consistent(params: ArrayLike, tol: float = 0.0) -> NDArray[np.bool_]:
    """Whether each link's standard parameters have a positive definite pseudo-inertia.

    Parameters
    ----------
    params : array_like, shape (10 n,)
        Standard parameters.
    tol : float
        Smallest eigenvalue accepted (kg m^2).
    """
    J = pseudo_inertia(np.asarray(params, dtype=np.float64).reshape(-1, 10))
    return np.array([scipy.linalg.eigvalsh(j).min() > tol for j in J])
