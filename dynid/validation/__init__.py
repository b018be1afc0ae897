"""dynid.validation: held-out validation, error metrics, the noise floor, plots and the HTML report.

The submodules are imported on first use (matplotlib and scikit-learn are slow to import):
:mod:`dynid.validation.metrics` (error figures, the noise floor), :mod:`dynid.validation.validate`
(a model's prediction of held-out data, methods side by side; its function
:func:`dynid.validation.validate.validate` is not exported here, as the name is the submodule's), :mod:`dynid.validation.report` and
:mod:`dynid.validation.plots` (the HTML report and its figures).  The gap diagnosis is
:mod:`dynid.diagnosis`.
"""

from __future__ import annotations

from dynid._lazy import lazy_exports

_EXPORTS = {
    "NoiseFloor": "metrics",
    "noise_floor": "metrics",
    "torque_metrics": "metrics",
    "COMPARISON": "validate",
    "ValidationResult": "validate",
    "compare": "validate",
    "compare_methods": "validate",
    "identify_methods": "validate",
    "nominal_model": "validate",
    "write_predictions": "validate",
    "Report": "report",
    "render_report": "report",
}

__all__, __getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
