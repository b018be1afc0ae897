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

The table is :data:`FRICTION_MODELS` (:mod:`dynid.identify.registry`): a model of one's own subclasses
:class:`FrictionModel` and is added with :func:`register_friction_model`.

Models linear in their coefficients for a fixed shape parameter (``lambda`` of the seed model, ``vs``
of Stribeck) are fitted by a search over that parameter with a bounded linear least squares inside;
each inner problem is first compressed by QR (m x k -> k x k), so a search over many candidates on
hundreds of thousands of samples stays fast.

Filtered data (parallel filtering)
----------------------------------
The torque the identification compares with is low-pass filtered; a friction model evaluated on the
states is not: at every velocity reversal its Coulomb step is sharp where the measured (filtered)
torque ramps over ~1 / (2 cutoff).  Fitted and compared that way, the seed model's threshold came out
3-10 times too small and the friction prediction missed the filtered torque by ~0.11 N m RMS on a
simulated UR5 (20 Hz filter, Coulomb 1-2 N m).  :meth:`FrictionLayer.fit` with ``prepared=`` therefore
fits ``filter(model(dq))`` to the filtered residual: the model's columns are evaluated at full rate,
filtered like the torque and taken at the kept samples, exactly as the link regressor is.  The shape
searches (``lambda``, ``vs``) filter a window of at most 10,000 samples per candidate; the
coefficients are then fitted on all samples.

Every model also exposes its linear part at the fitted shape (:meth:`basis`, :meth:`set_linear`,
``linear_bounds``) so that the three-layer pipeline can fit it jointly with the link parameters.
"""

from __future__ import annotations

import inspect
from abc import ABC, abstractmethod
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import Any, ClassVar, Self

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import least_squares, lsq_linear, nnls
from scipy.special import expit

from dynid._threads import JOINT_THREADS, one_blas_thread
from dynid.data.preprocess import filtfilt_rows
from dynid.exceptions import DataError, ModelFileError, UsageError
from dynid.identify._qr import r_factor
from dynid.identify.checks import check_is_fitted
from dynid.identify.registry import FRICTION_MODELS

__all__ = [
    "FRICTION_MODELS",
    "FrictionLayer",
    "FrictionModel",
    "LinearFriction",
    "NoFriction",
    "SeedFriction",
    "SigmoidFriction",
    "StribeckFriction",
    "bounded_lsq",
    "friction_model",
    "register_friction_model",
]

_SEARCH_SAMPLES = 10_000  # samples used in shape-parameter searches (evenly strided)
_SEARCH_WINDOW = 10_000  # full-rate samples filtered per candidate in a search on filtered data
_GOLDEN_STEPS = 20  # golden-section refinements of a threshold search

# What a simulator's damping and frictionloss leave out of the built-in models (FrictionModel.simulator_items)
_SIMULATOR_ITEMS = {
    "friction offset": "the constant torque fo of each joint (no simulator field)",
    "Stribeck friction": "the static level above the Coulomb level at low speed",
    "direction-dependent Coulomb friction": "different levels for positive and negative speed; their mean is "
    "the frictionloss",
    "nonlinear viscous friction": "the dq|dq| and dq^3 terms; only the linear term is damping",
    "sigmoid friction shape": "the smooth sigmoid and its shift; half its span is the frictionloss, no damping",
}


def _items(*whats: str) -> dict[str, str]:
    return {w: _SIMULATOR_ITEMS[w] for w in whats}


def _present(*flags: tuple[str, bool]) -> tuple[str, ...]:
    return tuple(what for what, on in flags if on)


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
    k = A.shape[1]
    Ab = np.empty((k + 1, len(b)))  # [A b] transposed: a Fortran-ordered [A b] for the QR, no copy
    Ab[:k] = A.T
    Ab[k] = b
    return _compress_rows(Ab)


def _compress_rows(Ab: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
    """:func:`_compress` of ``[A b]`` given transposed, ``Ab`` (k + 1, m), C order (overwritten)."""
    k = Ab.shape[0] - 1
    R = r_factor(Ab.T, overwrite=True)
    if R.shape[0] < k + 1:
        R = np.vstack([R, np.zeros((k + 1 - R.shape[0], k + 1))])
    return R[:k, :k], R[:k, k], float(R[k, k] ** 2)


def _stride(m: int, limit: int = _SEARCH_SAMPLES) -> slice:
    return slice(None, None, max(1, -(-m // limit)))


class _Sampling:
    """How one joint's model columns at full rate become comparable with the filtered residual.

    ``full(A)``: filter the full-rate columns ``A`` (M, k) like the torque, take the kept rows (m, k).
    ``search_into(At_window, out)``: the same on the search window only (columns given transposed, on
    ``window`` rows), writing the kept rows inside it away from its edges, to compare with
    ``F[search_rows]``.
    """

    def __init__(self, prepared: Any, window: int = _SEARCH_WINDOW) -> None:
        self.prepared = prepared
        rows = np.asarray(prepared.rows)
        runs = prepared.runs
        longest = max(runs, key=lambda r: r.stop - r.start)
        length = longest.stop - longest.start
        start = longest.start + max(0, (length - window) // 2)
        stop = min(longest.stop, start + window)
        self.window = slice(start, stop)
        edge = (
            int(np.ceil(5.0 * prepared.fs / prepared.settings["cutoff_hz"]))
            if prepared.parallel_filter
            else 0
        )
        inside = (rows >= start + edge) & (rows < stop - edge)
        if inside.sum() < 20:  # a short record: search on every kept row
            self.window = None
            inside = np.ones(len(rows), dtype=bool)
        self.search_rows = np.flatnonzero(inside)
        self._local = rows[inside] - (start if self.window is not None else 0)
        self._sos = prepared.sos  # None without the parallel filter

    def full(self, A: NDArray[np.float64]) -> NDArray[np.float64]:
        return self.prepared.filter(A)[self.prepared.rows]

    def search_into(self, At: NDArray[np.float64], out: NDArray[np.float64]) -> None:
        """``search`` of columns given transposed, ``At`` (k, len(window)), written into ``out`` (k, m_s).

        The window's columns filtered as :func:`dynid.data.preprocess.lowpass` filters them (one run,
        the same arithmetic), in the transposed layout the QR of the search takes without a copy.
        """
        if self.window is None:
            out[:] = self.full(At.T).T
        elif not self.prepared.parallel_filter:
            out[:] = At[:, self._local]
        else:
            out[:] = filtfilt_rows(self._sos, At)[:, self._local]

    def window_of(self, dq: NDArray[np.float64]) -> NDArray[np.float64]:
        return dq if self.window is None else dq[self.window]


class FrictionModel(ABC):
    """Base of the single-joint friction models: ``fit(dq, F) -> self``, ``predict(dq) -> F``.

    A model whose torque is linear in its coefficients needs only its name, its coefficients and their
    columns; the base fits them by bounded least squares (filtered like the torque on prepared data)::

        @register_friction_model
        class QuadraticFriction(FrictionModel):
            name = "quadratic"                  # the --friction choice and the model file's name
            coef_names = ("kv2",)               # coef_, as the model file writes it
            bounds = (0.0,)                     # lower bound of each coefficient: 0 or -inf

            def columns(self, dq):              # (m,) rad/s -> (m, k)
                return (dq * np.abs(dq))[:, None]

    A model with a shape parameter (a threshold, a Stribeck speed) keeps it as its last coefficient,
    lists its linear coefficients' positions in ``_linear``, overrides ``_fit`` (see
    :class:`SeedFriction`) and gives :meth:`columns` at the fitted shape.  The constructor takes
    keyword arguments with defaults only (a model file rebuilds the model as ``cls()``).

    What a simulator description can hold of the model (a joint's ``damping`` and ``frictionloss``) is
    :meth:`simulator_terms`; by default none of it, and the export lists the whole model as not carried.

    Attributes
    ----------
    coef_ : ndarray, shape (len(coef_names),)
        The fitted coefficients.
    rms_ : float
        RMS (N m) of ``F - predict(dq)`` on the fitting data.
    """

    name: ClassVar[str] = ""
    coef_names: ClassVar[tuple[str, ...]] = ()
    bounds: ClassVar[tuple[float, ...]] = ()
    """Lower bound of each linear coefficient, in the order of :meth:`columns`: 0 or -inf."""
    _min_samples: ClassVar[int] = 1  # fewer samples than this: DataError

    def __repr__(self) -> str:
        return f"{type(self).__name__}()"

    @one_blas_thread
    def fit(
        self, dq: ArrayLike, F: ArrayLike, *, sampling: _Sampling | None = None, around: float | None = None
    ) -> Self:
        """Fit the model to one joint's estimated friction torque (see the class docstring for how).

        Parameters
        ----------
        dq : array_like, shape (m,)
            Joint velocity (rad/s); at full rate with ``sampling``.
        F : array_like, shape (m,)
            Estimated friction torque (N m).
        sampling : optional
            Filtering of the model (see :meth:`FrictionLayer.fit`).
        around : float, optional
            A previous value of the shape parameter: search within a factor 3 of it (a warm start).
            Models without a searched shape parameter ignore it.
        """
        dq, F, dq_k = _inputs(dq, F, sampling, self._min_samples, self.name)
        self._fit(dq, F, dq_k, sampling, around)
        return self

    def _check_fitted(self) -> None:
        check_is_fitted(self, "coef_", call="fit(dq, F)")

    def predict(self, dq: ArrayLike) -> NDArray[np.float64]:
        """Friction torque (N m) at velocities ``dq`` (rad/s), same shape as ``dq``.

        Parameters
        ----------
        dq : array_like
            Joint velocity (rad/s).
        """
        self._check_fitted()
        dq = np.asarray(dq, dtype=np.float64)
        return (self.basis(dq.ravel()) @ self.linear_coef()).reshape(dq.shape)

    # the linear part at the fitted shape: F = basis(dq) @ linear_coef()
    def basis(self, dq: ArrayLike) -> NDArray[np.float64]:
        """Columns of the coefficients that enter linearly, at the fitted shape: (len(dq), k).

        Parameters
        ----------
        dq : array_like, shape (m,)
            Joint velocity (rad/s).
        """
        self._check_fitted()
        return self.columns(np.asarray(dq, dtype=np.float64).ravel())

    def linear_coef(self) -> NDArray[np.float64]:
        """The coefficients that enter linearly (k,), in the order of :meth:`basis`."""
        self._check_fitted()
        return self.coef_[list(self._linear)]

    def set_linear(self, coef: ArrayLike) -> None:
        """Replace the linear coefficients (e.g. by a joint fit with the link parameters), kept in bounds.

        Parameters
        ----------
        coef : array_like, shape (k,)
            New values, in the order of :meth:`basis`.
        """
        self._check_fitted()
        coef = np.maximum(np.asarray(coef, dtype=np.float64), self.linear_bounds)
        new = self.coef_.copy()
        new[list(self._linear)] = coef
        self.coef_ = new

    @property
    def linear_bounds(self) -> NDArray[np.float64]:
        """Lower bounds of the linear coefficients (0 or -inf)."""
        return np.array(self.bounds[: len(self._linear)], dtype=np.float64)

    @property
    def _linear(self) -> tuple[int, ...]:
        """Positions in ``coef_`` of the coefficients that enter linearly (default: all of them)."""
        return tuple(range(len(self.coef_names)))

    @abstractmethod
    def columns(self, dq: NDArray[np.float64]) -> NDArray[np.float64]:
        """The columns of the linear coefficients, at the fitted shape for a model with one: (m, k).

        Parameters
        ----------
        dq : ndarray, shape (m,)
            Joint velocity (rad/s).
        """

    @classmethod
    def simulator_items(cls) -> dict[str, str]:
        """What a simulator's joint damping and frictionloss may leave out of this model: ``{what: detail}``,
        in the order the export lists them.  Default: the whole model."""
        return {
            f"{cls.name} friction": f"the {cls.name} friction model ({', '.join(cls.coef_names)}) has no "
            "simulator field; no damping and frictionloss were written for it"
        }

    def simulator_terms(self) -> tuple[float, float, tuple[str, ...]]:
        """This joint's fit in a simulator's terms.

        Returns
        -------
        damping : float
            Viscous coefficient (N m s/rad).
        frictionloss : float
            Coulomb level (N m).
        left : tuple of str
            The keys of :meth:`simulator_items` that the two leave out of this fit.  Default: no
            damping, no frictionloss, the whole model left out.
        """
        self._check_fitted()
        return 0.0, 0.0, tuple(self.simulator_items())

    def _fit(
        self,
        dq: NDArray[np.float64],
        F: NDArray[np.float64],
        dq_k: NDArray[np.float64],
        sampling: _Sampling | None,
        around: float | None,
    ) -> None:
        """Fit on checked inputs (see :func:`_inputs`) and store the result with :meth:`_set`.

        Default: the bounded least squares of :meth:`columns` (a model linear in all its coefficients).
        """
        coef, rss = self._fit_columns(self.columns, dq, F, sampling, self.bounds)
        self._set(coef, rss, len(F))

    def _fit_columns(
        self,
        columns,
        dq: NDArray[np.float64],
        F: NDArray[np.float64],
        sampling: _Sampling | None,
        bounds: tuple[float, ...],
    ) -> tuple[NDArray[np.float64], float]:
        """Bounded least squares of F on the (filtered) columns ``columns(dq)``: (coef, rss)."""
        A = columns(dq) if sampling is None else sampling.full(columns(dq))
        if sampling is not None:  # the filtered basis at the fitted shape (see FrictionLayer.filtered_basis)
            self._filtered_basis = A
        return bounded_lsq(A, F, bounds)

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


def bounded_lsq(
    A: NDArray[np.float64], F: NDArray[np.float64], bounds: tuple[float, ...]
) -> tuple[NDArray[np.float64], float]:
    """``min ||A c - F||^2`` with ``c >= bounds`` (0 or -inf each), compressed by QR first: (c, rss).

    Parameters
    ----------
    A : ndarray, shape (m, k)
        Columns.
    F : ndarray, shape (m,)
        Target.
    bounds : tuple of float, length k
        Lower bound of each coefficient: 0 or -inf.

    Returns
    -------
    c : ndarray, shape (k,)
        Coefficients.
    rss : float
        Residual sum of squares at ``c``.
    """
    return _bounded_solve(*_compress(A, F), bounds)


def _bounded_solve(
    R: NDArray[np.float64], qtb: NDArray[np.float64], rest: float, bounds: tuple[float, ...]
) -> tuple[NDArray[np.float64], float]:
    """:func:`bounded_lsq` on the compressed problem ``(R, Q^T b, rest)`` of :func:`_compress`."""
    lb = np.asarray(bounds, dtype=np.float64)
    if np.all(lb == 0):
        coef, res = nnls(R, qtb, maxiter=50 * R.shape[1])
        return coef, float(res**2) + rest
    if np.all(np.isinf(lb)):
        coef = np.linalg.lstsq(R, qtb, rcond=None)[0]
    else:
        coef = lsq_linear(R, qtb, bounds=(lb, np.inf), method="bvls").x
    return coef, float(np.sum((R @ coef - qtb) ** 2)) + rest


def _inputs(
    dq: ArrayLike, F: ArrayLike, sampling: _Sampling | None, need: int, name: str
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Checked (dq, F, dq at the samples of F): dq is at full rate when ``sampling`` is given."""
    if sampling is None:
        dq, F = _check_pair(dq, F, need, name)
        return dq, F, dq
    dq = np.asarray(dq, dtype=np.float64).ravel()
    F = np.asarray(F, dtype=np.float64).ravel()
    rows = sampling.prepared.rows
    if dq.size != len(sampling.prepared.t) or F.size != len(rows):
        raise DataError(
            f"with prepared data, dq must be at full rate ({len(sampling.prepared.t)} samples, got {dq.size}) "
            f"and F at the kept rows ({len(rows)}, got {F.size})"
        )
    dq_k, F = _check_pair(dq[rows], F, need, name)
    if not np.all(np.isfinite(dq)):
        raise DataError("dq holds a non-finite value; drop or interpolate that sample")
    return dq, F, dq_k


def _near(value: float, lo: float, hi: float) -> NDArray[np.float64]:
    """Candidates of a warm-started shape search: 9 values within a factor 3 of ``value``, in [lo, hi]."""
    return np.unique(np.clip(float(value) * np.geomspace(1 / 3, 3, 9), lo, hi))


def _shape_search(
    cost, candidates: NDArray[np.float64], refine: bool = True
) -> tuple[float, NDArray[np.float64]]:
    """Best shape parameter: least cost among the candidates, refined by golden section (log scale)."""
    sse = np.array([cost(c) for c in candidates])
    k = int(np.argmin(sse))
    if not refine or len(candidates) < 3:
        return float(candidates[k]), sse
    a_lo, a_hi = np.log(candidates[max(k - 1, 0)]), np.log(candidates[min(k + 1, len(candidates) - 1)])
    g = (np.sqrt(5.0) - 1) / 2
    x1, x2 = a_hi - g * (a_hi - a_lo), a_lo + g * (a_hi - a_lo)
    f1, f2 = cost(np.exp(x1)), cost(np.exp(x2))
    for _ in range(_GOLDEN_STEPS):
        if f1 < f2:
            a_hi, x2, f2 = x2, x1, f1
            x1 = a_hi - g * (a_hi - a_lo)
            f1 = cost(np.exp(x1))
        else:
            a_lo, x1, f1 = x1, x2, f2
            x2 = a_lo + g * (a_hi - a_lo)
            f2 = cost(np.exp(x2))
    best = [(sse[k], candidates[k]), (f1, np.exp(x1)), (f2, np.exp(x2))]
    return float(min(best)[1]), sse


class NoFriction(FrictionModel):
    """No friction: predicts zero."""

    name = "none"
    coef_names = ()

    def _fit(self, dq, F, dq_k, sampling, around) -> None:
        self._set([], float(F @ F), len(F))

    def columns(self, dq):
        return np.zeros((len(dq), 0))

    @classmethod
    def simulator_items(cls) -> dict[str, str]:
        return {}

    def simulator_terms(self) -> tuple[float, float, tuple[str, ...]]:
        self._check_fitted()
        return 0.0, 0.0, ()


class LinearFriction(FrictionModel):
    """``F = fc sign(dq) + fv dq + fo`` with ``fc, fv >= 0`` (METHOD.md's linear baseline plus an offset).

    Fitted by bounded linear least squares.

    Parameters
    ----------
    offset : bool
        Fit the offset ``fo`` (N m); False fixes it at 0 (the paper's baseline).
    """

    name = "linear"
    coef_names = ("fc", "fv", "fo")
    bounds = (0.0, 0.0, -np.inf)
    _min_samples = 3

    def __init__(self, *, offset: bool = True) -> None:
        self.offset = offset

    @property
    def _linear(self) -> tuple[int, ...]:  # type: ignore[override]
        return (0, 1, 2) if getattr(self, "offset", True) else (0, 1)

    def _fit(self, dq, F, dq_k, sampling, around) -> None:
        k = 3 if self.offset else 2
        coef, rss = self._fit_columns(lambda v: self._columns(v)[:, :k], dq, F, sampling, self.bounds[:k])
        self._set(np.append(coef, 0.0) if k == 2 else coef, rss, len(F))

    @staticmethod
    def _columns(dq):
        return np.column_stack([np.sign(dq), dq, np.ones_like(dq)])

    def columns(self, dq):
        return self._columns(dq)[:, : len(self._linear)]

    @classmethod
    def simulator_items(cls) -> dict[str, str]:
        return _items("friction offset")

    def simulator_terms(self) -> tuple[float, float, tuple[str, ...]]:
        c = self.to_dict()["coef"]
        return max(c["fv"], 0.0), max(c["fc"], 0.0), _present(("friction offset", abs(c["fo"]) > 0))


def _seed_columns(dq: NDArray[np.float64], lam: float) -> NDArray[np.float64]:
    """Columns of the seed model at threshold ``lam`` for ``[kc+, kc-, kv1, kv2, kv3, ks+, ks-]``.

    Written with whole-array ``np.where`` (the same values as per-region assignments, several times
    faster: the shape search evaluates it about a thousand times in a default identification).
    """
    return np.ascontiguousarray(_seed_rows(_SeedSpeeds(dq), lam).T)


class _SeedSpeeds:
    """What the seed model's columns need of ``dq`` at any threshold, computed once per search."""

    def __init__(self, dq: NDArray[np.float64]) -> None:
        self.dq = dq
        self.a = np.abs(dq)
        self.pos, self.neg = dq > 0, dq < 0
        self.dqa = dq * self.a
        self.dq3 = dq**3


def _seed_rows(s: _SeedSpeeds, lam: float) -> NDArray[np.float64]:
    """:func:`_seed_columns` transposed, (7, len(dq)): the same values, written row by row."""
    high = s.a >= lam  # lam > 0: a high-speed sample moves
    r = s.a / lam
    low = ~high
    pl, nl = s.pos & low, s.neg & low
    # low speed: a straight line from the static level (at 0+) to the high-speed curve (at +-lam)
    signed = np.zeros(len(r))
    np.copyto(signed, r, where=pl)
    neg_r = -r
    np.copyto(signed, neg_r, where=nl)
    A = np.zeros((7, len(r)))
    np.copyto(A[0], r, where=pl)
    A[0][s.pos & high] = 1.0
    np.copyto(A[1], neg_r, where=nl)
    A[1][s.neg & high] = -1.0
    for k, (fast, power) in enumerate(((s.dq, lam), (s.dqa, lam**2), (s.dq3, lam**3)), start=2):
        np.multiply(signed, power, out=A[k])
        np.copyto(A[k], fast, where=high)
    one_minus = 1.0 - r
    np.copyto(A[5], one_minus, where=pl)
    np.negative(one_minus, out=one_minus)
    np.copyto(A[6], one_minus, where=nl)
    return A


class _ShapedFriction(FrictionModel):
    """Models linear in their coefficients at a fixed shape parameter, the last coefficient.

    The shape parameter is searched among candidates between the quantiles ``quantiles`` of ``|dq|``
    (or near a previous value), each scored by the bounded linear least squares of the other
    coefficients; the coefficients are then fitted on all samples at the winner.  On filtered data the
    search filters a window of the record per candidate (see :class:`_Sampling`).

    Attributes
    ----------
    candidates_ : ndarray
        The candidate shape parameters of the search.
    candidate_sse_ : ndarray
        The squared error of the fit at each candidate.
    """

    n_candidates: int
    quantiles: tuple[float, float]
    _min_samples = 20
    _search_label: ClassVar[str] = ""  # the model's name in messages
    _move_advice: ClassVar[str] = ""  # appended to the message when the joint hardly moves
    _refine: ClassVar[bool] = True  # refine the best candidate by golden section

    @staticmethod
    def _columns(dq: NDArray[np.float64], shape: float) -> NDArray[np.float64]:
        """Columns of the linear coefficients at shape parameter ``shape``: (len(dq), k)."""
        raise NotImplementedError

    def _fit(self, dq, F, dq_k, sampling, around) -> None:
        a = np.abs(dq_k[dq_k != 0])
        if a.size < 20:
            raise DataError(
                f"the {self._search_label} friction model needs the joint to move; only {a.size} samples "
                f"have dq != 0{self._move_advice}"
            )
        lo, hi = np.quantile(a, self.quantiles)
        lo = max(lo, hi * 1e-4)
        cands = np.geomspace(lo, hi, int(self.n_candidates)) if around is None else _near(around, lo, hi)
        bounds = self.bounds
        columns = self._columns
        if sampling is None:
            s = _stride(len(dq))
            d_s, F_s = dq[s], F[s]

            def cost(shape):
                return bounded_lsq(columns(d_s, shape), F_s, bounds)[1]
        else:
            d_w, F_w = sampling.window_of(dq), F[sampling.search_rows]
            speeds = self._speeds(d_w)
            k = len(bounds)

            def cost(shape):
                Ab = np.empty((k + 1, len(F_w)))  # the filtered columns and F_w, transposed
                sampling.search_into(self._rows(speeds, shape), Ab[:k])
                Ab[k] = F_w
                return _bounded_solve(*_compress_rows(Ab), bounds)[1]

        shape, sse = _shape_search(cost, cands, refine=self._refine)
        coef, rss = self._fit_columns(lambda v: columns(v, shape), dq, F, sampling, bounds)
        self.candidates_ = cands
        self.candidate_sse_ = sse
        self._set(np.append(coef, shape), rss, len(F))

    def columns(self, dq):
        return self._columns(dq, self.coef_[-1])

    def _speeds(self, dq: NDArray[np.float64]) -> Any:
        """What :meth:`_rows` needs of the search window's velocities (computed once per search)."""
        return dq

    def _rows(self, speeds: Any, shape: float) -> NDArray[np.float64]:
        """The columns at ``shape`` on the search window, transposed: (k, len(window))."""
        return np.ascontiguousarray(self._columns(speeds, shape).T)


_STATIC_PAIRS = ((0, 5), (1, 6))  # the seed model's (Coulomb, static level) coefficients, per direction


class SeedFriction(_ShapedFriction):
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
        Range of the candidates as quantiles of ``|dq|``.  At least 1 % of the moving samples lie
        below the threshold by default: with fewer, the static levels are free to fit the few samples
        of the velocity reversals (on 10 s of simulated data: a threshold of 0.001 rad/s with static
        levels of 100-500 N m, and held-out errors three times larger).
    """

    name = "seed"
    coef_names = ("kc_pos", "kc_neg", "kv1", "kv2", "kv3", "ks_pos", "ks_neg", "lam")
    bounds = (0.0,) * 7
    static_ratio: ClassVar[float] = 3.0
    """Most a static level may exceed its Coulomb level by (``ks <= static_ratio kc``); beyond it the
    static level is held at the Coulomb level (``ks = kc``, no Stribeck excess in that direction) and the
    others are fitted again.

    Below a small threshold the static column lives on the few samples of the velocity reversals, and
    after the torque's filter it is a short blip: the fit is then free to put a static level of many times
    the Coulomb level there, filling the reversals' timing errors rather than any friction (12.3 N m against
    1.6 at a threshold of 0.002 rad/s on a simulated xArm 7 whose friction was Coulomb and viscous alone; 5.4
    times on a Unitree Z1's wrist), which a motion with other reversals turns into errors of several N m
    (2.5 and 1.8 times the held-out RMS of OLS with linear friction).  Measured stiction stays within
    1.5-2 times the Coulomb level; on the TX40 and the Panda the fitted static levels are below their
    Coulomb levels on every joint."""

    def __init__(self, *, n_candidates: int = 30, quantiles: tuple[float, float] = (0.01, 0.5)) -> None:
        self.n_candidates = n_candidates
        self.quantiles = quantiles

    _columns = staticmethod(_seed_columns)
    _speeds = staticmethod(_SeedSpeeds)  # type: ignore[assignment]
    _rows = staticmethod(_seed_rows)  # type: ignore[assignment]

    @property
    def tied_(self) -> tuple[bool, bool]:
        """Whether ``ks+ = kc+`` and ``ks- = kc-`` are held (the static level not told apart); the model
        file records it (``ks_pos_held``, ``ks_neg_held``; files written before the rule held none)."""
        return self.__dict__.get("_tied") or (False, False)

    def to_dict(self) -> dict[str, Any]:
        out = super().to_dict()
        out["coef"]["ks_pos_held"], out["coef"]["ks_neg_held"] = (float(t) for t in self.tied_)
        return out

    def _restore(self, coef: dict[str, Any]) -> None:
        """Read what :meth:`to_dict` wrote beside the coefficients (the held static levels)."""
        self._tied = (bool(coef.get("ks_pos_held", 0.0)), bool(coef.get("ks_neg_held", 0.0)))

    @property
    def _linear(self) -> tuple[int, ...]:  # type: ignore[override]
        tied = self.tied_
        return (0, 1, 2, 3, 4, *(st for (_, st), held in zip(_STATIC_PAIRS, tied, strict=True) if not held))

    def merged(self, cols: Sequence[Any]) -> list[Any]:
        """The seven columns (arrays, or symbols for the C export) in the order of :meth:`linear_coef`: a
        held static level's column added to its Coulomb column, and dropped."""
        cols = list(cols)
        for (c, st), held in zip(_STATIC_PAIRS, self.tied_, strict=True):
            if held:
                cols[c] = cols[c] + cols[st]
        return [cols[k] for k in self._linear]

    def columns(self, dq):
        A = self._columns(dq, self.coef_[-1])
        return np.column_stack(self.merged(A.T)) if any(self.tied_) else A

    def set_linear(self, coef: ArrayLike) -> None:
        super().set_linear(coef)
        new = self.coef_.copy()
        for (c, st), held in zip(_STATIC_PAIRS, self.tied_, strict=True):
            if held:
                new[st] = new[c]
        self.coef_ = new

    def _fit(self, dq, F, dq_k, sampling, around) -> None:
        self._tied = (False, False)
        self.__dict__.pop("_filtered_basis", None)  # an earlier fit's
        super()._fit(dq, F, dq_k, sampling, around)
        A = self.__dict__.get("_filtered_basis")
        if A is None:
            A = self._columns(dq if sampling is None else dq_k, self.coef_[-1])
        c = self.coef_
        held = tuple(bool(c[st] > self.static_ratio * c[k] + 1e-12) for k, st in _STATIC_PAIRS)
        if not any(held):
            return
        self._tied = held
        merged = np.column_stack(self.merged(A.T))
        coef, rss = bounded_lsq(merged, F, self.bounds[: merged.shape[1]])
        self.set_linear(coef)  # the held static levels follow their Coulomb levels
        if sampling is not None:
            self._filtered_basis = merged
        self._set(self.coef_, rss, len(F))

    @classmethod
    def simulator_items(cls) -> dict[str, str]:
        return _items("Stribeck friction", "direction-dependent Coulomb friction", "nonlinear viscous friction")

    def simulator_terms(self) -> tuple[float, float, tuple[str, ...]]:
        c = self.to_dict()["coef"]
        left = _present(
            ("Stribeck friction", c["ks_pos"] != c["kc_pos"] or c["ks_neg"] != c["kc_neg"]),
            ("direction-dependent Coulomb friction", c["kc_pos"] != c["kc_neg"]),
            ("nonlinear viscous friction", c["kv2"] > 0 or c["kv3"] > 0),
        )
        return c["kv1"], 0.5 * (c["kc_pos"] + c["kc_neg"]), left


class StribeckFriction(_ShapedFriction):
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
    _linear = (0, 1, 2, 3)
    bounds = (0.0, 0.0, 0.0, -np.inf)

    _search_label = "Stribeck"
    _refine = False

    def __init__(self, *, n_candidates: int = 30, quantiles: tuple[float, float] = (0.002, 0.5)) -> None:
        self.n_candidates = n_candidates
        self.quantiles = quantiles

    @staticmethod
    def _columns(dq, vs):
        e = np.exp(-((dq / vs) ** 2))
        sg = np.sign(dq)
        return np.column_stack([sg * (1.0 - e), sg * e, dq, np.ones_like(dq)])

    @classmethod
    def simulator_items(cls) -> dict[str, str]:
        return _items("friction offset", "Stribeck friction")

    def simulator_terms(self) -> tuple[float, float, tuple[str, ...]]:
        c = self.to_dict()["coef"]
        left = _present(("friction offset", abs(c["fo"]) > 0), ("Stribeck friction", abs(c["fs"] - c["fc"]) > 0))
        return max(c["fv"], 0.0), max(c["fc"], 0.0), left


class SigmoidFriction(FrictionModel):
    """``F = phi1 / (1 + exp(-phi2 (dq + phi3))) - phi1 / (1 + exp(-phi2 phi3))`` (Gaz et al. 2019).

    ``phi1`` (N m) scales, ``phi2`` (s/rad) sets the steepness, ``phi3`` (rad/s) shifts; ``F(0) = 0``.
    Fitted by variable projection (``phi1`` linear) and :func:`scipy.optimize.least_squares` on
    ``(log phi2, phi3)`` from a few starts.  On filtered data the shape ``(phi2, phi3)`` comes from
    the unfiltered fit at the kept samples and ``phi1`` is then refitted on the filtered shape.

    Parameters
    ----------
    max_samples : int
        Samples used in the nonlinear fit (evenly strided).
    """

    name = "sigmoid"
    coef_names = ("phi1", "phi2", "phi3")
    _linear = (0,)
    bounds = (-np.inf,)
    _min_samples = 10

    def __init__(self, *, max_samples: int = 20_000) -> None:
        self.max_samples = max_samples

    @staticmethod
    def _shape(dq, phi2, phi3):
        return expit(phi2 * (dq + phi3)) - expit(phi2 * phi3)

    def _fit(self, dq, F, dq_k, sampling, around) -> None:
        s = _stride(len(dq_k), int(self.max_samples))
        d, f = dq_k[s], F[s]
        scale = float(np.median(np.abs(d[d != 0]))) if np.any(d != 0) else 1.0

        def resid(z):
            g = self._shape(d, np.exp(z[0]), z[1])
            gg = float(g @ g)
            phi1 = float(g @ f) / gg if gg > 0 else 0.0
            return phi1 * g - f

        starts = [
            np.array([np.log(k2 / scale), k3 * scale]) for k2 in (1.0, 10.0, 100.0) for k3 in (0.0, 0.3, -0.3)
        ]
        fits = [least_squares(resid, z0, method="lm", max_nfev=200) for z0 in starts]
        best = min(fits, key=lambda sol: sol.cost)  # the first of the least cost, as before
        phi2, phi3 = float(np.exp(best.x[0])), float(best.x[1])
        coef, rss = self._fit_columns(
            lambda v: self._shape(v, phi2, phi3)[:, None], dq, F, sampling, self.bounds
        )
        self._set([float(coef[0]), phi2, phi3], rss, len(F))

    def columns(self, dq):
        return self._shape(dq, self.coef_[1], self.coef_[2])[:, None]

    @classmethod
    def simulator_items(cls) -> dict[str, str]:
        return _items("sigmoid friction shape")

    def simulator_terms(self) -> tuple[float, float, tuple[str, ...]]:
        c = self.to_dict()["coef"]
        return 0.0, 0.5 * abs(c["phi1"]), ("sigmoid friction shape",)


def register_friction_model(cls: type[FrictionModel], *, replace: bool = False) -> type[FrictionModel]:
    """Add a friction model to :data:`FRICTION_MODELS` under its ``name`` (usable as a class decorator).

    It is then a ``friction=`` of :func:`dynid.identify.model.identify` and a ``--friction`` choice of
    ``dynid identify`` and ``dynid fleet``, and model files that use it load in this process.

    Parameters
    ----------
    cls : type
        A concrete subclass of :class:`FrictionModel` with a ``name``, ``coef_names`` and a constructor
        whose arguments all have defaults.
    replace : bool
        Replace a model registered under the same name.

    Returns
    -------
    type
        ``cls``.

    Raises
    ------
    UsageError
        Not such a class, or a name that is taken (without ``replace``) or reserved.
    """
    if not (isinstance(cls, type) and issubclass(cls, FrictionModel)):
        raise UsageError(f"{cls!r} is not a friction model; subclass dynid.identify.friction.FrictionModel")
    name = cls.name
    if not (isinstance(name, str) and name.isidentifier()) or name == "auto":
        raise UsageError(
            f"the friction model {cls.__name__} has the name {name!r}; give it a name attribute made of letters, "
            "digits and underscores, other than 'auto'"
        )
    if inspect.isabstract(cls):
        missing = ", ".join(sorted(cls.__abstractmethods__))
        raise UsageError(f"the friction model {cls.__name__} does not define {missing}; define it")
    required = [
        p.name
        for p in inspect.signature(cls).parameters.values()
        if p.default is inspect.Parameter.empty and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)
    ]
    if required:
        raise UsageError(
            f"the friction model {cls.__name__} needs the arguments {', '.join(required)}; give every constructor "
            "argument a default (a model file rebuilds it without arguments)"
        )
    FRICTION_MODELS.add(name, cls, replace=replace)
    return cls


def friction_model(name: str, **options: Any) -> FrictionModel:
    """A new, unfitted single-joint friction model by name.

    Parameters
    ----------
    name : str
        One of :data:`FRICTION_MODELS`.
    **options
        Constructor arguments of that model.
    """
    if name not in FRICTION_MODELS:
        raise UsageError(
            f"unknown friction model {name!r}; choose one of {', '.join(FRICTION_MODELS)} (or register one with "
            "register_friction_model)"
        )
    return FRICTION_MODELS[name](**options)


class FrictionLayer:
    """One friction model per joint: ``fit(dq, F)`` on (m, n) arrays, ``predict(dq) -> (m, n)``.

    Parameters
    ----------
    model : str
        Friction model of every joint: a name of :data:`FRICTION_MODELS` (the table of the module
        docstring, and any model registered with :func:`register_friction_model`).
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

    def _check_fitted(self) -> None:
        check_is_fitted(self, "models_", call="fit(dq, F)")

    def _speeds(self, dq: ArrayLike) -> NDArray[np.float64]:
        """Joint velocities (m, n) checked against the fitted joints."""
        self._check_fitted()
        dq = np.atleast_2d(np.asarray(dq, dtype=np.float64))
        if dq.shape[1] != len(self.models_):
            raise DataError(
                f"dq has {dq.shape[1]} columns; the friction layer has {len(self.models_)} joints"
            )
        return dq

    @one_blas_thread
    def fit(
        self, dq: ArrayLike, F: ArrayLike, *, prepared: Any = None, around: FrictionLayer | None = None
    ) -> FrictionLayer:
        """Fit one model per joint.

        Parameters
        ----------
        dq : array_like, shape (m, n) or (M, n)
            Joint velocities (rad/s): at the samples of ``F``, or at full rate (``prepared.dq``) with
            ``prepared``.
        F : array_like, shape (m, n)
            Estimated friction torques (N m).
        prepared : Prepared, optional
            The preprocessing of the data (:func:`dynid.data.preparation.prepare`).  Given, the
            models are fitted as they will predict the filtered torque: evaluated at full rate,
            filtered like the torque and taken at ``prepared.rows`` (the rows of ``F``).  See the
            module docstring.
        around : FrictionLayer, optional
            An earlier fit of the same model: each joint's shape parameter is searched near its value.
        """
        dq_in = dq
        self.__dict__.pop("_filtered_basis", None)
        dq = np.atleast_2d(np.asarray(dq, dtype=np.float64))
        F = np.atleast_2d(np.asarray(F, dtype=np.float64))
        sampling = None
        if prepared is not None:
            sampling = _Sampling(prepared)
            if dq.shape[1] != F.shape[1]:
                raise DataError(f"dq has {dq.shape[1]} columns but F has {F.shape[1]}; give one per joint")
        elif dq.shape != F.shape:
            raise DataError(f"dq has shape {dq.shape} but F has {F.shape}; give (m, n) arrays of one shape")

        def fit_joint(j: int) -> FrictionModel | DataError:
            try:
                mdl = friction_model(self.model, **(self.options or {}))
                hint = None
                if around is not None and around.model == self.model and isinstance(mdl, _ShapedFriction):
                    hint = float(around.models_[j].coef_[-1])
                return mdl.fit(dq[:, j], F[:, j], sampling=sampling, around=hint)
            except DataError as err:
                return DataError(f"joint {j + 1}: {err}")

        # The joints are independent, and their searches spend most of their time in filtering, QR and
        # large array operations that release the GIL: two threads fit two joints at once on 2 cores
        # (the same CPU time and the same result, bit for bit, as one after the other).
        workers = min(dq.shape[1], JOINT_THREADS)  # the result does not depend on it
        if workers > 1:
            with ThreadPoolExecutor(max_workers=workers) as pool:
                models = list(pool.map(fit_joint, range(dq.shape[1])))
        else:
            models = [fit_joint(j) for j in range(dq.shape[1])]
        for mdl in models:
            if isinstance(mdl, DataError):
                raise mdl
        self.models_ = models
        self.rms_ = np.array([mdl.rms_ for mdl in models])
        self.filtered_ = prepared is not None
        kept = [mdl.__dict__.pop("_filtered_basis", None) for mdl in models]
        if prepared is not None and dq_in is prepared.dq and all(a is not None for a in kept):
            self._filtered_basis = (prepared, kept)
        return self

    def filtered_basis(self, prepared: Any) -> list[NDArray[np.float64]]:
        """``basis(prepared.dq)`` filtered like the torque and taken at ``prepared.rows``: list of (m, k_j).

        A layer just fitted on ``prepared.dq`` with ``prepared`` filtered these columns for its final
        coefficients already: the first call returns those (the same values) and lets them go.

        Parameters
        ----------
        prepared : Prepared
            The preprocessing of the data (:func:`dynid.data.preparation.prepare`).
        """
        kept = self.__dict__.pop("_filtered_basis", None)
        if kept is not None and kept[0] is prepared:
            return kept[1]
        return [prepared.filter(B)[prepared.rows] for B in self.basis(prepared.dq)]

    def basis(self, dq: ArrayLike) -> list[NDArray[np.float64]]:
        """Per joint, the columns of its linear coefficients at the fitted shapes: list of (m, k_j).

        Parameters
        ----------
        dq : array_like, shape (m, n)
            Joint velocities (rad/s).
        """
        dq = self._speeds(dq)
        return [mdl.basis(dq[:, j]) for j, mdl in enumerate(self.models_)]

    def set_linear(self, coefs: list[ArrayLike]) -> None:
        """Replace the linear coefficients of every joint (see :meth:`basis`), kept within their bounds.

        Parameters
        ----------
        coefs : list of array_like
            One array per joint, in the order of :meth:`basis`.
        """
        for mdl, c in zip(self.models_, coefs, strict=True):
            mdl.set_linear(c)

    def predict(self, dq: ArrayLike) -> NDArray[np.float64]:
        """Friction torques (N m), shape (m, n).

        Parameters
        ----------
        dq : array_like, shape (m, n)
            Joint velocities (rad/s).
        """
        dq = self._speeds(dq)
        return np.column_stack([mdl.predict(dq[:, j]) for j, mdl in enumerate(self.models_)])

    def to_dict(self) -> dict[str, Any]:
        """``{"model": name, "joints": [coef dict per joint]}`` (JSON-ready)."""
        self._check_fitted()
        return {"model": self.model, "joints": [mdl.to_dict()["coef"] for mdl in self.models_]}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> FrictionLayer:
        """A fitted layer from :meth:`to_dict`'s output.

        Parameters
        ----------
        data : dict
            ``{"model": name, "joints": [{coef name: value}, ...]}``.
        """
        name = data.get("model") if isinstance(data, dict) else None
        if isinstance(name, str) and name not in FRICTION_MODELS:
            raise ModelFileError(
                f"the model file's friction model {name!r} is not registered (the models are "
                f"{', '.join(FRICTION_MODELS)}); register its class with register_friction_model before loading"
            )
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
                if hasattr(mdl, "_restore"):
                    mdl._restore(coef)
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
