"""dynid.diagnosis: where the sim-to-real gap lies, which unmodelled effect causes it, how far it shrinks.

The method is in DIAGNOSIS.md.  Submodules are imported on first use (scikit-learn and matplotlib are
slow to import).
"""

from __future__ import annotations

from dynid._lazy import lazy_exports

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

__all__, __getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
