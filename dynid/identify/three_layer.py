"""The three-layer identification: :class:`ThreeLayerModel` (what :func:`dynid.identify.model.identify` runs).

The layers, and how they are refitted together, are described in :mod:`dynid.identify.model`.
The thresholds that guard the mixture and the figures the fit reports are
:mod:`dynid.identify.fit_figures`; the result is an :class:`~dynid.identify.identified.IdentifiedModel`.
"""

from __future__ import annotations

import hashlib
import inspect
from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dynid._memory import give_back
from dynid._progress import say
from dynid._threads import single_blas_thread
from dynid.data.dataset import Dataset
from dynid.data.preparation import Preprocessing
from dynid.exceptions import DynidError, UsageError
from dynid.identify.columns import ColumnSet, coupled_pairs, linear_torque, robot_coupling
from dynid.identify.consistent import ConsistentLS, consistent_projection
from dynid.identify.effect_terms import (
    Candidate,
    EffectColumns,
    FeatureSource,
    coefficient_names,
    effect_values,
    parse_effect_terms,
    tune_terms,
)
from dynid.identify.estimators import (
    ESTIMATORS,
    LinkEstimator,
    bounded_triangular,
    check_is_fitted,
    physical_lower_bounds,
)
from dynid.identify.fit_figures import (
    TAKEOVER,
    TAKEOVER_GAIN,
    TAKEOVER_SHARE,
    at_bound,
    bounds_info,
    cap_mixture,
    consistency_figures,
    joint_rms,
    layer1_friction,
    speed_quantiles,
    warn_unexplained,
)
from dynid.identify.friction import FRICTION_MODELS, FrictionLayer
from dynid.identify.gmr import GMRCorrection
from dynid.identify.identified import IdentifiedModel
from dynid.identify.linear_system import build_system, forget_shared, sharing_systems
from dynid.identify.prior import PriorChoice, choose_prior
from dynid.identify.refine import refine
from dynid.identify.registry import method_names

__all__ = ["ThreeLayerModel", "data_fingerprint"]


FOLD_IRLS_STEPS = 50
"""Most IRLS steps of a fit that scores a candidate pipeline on a fold.

IRLS converges linearly (:class:`~dynid.identify.estimators.IRLS`): 50 steps leave the whole TX40
recording 0.57 standard deviation from the fixed point it reaches in 225.  The folds rank pipelines, and
an estimate within a standard deviation ranks them alike: on the unseen-arms benchmark every choice was
the same with 50 and with 300 steps, for about 0.2 s less on the TX40 split."""


class ThreeLayerModel:
    """Link parameters, friction and a mixture-regression correction, identified in three layers.

    Parameters
    ----------
    robot : RobotModel
        The robot that recorded the data.
    method : str
        Layer-1 method: a weighting of :data:`~dynid.identify.registry.ESTIMATORS` (``ols``, ``irls``, ...)
        or ``consistent`` (IRLS weighting with physically consistent links).  ``"auto"`` (default): the
        pipeline chosen from the recording (:mod:`dynid.identify.pipeline`): among OLS or IRLS with linear
        friction, OLS with the paper's friction and the paper's IRLS + nonlinear friction + mixture, the
        simplest within 5 points of the one that predicts each half of the training recording from the
        other best (none with a joint more than 5 % worse than OLS with linear friction), with a drive
        gain on the joints that earn one (:func:`dynid.identify.pipeline.choose_gains`);
        ``model_.info["pipeline"]`` records the choice and its reason.
    friction : str
        Friction model (layer 2): a name of :data:`~dynid.identify.registry.FRICTION_MODELS` (``none``,
        ``seed``, ...); ``linear`` keeps the coefficients identified with the links.  ``"auto"``
        (default): chosen with ``method="auto"``, else ``seed`` (the paper's).
    gmm : "off" or "auto" or int
        Layer 3: off, mixture size by validation, or a fixed number of components.
    preprocessing : Preprocessing, optional
        Filtering, differentiation, trimming, decimation (default :class:`Preprocessing`).
    armature : bool
        Identify the armature with the link parameters.
    reference_weight : float or "auto"
        Pull of the physically consistent links toward the description's (URDF / DH) bodies, in
        squared standard deviations of the data per unit of entropic divergence
        (:mod:`dynid.identify.prior`).  ``"auto"`` (default): the strongest pull whose blocked
        cross-validated mean relative error on the training recording stays within 2 % of the best,
        so the description stands wherever the data do not measurably predict better without it.
        0: only the directions the data cannot see at all keep the description.
    gmm_mode : {"position", "own", "per_joint", "vector"}
        Inputs of the mixture regression (see :class:`GMRCorrection`); default ``position``, each
        joint's own angle.
    random_state : int
        Seed of the mixture's EM.
    rounds : int
        Rounds in which the layers are refitted together (:mod:`dynid.identify.refine`; default 2).
        0: the paper's sequence, each layer fitted once on what the previous one left.
    effects : str or sequence, optional
        Effects of the catalogue added as identified terms, ``"coupled_friction@5+6,stribeck@3"``
        (:func:`dynid.identify.effect_terms.parse_effect_terms`), refitted with the link parameters; their
        hyper-parameters, when not given, are tuned on the training data.
    drive_gains : bool
        With ``method="auto"`` and no ``effects``, a drive gain (``drive_gain@j``: the measured torque a
        constant times the model's) on each joint whose gain the recording shows and its folds confirm
        (:func:`dynid.identify.pipeline.choose_gains`; default).  False: none, for a model whose bodies
        go into a description that cannot carry a gain (a URDF).
    physical : bool
        Keep armature, Coulomb and viscous coefficients non-negative (default; bounded-variable least
        squares on the same weighted system).  False: the unconstrained fit.  ``info["bounds"]`` names
        the parameters held at a bound.

    Attributes
    ----------
    model_ : IdentifiedModel
        The identified model.
    link_ : LinkEstimator
        The fitted layer-1 estimator (its figures are those of layer 1 alone).
    """

    def __init__(
        self,
        *,
        robot,
        method: str = "auto",
        friction: str = "auto",
        gmm: str | int = "auto",
        preprocessing: Preprocessing | None = None,
        armature: bool = True,
        reference_weight: float | str = "auto",
        gmm_mode: str = "position",
        random_state: int = 0,
        rounds: int = 2,
        physical: bool = True,
        effects: str | Sequence[Any] | None = None,
        drive_gains: bool = True,
    ) -> None:
        self.robot = robot
        self.method = method
        self.friction = friction
        self.gmm = gmm
        self.preprocessing = preprocessing
        self.armature = armature
        self.reference_weight = reference_weight
        self.gmm_mode = gmm_mode
        self.random_state = random_state
        self.rounds = rounds
        self.physical = physical
        self.effects = effects
        self.drive_gains = drive_gains

    def __repr__(self) -> str:
        return (
            f"ThreeLayerModel(robot={getattr(self.robot, 'name', self.robot)!r}, method={self.method!r}, "
            f"friction={self.friction!r}, gmm={self.gmm!r})"
        )

    def _check(self) -> None:
        if self.method not in ("auto", *method_names()):
            raise UsageError(f"unknown method {self.method!r}; choose one of auto, {', '.join(method_names())}")
        if self.friction != "auto" and self.friction not in FRICTION_MODELS:
            raise UsageError(
                f"unknown friction model {self.friction!r}; choose one of auto, {', '.join(FRICTION_MODELS)}"
            )
        g = self.gmm
        ok = g in ("off", "auto") or (isinstance(g, int | np.integer) and not isinstance(g, bool) and g >= 1)
        if not ok:
            raise UsageError(f"gmm is {g!r}; give 'off', 'auto' or a positive number of components")
        r = self.rounds
        if not (isinstance(r, int | np.integer) and not isinstance(r, bool) and r >= 0):
            raise UsageError(
                f"rounds is {r!r}; give 0 (the layers in sequence) or a positive number of rounds"
            )
        w = self.reference_weight
        numeric = isinstance(w, int | float | np.integer | np.floating) and not isinstance(w, bool)
        if isinstance(w, PriorChoice):
            pass
        elif not (w == "auto" if isinstance(w, str) else numeric and np.isfinite(w) and w >= 0):
            raise UsageError(
                f"reference_weight is {w!r}; give 'auto' (chosen by cross-validation) or a number >= 0"
            )

    def fit(self, data: Dataset) -> ThreeLayerModel:
        """Identify the three layers.

        Parameters
        ----------
        data : Dataset
            Measured data of the robot.

        Returns
        -------
        self
        """
        self._check()
        fitted = self._fit(data)
        info = dict(fitted.model_.info)
        info["data_sha256"] = data_fingerprint(data)
        fitted.model_ = replace(fitted.model_, info=info)
        return fitted

    def _fit(self, data: Dataset) -> ThreeLayerModel:
        if self.method == "auto":
            return self._fit_chosen(data)
        if self.friction == "auto":  # an explicit method: the paper's friction model
            return self._with(friction="seed").fit(data)._adopt_into(self)
        robot = self.robot
        layer1_friction = self.friction != "none"
        terms = self._effect_terms(layer1_friction)
        effect_columns, effect_reference = None, None
        if terms:
            effect_columns, effect_reference = self._effect_columns(data, terms, layer1_friction)
        say(f"preparing {data.m} samples and evaluating the regressor")
        system = build_system(
            robot,
            data,
            preprocessing=self.preprocessing,
            friction=layer1_friction,
            armature=self.armature,
            effects=effect_columns,
        )
        # the layers are refitted together unless layer 1 already is the whole model (linear friction
        # or none, no correction) or the paper's sequence is asked for
        joint = self.rounds > 0 and not (self.friction in ("none", "linear") and self.gmm == "off")
        self._prior = None
        if isinstance(self.reference_weight, PriorChoice):  # chosen already (the pipeline's folds)
            self._prior = self.reference_weight
        elif self.reference_weight == "auto" and (self.physical or self.method == "consistent"):
            say("the description's prior: its strength by blocked cross-validation")
            self._prior = choose_prior(robot, system)
        est: LinkEstimator
        options = {"robot": robot, "friction": layer1_friction, "armature": self.armature}
        if self.method == "consistent" and not joint:
            est = ConsistentLS(
                **options, preprocessing=self.preprocessing, reference_weight=self._weight(effective=False)
            )
        else:
            name = "irls" if self.method == "consistent" else self.method
            steps = getattr(self, "_irls_steps", None)  # the folds' fits (see _for_folds)
            est = ESTIMATORS[name](
                **options, preprocessing=self.preprocessing, **({"max_iter": steps} if steps and name == "irls" else {})
            )
        say(f"layer 1: link parameters ({est.method})")
        est.fit(system)
        cols = system.columns
        prep = system.prepared
        rows = prep.rows
        info: dict[str, Any] = {
            "n_samples": len(rows),
            "notes": [*([prep.settings["decimate_rule"]] if "decimate_rule" in prep.settings else []), *est.notes_],
            "reference": prep.reference,
        }
        if self._prior is not None:
            info["prior"] = self._prior.to_dict()
        tau_seen = prep.tau_reference
        info["torque_range"] = np.stack([tau_seen.min(axis=0), tau_seen.max(axis=0)], axis=1).tolist()
        info["speed_quantiles"] = speed_quantiles(prep.dq[rows])
        if hasattr(est, "n_iter_"):
            info["irls"] = {"iterations": int(est.n_iter_), "converged": bool(est.converged_)}
        lower = physical_lower_bounds(cols) if self.physical else None
        consistent = self._consistency(effective=joint)
        x0 = est.params_
        if lower is not None and hasattr(est, "R_"):
            x0 = bounded_triangular(est.R_, est.rhs_, lower)
        if joint:
            say(f"friction ({self.friction}) and correction (gmm {self.gmm}) refitted with the links")
            x, cov, friction, source, gmr, rms_layers = self._joint(system, est, info, x0, lower, consistent)
        else:
            if consistent is not None and not isinstance(est, ConsistentLS):
                x0 = self._project_layer1(system, est, x0, consistent, info)
            x, cov, friction, source, gmr, rms_layers = self._sequence(system, est, info, x0)
        # the barrier of the consistent projection stops a rounding error inside a bound: put it on it
        if lower is not None:
            x = np.asarray(x, dtype=np.float64).copy()
            x[at_bound(x, lower)] = lower[at_bound(x, lower)]
        info["bounds"] = bounds_info(cols, np.asarray(x), lower, np.sqrt(np.maximum(np.diag(cov), 0.0)))
        system.release()
        if isinstance(est, ConsistentLS):
            info["consistency"] = consistency_figures(
                est.standard_,
                est.solver_,
                relative_distance=est.distance_["relative"],
                mahalanobis=est.distance_["mahalanobis"],
                rms_before=est.unconstrained_.rms_,
                rms_after=est.rms_,
            )
        if "consistency" in info:
            info["bounds"]["links_at_bound"] = list(info["consistency"]["at_bound"])
        if gmr is not None:
            rms_layers = cap_mixture(gmr, system.prepared, rms_layers, info)
            info["gmm_validation_rms"] = gmr.validation_rms_.tolist()
        warn_unexplained(np.asarray(rms_layers["gmm"]), tau_seen)
        self.link_ = est
        self.model_ = IdentifiedModel(
            robot=robot,
            columns=cols,
            params=np.asarray(x, dtype=np.float64),
            cov=np.asarray(cov, dtype=np.float64),
            method=self.method,
            preprocessing=dict(prep.settings),
            friction=friction,
            friction_source=source,
            gmr=gmr,
            cond=float(est.cond_),
            rms=np.array(rms_layers["gmm"]),
            rms_layers=rms_layers,
            info=info,
            layers_filtered=True,
            effect_reference=effect_reference,
        )
        return self

    def _with(self, **changes: Any) -> ThreeLayerModel:
        """An unfitted copy with some settings changed (the settings: the keywords of ``__init__``)."""
        keys = [k for k in inspect.signature(ThreeLayerModel.__init__).parameters if k != "self"]
        return ThreeLayerModel(**{k: changes.get(k, getattr(self, k)) for k in keys})

    def _for_folds(self, **changes: Any) -> ThreeLayerModel:
        """:meth:`_with` for a fit that only scores a pipeline on a fold: IRLS stops after
        :data:`FOLD_IRLS_STEPS` steps (the final fit iterates to its tolerance)."""
        model = self._with(**changes)
        model._irls_steps = FOLD_IRLS_STEPS
        return model

    def _adopt_into(self, target: ThreeLayerModel) -> ThreeLayerModel:
        """Copy this fit's results into ``target`` (whose settings asked for it) and return ``target``."""
        target.model_ = self.model_
        target.link_ = self.link_
        target._prior = self._prior
        return target

    def _fit_chosen(self, data: Dataset) -> ThreeLayerModel:
        """``method="auto"``: the pipeline blocked cross-validation prefers, then fitted on all the data."""
        with sharing_systems():  # one system of the whole recording for the prior and the final fit
            return self._fit_chosen_shared(data)

    def _fit_chosen_shared(self, data: Dataset) -> ThreeLayerModel:
        from dynid.identify.pipeline import (
            candidates,
            choose_gains,
            choose_pipeline,
            coarse_recording,
            gain_screen,
        )

        weight = self.reference_weight
        if weight == "auto" and self.physical and not self.effects and self.friction != "none":
            # the prior's strength once, on the whole recording; each fold takes half its weight (the
            # weight is in effective samples, and a fold has about half of them: a third to two thirds)
            say("the description's prior: its strength by blocked cross-validation")
            system = build_system(
                self.robot, data, preprocessing=self.preprocessing, friction=True, armature=self.armature
            )
            weight = choose_prior(self.robot, system)
            system.release()
            if "decimate_rule" in system.prepared.settings:  # past the memory budget: not held through the
                forget_shared(data)  # cross-validation (the final fit builds it again)
            del system  # its full-rate states too
            give_back()
        half = replace(weight, weight=0.5 * weight.weight) if isinstance(weight, PriorChoice) else weight
        cv_data, cv_pre = data, self.preprocessing
        pre = self.preprocessing or Preprocessing()
        if pre.decimate == 1:  # scored at a rate of RATE_FACTOR times the cut-off, at the whole one's cut-off
            settings = pre.resolve(data)
            # the rate must carry the states' band too (a state cut-off above the torque's)
            band = max(c for c in (settings["cutoff_hz"], settings["state_cutoff_hz"], 0.0) if c is not None)
            cv_data = coarse_recording(data, band or None)
            if cv_data is not data:
                cv_pre = replace(
                    pre, cutoff=settings["cutoff_hz"], state_cutoff=settings["state_cutoff_hz"], trim=settings["trim_s"]
                )
                if isinstance(half, PriorChoice):  # the same information in D times fewer, less correlated samples
                    half = replace(half, kappa=max(1.0, half.kappa / cv_data.meta["coarse"]["decimate"]))
        if cv_data is data:  # folds at full size: the whole recording's system is not held beside theirs
            forget_shared(data)
        choice = choose_pipeline(
            lambda m, f, g: self._for_folds(method=m, friction=f, gmm=g, reference_weight=half, preprocessing=cv_pre),
            cv_data,
            candidates(self.friction, self.gmm),
            share_static=self.friction == "auto",
        )
        if self.drive_gains and not self.effects:  # a gain per joint where the folds show one
            try:
                joints = gain_screen(
                    build_system(self.robot, cv_data, preprocessing=cv_pre, friction=True, armature=self.armature)
                )
            except DynidError:  # a recording whose system cannot be solved has no gain to screen
                joints = []
            if joints:  # refits on the folds follow: the system is not held beside theirs
                forget_shared(cv_data)
                give_back()
            choice = choose_gains(
                lambda m, f, g, e: self._for_folds(
                    method=m, friction=f, gmm=g, reference_weight=half, preprocessing=cv_pre, effects=e
                ),
                cv_data,
                choice,
                joints,
            )
        say(f"pipeline: {choice.said}")
        give_back()
        chosen = self._with(
            method=choice.method,
            friction=choice.friction,
            gmm=choice.gmm,
            # with drive gains the prior's strength is chosen again, on the system that holds them
            reference_weight=self.reference_weight if choice.gains else weight,
            effects=choice.effects if choice.gains else self.effects,
        ).fit(data)
        info = dict(chosen.model_.info)
        info["pipeline"] = choice.to_dict()
        info["notes"] = [f"pipeline chosen from the recording: {choice.said}", *info.get("notes", [])]
        chosen.model_ = replace(chosen.model_, info=info)
        return chosen._adopt_into(self)

    def _weight(self, *, effective: bool) -> float:
        """The pull toward the description for a consistency step whose data term is in effective
        samples (the joint refit's, with the long-run variance factor) or in plain squared standard
        deviations (layer 1's own metric)."""
        if self._prior is not None:
            return self._prior.weight if effective else self._prior.weight * self._prior.kappa
        if self.reference_weight == "auto":
            return 0.0
        return float(self.reference_weight)

    def _consistency(self, *, effective: bool) -> dict[str, Any] | None:
        """Options of the consistent projection of the link parameters (None: the unconstrained fit).

        Every physical fit keeps its links consistent (``J >= eps I`` for every pseudo-inertia) and
        pulled toward the description's bodies (:mod:`dynid.identify.prior`): in the directions the
        data do not determine the description stands, in the others the data move the bodies as far as
        the pull's strength allows; the later layers are refitted on what the links leave.
        """
        if self.method == "consistent" or self.physical:
            return {"reference_weight": self._weight(effective=effective)}
        return None

    def _project_layer1(
        self, system, est: LinkEstimator, x0, consistent: dict[str, Any], info: dict[str, Any]
    ):
        """Layer 1 made consistent: the closest consistent parameters in the weighted least-squares metric."""
        cols = system.columns
        x_hat = np.asarray(est.params_, dtype=np.float64)
        sigma2 = float(est.rss_) / max(system.m * cols.n - cols.p, 1)
        x_c, phi, solver = consistent_projection(
            self.robot, cols, x_hat, est.R_, max(sigma2, 1e-300), **consistent
        )
        if solver["iterations"] == 0:
            x_c = np.asarray(x0, dtype=np.float64)
        with single_blas_thread():
            before, after = system.rms(x0), system.rms(x_c)
        info["consistency"] = consistency_figures(
            phi[: 10 * cols.n],
            solver,
            relative_distance=float(np.linalg.norm(x_c - x_hat) / max(np.linalg.norm(x_hat), 1e-300)),
            mahalanobis=float(np.linalg.norm(est.R_ @ (x_c - x_hat)) / np.sqrt(max(sigma2, 1e-300))),
            rms_before=before,
            rms_after=after,
        )
        return x_c

    def _effect_terms(self, layer1_friction: bool) -> tuple[Candidate, ...]:
        """The effect terms asked for, checked against what the model identifies anyway."""
        spec = self.effects
        if spec is None or (isinstance(spec, str) and not spec.strip()):
            return ()
        if not isinstance(spec, str) and all(isinstance(t, Candidate) for t in spec):
            terms = tuple(spec)
        else:
            terms = parse_effect_terms(spec, self.robot.n)
        names = {t.effect for t in terms}
        R = robot_coupling(self.robot)
        if R is not None:
            terms = tuple(_transmission_sign(t, R) for t in terms)
        for t in terms:
            if t.effect == "coupled_friction" and R is not None and t.joints is not None:
                pair = set(t.joints)
                a, b = t.joints
                signs = (1.0, -1.0) if t.hyper.get("sign") is None else (t.hyper["sign"],)  # None: tuned
                mix = t.hyper.get("mix", 1.0)
                for i, row in enumerate(R):
                    # the term's speed mix dq_a + sign dq_b is motor i's, row[a] dq_a + row[b] dq_b, when
                    # proportional (the output stage's friction, mix 0, is another column)
                    same = any(np.isclose(mix * row[b], s * row[a]) for s in signs)
                    if set(np.flatnonzero(np.abs(row) > 1e-12).tolist()) == pair and same:
                        a, b = sorted(pair)
                        raise UsageError(
                            f"the effect '{t.key}' is the friction of motor {i + 1}, which the robot's transmission "
                            f"already turns with joints {a + 1} and {b + 1} (its Coulomb and viscous friction are "
                            "identified on that motor's speed); drop the effect, or identify without the transmission"
                        )
        if "offset" in names and layer1_friction:
            raise UsageError(
                "the effect 'offset' is identified already as the offset fo_j of the linear friction; drop it from "
                "the effects (or identify with friction 'none')"
            )
        if "armature" in names and self.armature:
            raise UsageError(
                "the effect 'armature' is identified already (armature ia_j); drop it from the effects (or "
                "identify without the armature)"
            )
        if self.method == "consistent":
            raise UsageError(
                "the method 'consistent' cannot take effect terms (they are no physical parameter of the links); "
                "use irls, or add the effects to a consistent model's refit with 'dynid diagnose --out'"
            )
        return terms

    def _effect_columns(self, data: Dataset, terms, layer1_friction: bool):
        """Tune the terms on a first fit without them and build their columns on the prepared grid."""
        robot = self.robot
        system0 = build_system(
            robot, data, preprocessing=self.preprocessing, friction=layer1_friction, armature=self.armature
        )
        first = ESTIMATORS["ols"](
            robot=robot, friction=layer1_friction, armature=self.armature, preprocessing=self.preprocessing
        ).fit(system0)
        x_ref = np.asarray(first.params_, dtype=np.float64)
        prep = system0.prepared
        tau_ref = linear_torque(system0.columns, x_ref, prep.q, prep.dq, prep.ddq)
        src = FeatureSource(
            t=prep.t - prep.t[0],
            q=prep.q,
            dq=prep.dq,
            ddq=prep.ddq,
            tau_pred=tau_ref,
            robot=robot,
            fs=float(prep.fs),
            runs=list(prep.runs),
        )
        with single_blas_thread():
            resid = system0.tau() - system0.predict(x_ref)
        system0.release()
        terms = tune_terms(src, terms, resid, lambda v: prep.filter(v)[prep.rows])
        values, widths = effect_values(src, terms)
        names = tuple(
            name for term, w in zip(terms, widths, strict=True) for name in coefficient_names(term, w)
        )
        return EffectColumns(terms=tuple(terms), names=names, values=values), x_ref

    def _linear_layer(self, cols: ColumnSet, x: NDArray[np.float64]) -> FrictionLayer:
        xe = dict(zip(cols.names, x, strict=True))
        n = self.robot.n
        return FrictionLayer.from_linear(
            [xe.get(f"fc{j + 1}", 0.0) for j in range(n)],
            [xe.get(f"fv{j + 1}", 0.0) for j in range(n)],
            [xe.get(f"fo{j + 1}", 0.0) for j in range(n)],
        )

    def _sequence(self, system, est: LinkEstimator, info: dict[str, Any], x):
        """The paper's order: each layer on what the previous one left (friction filtered like the torque)."""
        cols, prep = system.columns, system.prepared
        rows = prep.rows
        with single_blas_thread():
            tau = system.tau()
            resid = tau - system.predict(x, mask=cols.link_mask)  # F_est: what the rigid body leaves
        rms_layers = {"link": joint_rms(resid)}
        friction: FrictionLayer | None = None
        if self.friction == "none":
            source = "none"
        elif self.friction == "linear":
            source = "layer1"
            friction = self._linear_layer(cols, x)
            friction.rms_ = system.rms(x)  # with the link part: the layer-1 residual
            resid = resid - layer1_friction(cols, x, prep)
        else:
            source = "layer2"
            friction = FrictionLayer(model=self.friction).fit(prep.dq, resid, prepared=prep)
            # the fit's own filtered columns (taking them also frees them: the layer must not keep them)
            filtered = friction.filtered_basis(prep)
            resid = resid - np.column_stack(
                [B @ mdl.linear_coef() for B, mdl in zip(filtered, friction.models_, strict=True)]
            )
        rms_layers["friction"] = joint_rms(resid)
        gmr: GMRCorrection | None = None
        if self.gmm != "off":
            u = np.hstack([prep.q, prep.dq])
            gmr = GMRCorrection(
                n_components=self.gmm if self.gmm == "auto" else int(self.gmm),
                mode=self.gmm_mode,
                random_state=self.random_state,
            ).fit(u[rows], resid)
            if gmr.active_.any():
                resid = resid - prep.filter(gmr.predict(u))[rows]
        rms_layers["gmm"] = joint_rms(resid)
        info["refinement"] = {"rounds": 0}
        return x, est.cov_, friction, source, gmr, rms_layers

    def _physical_first(self, system, est: LinkEstimator, x0, lower, consistent, out, info: dict[str, Any]):
        """Keep the mixture from taking over torque that the physical layers explain.

        The physical layers are also fitted alone (link and friction refitted together, no mixture).
        If, in the joint fit, link + friction leave more than :data:`TAKEOVER` times the RMS they leave
        alone on some joint, or leave more than :data:`TAKEOVER_SHARE` of that joint's torque power
        beyond it while the joint fit buys less than :data:`TAKEOVER_GAIN` in training RMS on every
        joint (the whole TX40 recording: ratio 5, but a tenth of joint 2's power, its gravity, for a
        gain of at most 1.07), the mixture has taken over physical torque (on the Panda at 6 Hz, a
        position mixture carried joint 2's gravity: link + friction 1.15 N m against 0.1 alone, and
        1.2 N m on held-out data); then the physical layers fitted alone are kept and the mixture is
        fitted on what they leave, validated as in :class:`GMRCorrection`.  A correction that only adds
        to good physical layers keeps the joint fit (a simulated UR5 with a position ripple that the
        physical layers alone partly absorb into gravity: ratio 4 on the shoulder, and the joint fit
        predicts held-out data twice as well as the physical layers first; the identification
        benchmark: ratio 5.7, held-out 0.26x OLS with the joint fit against 0.84x without).
        """
        prep = system.prepared
        rows = prep.rows
        phys = refine(
            system,
            x0,
            est.omega_,
            friction=self.friction,
            gmm="off",
            rounds=int(self.rounds),
            weighting="none" if self.method == "ols" else "per-joint",
            consistent=consistent,
            random_state=self.random_state,
            lower=lower,
        )
        alone = np.asarray(phys.rms_layers["friction"], dtype=np.float64)
        joint = np.asarray(out.rms_layers["friction"], dtype=np.float64)
        ratio = joint / np.maximum(alone, 1e-300)
        power = np.mean(prep.tau_reference**2, axis=0)
        share = (joint**2 - alone**2) / np.maximum(power, 1e-300)
        check = {
            "physical_alone_rms": alone.tolist(),
            "physical_in_joint_fit_rms": joint.tolist(),
            "ratio": ratio.tolist(),
            "limit": TAKEOVER,
            "share": share.tolist(),
            "share_limit": TAKEOVER_SHARE,
        }
        over_ratio = ratio > TAKEOVER
        over_share = share > TAKEOVER_SHARE
        if not (over_ratio | over_share).any():
            info["physical_check"] = {**check, "kept": "joint fit"}
            return out
        u = np.hstack([prep.q, prep.dq])
        gmr = GMRCorrection(
            n_components=self.gmm if self.gmm == "auto" else int(self.gmm),
            mode=self.gmm_mode,
            random_state=self.random_state,
        ).fit(u[rows], phys.residual)
        resid = phys.residual
        if gmr.active_.any():
            resid = resid - prep.filter(gmr.predict(u))[rows]
        first = joint_rms(resid)
        fitted = np.asarray(out.rms_layers["gmm"], dtype=np.float64)
        gain = np.asarray(first, dtype=np.float64) / np.maximum(fitted, 1e-300)
        check.update(
            {"physical_first_rms": first, "joint_fit_rms": fitted.tolist(), "gain_limit": TAKEOVER_GAIN}
        )
        if not over_ratio.any() and np.any(gain > TAKEOVER_GAIN):
            moved = ", ".join(str(j + 1) for j in np.flatnonzero(over_share))
            info["physical_check"] = {
                **check,
                "kept": (
                    f"joint fit (the mixture carries a share of joint {moved}'s torque, and the physical layers "
                    f"first fit up to {gain.max():.2f}x worse)"
                ),
            }
            return out
        phys.gmr = gmr
        phys.residual = resid
        phys.rms_layers = {**phys.rms_layers, "gmm": first}
        over = ", ".join(str(j + 1) for j in np.flatnonzero(over_ratio | over_share))
        info["physical_check"] = {
            **check,
            "kept": f"physical layers first (the mixture took over physical torque on joints {over})",
        }
        return phys

    def _joint(self, system, est: LinkEstimator, info: dict[str, Any], x0, lower, consistent):
        """The layers refitted together (:func:`dynid.identify.refine.refine`)."""
        cols = system.columns
        out = refine(
            system,
            x0,
            est.omega_,
            friction=self.friction,
            gmm=self.gmm,
            gmm_mode=self.gmm_mode,
            rounds=int(self.rounds),
            weighting="none" if self.method == "ols" else "per-joint",
            consistent=consistent,
            random_state=self.random_state,
            lower=lower,
        )
        if out.gmr is not None and out.gmr.active_.any():
            out = self._physical_first(system, est, x0, lower, consistent, out, info)
        cov = np.array(est.cov_, dtype=np.float64)
        cov[out.mask, :] = 0.0
        cov[:, out.mask] = 0.0
        cov[np.ix_(out.mask, out.mask)] = out.cov[np.ix_(out.mask, out.mask)]
        if self.friction == "linear":
            friction, source = self._linear_layer(cols, out.params), "layer1"
        elif self.friction == "none":
            friction, source = None, "none"
        else:
            friction, source = out.friction, "layer2"
        refinement = {k: v for k, v in out.info.items() if k != "consistency"}
        info["refinement"] = refinement
        if "consistency" in out.info:
            c = out.info["consistency"]
            info["consistency"] = consistency_figures(
                c["standard_params"],
                c["solver"],
                relative_distance=c["relative_distance"],
                mahalanobis=c["mahalanobis"],
                rms_before=c.get("rms_unprojected"),
                rms_after=c.get("rms_projected"),
            )
        return out.params, cov, friction, source, out.gmr, out.rms_layers

    def predict(self, q, dq=None, ddq=None) -> NDArray[np.float64]:
        """Joint torques (N m) of the identified model (see :meth:`IdentifiedModel.predict`).

        Parameters
        ----------
        q : ndarray, shape (m, n), or Dataset
            Joint angles (rad), or a dataset.
        dq, ddq : ndarray, shape (m, n)
            Joint velocities (rad/s) and accelerations (rad/s^2).
        """
        check_is_fitted(self, "model_")
        return self.model_.predict(q, dq, ddq)


def data_fingerprint(data: Dataset) -> str:
    """The sha256 of a recording's time stamps, angles and torques (what a model file records of its
    training data, so that scoring a model on them is recognised)."""
    digest = hashlib.sha256()
    for a in (data.t, data.q, data.tau):
        digest.update(np.ascontiguousarray(a, dtype=np.float64).tobytes())
    return digest.hexdigest()


def _transmission_sign(term: Candidate, R: NDArray[np.float64]) -> Candidate:
    """A coupled pair's output-stage friction (``coupled_friction`` with mix < 1, sign not given) on a robot
    whose transmission has a motor turning with exactly that pair (its own joint and one other,
    :func:`~dynid.identify.columns.coupled_pairs`): that motor drives the stage, so its
    torque reaches the two joints with the transmission's sign, which the term takes instead of tuning it."""
    if term.effect != "coupled_friction" or term.joints is None or "sign" in term.hyper:
        return term
    if term.hyper.get("mix", 1.0) == 1.0:
        return term
    for a, b in coupled_pairs(R):
        if {a, b} == set(term.joints):
            return replace(term, hyper={**term.hyper, "sign": float(np.sign(R[b, a] * R[b, b]))})
    return term
