"""A simulated fleet with a known truth: robots within manufacturing tolerance, some of which change.

>>> changes = {3: Change("friction", joint=2, factor=1.5, at=3), 9: Change("tool", mass=1.0, at=4)}
>>> truth = simulate_fleet("ur5", "recordings", robots=10, recordings=6, changes=changes)
>>> identify_fleet("ur5", "recordings/**/*.csv", friction="linear", gmm="off")

Every robot is the nominal model with its standard parameters perturbed by ``perturb`` (relative,
physically consistent: :func:`dynid.sim.truth.build_truth`) and its friction (the paper's nonlinear
model, ``friction="seed"``) scaled per joint by a factor drawn in ``1 +- friction_spread``.  All
robots run the same excitation (a random feasible Fourier trajectory of
:meth:`dynid.optim.excitation.ExcitationProblem.random_trajectory`, as a fleet re-runs one test
program), under the simulator's tracking controller (:func:`dynid.sim.simulator.simulate`).

A recording is the robot's run with its own sensor noise: the tracking of one robot state is
deterministic, so each state (a robot before or after its change) is simulated once at the control rate
and each recording reads its torque through the simulator's sensor chain
(:func:`dynid.sim.sensors.measured_torque`) with its own seed, then is taken at ``rate``.

Files: ``<out>/<robot>/<YYYY-MM-DD>.csv`` (recording ``k`` on the 15th of month ``k + 1``, the path
rule of :mod:`dynid.fleet.recordings`) and ``<out>/truth.json`` (each robot's perturbation seed,
friction factors and change).  One task per robot state goes to a Dask client when one is given.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from dynid._io import write_json
from dynid.exceptions import UsageError

__all__ = ["Change", "recording_time", "robot_name", "simulate_fleet"]


@dataclass(frozen=True)
class Change:
    """A change of one robot from one of its recordings on.

    Parameters
    ----------
    kind : {"friction", "tool"}
        ``friction``: every friction coefficient of ``joint`` times ``factor`` (wear); ``tool``: a
        point mass of ``mass`` kg on the last link (the simulator's ``payload`` effect: 5 cm along the
        tool frame's z axis).
    at : int
        First recording (from 0) with the change.
    joint : int
        Joint (from 1) of a friction change.
    factor : float
        Friction factor.
    mass : float
        Tool mass (kg).
    """

    kind: str
    at: int
    joint: int = 1
    factor: float = 1.5
    mass: float = 1.0

    def __post_init__(self) -> None:
        if self.kind not in ("friction", "tool"):
            raise UsageError(f"a fleet change is 'friction' or 'tool'; got '{self.kind}'.")


def robot_name(index: int) -> str:
    """``robot_07``: the folder of robot ``index`` (from 0)."""
    return f"robot_{index:02d}"


def recording_time(order: int) -> str:
    """``2026-01-15`` for recording 0, one month later per recording (ISO date)."""
    year, month = divmod(order, 12)
    return f"{2026 + year:04d}-{month + 1:02d}-15"


def _truth(robot: Any, index: int, change: Change | None, perturb: float, friction_spread: float, seed: int):
    from dynid.sim.truth import build_truth

    effects = None
    if change is not None and change.kind == "tool":
        total = float(np.sum(robot.params[0::10]))
        effects = f"payload:{change.mass / (0.05 * total)!r}"
    truth = build_truth(robot, friction="seed", perturb=perturb, truth_seed=seed + index, effects=effects)
    rng = np.random.default_rng([seed, index, 7])
    scale = 1.0 + friction_spread * rng.uniform(-1.0, 1.0, robot.n)
    if change is not None and change.kind == "friction":
        scale[change.joint - 1] *= change.factor
    fric = truth.friction
    fric = replace(fric, **{k: np.asarray(getattr(fric, k)) * scale for k in ("kc_pos", "kc_neg", "kv1", "kv2", "kv3", "ks")})
    return replace(truth, friction=fric), scale


def _simulate_state(
    robot: Any, trajectory: Any, index: int, change: Change | None, orders: list[int], out: str, settings: dict
) -> dict[str, Any]:
    """One robot state simulated once, its recordings written: the task of :func:`simulate_fleet`."""
    from dynid.data.dataset import Dataset
    from dynid.data.files import save_dataset
    from dynid.sim.sensors import measured_torque
    from dynid.sim.simulator import simulate

    truth, scale = _truth(robot, index, change, settings["perturb"], settings["friction_spread"], settings["seed"])
    run = simulate(robot, trajectory, truth=truth, seed=settings["seed"] + index, duration=settings["duration"],
                   rate=settings["control_rate"], control_rate=settings["control_rate"])
    stride = round(settings["control_rate"] / settings["rate"])
    folder = Path(out) / robot_name(index)
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for order in orders:
        tau = measured_torque(truth, run.noise, run.t, run.tau_drive, seed=settings["seed"] * 1000 + 100 * index + order)
        path = folder / f"{recording_time(order)}.csv"
        save_dataset(Dataset(run.t[::stride], run.q[::stride], tau[::stride]), path)
        paths.append(str(path))
    return {"robot": robot_name(index), "friction_scale": scale.tolist(), "paths": paths, "elapsed_s": run.elapsed}


def simulate_fleet(
    robot: Any,
    out_dir: str | os.PathLike[str],
    *,
    robots: int = 40,
    recordings: int = 6,
    changes: dict[int, Change] | None = None,
    duration: float = 30.0,
    rate: float = 200.0,
    perturb: float = 0.05,
    friction_spread: float = 0.1,
    harmonics: int = 3,
    base_freq: float = 0.1,
    seed: int = 0,
    client: Any = None,
) -> dict[str, Any]:
    """Simulate a fleet's recordings into ``out_dir`` (see the module's docstring).

    Parameters
    ----------
    robot : RobotModel or str
        The nominal model every robot is made from.
    out_dir : str or path-like
        Folder for ``<robot>/<date>.csv`` and ``truth.json`` (created if missing).
    robots, recordings : int
        Fleet size and recordings per robot.
    changes : dict of int to Change, optional
        Robot index (from 0) -> its change.
    duration : float
        Length of each recording (s).
    rate : float
        Sample rate of the files (Hz), a divisor of the simulator's control rate (1 kHz).
    perturb : float
        Relative perturbation of each robot's standard parameters (manufacturing tolerance).
    friction_spread : float
        Half-width of each robot's friction factor per joint.
    harmonics, base_freq : int, float
        The excitation's Fourier series (``base_freq`` in Hz).
    seed : int
        Seed of the trajectory, the robots and the noise.
    client : distributed.Client, optional
        Run one task per robot state on it.

    Returns
    -------
    dict
        The truth (also in ``truth.json``): per robot its friction factors, change and files.
    """
    from dynid.optim.excitation import ExcitationProblem
    from dynid.sim.simulator import CONTROL_RATE
    from dynid.symbolic.robot import load_robot

    robot = load_robot(robot) if isinstance(robot, str) else robot
    changes = dict(changes or {})
    for index, change in changes.items():
        if not (0 <= index < robots and 0 < change.at < recordings):
            raise UsageError(
                f"the change of robot {index} at recording {change.at} is outside a fleet of {robots} robots with "
                f"{recordings} recordings; give a robot below {robots} and a recording in 1..{recordings - 1}."
            )
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    problem = ExcitationProblem(robot=robot, harmonics=harmonics, base_freq=base_freq)
    trajectory = problem.random_trajectory(np.random.default_rng([seed, 3]), amplitude=0.9)
    settings = {"perturb": perturb, "friction_spread": friction_spread, "seed": seed, "duration": duration,
                "rate": rate, "control_rate": CONTROL_RATE}
    tasks = []
    for index in range(robots):
        change = changes.get(index)
        if change is None:
            tasks.append((index, None, list(range(recordings))))
        else:
            tasks.append((index, None, list(range(change.at))))
            tasks.append((index, change, list(range(change.at, recordings))))
    args = [robot, trajectory, out]
    if client is None:
        done = [_simulate_state(args[0], args[1], i, c, o, str(args[2]), settings) for i, c, o in tasks]
    else:
        futures = [
            client.submit(_simulate_state, robot, trajectory, i, c, o, str(out), settings, pure=False)
            for i, c, o in tasks
        ]
        done = client.gather(futures)
    truth: dict[str, Any] = {"robot": robot.name, "recordings": recordings, "duration_s": duration, "rate_hz": rate,
                             "perturb": perturb, "friction_spread": friction_spread, "seed": seed, "robots": {}}
    for (_, change, _), item in zip(tasks, done, strict=True):
        entry = truth["robots"].setdefault(item["robot"], {"paths": [], "change": None})
        entry["paths"] += item["paths"]
        if change is None:
            entry["friction_scale"] = item["friction_scale"]
        else:
            entry["change"] = {"kind": change.kind, "at": change.at, "time": recording_time(change.at),
                               "joint": change.joint if change.kind == "friction" else None,
                               "factor": change.factor if change.kind == "friction" else None,
                               "mass": change.mass if change.kind == "tool" else None}
    write_json(out / "truth.json", truth)
    return truth
