"""Design an excitation trajectory for a UR5 standing on a table, and write what the robot runs.

Run:  python scripts/design_excitation.py [OUT_DIR]        (about a minute on 2 cores)

The same as ``dynid excite --robot ur5 --criterion seed --z-min -0.3 --out OUT/ur5.json --csv OUT/ur5.csv``,
spelled out step by step.
"""

import sys
from pathlib import Path

import numpy as np

from dynid.optim.approach import executable_trajectory
from dynid.optim.excitation import CartesianLimits, ExcitationProblem, design_excitation
from dynid.symbolic import load_robot

out = Path(sys.argv[1] if len(sys.argv) > 1 else ".")

# The robot and its limits.  The URDF gives position and velocity limits; the acceleration limit is
# dynid's default (10 rad/s^2) since URDF has no field for it.  Slow the arm down for a first run.
robot = load_robot("ur5").with_limits(dq_max=2.0, ddq_max=6.0)

# The excitation: N = 5 harmonics at ff = 0.1 Hz, so one period lasts 10 s.  The criterion is the
# paper's: condition numbers of the noise-weighted base regressor and of its gravity-related and
# gravity-independent parts.  Torque noise differs per joint (N m): the big joints are noisier.
# The tool must stay above a table 0.3 m below the robot's base plate.
problem = ExcitationProblem(
    robot=robot,
    harmonics=5,
    base_freq=0.1,
    criterion="seed",
    noise_std=[0.5, 0.5, 0.3, 0.1, 0.1, 0.1],
    cartesian=CartesianLimits(z_min=-0.3),
)

# Random starts, optimised by IPOPT in parallel; the search stops after 15 tries without improvement.
result = design_excitation(problem, seed=0, patience=15, n_jobs=2, progress=print)
print(f"cond {result.cond:.1f}; the best of 100 random feasible trajectories: {result.baseline_cond:.1f}")

# Every limit holds between the samples of the optimisation grid too (checked 10x finer).
trajectory = result.trajectories[0]
assert problem.is_feasible(trajectory)

# What the robot runs: from its home pose to the start of the excitation (jerk-limited, ruckig),
# three periods of the excitation, and back home, sampled at the controller's 500 Hz.
home = np.array([0.0, -1.57, 1.57, -1.57, -1.57, 0.0])
run = executable_trajectory(robot, result.trajectories, rate=500.0, home=home, periods=3)
for segment in run.meta["segments"]:
    print(f"  {segment['kind']:<10} from {segment['start']:6.2f} s for {segment['duration']:5.2f} s")

trajectory.save(out / "ur5_excitation.json")  # coefficients: dynid simulate --trajectory reads it
run.to_csv(out / "ur5_excitation.csv")  # t, q_i, dq_i, ddq_i for the robot's controller
print(f"wrote {out / 'ur5_excitation.json'} and {out / 'ur5_excitation.csv'}")
