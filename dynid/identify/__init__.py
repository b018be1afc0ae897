"""dynid.identify: the three layers (link parameters, friction, GMR), the linear system and model files.

The submodules are imported on demand: :mod:`dynid.identify.columns` (the identified parameters),
:mod:`dynid.identify.linear_system` (the compressed least-squares system), the estimators, friction and
GMR layers and :mod:`dynid.identify.model` (the three-layer pipeline and the model file).  The data they
take (the :class:`~dynid.data.dataset.Dataset` type, its files, preprocessing) are :mod:`dynid.data`.
"""

from __future__ import annotations

from dynid._lazy import lazy_exports

# Identification: layer 1 (estimators, consistent fit), layer 2 (friction), layer 3 (GMR), the
# three-layer pipeline and the model file.  Imported on first use (CasADi and scikit-learn are slow).
_IDENTIFY = {
    "OLS": "estimators",
    "WLS": "estimators",
    "GLS": "estimators",
    "IRLS": "estimators",
    "ConsistentLS": "consistent",
    "LinkEstimator": "estimators",
    "register_estimator": "estimators",
    "ESTIMATORS": "registry",
    "FrictionLayer": "friction",
    "FrictionModel": "friction",
    "register_friction_model": "friction",
    "FRICTION_MODELS": "registry",
    "GMRCorrection": "gmr",
    "build_system": "linear_system",
    "IdentifiedModel": "model",
    "ThreeLayerModel": "model",
    "identify": "model",
    "load_model": "model",
    "save_model": "model",
}
__all__, __getattr__, __dir__ = lazy_exports(__name__, _IDENTIFY)
