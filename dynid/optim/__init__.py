"""Excitation design (Fourier series optimised with IPOPT), trajectory types and files, ruckig approach."""

from __future__ import annotations

from dynid._lazy import lazy_exports

_LAZY = {
    "CartesianLimits": "excitation",
    "ExcitationError": "excitation",
    "ExcitationProblem": "excitation",
    "ExcitationResult": "excitation",
    "design_excitation": "excitation",
    "default_home": "approach",
    "executable_trajectory": "approach",
    "point_to_point": "approach",
    "FourierTrajectory": "trajectory",
    "SampledTrajectory": "trajectory",
    "load_trajectory": "trajectory",
}

__all__, __getattr__, __dir__ = lazy_exports(__name__, _LAZY)
