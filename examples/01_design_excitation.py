"""
Design an excitation trajectory
===============================

An identification is only as good as the motion it is identified from.  dynid designs that motion
as a finite Fourier series per joint, optimised with IPOPT so that the noise-weighted base
regressor is well conditioned, while every joint stays within its position, velocity and
acceleration limits over the whole period and starts and ends at rest.

This is ``dynid excite --robot ur5 --harmonics 3 --base-freq 0.2 --out excitation.json --csv
excitation.csv`` spelled out, with small settings (3 harmonics, a 5 s period, a few random starts).
"""

import sys
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

import dynid
from dynid.optim import executable_trajectory

out = (
    Path(sys.argv[1])
    if len(sys.argv) > 1
    else Path(tempfile.mkdtemp(prefix="dynid-excitation-"))
)
out.mkdir(parents=True, exist_ok=True)

# %%
# The robot and the problem
# -------------------------
# The UR5's URDF gives position and velocity limits; the acceleration limit is dynid's default
# (10 rad/s^2).  Slow the arm down for a first run on a real robot.  The ``seed`` criterion is the
# paper's: condition numbers of the whole regressor and of its gravity-related and other columns.
robot = dynid.load_robot("ur5").with_limits(dq_max=2.0, ddq_max=6.0)
problem = dynid.ExcitationProblem(
    robot=robot, harmonics=3, base_freq=0.2, criterion="seed"
)
print(f"{robot.name}: {robot.n} joints, {problem.n_free} decision variables")

# %%
# Optimise
# --------
# Random feasible starts are screened and the best ones polished; the result is compared with the
# best of ``baseline`` random feasible trajectories, the figure to beat.
design = dynid.design_excitation(
    problem, seed=0, max_tries=4, patience=2, baseline=20
)
trajectory = design.trajectories[0]
print(f"cond {design.cond:.3g}, designed in {design.seconds:.1f} s")
print(
    f"best of 20 random feasible trajectories: cond {design.baseline_cond:.3g}"
)
print(f"every limit met over the whole period: {design.feasible}")

# %%
# The motion against its limits
# ------------------------------
# Each signal divided by its limit: every curve stays within +-1, and the period starts and ends at
# rest (zero velocity and acceleration).
t = np.linspace(0.0, trajectory.period, 1001)
q, dq, ddq = trajectory.evaluate(t)
middle, half = (robot.q_max + robot.q_min) / 2, (robot.q_max - robot.q_min) / 2
fig, axes = plt.subplots(
    3, 1, figsize=(8, 6.5), sharex=True, layout="constrained"
)
for ax, values, label in zip(
    axes,
    [(q - middle) / half, dq / robot.dq_max, ddq / robot.ddq_max],
    ["angle", "velocity", "acceleration"],
    strict=True,
):
    ax.plot(t, values, lw=1.2)
    ax.axhline(1.0, color="k", lw=0.8, ls="--")
    ax.axhline(-1.0, color="k", lw=0.8, ls="--")
    ax.set_ylabel(f"{label} / limit")
fig.legend(
    [f"joint {j + 1}" for j in range(robot.n)],
    loc="outside right upper",
    fontsize=8,
)
axes[-1].set_xlabel("time (s)")
fig.suptitle(f"UR5 excitation, cond {design.cond:.3g}")
fig.savefig(out / "excitation.png", dpi=90)

# %%
# What the robot runs
# -------------------
# The coefficients go to ``excitation.json`` (``dynid simulate --trajectory`` reads it).  The CSV for
# the robot's controller adds a jerk-limited approach from a home pose and a retreat to it (ruckig),
# with three periods of the excitation in between, so that the noise floor can later be measured
# from the spread across periods.
home = np.array([0.0, -1.57, 1.57, -1.57, -1.57, 0.0])
run = executable_trajectory(robot, trajectory, rate=500.0, home=home, periods=3)
for seg in run.meta["segments"]:
    print(
        f"  {seg['kind']:<10} {seg['start']:6.2f} s + {seg['duration']:5.2f} s"
    )
trajectory.save(out / "excitation.json")
run.to_csv(out / "excitation.csv")
print(f"wrote {out / 'excitation.json'} and {out / 'excitation.csv'}")
