"""dynid.simmodel: identified models written into simulator descriptions (URDF, MuJoCo MJCF), reload-checked.

:mod:`dynid.simmodel.parameters` (consistent bodies, armature, damping and frictionloss of a model, and
what a simulator cannot carry), :mod:`dynid.simmodel.urdf` (a copy of the robot's URDF with them),
:mod:`dynid.simmodel.mjcf` (the MJCF MuJoCo builds from that URDF), :mod:`dynid.simmodel.checks` (the
reload checks) and :mod:`dynid.simmodel.export` (:func:`export_model`, what ``dynid export`` calls) and
:mod:`dynid.simmodel.nominal` (a URDF or MJCF as the model under test, what ``dynid validate --model
robot.urdf`` scores) and :mod:`dynid.simmodel.correct` (the description corrected from data, what ``dynid
diagnose --model robot.urdf --out corrected.urdf`` writes) and :mod:`dynid.simmodel.rollout` (a
trajectory tracked in MuJoCo by dynid's controller, against dynid's simulator).
The submodules are imported on first use (``mujoco`` is optional).
"""

from __future__ import annotations

from dynid._lazy import lazy_exports

_EXPORTS = {
    "SimParameters": "parameters",
    "simulator_parameters": "parameters",
    "ExportResult": "export",
    "export_model": "export",
    "check_urdf": "checks",
    "check_mjcf": "checks",
    "description_model": "nominal",
    "correct_description": "correct",
    "mujoco_tracking": "rollout",
    "forward_agreement": "rollout",
}

__all__, __getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
