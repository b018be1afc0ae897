"""Simulated data and identified models shared by the validation, report and command tests.

Built once per test session (a cache keyed by pytest's base temporary folder): a UR5 whose inertial
parameters are perturbed by 10 %, with the paper's friction and the simulator's default noise, records
8 s on one random trajectory (identification) and 10.5 s on another (validation: two whole periods
of 5 s are left after the filter's trimming).  Two models are identified on the first: the full
method (consistent links, the paper's friction, a 2-component GMM) and OLS with linear friction.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path

import numpy as np

PERIOD = 5.0


@dataclass(frozen=True)
class Case:
    folder: Path
    train: Path
    heldout: Path
    full: Path
    ols: Path


@functools.cache
def simulated_case(base: Path) -> Case:
    import warnings

    from dynid.data.preparation import Preprocessing
    from dynid.identify.model import identify, save_model
    from dynid.optim.excitation import ExcitationProblem
    from dynid.sim.simulator import build_truth, simulate, write_simulation
    from dynid.symbolic import load_robot

    folder = base / "validation-case"
    folder.mkdir(exist_ok=True)
    robot = load_robot("ur5")
    problem = ExcitationProblem(robot=robot, harmonics=4, base_freq=1.0 / PERIOD)
    rng = np.random.default_rng(11)
    train_traj, heldout_traj = problem.random_trajectory(rng), problem.random_trajectory(rng)
    truth = build_truth(robot, friction="seed", perturb=0.1, truth_seed=3)
    train, _ = write_simulation(
        simulate(robot, train_traj, truth=truth, seed=1, duration=8.0), folder / "D.csv"
    )
    heldout, _ = write_simulation(
        simulate(robot, heldout_traj, truth=truth, seed=2, duration=2 * PERIOD + 0.5), folder / "V.csv"
    )
    from dynid.data.files import load_dataset

    data = load_dataset(train, robot.n)
    pre = Preprocessing(decimate=4)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        full = identify(robot, data, method="consistent", friction="seed", gmm=2, preprocessing=pre)
        # the plain OLS baseline: unconstrained (no bounds, links not made consistent)
        ols = identify(
            robot, data, method="ols", friction="linear", gmm="off", preprocessing=pre, physical=False
        )
    save_model(full, folder / "M.json")
    save_model(ols, folder / "M_ols.json")
    return Case(
        folder=folder, train=train, heldout=heldout, full=folder / "M.json", ols=folder / "M_ols.json"
    )
