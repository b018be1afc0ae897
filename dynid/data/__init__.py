"""dynid.data: the dataset type, its readers, the real recordings' adapters, preprocessing, periods.

:mod:`dynid.data.dataset` (the :class:`Dataset` type), :mod:`dynid.data.files` (:func:`load_dataset`,
the one reader of CSV, npz and ROS 2 recordings, and :func:`save_dataset`), :mod:`dynid.data.rosbag`
(``sensor_msgs/JointState`` from rosbag2 folders and MCAP files), :mod:`dynid.data.adapters` (the real
recordings under ``../shared/data``), :mod:`dynid.data.preprocess` (resampling, filtering,
differentiation, parallel filtering), :mod:`dynid.data.preparation` (the preprocessing settings and the
prepared data) and :mod:`dynid.data.periodic` (period detection).  Submodules are imported on first use.
"""

from __future__ import annotations

from dynid._lazy import lazy_exports

_EXPORTS = {
    "Dataset": "dataset",
    "load_dataset": "files",
    "save_dataset": "files",
    "read_rosbag": "rosbag",
    "load_recording": "adapters",
    "Prepared": "preparation",
    "Preprocessing": "preparation",
    "prepare": "preparation",
    "period_of": "periodic",
}

__all__, __getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
