"""dynid.identify: datasets and preprocessing (estimators, friction, GMM/GMR and the simulator follow).

The submodules are imported on demand: :mod:`dynid.identify.dataset` (the :class:`Dataset` type and its
files), :mod:`dynid.identify.preprocess` (resampling, filtering, differentiation, parallel filtering) and
:mod:`dynid.identify.adapters` (the real recordings under ``../shared/data``).
"""

from __future__ import annotations

from dynid.identify.dataset import Dataset, DataWarning, load_dataset, save_dataset

__all__ = ["DataWarning", "Dataset", "load_dataset", "save_dataset"]
