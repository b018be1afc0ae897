"""A model's validation on held-out data, as :func:`dynid.validation.validate.validate` returns it.

:class:`ValidationResult` holds the prediction split into its layers (rigid body, friction, GMM), the
measured torque as compared, the error figures and the noise floor; :func:`describe_model` names a
model's three layers in one line for its tables.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dynid.identify.model import IdentifiedModel
from dynid.validation.metrics import NoiseFloor

__all__ = ["ValidationResult", "describe_model"]


def _finite(values: NDArray[np.float64]) -> list[float | None]:
    return [float(v) if np.isfinite(v) else None for v in np.ravel(values)]


def describe_model(model: IdentifiedModel) -> str:
    """One line naming a model's three layers, e.g. ``consistent + seed friction + GMM (joints 1, 2)``.

    Parameters
    ----------
    model : IdentifiedModel
        The model.
    """
    parts = [model.method]
    if model.friction is None:
        parts.append("no friction")
    elif model.friction_source == "layer1":
        parts.append("linear friction")
    else:
        parts.append(f"{model.friction.model} friction")
    if model.gmr is None:
        parts.append("no GMM")
    elif model.gmr.active_.any():
        parts.append("GMM (joints " + ", ".join(str(j + 1) for j in np.flatnonzero(model.gmr.active_)) + ")")
    else:
        parts.append("GMM (no joint helped)")
    return " + ".join(parts)


@dataclass(frozen=True, eq=False)
class ValidationResult:
    """A model's prediction of held-out data, split into layers, with its error figures.

    Attributes
    ----------
    label : str
        Name of the model in tables and legends.
    model : IdentifiedModel
        The model validated.
    t : ndarray, shape (m,)
        Time stamps of the compared samples (s).
    q, dq : ndarray, shape (m, n)
        States there (rad, rad/s), as reconstructed by the model's preprocessing.
    tau : ndarray, shape (m, n)
        Measured torque as compared (N m): treated as described by ``reference``.
    tau_pred : ndarray, shape (m, n)
        Predicted torque (N m); ``tau_link + tau_friction + tau_gmm``.
    tau_link, tau_friction, tau_gmm : ndarray, shape (m, n)
        Rigid-body, friction and GMM parts of the prediction (N m).
    metrics : dict
        :func:`dynid.validation.metrics.torque_metrics` of ``tau`` against ``tau_pred``.
    metrics_before_gmm : dict
        The same without the GMM part.
    noise : NoiseFloor
        Measured noise floor of ``tau``.
    reference : str
        How the measured torque was treated ("raw", "filtered and trimmed", ...).
    data : str
        Where the data came from (a file name or a description).
    info : dict
        Anything else worth reporting (the model file, ...).
    """

    label: str
    model: IdentifiedModel
    t: NDArray[np.float64]
    q: NDArray[np.float64]
    dq: NDArray[np.float64]
    tau: NDArray[np.float64]
    tau_pred: NDArray[np.float64]
    tau_link: NDArray[np.float64]
    tau_friction: NDArray[np.float64]
    tau_gmm: NDArray[np.float64]
    metrics: dict[str, Any]
    metrics_before_gmm: dict[str, Any]
    noise: NoiseFloor
    reference: str
    data: str
    info: dict[str, Any] = field(default_factory=dict)

    @property
    def n(self) -> int:
        """Number of joints."""
        return self.tau.shape[1]

    @property
    def residual(self) -> NDArray[np.float64]:
        """``tau - tau_pred`` (N m), shape (m, n)."""
        return self.tau - self.tau_pred

    @property
    def residual_before_gmm(self) -> NDArray[np.float64]:
        """``tau - tau_link - tau_friction`` (N m): the residual the GMM layer is given."""
        return self.tau - self.tau_link - self.tau_friction

    @property
    def friction_estimate(self) -> NDArray[np.float64]:
        """``tau - tau_link`` (N m): the friction torque the data show, as layer 2 sees it."""
        return self.tau - self.tau_link

    @property
    def has_gmm(self) -> bool:
        """Whether the model's GMM layer corrects at least one joint."""
        return self.model.gmr is not None and bool(self.model.gmr.active_.any())

    def summary(self) -> dict[str, Any]:
        """The figures of this model alone (a row of a comparison): JSON-ready."""
        m = self.metrics
        return {
            "label": self.label,
            "description": describe_model(self.model),
            "method": self.model.method,
            "friction": "none" if self.model.friction is None else self.model.friction.model,
            "friction_source": self.model.friction_source,
            "gmm": self.has_gmm,
            "cond": float(self.model.cond) if np.isfinite(self.model.cond) else None,
            "rms": _finite(m["rms"]),
            "rms_mean": float(m["rms_mean"]),
            "nrms": _finite(m["nrms"]),
            "r2": _finite(m["r2"]),
            "max_error": _finite(m["max_error"]),
            "rms_before_gmm": _finite(self.metrics_before_gmm["rms"]),
            "rms_mean_before_gmm": float(self.metrics_before_gmm["rms_mean"]),
            **({"model_file": self.info["model_file"]} if "model_file" in self.info else {}),
        }

    def figures(self) -> dict[str, Any]:
        """The ``dynid validate`` figures (DESIGN.md): JSON-ready.

        Keys: ``rms`` (per joint, N m), ``rms_mean``, ``nrms``, ``r2``, ``max_error``, ``noise_floor``
        (per joint, N m), ``noise_floor_mean``, ``noise_floor_method``, ``noise_floor_detail``,
        ``rms_over_noise``, ``reference``, ``n_samples``, ``duration_s``, ``data``, ``robot``, and the
        model's ``label``, ``description``, ``method``, ``cond``, ``rms_before_gmm``.
        """
        row = self.summary()
        std = self.noise.std
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.where(std > 0, self.metrics["rms"] / std, np.where(std == 0, np.inf, np.nan))
        return {
            **row,
            "noise_floor": _finite(self.noise.std),
            "noise_floor_mean": _finite(np.array([self.noise.rms_mean]))[0],
            "noise_floor_method": self.noise.method,
            "noise_floor_detail": self.noise.detail,
            "rms_over_noise": _finite(ratio),
            "reference": self.reference,
            "n_samples": int(self.t.size),
            "duration_s": float(self.t[-1] - self.t[0]) if self.t.size else 0.0,
            "data": self.data,
            "robot": self.model.robot.name,
        }
