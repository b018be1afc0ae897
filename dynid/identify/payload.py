"""What the gripper holds: a payload identified on an identified arm, and the drives' torque constants.

The arm's model stays as it was identified.  The payload is the change ``delta`` of the ten inertial
parameters of the body that carries frame F (default the tool frame), written in F:
``[m, m cx, m cy, m cz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz]`` (kg, kg m, kg m^2 about F's origin, F's axes).
The joint torque it adds is linear in it, ``A(q, dq, ddq) delta``, with ``A`` the link's ten columns
of the regressor moved into F (:func:`frame_transform`), seen through the model's own preprocessing
(filter, decimation, trimming) exactly as its predictions are.  The payload is fitted to what the
arm model leaves of the loaded run::

    b = tau_loaded - arm(loaded)                          without a reference run
    b = [tau_loaded - arm(loaded)] - [tau_ref - arm(ref)]  with the same motion run without the payload

The second form cancels most of what the arm's model gets wrong (an unmodelled effect repeats on the
same motion); the reference is aligned to the loaded run by the lag that best matches their angles.
Per joint, a change of Coulomb and viscous friction and an offset is fitted beside the payload
(friction grows with the load a joint carries; a torque sensor drifts between runs) and projected out.

Which parameters the motion determines is decided in physical units.  Each parameter gets a stated
prior: a point mass at the centre of mass (no inertia about it), with a standard deviation of one
scale unit, the payload's mass ``M`` times a length of :data:`LENGTH` to the power it carries (``M``,
``M L``, ``M L^2``).  The data's information is added to it, and a parameter is *determined* when its
marginal posterior standard deviation (every other parameter free) is below :data:`DETERMINED_STD` of
its prior's: the data, not the stated default, decided it.  An undetermined one is reported null, never
guessed from noise, and the model with the payload keeps the default there.  (The prior's pull on a
determined parameter is at most 1 % of the data's.  A truncation of the weak directions instead biased
the mass by the default's error in the centre of mass it is correlated with: 21 % on a 0.25 kg
payload of the Panda at field noise.)  The estimate is then made physically consistent (the payload's
pseudo-inertia positive semi-definite: a real body, Wensing et al.) by the nearest such body in the
fit's own metric.  Standard deviations: the posterior covariance, each joint's residual variance
times its long-run correlation factor (a filtered or coloured residual is worth fewer samples than it
has), carried to the centre of mass and the inertia about it by the delta method.

With the payload's mass known (``mass=``), the torque constants are calibrated from it as Gautier and
Mamedov do: each joint's measured torque is ``g_j`` times the true one, the payload's torque fixes the
scale through its known mass, and ``g`` and the other nine parameters are fitted together (alternating
least squares, then the Gauss-Newton covariance).

Still poses (no motion at all) are the same problem with the inertia columns zero: the mass and the
centre of mass come out, and the inertia is reported undetermined.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares

from dynid._progress import say
from dynid._rest import direction
from dynid.data.dataset import Dataset
from dynid.data.preparation import Prepared
from dynid.data.preprocess import resample_uniform
from dynid.exceptions import DataError, UsageError
from dynid.identify.columns import CHUNK_SAMPLES, compiled_base_regressor
from dynid.identify.consistent import pseudo_inertia
from dynid.identify.estimators import long_run_factor
from dynid.symbolic.bodies import (
    PayloadFrame,
    body_figures,
    frame_transform,
    inertia_matrix,
    payload_frame,
    point_mass,
)

__all__ = [
    "DETERMINED_STD",
    "LENGTH",
    "PARAM_NAMES",
    "PayloadResult",
    "attach_payload",
    "identify_payload",
    "payload_problem",
]

PARAM_NAMES = ("m", "mx", "my", "mz", "Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz")
"""The payload's ten parameters in frame F (Pinocchio's order; the inertia about F's origin)."""

LENGTH = 0.1
"""Length scale (m) of a payload: a centre of mass or a radius of gyration of about 10 cm."""

DETERMINED_STD = 0.1
"""A parameter is determined when its posterior standard deviation is below this fraction of its prior's."""

_MIN_MASS_SCALE = 0.05  # kg: the mass scale of the determinacy test is at least this
_ALIGN_TOLERANCE = 0.05  # the aligned reference's angles may differ by this fraction of each joint's range
_GAIN_ITERATIONS = 200


# ---------------------------------------------------------------------------- the columns
def _payload_columns(model, prep: Prepared, link_to_params: NDArray[np.float64]) -> NDArray[np.float64]:
    """``A``: (m, n, 10) torque of each unit payload parameter at the kept rows, filtered as the torque."""
    cols = model.columns
    nb = cols.n_base
    B = cols.P[:nb] @ link_to_params  # (n_b, 10): base parameters moved by each unit payload parameter
    M = len(prep.q)
    out = np.empty((M, cols.n, 10))
    for a in range(0, M, CHUNK_SAMPLES):
        s = slice(a, min(a + CHUNK_SAMPLES, M))
        out[s] = compiled_base_regressor(model.robot, prep.q[s], prep.dq[s], prep.ddq[s]) @ B
    return prep.filter(out)[prep.rows]


def _nuisance(prep: Prepared) -> NDArray[np.float64]:
    """(m, n, 3): per joint, a change of Coulomb friction, viscous friction and offset, filtered."""
    dq = prep.dq
    N = np.stack([direction(dq), dq, np.ones_like(dq)], axis=2)
    return prep.filter(N)[prep.rows]


def _residual(model, ds: Dataset, prep: Prepared) -> NDArray[np.float64]:
    parts = model.predict_parts(ds, prep=prep)
    return prep.tau_reference - (parts["link"] + parts["friction"] + parts["gmm"])


def payload_problem(
    model, ds: Dataset, place: PayloadFrame
) -> tuple[Prepared, NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """The linear problem of a payload on one run, at the model's kept samples.

    Parameters
    ----------
    model : IdentifiedModel
        The arm without the payload.
    ds : Dataset
        A run of it with the payload.
    place : PayloadFrame
        Where the payload is written.

    Returns
    -------
    prep : Prepared
        The run prepared as the model's identification data were.
    A : ndarray, shape (m, n, 10)
        The torque of each unit payload parameter (:data:`PARAM_NAMES`, in F), filtered as the torque.
    N : ndarray, shape (m, n, 3)
        Per joint, a change of Coulomb and viscous friction and an offset (each acts on its own joint).
    b : ndarray, shape (m, n)
        What the arm model leaves of the measured torque (N m).
    """
    prep = model.prepare(ds)
    A = _payload_columns(model, prep, _link_columns(model, place, frame_transform(place)))
    return prep, A, _nuisance(prep), _residual(model, ds, prep)


# ---------------------------------------------------------------------------- the reference run
def _align(loaded: Prepared, ref: Prepared) -> float:
    """The lag (s) with ``q_ref(t - t0_loaded + lag) ~ q_loaded(t)``: the reference's time of each loaded sample.

    Both runs' angles are resampled on a uniform grid at the loaded run's rate (a still-pose routine's
    log has gaps between its poses), each joint scaled by its range, and cross-correlated; the peak is
    refined to a fraction of a sample.  Runs logged on the same clock with the same angles need none.
    """
    tl, tr = loaded.t - loaded.t[0], ref.t - ref.t[0]
    if len(tl) == len(tr) and np.allclose(tl, tr) and np.allclose(loaded.q, ref.q, atol=1e-3):
        return 0.0
    from scipy.signal import correlate

    fs = loaded.fs
    ql = resample_uniform(tl, loaded.q, dt=1.0 / fs)[1]
    qr = resample_uniform(tr, ref.q, dt=1.0 / fs)[1]
    span = np.maximum(np.ptp(ql, axis=0), 1e-9)
    a = (ql - ql.mean(axis=0)) / span
    b = (qr - qr.mean(axis=0)) / span
    score = sum(correlate(b[:, j], a[:, j], mode="full", method="fft") for j in range(a.shape[1]))
    k = int(np.argmax(score))
    shift = float(k - (len(a) - 1))  # samples: b[i + shift] matches a[i]
    if 0 < k < len(score) - 1:  # parabolic refinement to a fraction of a sample
        y0, y1, y2 = score[k - 1], score[k], score[k + 1]
        den = y0 - 2 * y1 + y2
        if den < 0:
            shift += 0.5 * (y0 - y2) / den
    return shift / fs


def _reference_residual(
    model, loaded: Prepared, ref_ds: Dataset, ref: Prepared
) -> tuple[NDArray[np.float64], NDArray[np.bool_], float]:
    """The reference's residual at the loaded run's kept samples, the samples it covers, and the lag (s)."""
    lag = _align(loaded, ref)
    r_ref = _residual(model, ref_ds, ref)
    t_ref = ref.t[ref.rows] - ref.t[0]
    t_at = loaded.t[loaded.rows] - loaded.t[0] + lag
    inside = (t_at >= t_ref[0]) & (t_at <= t_ref[-1])
    if inside.sum() < 0.5 * len(t_at):
        raise DataError(
            f"the reference run covers {100 * inside.mean():.0f} % of the loaded run once aligned (lag {lag:.3g} s); "
            "give the same motion run without the payload, at least as long, or leave --reference out"
        )
    q_ref = np.stack([np.interp(t_at, ref.t - ref.t[0], ref.q[:, j]) for j in range(ref.q.shape[1])], axis=1)
    q_l = loaded.q[loaded.rows]
    span = np.maximum(np.ptp(q_l, axis=0), 1e-3)
    off = np.sqrt(np.mean((q_ref[inside] - q_l[inside]) ** 2, axis=0)) / span
    if off.max() > _ALIGN_TOLERANCE:
        j = int(np.argmax(off))
        raise DataError(
            f"the reference run does not follow the loaded run's motion: joint {j + 1}'s angles differ by "
            f"{100 * off[j]:.0f} % of its range after the best alignment (lag {lag:.3g} s); give the same trajectory "
            "run without the payload, or leave --reference out"
        )
    r = np.stack([np.interp(t_at, t_ref, r_ref[:, j]) for j in range(r_ref.shape[1])], axis=1)
    return r, inside, lag


# ---------------------------------------------------------------------------- the fit
@dataclass(frozen=True)
class _System:
    """Per joint, the payload columns and the target with the joint's nuisance projected out."""

    A: NDArray[np.float64]  # (m, n, 10)
    b: NDArray[np.float64]  # (m, n)
    N: NDArray[np.float64]  # (m, n, k) nuisance, k may be 0

    def projected(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        A, b = self.A.copy(), self.b.copy()
        if self.N.shape[2]:
            for j in range(A.shape[1]):
                Q, _ = np.linalg.qr(self.N[:, j, :])
                A[:, j] -= Q @ (Q.T @ A[:, j])
                b[:, j] -= Q @ (Q.T @ b[:, j])
        return A, b

    def nuisance_fit(self, delta: NDArray[np.float64]) -> NDArray[np.float64]:
        """(n, k) nuisance coefficients given the payload."""
        n, k = self.A.shape[1], self.N.shape[2]
        out = np.zeros((n, k))
        for j in range(n):
            if k:
                out[j] = np.linalg.lstsq(self.N[:, j], self.b[:, j] - self.A[:, j] @ delta, rcond=None)[0]
        return out


def _information(A: NDArray[np.float64], w: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.einsum("mjk,j,mjl->kl", A, w, A)


def _scales(mass: float) -> NDArray[np.float64]:
    M = max(abs(mass), _MIN_MASS_SCALE)
    return np.array([M, *(3 * [M * LENGTH]), *(6 * [M * LENGTH**2])])


@dataclass(frozen=True)
class _Solution:
    x: NDArray[np.float64]
    cov: NDArray[np.float64]
    determined: NDArray[np.bool_]


def _posterior(
    F: NDArray[np.float64], g: NDArray[np.float64], x0: NDArray[np.float64], scale: NDArray[np.float64]
) -> _Solution:
    """The data (information ``F``, ``g = A' W b``) with the prior ``N(x0, diag(scale)^2)``.

    In scaled units ``z = (x - x0) / scale`` the prior is the identity; the posterior precision is
    ``D F D + I``.  Determined: a marginal posterior standard deviation below :data:`DETERMINED_STD`.
    """
    D = np.diag(scale)
    P = D @ F @ D + np.eye(len(F))
    cov_s = np.linalg.inv(P)
    z = cov_s @ (D @ (g - F @ x0))
    determined = np.sqrt(np.maximum(np.diag(cov_s), 0.0)) < DETERMINED_STD
    return _Solution(x0 + D @ z, D @ cov_s @ D, determined)


def _nearest_body(
    x: NDArray[np.float64], H: NDArray[np.float64], scale: NDArray[np.float64]
) -> NDArray[np.float64]:
    """The physically consistent parameters (pseudo-inertia PSD) nearest ``x`` in the metric ``H``.

    ``J = L L^T`` with ``L`` lower triangular (10 entries, as many as the parameters), fitted by
    least squares; ``H`` gets a small ridge in ``scale`` units so that unseen directions stay put.
    """
    if np.linalg.eigvalsh(pseudo_inertia(x)).min() >= -1e-12 * max(abs(x[0]), 1e-9):
        return x
    D = np.diag(1.0 / scale)
    Hs = H + 1e-6 * max(np.trace(np.diag(scale) @ H @ np.diag(scale)) / 10.0, 1e-12) * D @ D
    R = np.linalg.cholesky(Hs).T
    E = pseudo_inertia(np.eye(10)).reshape(10, 16)  # J = x @ E
    Einv = np.linalg.pinv(E)  # (16, 10): x = vec(J) @ Einv
    rows, cols = np.tril_indices(4)

    def params(entries: NDArray[np.float64]) -> NDArray[np.float64]:
        L = np.zeros((4, 4))
        L[rows, cols] = entries
        return (L @ L.T).reshape(16) @ Einv

    w, U = np.linalg.eigh(pseudo_inertia(x))
    J0 = (U * np.maximum(w, 1e-6 * max(w.max(), 1e-12))) @ U.T
    l0 = np.linalg.cholesky(J0)[rows, cols]
    fit = least_squares(lambda e: R @ (params(e) - x), l0, method="lm", xtol=1e-14, ftol=1e-14, max_nfev=2000)
    return params(fit.x)


def _inertia_resolved(
    x: NDArray[np.float64], cov: NDArray[np.float64], determined: NDArray[np.bool_]
) -> NDArray[np.bool_]:
    """An inertia entry counts as determined only if its standard deviation is also within
    :data:`DETERMINED_STD` of the payload's own largest principal moment (about its centre of mass).

    The prior's scale is a 10 cm body: a compact payload's inertia (a 3 kg cylinder of 3 cm radius:
    0.0017 kg m^2 at most) can be "determined" against it with a standard deviation twice its size.
    """
    moments = np.linalg.eigvalsh(inertia_matrix(body_figures(x)[4:]))
    largest = max(float(moments.max()), 1e-12)
    std = np.sqrt(np.maximum(np.diag(cov), 0.0))
    out = determined.copy()
    out[4:] &= std[4:] < DETERMINED_STD * largest
    return out


def _weights(r: NDArray[np.float64]) -> NDArray[np.float64]:
    var = np.mean(r**2, axis=0)
    floor = 1e-12 * max(float(var.max()), 1e-300)
    return 1.0 / np.maximum(var, floor)


def _jacobian(f, x: NDArray[np.float64], scale: NDArray[np.float64]) -> NDArray[np.float64]:
    h = 1e-6 * scale
    cols = []
    for i in range(len(x)):
        e = np.zeros_like(x)
        e[i] = h[i]
        cols.append((f(x + e) - f(x - e)) / (2 * h[i]))
    return np.stack(cols, axis=1)


def _fit(system: _System, kappa_floor: float, *, pooled: bool) -> tuple[_Solution, NDArray[np.float64]]:
    """The payload with its covariance and determinacy, and the joints' weights.

    Each joint is weighted by ``1 / (s_j^2 kappa_j)``: its residual variance times its long-run
    correlation factor, so the information counts a filtered or coloured residual's samples at what
    they are worth and ``F^-1`` is the covariance.  ``pooled``: one weight for all joints, their mean
    ``s_j^2 kappa_j``.  That is the rule without a reference run, where the residual is mostly the arm
    model's own error, which follows the motion (and so the payload's columns) rather than noise:
    weighting each joint by its size then trusts most the joints whose torque is smallest, where that
    error is largest beside the payload's torque (measured: 2-4x the centre-of-mass error of equal
    weights on the UR5; with a reference run, per-joint weights gain 3-10x).  Three passes decide the
    weights and the mass scale (and the default of the undetermined directions, a point mass at the
    centre of mass).
    """
    A, b = system.projected()
    n = A.shape[1]
    v = np.ones(n) / kappa_floor
    sol = None
    for _ in range(3):  # weights from the residual, mass scale from the estimate
        F, g = _information(A, v), np.einsum("mjk,j,mj->k", A, v, b)
        first = _posterior(F, g, np.zeros(10), _scales(1.0))
        scale = _scales(first.x[0])
        sol = _posterior(F, g, point_mass(first.x), scale)
        r = b - A @ sol.x
        kappa, _ = long_run_factor(r, kappa_floor)
        v = _weights(r) / kappa
        if pooled:
            v = np.full(n, 1.0 / float(np.mean(1.0 / v)))
    F, g = _information(A, v), np.einsum("mjk,j,mj->k", A, v, b)
    scale = _scales(sol.x[0])
    first = _posterior(F, g, point_mass(sol.x), scale)
    sol = _posterior(F, g, point_mass(first.x), scale)
    return sol, v


# ---------------------------------------------------------------------------- result
@dataclass(frozen=True)
class PayloadResult:
    """An identified payload (and, with its mass known, the drives' torque constants).

    Attributes
    ----------
    frame : PayloadFrame
    params : ndarray, shape (10,)
        The payload in F (:data:`PARAM_NAMES`), physically consistent; undetermined directions hold the
        default (a point mass at the centre of mass).
    cov : ndarray, shape (10, 10)
        Their covariance (zero along undetermined directions).
    determined : ndarray of bool, shape (10,)
    rms_before, rms_after : ndarray, shape (n,)
        The arm model's error on the loaded run (N m), without and with the payload attached.
    friction_change : ndarray, shape (n, 3)
        Coulomb (N m), viscous (N m s/rad) and offset (N m) change per joint fitted beside it.
    reference : str or None
        The reference run (None: the model's prediction stood in).
    lag : float or None
        The reference's alignment (s).
    samples : int
    gains, gains_std : ndarray, shape (n,), or None
        Drive gains (measured / true torque) from the known mass, and their standard deviations.
    gains_determined : ndarray of bool, or None
    mass_given : float or None
    free_mass, free_mass_std : float
        The mass fitted with the gains at 1 (with a known mass, its ratio to it is the common gain).
    notes : tuple of str
    t : ndarray, shape (m,), optional
        Times (s) of the loaded run's samples used.
    residual : ndarray, shape (m, n), optional
        The arm model's error on them before the payload (N m), measured minus predicted.
    torque : ndarray, shape (m, n), optional
        The payload's torque there (N m): ``residual - torque`` is the error after.
    """

    frame: PayloadFrame
    params: NDArray[np.float64]
    cov: NDArray[np.float64]
    determined: NDArray[np.bool_]
    rms_before: NDArray[np.float64]
    rms_after: NDArray[np.float64]
    friction_change: NDArray[np.float64]
    reference: str | None
    lag: float | None
    samples: int
    gains: NDArray[np.float64] | None = None
    gains_std: NDArray[np.float64] | None = None
    gains_determined: NDArray[np.bool_] | None = None
    mass_given: float | None = None
    free_mass: float = math.nan
    free_mass_std: float = math.nan
    notes: tuple[str, ...] = ()
    t: NDArray[np.float64] | None = None
    residual: NDArray[np.float64] | None = None
    torque: NDArray[np.float64] | None = None

    @property
    def std(self) -> NDArray[np.float64]:
        """Standard deviation of each of the ten parameters (0 where undetermined)."""
        return np.sqrt(np.maximum(np.diag(self.cov), 0.0))

    def _body(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Mass, com, inertia about the com (the ten ``body_figures``) and their standard deviations."""
        x = self.params
        J = _jacobian(body_figures, x, _scales(x[0]))
        return body_figures(x), np.sqrt(np.maximum(np.diag(J @ self.cov @ J.T), 0.0))

    @property
    def mass(self) -> float:
        return float(self.params[0])

    @property
    def com(self) -> NDArray[np.float64]:
        """Centre of mass in F (m)."""
        return self._body()[0][1:4]

    @property
    def inertia(self) -> NDArray[np.float64]:
        """Inertia about the centre of mass, F's axes (kg m^2)."""
        return inertia_matrix(self._body()[0][4:])

    @property
    def link_params(self) -> NDArray[np.float64]:
        """The payload as a change of the carrying link's standard parameters (its joint frame)."""
        return frame_transform(self.frame) @ self.params

    def figures(self) -> dict[str, Any]:
        """The JSON figures: ``mass``, ``mass_std``, ``com``, ``com_std``, ``inertia``, ``inertia_std``,
        ``frame``, ``determined``, ``drive_gains`` and the loaded run's error before and after.

        A figure the motion did not determine is ``null`` (the mass, a centre-of-mass coordinate, an
        inertia entry), never a number made up from noise.
        """
        v, s = self._body()
        d = self.determined
        com_ok = d[0] & d[1:4]
        inertia_ok = d[4:] & bool(d[0]) & bool(com_ok.all())

        def val(ok, a, b):
            return float(a) if ok else None

        mat = inertia_matrix(np.where(inertia_ok, v[4:], np.nan))
        mat_s = inertia_matrix(np.where(inertia_ok, s[4:], np.nan))

        def nested(M):
            return [[None if math.isnan(a) else float(a) for a in row] for row in M]

        gains = None
        if self.gains is not None:
            assert self.gains_std is not None and self.gains_determined is not None
            gains = {
                "gain": [
                    float(g) if ok else None for g, ok in zip(self.gains, self.gains_determined, strict=True)
                ],
                "std": [
                    float(g) if ok else None
                    for g, ok in zip(self.gains_std, self.gains_determined, strict=True)
                ],
                "determined": [bool(ok) for ok in self.gains_determined],
                "mass_given": self.mass_given,
                "common": self.free_mass / self.mass_given if self.mass_given else None,
                "meaning": "measured torque / true torque per joint; divide a joint's measured torque (and its "
                "arm model's prediction) by its gain for newton-metres; a gain common to all joints scales every "
                "identified mass and inertia of the arm by 1 / gain",
            }
        names = list(PARAM_NAMES)
        return {
            "frame": self.frame.name,
            "link": int(self.frame.link + 1),
            "mass": val(d[0], v[0], s[0]),
            "mass_std": val(d[0], s[0], None),
            "com": [val(ok, a, None) for ok, a in zip(com_ok, v[1:4], strict=True)],
            "com_std": [val(ok, a, None) for ok, a in zip(com_ok, s[1:4], strict=True)],
            "inertia": nested(mat),
            "inertia_std": nested(mat_s),
            "determined": {k: bool(ok) for k, ok in zip(names, d, strict=True)},
            "params": {k: float(a) for k, a in zip(names, self.params, strict=True)},
            "params_std": {k: float(a) for k, a in zip(names, self.std, strict=True)},
            "drive_gains": gains,
            "mass_free": float(self.free_mass),
            "mass_free_std": float(self.free_mass_std),
            "rms_before": [float(a) for a in self.rms_before],
            "rms_after": [float(a) for a in self.rms_after],
            "friction_change": {
                "coulomb": [float(a) for a in self.friction_change[:, 0]],
                "viscous": [float(a) for a in self.friction_change[:, 1]],
                "offset": [float(a) for a in self.friction_change[:, 2]],
            },
            "reference": self.reference,
            "lag_s": self.lag,
            "samples": int(self.samples),
            "notes": list(self.notes),
        }


# ---------------------------------------------------------------------------- entry point
def identify_payload(
    model,
    loaded: Dataset,
    *,
    reference: Dataset | None = None,
    frame: str | None = None,
    mass: float | None = None,
    friction: bool = True,
) -> PayloadResult:
    """Identify the payload at frame F from a run with it, the arm's model held fixed.

    Parameters
    ----------
    model : IdentifiedModel
        The arm without the payload.
    loaded : Dataset
        A run with the payload (any motion; still poses give the mass and centre of mass).
    reference : Dataset, optional
        The same motion run without the payload: the difference cancels most of what the arm's model
        gets wrong.  Without it, the model's prediction stands in.
    frame : str, optional
        The frame F (a frame of the robot's description); default the tool frame.
    mass : float, optional
        The payload's known mass (kg): then the drives' torque constants are calibrated from it.
    friction : bool
        Fit a per-joint change of Coulomb and viscous friction and an offset beside the payload.

    Returns
    -------
    PayloadResult

    Raises
    ------
    UsageError
        A non-positive or non-finite ``mass``, an unknown frame.
    DataError
        A reference run that is not the loaded run's motion.
    """
    if mass is not None and not (math.isfinite(mass) and mass > 0):
        raise UsageError(f"--mass is {mass}; give the payload's known mass in kg (> 0)")
    place = payload_frame(model.robot, frame)
    say(f"the payload's columns on the loaded run ({len(loaded.t)} samples)")
    prep, A, N, r_loaded = payload_problem(model, loaded, place)
    b = r_loaded.copy()
    keep = np.ones(len(b), dtype=bool)
    lag = None
    notes: list[str] = []
    if reference is not None:
        say("aligning the reference run and predicting it with the arm's model")
        ref_prep = model.prepare(reference)
        r_ref, keep, lag = _reference_residual(model, prep, reference, ref_prep)
        b = b - np.where(keep[:, None], r_ref, 0.0)
    if not friction:
        N = N[:, :, :0]
    system = _System(A[keep], b[keep], N[keep])
    say("fitting the payload")
    sol, v = _fit(system, prep.noise_correlation, pooled=reference is None)
    A_p, _ = system.projected()
    F = _information(A_p, v)
    x = _nearest_body(sol.x, F, _scales(sol.x[0]))
    moved = float(np.sqrt(max((x - sol.x) @ F @ (x - sol.x), 0.0)))
    if moved > 1.0:
        notes.append(
            f"the least-squares payload is no physical body (its pseudo-inertia is not positive semi-definite); the "
            f"nearest body is reported, {moved:.3g} standard deviations away in the fit's own metric"
        )
    sol = dataclasses.replace(sol, determined=_inertia_resolved(x, sol.cov, sol.determined))
    if not sol.determined.all():
        missing = [k for k, ok in zip(PARAM_NAMES, sol.determined, strict=True) if not ok]
        notes.append(
            f"the motion does not determine {', '.join(missing)}: they are reported null, and the model with "
            "the payload keeps a point mass at the centre of mass in those directions; a motion that turns the "
            "payload about every axis (dynid excite --payload) determines them"
        )
    fric = system.nuisance_fit(x) if friction else np.zeros((model.robot.n, 3))
    rms_before = np.sqrt(np.mean(r_loaded[keep] ** 2, axis=0))
    rms_after = np.sqrt(np.mean((r_loaded[keep] - A[keep] @ x) ** 2, axis=0))
    free_std = float(math.sqrt(max(sol.cov[0, 0], 0.0)))
    result = PayloadResult(
        frame=place,
        params=x,
        cov=sol.cov,
        determined=sol.determined,
        rms_before=rms_before,
        rms_after=rms_after,
        friction_change=fric,
        reference=None if reference is None else "the reference run",
        lag=lag,
        samples=int(keep.sum()),
        free_mass=float(x[0]),
        free_mass_std=free_std,
        notes=tuple(notes),
        t=prep.t[prep.rows][keep],
        residual=r_loaded[keep],
        torque=A[keep] @ x,
    )
    if mass is not None:
        say("calibrating the drive gains from the known mass")
        result = _with_gains(result, system, v, float(mass))
        assert result.gains is not None
        torque = (A[keep] @ result.params) * result.gains  # in the drives' units, as the arm model's
        result = dataclasses.replace(
            result, torque=torque, rms_after=np.sqrt(np.mean((r_loaded[keep] - torque) ** 2, axis=0))
        )
    return result


def _link_columns(model, place: PayloadFrame, T: NDArray[np.float64]) -> NDArray[np.float64]:
    """(14 n, 10): the physical parameter vector's change for each unit payload parameter in F."""
    n = model.robot.n
    out = np.zeros((14 * n, 10))
    out[10 * place.link : 10 * place.link + 10] = T
    return out


def _with_gains(result: PayloadResult, system: _System, w: NDArray[np.float64], mass: float) -> PayloadResult:
    """Drive gains and the payload's other nine parameters with its mass known (alternating least squares)."""
    A, b = system.projected()
    n = A.shape[1]
    x = result.params.copy()
    if x[0] > 0:
        x[1:] *= mass / x[0]  # the same body scaled to the known mass: a start near the answer
    x[0] = mass
    g = np.ones(n)
    scale = _scales(mass)
    for _ in range(_GAIN_ITERATIONS):
        tau = A @ x  # (m, n) the payload's true torque
        den = np.sum(tau**2, axis=0)
        g_new = np.where(den > 0, np.sum(tau * b, axis=0) / np.where(den > 0, den, 1.0), 1.0)
        Ag = A * g_new[None, :, None]
        F = _information(Ag, w)
        rhs = np.einsum("mjk,j,mj->k", Ag, w, b) - F[:, 0] * mass
        # the prior: the point mass at the current centre of mass
        sub = _posterior(F[1:, 1:], rhs[1:], point_mass(x)[1:], scale[1:])
        x_new = np.concatenate([[mass], sub.x])
        done = np.allclose(g_new, g, rtol=1e-10, atol=1e-12) and np.allclose(x_new, x, rtol=1e-10, atol=1e-14)
        g, x = g_new, x_new
        if done:
            break
    # Gauss-Newton covariance of (g, the nine) from the Jacobian of b - g * (A x)
    tau = A @ x
    m = A.shape[0]
    J = np.zeros((m, n, n + 9))
    for j in range(n):
        J[:, j, j] = tau[:, j]
        J[:, j, n:] = g[j] * A[:, j, 1:]
    Fk = np.einsum("mja,j,mjb->ab", J, w, J)
    prior = np.concatenate([np.full(n, 1.0), scale[1:]])  # a gain's prior: 1 +- 1, the nine's as above
    cov = np.linalg.inv(Fk + np.diag(1.0 / prior**2))
    g_std = np.sqrt(np.maximum(np.diag(cov)[:n], 0.0))
    g_ok = (g_std < 0.05 * np.abs(g)) & (np.sum(tau**2, axis=0) > 0)
    x = _nearest_body(x, _information(A * g[None, :, None], w), scale)
    x[0] = mass
    full_cov = np.zeros((10, 10))
    full_cov[1:, 1:] = cov[n:, n:]
    determined = _inertia_resolved(x, full_cov, np.concatenate([[True], sub.determined]))
    notes = list(result.notes)
    bad = [str(j + 1) for j in np.flatnonzero(~g_ok)]
    if bad:
        notes.append(
            f"the payload loads joint(s) {', '.join(bad)} too little to calibrate their gains (standard deviation "
            "above 5 %): they are reported null"
        )
    return dataclasses.replace(
        result,
        params=x,
        cov=full_cov,
        determined=determined,
        gains=g,
        gains_std=g_std,
        gains_determined=g_ok,
        mass_given=mass,
        notes=tuple(notes),
    )


def attach_payload(model, payload: PayloadResult):
    """The arm model with the payload attached: its link parameters moved by the payload.

    The base parameters change by exactly the payload's (``x += P delta``); a model with consistent
    link bodies gets the payload added to the carrying link's body; ``info["payload"]`` keeps the
    payload's figures so that :mod:`dynid.simmodel` can write it as a link of its own.

    Parameters
    ----------
    model : IdentifiedModel
    payload : PayloadResult
    """
    if payload.frame.link >= model.robot.n:
        raise UsageError("the payload's link is not a link of this model")
    delta = _link_columns(model, payload.frame, frame_transform(payload.frame))
    P = model.columns.P
    x = model.params + P @ delta @ payload.params
    Pd = P @ delta
    cov = model.cov + Pd @ payload.cov @ Pd.T
    info = dict(model.info)
    info.pop("data_sha256", None)  # a model with a payload was not identified on the unloaded recording alone
    info.pop("data_parts_sha256", None)
    consistency = info.get("consistency")
    if consistency and "standard_params" in consistency:
        phi = np.asarray(consistency["standard_params"], dtype=np.float64).reshape(-1).copy()
        k = payload.frame.link
        phi[10 * k : 10 * k + 10] += payload.link_params
        info["consistency"] = {**consistency, "standard_params": phi.tolist()}
    seen = info.get("torque_range")
    if seen is not None and payload.torque is not None and len(payload.torque):
        # the training range widened by what the payload adds, so that predicting a loaded run is no
        # extrapolation
        lo, hi = np.asarray(seen, dtype=np.float64).T
        lo = np.minimum(lo, lo + payload.torque.min(axis=0))
        hi = np.maximum(hi, hi + payload.torque.max(axis=0))
        info["torque_range"] = np.stack([lo, hi], axis=1).tolist()
    info["payload"] = {
        **payload.figures(),
        "link_params": [float(a) for a in payload.link_params],
        "frame_rotation": payload.frame.rotation.tolist(),
        "frame_translation": payload.frame.translation.tolist(),
    }
    return dataclasses.replace(model, params=x, cov=cov, info=info)
