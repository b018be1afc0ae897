"""Layer 2: joint friction models fitted to ``F_est = tau - tau_link``, in scikit-learn style.

Each model fits one joint: ``model.fit(dq, F)`` with ``dq`` (m,) in rad/s and ``F`` (m,) in N m,
then ``model.predict(dq) -> F``.  :class:`FrictionLayer` fits one model per joint on (m, n) arrays.

The models and their names are in :mod:`dynid.identify.friction_models` (its table) and
:data:`FRICTION_MODELS` (:mod:`dynid.identify.registry`); a model of one's own subclasses
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

This module holds the per-joint layer (:class:`FrictionLayer`) and gives every public name of the
friction models: their base and registration are :mod:`dynid.identify.friction_base`, the built-in
models :mod:`dynid.identify.friction_models`, and the least squares, shape searches and filtering of
their fits :mod:`dynid.identify.friction_fitting`.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dynid._threads import one_blas_thread
from dynid.exceptions import DataError, ModelFileError
from dynid.identify.checks import check_is_fitted
from dynid.identify.friction_base import FrictionModel, friction_model, register_friction_model
from dynid.identify.friction_fitting import Sampling, bounded_lsq
from dynid.identify.friction_models import (
    LinearFriction,
    NoFriction,
    SeedFriction,
    ShapedFriction,
    SigmoidFriction,
    StribeckFriction,
)
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
            sampling = Sampling(prepared)
            if dq.shape[1] != F.shape[1]:
                raise DataError(f"dq has {dq.shape[1]} columns but F has {F.shape[1]}; give one per joint")
        elif dq.shape != F.shape:
            raise DataError(f"dq has shape {dq.shape} but F has {F.shape}; give (m, n) arrays of one shape")

        # One joint after the other: two threads, one joint each, cost more CPU and wall time than this
        # loop (their searches are many small array operations that hold the interpreter lock; see
        # dynid.identify.refine._per_joint).
        models = []
        for j in range(dq.shape[1]):
            try:
                mdl = friction_model(self.model, **(self.options or {}))
                hint = None
                if around is not None and around.model == self.model and isinstance(mdl, ShapedFriction):
                    hint = float(around.models_[j].coef_[-1])
                models.append(mdl.fit(dq[:, j], F[:, j], sampling=sampling, around=hint))
            except DataError as err:
                raise DataError(f"joint {j + 1}: {err}") from None
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
