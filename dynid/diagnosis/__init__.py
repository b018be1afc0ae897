"""dynid.diagnosis: where the sim-to-real gap lies, which unmodelled effect causes it, how far it shrinks.

The method is in DIAGNOSIS.md.  Submodules are imported on first use (scikit-learn and matplotlib are
slow to import).
"""

from __future__ import annotations

_EXPORTS = {
    "Diagnosis": "result",
    "DiagnosisSettings": "settings",
    "RankedCandidate": "result",
    "diagnose": "core",
    "run_diagnosis": "core",
    "EFFECT_NAMES": "candidates",
    "gap_map": "gapmap",
    "write_diagnosis_report": "report",
}
__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        import importlib

        return getattr(importlib.import_module(f"dynid.diagnosis.{_EXPORTS[name]}"), name)
    raise AttributeError(f"module 'dynid.diagnosis' has no attribute {name!r}")
