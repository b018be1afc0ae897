"""Simulator speed: seconds of wall and CPU time to simulate a run at 1 kHz.

For UR5 (6 joints) and Panda (7 joints), a 60 s Fourier trajectory (5 harmonics, 0.1 Hz), default
sensor noise, four set-ups: linear friction; the paper's friction (seed); elasticity on every joint;
all 14 effects with the paper's friction and a 10 % parameter perturbation.  Also the integration
error: the largest difference of the true joint angles from a run with 8 times more substeps.  Run::

    python benchmarks/simulate_benchmark.py [--duration 60]
"""

from __future__ import annotations

import argparse
import os
import time

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

from dynid.optim.trajectory import FourierTrajectory  # noqa: E402
from dynid.sim.effects import EFFECTS  # noqa: E402
from dynid.sim.simulator import simulate  # noqa: E402
from dynid.symbolic import load_robot  # noqa: E402

SETUPS = {
    "linear friction": {"friction": "linear"},
    "seed friction": {"friction": "seed"},
    "elasticity, all joints": {"friction": "linear", "effects": "elasticity"},
    "all 14 effects": {"friction": "seed", "effects": ",".join(EFFECTS), "perturb": 0.1},
}


def trajectory_for(robot) -> FourierTrajectory:
    rng = np.random.default_rng(1)
    n = robot.n
    centre = 0.5 * (np.maximum(robot.q_min, -np.pi) + np.minimum(robot.q_max, np.pi))
    return FourierTrajectory(
        a=rng.normal(scale=0.1, size=(5, n)), b=rng.normal(scale=0.1, size=(5, n)), c=centre, base_freq=0.1
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=60.0, help="simulated time per run (s)")
    args = parser.parse_args()
    print(
        f"{'robot':<6} {'set-up':<24} {'wall s':>7} {'cpu s':>7} {'substeps':>8} {'q error vs 8x substeps':>24}"
    )
    for name in ("ur5", "panda"):
        robot = load_robot(name)
        traj = trajectory_for(robot)
        for label, options in SETUPS.items():
            wall, cpu = time.perf_counter(), time.process_time()
            res = simulate(robot, traj, duration=args.duration, **options)
            wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
            fine = simulate(
                robot, traj, duration=min(args.duration, 10.0), substeps=8 * res.substeps, **options
            )
            err = np.abs(fine.q_true - res.q_true[: fine.t.size]).max()
            print(f"{name:<6} {label:<24} {wall:>7.2f} {cpu:>7.2f} {res.substeps:>8d} {err:>20.2e} rad")


if __name__ == "__main__":
    main()
