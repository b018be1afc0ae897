"""The identified model: :class:`IdentifiedModel`, what :func:`dynid.identify.model.identify` returns.

>>> tau = model.predict(q, dq, ddq)             # or model.predict(dataset)
>>> model.figures()                             # what the model file shows (dynid.identify.model_file)

Prediction on a dataset repeats the identification's preprocessing: every layer is evaluated on the
states at full rate and filtered like the torque (parallel filtering), then taken at the kept samples.
Compare the result with :meth:`IdentifiedModel.prepare` ``(ds).tau_reference``.  (Models written before
the layers were filtered, ``layers_filtered`` false, add layers 2 and 3 unfiltered at the kept samples.)
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dynid._io import to_jsonable
from dynid.data.dataset import Dataset
from dynid.data.preparation import Prepared, Preprocessing, prepare
from dynid.exceptions import UsageError
from dynid.identify.columns import ColumnSet, column_set, linear_torque
from dynid.identify.consistent import link_inertials
from dynid.identify.effect_terms import (
    Candidate,
    FeatureSource,
    effect_to_dict,
    effect_values,
    needs_time,
    needs_torque,
)
from dynid.identify.estimators import IdentificationWarning
from dynid.identify.friction import FrictionLayer
from dynid.identify.gmr import GMRCorrection
from dynid.identify.prior import link_report

__all__ = ["IdentifiedModel"]


@dataclass(frozen=True, eq=False)
class IdentifiedModel:
    """An identified robot model: predicts joint torques from states or from a dataset.

    Attributes
    ----------
    robot : RobotModel
        The robot it was identified for.
    columns : ColumnSet
        Layer-1 parameters (names, kinds, expressions).
    params : ndarray, shape (p,)
        Layer-1 parameter values (SI).
    cov : ndarray, shape (p, p)
        Their covariance.
    method : str
        Layer-1 method.
    preprocessing : dict
        Resolved preprocessing settings (applied again by :meth:`predict` on a dataset).
    friction : FrictionLayer or None
        Friction model; with ``friction_source == "layer1"`` it restates the layer-1 coefficients.
    friction_source : str
        ``"layer1"`` (linear friction identified with the links), ``"layer2"`` (refitted) or ``"none"``.
    gmr : GMRCorrection or None
        Layer-3 correction.
    cond : float
        Condition number of the weighted regressor.
    rms : ndarray, shape (n,)
        Residual RMS per joint (N m) of the whole model on the identification data.
    rms_layers : dict
        RMS per joint after each layer: ``link``, ``friction``, ``gmm``.
    info : dict
        Everything else reported (samples, notes, IRLS iterations, consistency distance, GMM state).
    layers_filtered : bool
        Whether friction and correction are filtered like the torque in :meth:`predict` on a dataset
        (True for models identified by this version; False: added unfiltered at the kept samples).
    effect_reference : ndarray, shape (p0,), or None
        Parameters of the first fit without effect terms (base columns and extras of ``columns``),
        whose torque the effects of :data:`dynid.identify.effect_terms.TAU_EFFECTS` are built from.
    """

    robot: Any
    columns: ColumnSet
    params: NDArray[np.float64]
    cov: NDArray[np.float64]
    method: str
    preprocessing: dict[str, Any]
    friction: FrictionLayer | None
    friction_source: str
    gmr: GMRCorrection | None
    cond: float
    rms: NDArray[np.float64]
    rms_layers: dict[str, list[float]]
    info: dict[str, Any] = field(default_factory=dict)
    layers_filtered: bool = False
    effect_reference: NDArray[np.float64] | None = None

    @property
    def std(self) -> NDArray[np.float64]:
        """Standard deviation of each layer-1 parameter."""
        return np.sqrt(np.maximum(np.diag(self.cov), 0.0))

    @property
    def std_percent(self) -> NDArray[np.float64]:
        """Standard deviation in % of ``|params|`` (inf for a zero value)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(np.abs(self.params) > 0, 100.0 * self.std / np.abs(self.params), np.inf)

    @property
    def filtered_mask(self) -> NDArray[np.bool_]:
        """Layer-1 parameters in the filtered part of a prediction (rigid body, and layer-1 friction)."""
        mask = self.columns.link_mask.copy()
        if self.friction_source == "layer1":
            mask |= self.columns.friction_mask
        return mask

    def prepare(self, ds: Dataset) -> Prepared:
        """Preprocess a dataset as the identification data were.

        Parameters
        ----------
        ds : Dataset
            Data of the same robot.
        """
        return prepare(ds, Preprocessing.from_settings(self.preprocessing), n_joints=self.robot.n)

    def _friction_torque(self, dq: NDArray[np.float64]) -> NDArray[np.float64]:
        if self.friction is not None and self.friction_source == "layer2":
            return self.friction.predict(dq)
        return np.zeros_like(dq)

    def _correction(self, q: NDArray[np.float64], dq: NDArray[np.float64]) -> NDArray[np.float64]:
        if self.gmr is not None:
            return self.gmr.predict(np.hstack([q, dq]))
        return np.zeros_like(q)

    def _direct(self, q: NDArray[np.float64], dq: NDArray[np.float64]) -> NDArray[np.float64]:
        return self._friction_torque(dq) + self._correction(q, dq)

    def _check_range(self, q: NDArray[np.float64], dq: NDArray[np.float64]) -> None:
        """Warn when a motion takes a corrected joint well beyond the states its correction was fitted on."""
        if self.gmr is None or not self.gmr.active_.any():
            return
        u = np.hstack([q, dq])
        n = q.shape[1]
        out = []
        for mdl in self.gmr.models_:
            if not self.gmr.active_[mdl["outputs"]].any():
                continue
            lo, hi = np.asarray(mdl["lo"]), np.asarray(mdl["hi"])
            margin = 0.05 * (hi - lo)
            for i, c in enumerate(np.asarray(mdl["inputs"])):
                v = u[:, c]
                if v.min() < lo[i] - margin[i] or v.max() > hi[i] + margin[i]:
                    label = f"q_{c + 1}" if c < n else f"dq_{c - n + 1}"
                    out.append(
                        f"{label} spans {v.min():.3g}..{v.max():.3g} (fitted on {lo[i]:.3g}..{hi[i]:.3g})"
                    )
        if out:
            warnings.warn(
                "the motion leaves the states the GMM correction was fitted on: "
                + "; ".join(dict.fromkeys(out))
                + "; there the correction fades to zero (the physical layers predict alone) and the link "
                "parameters fitted with it may be off: identify on data that cover this motion's workspace",
                IdentificationWarning,
                stacklevel=3,
            )

    @property
    def effects(self) -> tuple[Candidate, ...]:
        """The effect terms of the model (:mod:`dynid.identify.effect_terms`)."""
        return tuple(self.columns.effects)

    def effect_columns(self, q, dq, ddq, *, t=None, runs=None, fs=None) -> NDArray[np.float64] | None:
        """Columns (m, n, k) of the model's effect terms at these states; None without effect terms.

        Parameters
        ----------
        q, dq, ddq : ndarray, shape (m, n)
            States at a uniform rate.
        t : ndarray, shape (m,), optional
            Their time stamps (s); needed by the effects of
            :data:`dynid.identify.effect_terms.TIME_EFFECTS`.
        runs : list of slice, optional
            Runs within which to differentiate (default one run).
        fs : float, optional
            Sampling rate (Hz); default from ``t``.
        """
        terms = self.effects
        if not terms:
            return None
        q, dq, ddq = (np.atleast_2d(np.asarray(v, dtype=np.float64)) for v in (q, dq, ddq))
        m = len(q)
        if t is None:
            if needs_time(terms):
                slow = [
                    tm.key for tm in terms if tm.effect in ("temperature", "delay", "elasticity", "backlash")
                ]
                raise UsageError(
                    f"the effect terms {', '.join(slow)} need time stamps; predict from a Dataset (model.predict(ds)) "
                    "instead of (q, dq, ddq) arrays"
                )
            t = np.arange(m, dtype=np.float64)
        t = np.asarray(t, dtype=np.float64)
        if fs is None:
            fs = 1.0 / float(np.median(np.diff(t))) if m > 1 else 1.0
        tau_ref = np.zeros_like(q)
        if needs_torque(terms):
            base = column_set(self.robot, friction=self.columns.friction, armature=self.columns.armature)
            tau_ref = linear_torque(base, self.effect_reference, q, dq, ddq)
        src = FeatureSource(
            t=t - t[0],
            q=q,
            dq=dq,
            ddq=ddq,
            tau_pred=tau_ref,
            robot=self.robot,
            fs=float(fs),
            runs=list(runs) if runs is not None else [slice(0, m)],
        )
        return effect_values(src, terms)[0]

    def predict_parts(self, ds: Dataset, *, prep: Prepared | None = None) -> dict[str, NDArray[np.float64]]:
        """The prediction of a dataset split by layer, each treated as :meth:`predict` treats it.

        Parameters
        ----------
        ds : Dataset
            Data of the same robot.
        prep : Prepared, optional
            ``prepare(ds)`` when the caller has it already (it is not computed twice).

        Returns
        -------
        dict
            ``link`` (rigid body, and layer-1 friction when that is the friction model), ``friction``
            (layer 2), ``gmm`` (layer 3): (m, n) arrays at :meth:`prepare` ``(ds).rows`` (N m); their sum
            is :meth:`predict` ``(ds)``.
        """
        prep = self.prepare(ds) if prep is None else prep
        rows = prep.rows
        self._check_range(prep.q[rows], prep.dq[rows])
        values = self.effect_columns(prep.q, prep.dq, prep.ddq, t=prep.t, runs=prep.runs, fs=prep.fs)
        link = linear_torque(
            self.columns,
            self.params,
            prep.q,
            prep.dq,
            prep.ddq,
            mask=self.filtered_mask,
            effect_values=values,
        )
        if self.layers_filtered:
            fric = prep.filter(self._friction_torque(prep.dq))[rows]
            corr = prep.filter(self._correction(prep.q, prep.dq))[rows]
        else:
            fric = self._friction_torque(prep.dq[rows])
            corr = self._correction(prep.q[rows], prep.dq[rows])
        parts = {"link": prep.filter(link)[rows], "friction": fric, "gmm": corr}
        self._check_torque(parts["link"] + fric + corr)
        return parts

    def _check_torque(self, tau: NDArray[np.float64]) -> None:
        """Warn, in one sentence, when a prediction leaves the training torque's range by far.

        Far: beyond the range widened by twice its span on both sides.  A model whose base parameters
        are ill-determined (a CAD description's near-dependent columns, a motion that never excited
        them) can predict thousands of N m for an arm whose torque stays under ten: that is the sign.
        """
        seen = self.info.get("torque_range")
        if seen is None or tau.size == 0:
            return
        lo, hi = np.asarray(seen, dtype=np.float64).T
        span = np.maximum(hi - lo, 1e-9)
        far = (tau.min(axis=0) < lo - 2 * span) | (tau.max(axis=0) > hi + 2 * span)
        if not far.any():
            return
        joints = np.flatnonzero(far)
        below, above = (lo - tau.min(axis=0)) / span, (tau.max(axis=0) - hi) / span  # in spans beyond the range
        worst = joints[np.argmax(np.maximum(below, above)[joints])]
        # the extreme on the side that leaves the range (a joint trained on 12..18 N m may predict -13)
        reach = f"down to {tau[:, worst].min():.4g}" if below[worst] >= above[worst] else f"up to {tau[:, worst].max():.4g}"
        warnings.warn(
            f"the prediction leaves the training torque's range by far on joint(s) "
            f"{', '.join(str(j + 1) for j in joints)} (joint {worst + 1}: {reach} N m, trained on "
            f"{lo[worst]:.3g}..{hi[worst]:.3g} N m): the model "
            "extrapolates, from parameters the training motion did not determine or a motion unlike it; check "
            "the parameters' standard deviations, or identify on a motion that covers this one",
            IdentificationWarning,
            stacklevel=3,
        )

    def predict(self, q, dq=None, ddq=None) -> NDArray[np.float64]:
        """Joint torques (N m).

        Parameters
        ----------
        q : ndarray, shape (m, n), or Dataset
            Joint angles (rad); or a dataset, preprocessed as the identification data were: the result
            then holds :meth:`prepare` ``(ds).rows``, to compare with ``prepare(ds).tau_reference``.
        dq, ddq : ndarray, shape (m, n)
            Joint velocities (rad/s) and accelerations (rad/s^2); not given with a dataset.

        Returns
        -------
        ndarray, shape (m, n)
        """
        if isinstance(q, Dataset):
            parts = self.predict_parts(q)
            return parts["link"] + parts["friction"] + parts["gmm"]
        if dq is None or ddq is None:
            raise UsageError("predict takes (q, dq, ddq) arrays or one Dataset; dq and ddq are missing")
        values = self.effect_columns(q, dq, ddq)
        link = linear_torque(
            self.columns, self.params, q, dq, ddq, mask=self.filtered_mask, effect_values=values
        )
        out = link + self._direct(np.atleast_2d(np.asarray(q, float)), np.atleast_2d(np.asarray(dq, float)))
        self._check_torque(out)
        return out

    # ------------------------------------------------------------------ figures
    def _effect_figures(self) -> list[dict[str, Any]]:
        """Each effect term with its hyper-parameters, coefficients and their standard deviations."""
        cols = self.columns
        if not cols.n_effect:
            return []
        idx = np.flatnonzero(cols.effect_mask)
        std = self.std
        out = []
        for i, term in enumerate(cols.effects):
            mine = idx[cols.effect_owner == i]
            out.append(
                {
                    **effect_to_dict(term),
                    "coefficients": {cols.names[k].rsplit(".", 1)[1]: float(self.params[k]) for k in mine},
                    "std": {cols.names[k].rsplit(".", 1)[1]: float(std[k]) for k in mine},
                }
            )
        return out

    def figures(self) -> dict[str, Any]:
        """The JSON-ready figures of the model (the model file without its bookkeeping)."""
        cols = self.columns
        std, pct = self.std, self.std_percent
        return {
            "robot": {
                "name": self.robot.name,
                "source": self.robot.source,
                "key": self.robot.key,
                "n": self.robot.n,
                "joint_names": list(self.robot.joint_names),
                "transmission": None
                if getattr(self.robot, "transmission", None) is None
                else np.asarray(self.robot.transmission).tolist(),
            },
            "method": self.method,
            "layer1": {"friction": cols.friction, "armature": cols.armature},
            "effects": self._effect_figures(),
            "preprocessing": self.preprocessing,
            "parameters": [
                {
                    "name": name,
                    "expression": expr,
                    "kind": kind,
                    "value": float(v),
                    "std": float(s),
                    "std_percent": to_jsonable(float(pc)),
                }
                for name, expr, kind, v, s, pc in zip(
                    cols.names, cols.expressions, cols.kinds, self.params, std, pct, strict=True
                )
            ],
            "base_params": {name: float(v) for name, v in zip(cols.names, self.params, strict=True)},
            "std": {name: float(s) for name, s in zip(cols.names, std, strict=True)},
            "std_percent": {name: to_jsonable(float(pc)) for name, pc in zip(cols.names, pct, strict=True)},
            "cond": float(self.cond),
            "layers_filtered": bool(self.layers_filtered),
            "rms": [float(v) for v in self.rms],
            "rms_mean": float(np.mean(self.rms)),
            "rms_layers": self.rms_layers,
            "friction": {
                "model": "none" if self.friction is None else self.friction.model,
                "source": self.friction_source,
                "joints": [] if self.friction is None else self.friction.to_dict()["joints"],
            },
            "gmm": None
            if self.gmr is None
            else {
                "mode": self.gmr.mode,
                "n_components": [int(k) for k in self.gmr.n_components_],
                "active": [bool(a) for a in self.gmr.active_],
                "fallback": self.gmr.fallback_,
                "validation": getattr(self.gmr, "validation_", None),
                "validation_rms": self.info.get("gmm_validation_rms"),
            },
            **{k: v for k, v in self.info.items() if k != "gmm_validation_rms"},
            "links": self.links(),
        }

    @property
    def standard_params(self) -> NDArray[np.float64] | None:
        """Consistent standard parameters of the links, shape (n, 10) (kg, kg m, kg m^2 about each link
        frame's origin), or None for an unconstrained fit (and model files before version 3 made without
        the method ``consistent``)."""
        c = self.info.get("consistency")
        if not c or "standard_params" not in c:
            return None
        return np.asarray(c["standard_params"], dtype=np.float64).reshape(self.robot.n, 10)

    def links(self) -> list[dict[str, Any]] | None:
        """Each link's body as a URDF inertial takes it (:func:`dynid.identify.consistent.link_inertials`),
        with ``name`` (its joint), ``at_bound``, and how far it moved from the description and what
        decided it (:func:`dynid.identify.prior.link_report`: ``mass_description``, ``mass_ratio``,
        ``com_shift``, ``divergence``, ``data_share``, ``decided_by``: ``bound`` for a link the description
        would decide that sits at the consistency bound); None without consistent standard parameters."""
        phi = self.standard_params
        if phi is None:
            return None
        held = set(self.info["consistency"].get("at_bound", []))
        share = (self.info.get("prior") or {}).get("data_share")
        moved = link_report(self.robot, phi, None if share is None else np.asarray(share, dtype=np.float64))
        keys = ("mass_description", "mass_ratio", "com_shift", "divergence", "data_share", "decided_by")
        out = [
            {"joint": name, **body, "at_bound": j + 1 in held, **{k: moved[j][k] for k in keys}}
            for j, (name, body) in enumerate(zip(self.robot.joint_names, link_inertials(phi), strict=True))
        ]
        for body in out:
            # a link the data hardly see, held at the consistency bound: the bound moved it (the data moved the
            # links it shares base parameters with), not the description (a Z1's first link at 1.8x its mass)
            if body["at_bound"] and body["decided_by"] in ("description", "shared"):
                body["decided_by"] = "bound"
        return out
