"""
Validate on held-out data and read the noise floor
==================================================

A model's error on the data it was fitted to says little: the question is how well it predicts a
motion it has not seen, and how far that error is from the best any model could do.  dynid answers
the second part by measuring the noise floor, never assuming it: when the held-out run repeats a
period, the floor is the spread of the (filtered) torque across the periods, phase by phase.

Here the simulated UR5 has the paper's nonlinear friction (direction-dependent Coulomb levels, a
velocity-cubic viscous term, a low-speed negative slope).  Two models are identified on one run and
validated on another: ordinary least squares with linear friction, the baseline, and dynid's
default, which chooses its pipeline from the training recording itself.
"""

import json
import sys
import tempfile
import textwrap
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

import dynid
from dynid.validation import compare, render_report
from dynid.validation.plots import plot_method_rms

out = (
    Path(sys.argv[1])
    if len(sys.argv) > 1
    else Path(tempfile.mkdtemp(prefix="dynid-validate-"))
)
out.mkdir(parents=True, exist_ok=True)

# %%
# Two runs of one simulated robot
# -------------------------------
# One truth, two trajectories, independent noise.  The held-out run repeats its 5 s period three
# times: after the filter's ends are trimmed, at least two whole periods are left to measure the
# floor from.
robot = dynid.load_robot("ur5")
problem = dynid.ExcitationProblem(robot=robot, harmonics=3, base_freq=0.2)
train_motion = problem.random_trajectory(
    np.random.default_rng(0), amplitude=0.9
)
held_motion = problem.random_trajectory(np.random.default_rng(7), amplitude=0.9)
truth = dynid.build_truth(robot, friction="seed", perturb=0.1, truth_seed=0)
train = dynid.simulate(
    robot, train_motion, truth=truth, seed=1, duration=4 * train_motion.period
)
heldout = dynid.simulate(
    robot, held_motion, truth=truth, seed=2, duration=3 * held_motion.period
)
train, heldout = train.to_dataset(), heldout.to_dataset()

# %%
# Two models, the same training data
# ----------------------------------
# The default (``method="auto"``) fits each candidate pipeline on one half of the training run,
# scores its prediction of the other half, both ways, and records which it chose and why.
models = {
    "OLS + linear friction": dynid.identify_model(
        robot, train, method="ols", friction="linear", gmm="off"
    ),
    "dynid default": dynid.identify_model(robot, train),
}
reason = models["dynid default"].info["pipeline"]["reason"]
print(textwrap.fill(f"default pipeline: {reason}", 78))

# %%
# Validate
# --------
# Each model predicts the held-out run as it was identified (same filter, same trimming); the
# torque it is compared with went through the same treatment.  ``period`` tells the noise floor
# where to look for repetitions (a simulated file's sidecar holds it; a real recording's is
# detected from the angles, or the spectral floor, a lower bound, is used and said).
results = [
    dynid.validate(m, heldout, period=held_motion.period, label=name)
    for name, m in models.items()
]
floor = results[0].noise
print(textwrap.fill(f"noise floor ({floor.method}): {floor.detail}", 78))
print(
    "                           "
    + "".join(f"  joint {j + 1}" for j in range(robot.n))
)
print(f"{'noise floor (N m)':<27}" + "".join(f"{s:9.3f}" for s in floor.std))
for row in compare(results):
    print(f"{row['label']:<27}" + "".join(f"{r:9.3f}" for r in row["rms"]))

# %%
# Read the result in units of the floor
# -------------------------------------
# A held-out RMS at the floor is as good as any model can be on these data.  A ratio above 1 is
# either the parameters' own error (what a short training run leaves uncertain) or something the
# model lacks; the diagnosis (the last example) tells the two apart.
labels = [r.label for r in results]
rms = np.array([r.metrics["rms"] for r in results])
fig, ax = plt.subplots(figsize=(8, 3.8), layout="constrained")
plot_method_rms(ax, labels, rms, noise=floor.std)
ax.legend(fontsize=8)
ax.set_title("Held-out RMS per joint against the measured noise floor")
fig.savefig(out / "heldout_rms.png", dpi=90)
for label, row in zip(labels, rms / floor.std, strict=True):
    print(f"{label:<22} held-out RMS / floor: {np.round(row, 2)}")

# %%
# The HTML report
# ---------------
# What ``dynid validate --report`` writes: the figures, the torques and errors per joint, the
# friction curves and the parameters with their standard deviations.
report = render_report(results)
report.write(out / "validation.html")
figures = {
    "labels": labels,
    "rms": rms.tolist(),
    "floor": floor.std.tolist(),
    "floor_method": floor.method,
}
(out / "validation.json").write_text(json.dumps(figures, indent=1))
print(f"wrote {out / 'validation.html'}")
