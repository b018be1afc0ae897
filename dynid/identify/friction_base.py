"""The base of the single-joint friction models, and their registration by name.

:class:`FrictionModel` (fit, predict, the linear part at the fitted shape, the model file's
coefficients, what a simulator holds of a fit), :func:`register_friction_model` (a model of one's own
into :data:`~dynid.identify.registry.FRICTION_MODELS`) and :func:`friction_model` (a new model by
name).  The built-in models are :mod:`dynid.identify.friction_models`; the per-joint layer and the
table of models, :mod:`dynid.identify.friction`.
"""

from __future__ import annotations

import inspect
from abc import ABC, abstractmethod
from typing import Any, ClassVar, Self

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dynid._threads import one_blas_thread
from dynid.exceptions import UsageError
from dynid.identify.checks import check_is_fitted
from dynid.identify.friction_fitting import Sampling, bounded_lsq, checked_inputs
from dynid.identify.registry import FRICTION_MODELS

__all__ = ["FrictionModel", "friction_model", "register_friction_model"]


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
        self, dq: ArrayLike, F: ArrayLike, *, sampling: Sampling | None = None, around: float | None = None
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
        dq, F, dq_k = checked_inputs(dq, F, sampling, self._min_samples, self.name)
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

    def simulator_line(self, speeds: ArrayLike) -> tuple[float, float]:
        """The viscous coefficient and Coulomb level whose line is closest to this fit at ``speeds``.

        Least squares, both >= 0, of the fit's odd part ``(F(v) - F(-v)) / 2`` against ``fc + fv v`` at the
        given speeds (equal-probability samples of the training ``|dq|``): what a simulator holding only
        ``damping`` and ``frictionloss`` keeps best of a nonlinear model, where the arm moved.  A model's
        offset (its even part) has no simulator field either way.

        Parameters
        ----------
        speeds : array_like, shape (k,)
            Joint speeds (rad/s, >= 0).

        Returns
        -------
        damping, frictionloss : float
        """
        v = np.abs(np.asarray(speeds, dtype=np.float64).ravel())
        odd = 0.5 * (self.predict(v) - self.predict(-v))
        coef, _ = bounded_lsq(np.column_stack([np.ones_like(v), v]), odd, (0.0, 0.0))
        return float(coef[1]), float(coef[0])

    def _fit(
        self,
        dq: NDArray[np.float64],
        F: NDArray[np.float64],
        dq_k: NDArray[np.float64],
        sampling: Sampling | None,
        around: float | None,
    ) -> None:
        """Fit on checked inputs (see :func:`checked_inputs`) and store the result with :meth:`_set`.

        Default: the bounded least squares of :meth:`columns` (a model linear in all its coefficients).
        """
        coef, rss = self._fit_columns(self.columns, dq, F, sampling, self.bounds)
        self._set(coef, rss, len(F))

    def _fit_columns(
        self,
        columns,
        dq: NDArray[np.float64],
        F: NDArray[np.float64],
        sampling: Sampling | None,
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
