"""dynid: identify the dynamic model of a robot arm, then explain what the model still gets wrong.

The whole path from Python, one function per step (each imported on first use: CasADi, Pinocchio and
scikit-learn are slow to import)::

    import dynid

    robot = dynid.load_robot("ur5")                                    # RobotModel
    design = dynid.design_excitation(dynid.ExcitationProblem(robot=robot))
    run = dynid.simulate(robot, design.trajectories[0], friction="seed")  # SimulationResult
    data = run.to_dataset()                                            # or dynid.load_dataset("D.csv")
    heldout = dynid.load_dataset("V.csv")                              # another run of the same robot
    model = dynid.identify_model(robot, data)                          # IdentifiedModel
    result = dynid.validate(model, heldout)                            # ValidationResult
    found = dynid.diagnose(model, data, heldout)                       # Diagnosis
    dynid.export_c(robot, "ur5_c")                                     # C for a controller

``dynid.identify`` is the subpackage of the identification (estimators, friction, GMR, model files);
the one-call identification is :func:`identify_model` (the same function as
:func:`dynid.identify.identify`).  The command line (``dynid --help``) runs the same functions.
"""

from __future__ import annotations

import importlib
from typing import Any

__version__ = "0.1.0"

# Public name -> (module, name there).  Resolved on first use by __getattr__.
_API: dict[str, tuple[str, str]] = {
    # robots (dynid.symbolic)
    "RobotModel": ("dynid.symbolic.robot", "RobotModel"),
    "load_robot": ("dynid.symbolic.robot", "load_robot"),
    "robot_functions": ("dynid.symbolic.functions", "robot_functions"),
    "base_parameters": ("dynid.symbolic.base", "base_parameters"),
    "export_c": ("dynid.symbolic.export", "export_c"),
    # excitation (dynid.optim)
    "ExcitationProblem": ("dynid.optim.excitation", "ExcitationProblem"),
    "ExcitationResult": ("dynid.optim.excitation", "ExcitationResult"),
    "design_excitation": ("dynid.optim.excitation", "design_excitation"),
    "load_trajectory": ("dynid.optim.trajectory", "load_trajectory"),
    # data (dynid.data)
    "Dataset": ("dynid.data.dataset", "Dataset"),
    "load_dataset": ("dynid.data.files", "load_dataset"),
    "save_dataset": ("dynid.data.files", "save_dataset"),
    # identification (dynid.identify)
    "IdentifiedModel": ("dynid.identify.model", "IdentifiedModel"),
    "identify_model": ("dynid.identify.model", "identify"),
    "load_model": ("dynid.identify.model", "load_model"),
    "save_model": ("dynid.identify.model", "save_model"),
    "PayloadResult": ("dynid.identify.payload", "PayloadResult"),
    "identify_payload": ("dynid.identify.payload", "identify_payload"),
    "attach_payload": ("dynid.identify.payload", "attach_payload"),
    # simulation (dynid.sim)
    "SimulationResult": ("dynid.sim.simulator", "SimulationResult"),
    "build_truth": ("dynid.sim.simulator", "build_truth"),
    "simulate": ("dynid.sim.simulator", "simulate"),
    # validation (dynid.validation)
    "ValidationResult": ("dynid.validation.validate", "ValidationResult"),
    "validate": ("dynid.validation.validate", "validate"),
    # diagnosis (dynid.diagnosis: its package is the entry point)
    "Diagnosis": ("dynid.diagnosis", "Diagnosis"),
    "diagnose": ("dynid.diagnosis", "diagnose"),
    # fleets on Dask and drift (dynid.fleet)
    "FleetResult": ("dynid.fleet.core", "FleetResult"),
    "identify_fleet": ("dynid.fleet.core", "identify_fleet"),
    # the demo
    "DemoResult": ("dynid.demo", "DemoResult"),
    "run_demo": ("dynid.demo", "run_demo"),
}

__all__ = ["__version__", *sorted(_API)]


def __getattr__(name: str) -> Any:
    if name in _API:
        module, attr = _API[name]
        return getattr(importlib.import_module(module), attr)
    raise AttributeError(
        f"module 'dynid' has no attribute {name!r}; its top-level names are: {', '.join(sorted(_API))}"
    )


def __dir__() -> list[str]:
    return sorted({*globals(), *_API})
