"""Excitation design (Fourier series optimised with IPOPT), trajectory types and files, ruckig approach."""

from __future__ import annotations

__all__ = [
    "CartesianLimits",
    "ExcitationError",
    "ExcitationProblem",
    "ExcitationResult",
    "FourierTrajectory",
    "SampledTrajectory",
    "default_home",
    "design_excitation",
    "executable_trajectory",
    "load_trajectory",
    "point_to_point",
]

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


def __getattr__(name: str):
    # CasADi and ruckig are imported on first use (the command line starts faster).
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'dynid.optim' has no attribute {name!r}")
    import importlib

    return getattr(importlib.import_module(f"dynid.optim.{module}"), name)
