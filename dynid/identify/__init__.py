"""dynid.identify: datasets, preprocessing, the three layers (link parameters, friction, GMR), model files.

The submodules are imported on demand: :mod:`dynid.identify.dataset` (the :class:`Dataset` type and its
files), :mod:`dynid.identify.preprocess` (resampling, filtering, differentiation, parallel filtering),
:mod:`dynid.identify.preparation` (the preprocessing settings and the prepared data),
:mod:`dynid.identify.columns` (the identified parameters), :mod:`dynid.identify.linear_system` (the
compressed least-squares system) and :mod:`dynid.identify.adapters` (the real recordings under
``../shared/data``).
"""

from __future__ import annotations

from dynid._lazy import lazy_exports
from dynid.exceptions import DataWarning
from dynid.identify.dataset import Dataset, load_dataset, save_dataset

__all__ = ["DataWarning", "Dataset", "load_dataset", "save_dataset"]

# Identification: layer 1 (estimators, consistent fit), layer 2 (friction), layer 3 (GMR), the
# three-layer pipeline and the model file.  Imported on first use (CasADi and scikit-learn are slow).
_IDENTIFY = {
    "OLS": "estimators",
    "WLS": "estimators",
    "GLS": "estimators",
    "IRLS": "estimators",
    "ConsistentLS": "consistent",
    "FrictionLayer": "friction",
    "GMRCorrection": "gmr",
    "Preprocessing": "preparation",
    "build_system": "linear_system",
    "IdentifiedModel": "model",
    "ThreeLayerModel": "model",
    "identify": "model",
    "load_model": "model",
    "save_model": "model",
}
__all__, __getattr__, __dir__ = lazy_exports(__name__, _IDENTIFY, eager=tuple(__all__))
