"""Layer 2: joint friction models fitted to ``F_est = tau - tau_link``, in scikit-learn style.

Each model fits one joint: ``model.fit(dq, F)`` with ``dq`` (m,) in rad/s and ``F`` (m,) in N m,
then ``model.predict(dq) -> F``.  :class:`FrictionLayer` fits one model per joint on (m, n) arrays.

=============  ==================================================================================
``none``       no friction
``linear``     ``fc sign(dq) + fv dq + fo`` (Coulomb, viscous, offset; fc, fv >= 0)
``seed``       the paper's model (METHOD.md section 2), see :class:`SeedFriction`
``stribeck``   ``sign(dq) (fc + (fs - fc) exp(-(dq / vs)^2)) + fv dq + fo``
``sigmoid``    ``phi1 / (1 + exp(-phi2 (dq + phi3))) - phi1 / (1 + exp(-phi2 phi3))`` (Gaz et al. 2019,
               Franka Emika Panda)
=============  ==================================================================================

Models linear in their coefficients for a fixed shape parameter (``lambda`` of the seed model, ``vs``
of Stribeck) are fitted by a search over that parameter with a bounded linear least squares inside;
each inner problem is first compressed by QR (m x k -> k x k), so a search over many candidates on
hundreds of thousands of samples stays fast.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import least_squares, lsq_linear, nnls
from scipy.special import expit

from dynid.exceptions import DataError, ModelFileError, UsageError
from dynid.identify._threads import one_blas_thread

__all__ = [
    "FRICTION_MODELS",
    "FrictionLayer",
    "LinearFriction",
    "NoFriction",
    "SeedFriction",
    "SigmoidFriction",
    "StribeckFriction",
    "friction_model",
]

_SEARCH_SAMPLES = 10_000  # samples used in shape-parameter searches (evenly strided)


def _check_pair(
    dq: ArrayLike, F: ArrayLike, need: int, name: str
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    dq = np.asarray(dq, dtype=np.float64).ravel()
    F = np.asarray(F, dtype=np.float64).ravel()
    if dq.shape != F.shape:
        raise DataError(
            f"dq has {dq.size} values but F has {F.size}; give one friction torque (N m) per velocity sample"
        )
    for label, a in (("dq", dq), ("F", F)):
        if not np.all(np.isfinite(a)):
            raise DataError(
                f"{label} holds a non-finite value at sample {int(np.argmax(~np.isfinite(a)))}; drop or "
                "interpolate that sample"
            )
    if dq.size < need:
        raise DataError(
            f"the {name} friction model needs at least {need} samples; got {dq.size}: record longer"
        )
    return dq, F


def _compress(
    A: NDArray[np.float64], b: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
    """(R, Q^T b, ||b||^2 - ||Q^T b||^2): ``||A x - b||^2 = ||R x - Q^T b||^2 + rest``."""
    R = scipy.linalg.qr(np.column_stack([A, b]), mode="r", check_finite=False)[0]
    k = A.shape[1]
    R = R[: k + 1]
    if R.shape[0] < k + 1:
        R = np.vstack([R, np.zeros((k + 1 - R.shape[0], k + 1))])
    return R[:k, :k], R[:k, k], float(R[k, k] ** 2)


def _stride(m: int, limit: int = _SEARCH_SAMPLES) -> slice:
    return slice(None, None, max(1, -(-m // limit)))


class _Friction:
    """Common parts of the single-joint friction models."""

    name: ClassVar[str] = ""
    coef_names: ClassVar[tuple[str, ...]] = ()

    def __repr__(self) -> str:
        return f"{type(self).__name__}()"

    def _check_fitted(self) -> None:
        if not hasattr(self, "coef_"):
            raise UsageError(f"this {type(self).__name__} is not fitted yet; call fit(dq, F) first")

    def predict(self, dq: ArrayLike) -> NDArray[np.float64]:
        """Friction torque (N m) at velocities ``dq`` (rad/s), same shape as ``dq``.

        Parameters
        ----------
        dq : array_like
            Joint velocity (rad/s).
        """
        self._check_fitted()
        dq = np.asarray(dq, dtype=np.float64)
        return self._eval(dq.ravel()).reshape(dq.shape)

    def _eval(self, dq: NDArray[np.float64]) -> NDArray[np.float64]:
        raise NotImplementedError

    def to_dict(self) -> dict[str, Any]:
        """``{"model": name, "coef": {name: value}}`` (JSON-ready)."""
        self._check_fitted()
        return {
            "model": self.name,
            "coef": {k: float(v) for k, v in zip(self.coef_names, self.coef_, strict=True)},
        }

    def _set(self, coef: ArrayLike, rss: float, m: int) -> None:
        self.coef_ = np.asarray(coef, dtype=np.float64)
        self.rms_ = float(np.sqrt(max(rss, 0.0) / max(m, 1)))


class NoFriction(_Friction):
    """No friction: predicts zero."""

    name = "none"
    coef_names = ()

    @one_blas_thread
    def fit(self, dq: ArrayLike, F: ArrayLike) -> NoFriction:
        """Record nothing but the residual RMS.

        Parameters
        ----------
        dq : array_like, shape (m,)
            Joint velocity (rad/s).
        F : array_like, shape (m,)
            Estimated friction torque (N m).
        """
        dq, F = _check_pair(dq, F, 1, self.name)
        self._set([], float(F @ F), len(F))
        return self

    def _eval(self, dq):
        return np.zeros_like(dq)


class LinearFriction(_Friction):
    """``F = fc sign(dq) + fv dq + fo`` with ``fc, fv >= 0`` (METHOD.md's linear baseline plus an offset).

    Parameters
    ----------
    offset : bool
        Fit the offset ``fo`` (N m); False fixes it at 0 (the paper's baseline).
    """

    name = "linear"
    coef_names = ("fc", "fv", "fo")

    def __init__(self, *, offset: bool = True) -> None:
        self.offset = offset

    @one_blas_thread
    def fit(self, dq: ArrayLike, F: ArrayLike) -> LinearFriction:
        """Bounded linear least squares.

        Parameters
        ----------
        dq : array_like, shape (m,)
            Joint velocity (rad/s).
        F : array_like, shape (m,)
            Estimated friction torque (N m).
        """
        dq, F = _check_pair(dq, F, 3, self.name)
        A = np.column_stack([np.sign(dq), dq, np.ones_like(dq)])
        if not self.offset:
            A = A[:, :2]
        R, qtb, rest = _compress(A, F)
        lb = [0.0, 0.0, -np.inf][: A.shape[1]]
        res = lsq_linear(R, qtb, bounds=(lb, np.inf), method="bvls")
        coef = np.append(res.x, 0.0) if not self.offset else res.x
        self._set(coef, float(np.sum((R @ res.x - qtb) ** 2)) + rest, len(F))
        return self

    def _eval(self, dq):
        fc, fv, fo = self.coef_
        return fc * np.sign(dq) + fv * dq + fo


def _seed_columns(dq: NDArray[np.float64], lam: float) -> NDArray[np.float64]:
    """Columns of the seed model at threshold ``lam`` for ``[kc+, kc-, kv1, kv2, kv3, ks+, ks-]``."""
    A = np.zeros((len(dq), 7))
    a = np.abs(dq)
    pos, neg = dq > 0, dq < 0
    high = a >= lam
    ph, nh = pos & high, neg & high
    A[ph, 0] = 1.0
    A[nh, 1] = -1.0
    A[ph | nh, 2] = dq[ph | nh]
    A[ph | nh, 3] = dq[ph | nh] * a[ph | nh]
    A[ph | nh, 4] = dq[ph | nh] ** 3
    pl, nl = pos & ~high, neg & ~high
    r = a / lam
    # low speed: a straight line from the static level (at 0+) to the high-speed curve (at +-lam)
    A[pl, 0] = r[pl]
    A[pl, 2] = r[pl] * lam
    A[pl, 3] = r[pl] * lam**2
    A[pl, 4] = r[pl] * lam**3
    A[pl, 5] = 1.0 - r[pl]
    A[nl, 1] = -r[nl]
    A[nl, 2] = -r[nl] * lam
    A[nl, 3] = -r[nl] * lam**2
    A[nl, 4] = -r[nl] * lam**3
    A[nl, 6] = -(1.0 - r[nl])
    return A


class SeedFriction(_Friction):
    """The paper's friction model (METHOD.md section 2): low/high-speed split at a threshold lambda.

    Above the threshold (``|dq| >= lambda``)::

        F = kc+ + kv1 dq + kv2 dq |dq| + kv3 dq^3      (dq > 0)
        F = -kc- + kv1 dq + kv2 dq |dq| + kv3 dq^3     (dq < 0)

    Coulomb per direction, viscous odd in ``dq`` (``kv2 dq |dq|``: friction opposes motion).  Below it
    (ours: the paper leaves the form open) a straight line joins the static level ``+-ks+-`` at zero
    speed to the high-speed curve at ``+-lambda``, so the model is continuous at ``+-lambda``; with
    ``ks > kc`` it is the low-speed negative slope (Stribeck-like).  All seven coefficients are
    non-negative.

    ``lambda`` comes from the modified Lawson-Hanson search: for each candidate (quantiles of
    ``|dq|``), the coefficients by non-negative least squares (:func:`scipy.optimize.nnls`); the
    candidate with the least squared error wins, refined by a golden-section search between its
    neighbours; then the final coefficients on all samples.

    Parameters
    ----------
    n_candidates : int
        Candidate thresholds (geometrically spaced between the quantiles ``quantiles`` of ``|dq|``).
    quantiles : tuple of float
        Range of the candidates as quantiles of ``|dq|``.
    """

    name = "seed"
    coef_names = ("kc_pos", "kc_neg", "kv1", "kv2", "kv3", "ks_pos", "ks_neg", "lam")

    def __init__(self, *, n_candidates: int = 30, quantiles: tuple[float, float] = (0.002, 0.5)) -> None:
        self.n_candidates = n_candidates
        self.quantiles = quantiles

    @staticmethod
    def _nnls(dq, F, lam):
        R, qtb, rest = _compress(_seed_columns(dq, lam), F)
        coef, res = nnls(R, qtb, maxiter=50 * R.shape[1])
        return coef, res**2 + rest

    @one_blas_thread
    def fit(self, dq: ArrayLike, F: ArrayLike) -> SeedFriction:
        """Search the threshold and fit the coefficients.

        Parameters
        ----------
        dq : array_like, shape (m,)
            Joint velocity (rad/s).
        F : array_like, shape (m,)
            Estimated friction torque (N m).
        """
        dq, F = _check_pair(dq, F, 20, self.name)
        a = np.abs(dq[dq != 0])
        if a.size < 20:
            raise DataError(
                f"the seed friction model needs the joint to move; only {a.size} samples have dq != 0: "
                "record a motion of that joint"
            )
        lo, hi = np.quantile(a, self.quantiles)
        lo = max(lo, hi * 1e-4)
        cands = np.geomspace(lo, hi, int(self.n_candidates))
        s = _stride(len(dq))
        d_s, F_s = dq[s], F[s]
        sse = np.array([self._nnls(d_s, F_s, lam)[1] for lam in cands])
        k = int(np.argmin(sse))
        a_lo, a_hi = np.log(cands[max(k - 1, 0)]), np.log(cands[min(k + 1, len(cands) - 1)])
        g = (np.sqrt(5.0) - 1) / 2
        x1, x2 = a_hi - g * (a_hi - a_lo), a_lo + g * (a_hi - a_lo)
        f1, f2 = self._nnls(d_s, F_s, np.exp(x1))[1], self._nnls(d_s, F_s, np.exp(x2))[1]
        for _ in range(20):
            if f1 < f2:
                a_hi, x2, f2 = x2, x1, f1
                x1 = a_hi - g * (a_hi - a_lo)
                f1 = self._nnls(d_s, F_s, np.exp(x1))[1]
            else:
                a_lo, x1, f1 = x1, x2, f2
                x2 = a_lo + g * (a_hi - a_lo)
                f2 = self._nnls(d_s, F_s, np.exp(x2))[1]
        best = [(sse[k], cands[k]), (f1, np.exp(x1)), (f2, np.exp(x2))]
        lam = float(min(best)[1])
        coef, rss = self._nnls(dq, F, lam)
        self.candidates_ = cands
        self.candidate_sse_ = sse
        self._set(np.append(coef, lam), rss, len(F))
        return self

    def _eval(self, dq):
        lam = self.coef_[-1]
        return _seed_columns(dq, lam) @ self.coef_[:7]


class StribeckFriction(_Friction):
    """``F = sign(dq) (fc + (fs - fc) exp(-(dq / vs)^2)) + fv dq + fo``, ``fc, fs, fv >= 0``, ``vs > 0``.

    ``vs`` (rad/s) by a search over quantiles of ``|dq|`` with the other coefficients by bounded linear
    least squares.

    Parameters
    ----------
    n_candidates : int
        Candidate Stribeck velocities.
    quantiles : tuple of float
        Their range as quantiles of ``|dq|``.
    """

    name = "stribeck"
    coef_names = ("fc", "fs", "fv", "fo", "vs")

    def __init__(self, *, n_candidates: int = 30, quantiles: tuple[float, float] = (0.002, 0.5)) -> None:
        self.n_candidates = n_candidates
        self.quantiles = quantiles

    @staticmethod
    def _columns(dq, vs):
        e = np.exp(-((dq / vs) ** 2))
        sg = np.sign(dq)
        return np.column_stack([sg * (1.0 - e), sg * e, dq, np.ones_like(dq)])

    def _lin(self, dq, F, vs):
        R, qtb, rest = _compress(self._columns(dq, vs), F)
        res = lsq_linear(R, qtb, bounds=([0.0, 0.0, 0.0, -np.inf], np.inf), method="bvls")
        return res.x, float(np.sum((R @ res.x - qtb) ** 2)) + rest

    @one_blas_thread
    def fit(self, dq: ArrayLike, F: ArrayLike) -> StribeckFriction:
        """Search ``vs`` and fit the coefficients.

        Parameters
        ----------
        dq : array_like, shape (m,)
            Joint velocity (rad/s).
        F : array_like, shape (m,)
            Estimated friction torque (N m).
        """
        dq, F = _check_pair(dq, F, 20, self.name)
        a = np.abs(dq[dq != 0])
        if a.size < 20:
            raise DataError(
                f"the Stribeck friction model needs the joint to move; only {a.size} samples have dq != 0"
            )
        lo, hi = np.quantile(a, self.quantiles)
        cands = np.geomspace(max(lo, hi * 1e-4), hi, int(self.n_candidates))
        s = _stride(len(dq))
        sse = [self._lin(dq[s], F[s], vs)[1] for vs in cands]
        vs = float(cands[int(np.argmin(sse))])
        coef, rss = self._lin(dq, F, vs)
        self._set(np.append(coef, vs), rss, len(F))
        return self

    def _eval(self, dq):
        return self._columns(dq, self.coef_[-1]) @ self.coef_[:4]


class SigmoidFriction(_Friction):
    """``F = phi1 / (1 + exp(-phi2 (dq + phi3))) - phi1 / (1 + exp(-phi2 phi3))`` (Gaz et al. 2019).

    ``phi1`` (N m) scales, ``phi2`` (s/rad) sets the steepness, ``phi3`` (rad/s) shifts; ``F(0) = 0``.
    Fitted by variable projection (``phi1`` linear) and :func:`scipy.optimize.least_squares` on
    ``(log phi2, phi3)`` from a few starts.

    Parameters
    ----------
    max_samples : int
        Samples used in the nonlinear fit (evenly strided).
    """

    name = "sigmoid"
    coef_names = ("phi1", "phi2", "phi3")

    def __init__(self, *, max_samples: int = 20_000) -> None:
        self.max_samples = max_samples

    @staticmethod
    def _shape(dq, phi2, phi3):
        return expit(phi2 * (dq + phi3)) - expit(phi2 * phi3)

    @one_blas_thread
    def fit(self, dq: ArrayLike, F: ArrayLike) -> SigmoidFriction:
        """Fit ``phi1, phi2, phi3``.

        Parameters
        ----------
        dq : array_like, shape (m,)
            Joint velocity (rad/s).
        F : array_like, shape (m,)
            Estimated friction torque (N m).
        """
        dq, F = _check_pair(dq, F, 10, self.name)
        s = _stride(len(dq), int(self.max_samples))
        d, f = dq[s], F[s]
        scale = float(np.median(np.abs(d[d != 0]))) if np.any(d != 0) else 1.0

        def resid(z):
            g = self._shape(d, np.exp(z[0]), z[1])
            gg = float(g @ g)
            phi1 = float(g @ f) / gg if gg > 0 else 0.0
            return phi1 * g - f

        best = None
        for k2 in (1.0, 10.0, 100.0):
            for k3 in (0.0, 0.3, -0.3):
                z0 = np.array([np.log(k2 / scale), k3 * scale])
                sol = least_squares(resid, z0, method="lm", max_nfev=200)
                if best is None or sol.cost < best.cost:
                    best = sol
        assert best is not None
        phi2, phi3 = float(np.exp(best.x[0])), float(best.x[1])
        g = self._shape(dq, phi2, phi3)
        gg = float(g @ g)
        phi1 = float(g @ F) / gg if gg > 0 else 0.0
        r = phi1 * g - F
        self._set([phi1, phi2, phi3], float(r @ r), len(F))
        return self

    def _eval(self, dq):
        phi1, phi2, phi3 = self.coef_
        return phi1 * self._shape(dq, phi2, phi3)


FRICTION_MODELS: dict[str, type[_Friction]] = {
    "none": NoFriction,
    "linear": LinearFriction,
    "seed": SeedFriction,
    "stribeck": StribeckFriction,
    "sigmoid": SigmoidFriction,
}
"""Friction models by name (the ``--friction`` choices)."""


def friction_model(name: str, **options: Any) -> _Friction:
    """A new, unfitted single-joint friction model by name.

    Parameters
    ----------
    name : str
        One of :data:`FRICTION_MODELS`.
    **options
        Constructor arguments of that model.
    """
    if name not in FRICTION_MODELS:
        raise UsageError(f"unknown friction model {name!r}; choose one of {', '.join(FRICTION_MODELS)}")
    return FRICTION_MODELS[name](**options)


class FrictionLayer:
    """One friction model per joint: ``fit(dq, F)`` on (m, n) arrays, ``predict(dq) -> (m, n)``.

    Parameters
    ----------
    model : str
        Friction model of every joint: ``none``, ``linear``, ``seed``, ``stribeck`` or ``sigmoid``.
    options : dict, optional
        Constructor arguments of the model.

    Attributes
    ----------
    models_ : list
        The fitted single-joint models.
    rms_ : ndarray, shape (n,)
        RMS (N m) of ``F - predict(dq)`` per joint on the fitting data.
    """

    def __init__(self, *, model: str = "seed", options: dict[str, Any] | None = None) -> None:
        self.model = model
        self.options = options

    def __repr__(self) -> str:
        return f"FrictionLayer(model={self.model!r})"

    @one_blas_thread
    def fit(self, dq: ArrayLike, F: ArrayLike) -> FrictionLayer:
        """Fit one model per joint.

        Parameters
        ----------
        dq : array_like, shape (m, n)
            Joint velocities (rad/s).
        F : array_like, shape (m, n)
            Estimated friction torques (N m).
        """
        dq = np.atleast_2d(np.asarray(dq, dtype=np.float64))
        F = np.atleast_2d(np.asarray(F, dtype=np.float64))
        if dq.shape != F.shape:
            raise DataError(f"dq has shape {dq.shape} but F has {F.shape}; give (m, n) arrays of one shape")
        models = []
        for j in range(dq.shape[1]):
            try:
                models.append(friction_model(self.model, **(self.options or {})).fit(dq[:, j], F[:, j]))
            except DataError as err:
                raise DataError(f"joint {j + 1}: {err}") from None
        self.models_ = models
        self.rms_ = np.array([mdl.rms_ for mdl in models])
        return self

    def predict(self, dq: ArrayLike) -> NDArray[np.float64]:
        """Friction torques (N m), shape (m, n).

        Parameters
        ----------
        dq : array_like, shape (m, n)
            Joint velocities (rad/s).
        """
        if not hasattr(self, "models_"):
            raise UsageError("this FrictionLayer is not fitted yet; call fit(dq, F) first")
        dq = np.atleast_2d(np.asarray(dq, dtype=np.float64))
        if dq.shape[1] != len(self.models_):
            raise DataError(
                f"dq has {dq.shape[1]} columns; the friction layer has {len(self.models_)} joints"
            )
        return np.column_stack([mdl.predict(dq[:, j]) for j, mdl in enumerate(self.models_)])

    def to_dict(self) -> dict[str, Any]:
        """``{"model": name, "joints": [coef dict per joint]}`` (JSON-ready)."""
        if not hasattr(self, "models_"):
            raise UsageError("this FrictionLayer is not fitted yet; call fit(dq, F) first")
        return {"model": self.model, "joints": [mdl.to_dict()["coef"] for mdl in self.models_]}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> FrictionLayer:
        """A fitted layer from :meth:`to_dict`'s output.

        Parameters
        ----------
        data : dict
            ``{"model": name, "joints": [{coef name: value}, ...]}``.
        """
        try:
            name = data["model"]
            joints = data["joints"]
            klass = FRICTION_MODELS[name]
            layer = cls(model=name)
            models = []
            for coef in joints:
                mdl = klass()
                mdl.coef_ = np.array([float(coef[k]) for k in klass.coef_names])
                mdl.rms_ = float("nan")
                models.append(mdl)
        except (KeyError, TypeError, ValueError) as err:
            raise ModelFileError(
                f"the friction section is malformed ({type(err).__name__}: {err}); write it with FrictionLayer.to_dict"
            ) from None
        layer.models_ = models
        layer.rms_ = np.full(len(models), np.nan)
        return layer

    @classmethod
    def from_linear(cls, fc: ArrayLike, fv: ArrayLike, fo: ArrayLike) -> FrictionLayer:
        """A linear layer with given coefficients (e.g. identified with the link parameters).

        Parameters
        ----------
        fc, fv, fo : array_like, shape (n,)
            Coulomb (N m), viscous (N m s/rad) and offset (N m) per joint.
        """
        rows = np.column_stack([np.ravel(fc), np.ravel(fv), np.ravel(fo)])
        return cls.from_dict(
            {
                "model": "linear",
                "joints": [dict(zip(LinearFriction.coef_names, r, strict=True)) for r in rows],
            }
        )
