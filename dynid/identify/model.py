"""The three-layer identification and the identified model file.

>>> model = identify(load_robot("ur5"), load_dataset("D.csv"), method="irls", friction="seed", gmm="auto")
>>> save_model(model, "M.json")                 # M.json (figures, readable) + M.npz (arrays)
>>> model = load_model("M.json")
>>> tau = model.predict(q, dq, ddq)             # or model.predict(dataset)

Layers (METHOD.md section 4):

1. link parameters by OLS / WLS / GLS / IRLS / physically consistent least squares on the
   parallel-filtered stacked regressor (base parameters, armature, and linear friction identified
   with them unless ``friction="none"``);
2. friction: ``F_est = tau - tau_link`` (the rigid-body part of layer 1 removed, its linear friction
   not), fitted per joint by the chosen model; with ``friction="linear"`` the layer-1 coefficients are
   kept as they are;
3. what is left, ``tau_err``, by Gaussian mixture regression on ``[q, dq]`` (guarded: zero where it
   does not help on validation blocks).

By default the layers are not fitted one after the other but refitted together for a few rounds
(:mod:`dynid.identify.refine`: link parameters, friction coefficients and mixture experts in one least
squares, friction shape and mixture gates in between); ``rounds=0`` gives the paper's sequence.
Measured on a simulated UR5 (60 s at 1 kHz; the paper's friction and a smooth position-dependent
torque; development seeds, not the benchmark's), the held-out RMS of the full model against OLS with
linear friction fell from 0.9-1.0 (sequential, as first written) to about 0.2.

Prediction on a dataset repeats the identification's preprocessing: every layer is evaluated on the
states at full rate and filtered like the torque (parallel filtering), then taken at the kept samples.
Compare the result with :meth:`IdentifiedModel.prepare` ``(ds).tau_reference``.  (Models written before
the layers were filtered, ``layers_filtered`` false, add layers 2 and 3 unfiltered at the kept samples.)

Model file: ``M.json`` holds everything a person reads (robot, parameters with their standard
deviations, preprocessing, friction coefficients, condition number, RMS per layer) and the name and
SHA-256 of ``M.npz``, which holds the arrays (covariance, mixture).  The JSON is the pair's manifest:
both files are written in full to temporary files first, then renamed into place, the arrays first and
the JSON last, so the pair is valid exactly when the JSON's checksum names the arrays beside it.  An
interrupted write (Ctrl-C, SIGTERM, an error) removes its temporary files and leaves the old pair; a
process killed outright between the two renames leaves a pair that :func:`load_model` refuses in one
sentence (never a model with another model's arrays).

The code lives in four modules, all of whose public names this module re-exports:
:mod:`dynid.identify.identified` (:class:`IdentifiedModel`), :mod:`dynid.identify.three_layer`
(:class:`ThreeLayerModel`, :func:`data_fingerprint`), :mod:`dynid.identify.fit_figures` (the mixture's
guards and the fit's figures) and :mod:`dynid.identify.model_file` (:func:`save_model`,
:func:`load_model`); :func:`identify` is here.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from dynid.data.dataset import Dataset
from dynid.data.preparation import Preprocessing
from dynid.identify.fit_figures import AT_BOUND_STD, MIXTURE_SHARE, TAKEOVER, TAKEOVER_GAIN, TAKEOVER_SHARE
from dynid.identify.identified import IdentifiedModel
from dynid.identify.model_file import load_model, save_model
from dynid.identify.three_layer import ThreeLayerModel, data_fingerprint

__all__ = [
    "AT_BOUND_STD",
    "MIXTURE_SHARE",
    "TAKEOVER",
    "TAKEOVER_GAIN",
    "TAKEOVER_SHARE",
    "IdentifiedModel",
    "ThreeLayerModel",
    "data_fingerprint",
    "identify",
    "load_model",
    "save_model",
]


def identify(
    robot,
    data: Dataset,
    *,
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
) -> IdentifiedModel:
    """Identify a robot's dynamic model from data in three layers (see :class:`ThreeLayerModel`).

    Parameters
    ----------
    robot : RobotModel
        The robot that recorded the data.
    data : Dataset
        Measured data.
    method : str
        Layer-1 method (``"auto"``: the pipeline chosen from the recording; see :class:`ThreeLayerModel`).
    friction : str
        Friction model (``"auto"``: chosen with the pipeline, else ``seed``; see :class:`ThreeLayerModel`).
    gmm : "off" or "auto" or int
        Layer-3 correction.
    preprocessing : Preprocessing, optional
        Filtering and differentiation.
    armature : bool
        Identify the armature.
    reference_weight : float or "auto"
        Pull of the consistent links toward the description's bodies (see :class:`ThreeLayerModel`).
    gmm_mode : {"position", "own", "per_joint", "vector"}
        Inputs of the mixture regression.
    random_state : int
        Seed of the mixture's EM.
    rounds : int
        Rounds in which the layers are refitted together (0: the paper's sequence).
    physical : bool
        Non-negative armature, Coulomb and viscous coefficients (default); False: unconstrained.
    effects : str or sequence, optional
        Effects of the catalogue added as identified terms (``"coupled_friction@5+6"``; see
        :class:`ThreeLayerModel`).
    drive_gains : bool
        With ``method="auto"`` and no ``effects``, a drive gain on the joints that earn one (default);
        False: none (a model for a URDF, which cannot carry one).

    Returns
    -------
    IdentifiedModel
    """
    return (
        ThreeLayerModel(
            robot=robot,
            method=method,
            friction=friction,
            gmm=gmm,
            preprocessing=preprocessing,
            armature=armature,
            reference_weight=reference_weight,
            gmm_mode=gmm_mode,
            random_state=random_state,
            rounds=rounds,
            physical=physical,
            effects=effects,
            drive_gains=drive_gains,
        )
        .fit(data)
        .model_
    )
