"""
Identify a payload
==================

With the arm's model identified once, what the gripper holds is identified from a short run with
it, in a fraction of a second: the change of the ten inertial parameters of the body at the tool
frame, fitted to what the arm's model leaves of the loaded run.  A reference run of the same motion
without the payload cancels most of what the arm's model gets wrong.  What the motion cannot
determine is reported as undetermined (``None``), never guessed.

This is ``dynid excite --payload`` (the motion) and ``dynid payload --model M.json --data
loaded.csv --reference unloaded.csv`` (the fit).
"""

import json
import sys
import tempfile
import textwrap
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

import dynid
from dynid.optim.payload_motion import design_payload_motion
from dynid.symbolic.bodies import frame_transform, payload_frame

out = (
    Path(sys.argv[1])
    if len(sys.argv) > 1
    else Path(tempfile.mkdtemp(prefix="dynid-payload-"))
)
out.mkdir(parents=True, exist_ok=True)

# %%
# The arm's model, without the payload
# ------------------------------------
robot = dynid.load_robot("ur5")
problem = dynid.ExcitationProblem(robot=robot, harmonics=3, base_freq=0.2)
excitation = problem.random_trajectory(np.random.default_rng(0), amplitude=0.9)
truth = dynid.build_truth(robot, friction="linear", perturb=0.1, truth_seed=0)
arm_run = dynid.simulate(
    robot, excitation, truth=truth, seed=1, duration=3 * excitation.period
)
model = dynid.identify_model(
    robot, arm_run.to_dataset(), friction="linear", gmm="off"
)

# %%
# A short motion that determines the payload
# ------------------------------------------
# 10 s, at rest at the given pose at both ends, designed (IPOPT, A-optimality) for the payload's ten
# parameters alone: the arm's model is known.  ``relative_std`` is each parameter's predicted
# standard deviation in units of the payload's mass, 10 cm and (10 cm)^2.
place = payload_frame(robot)  # the tool frame
pose = np.array([0.0, -1.2, 1.0, -1.0, 0.5, 0.0])
motion = design_payload_motion(
    robot, place.link, frame_transform(place), pose=pose, duration=10.0
)
print(f"payload motion at frame '{place.name}': {motion.trajectory.period:g} s")
print(f"every limit met: {motion.feasible}")
print("predicted relative std:", np.round(motion.relative_std, 3))

# %%
# Run it without and with the payload
# -----------------------------------
# The simulator's ``payload`` effect: a point mass of 5 % of the arm's mass, 5 cm along the tool's z
# axis.  The same truth otherwise.
loaded_truth = dynid.build_truth(
    robot, friction="linear", perturb=0.1, truth_seed=0, effects="payload"
)
true_payload = loaded_truth.effect("payload")
unloaded = dynid.simulate(
    robot, motion.trajectory, truth=truth, seed=2
).to_dataset()
loaded = dynid.simulate(
    robot, motion.trajectory, truth=loaded_truth, seed=3
).to_dataset()
dynid.save_dataset(unloaded, out / "unloaded.csv")
dynid.save_dataset(loaded, out / "loaded.csv")

# %%
# Identify it
# -----------
result = dynid.identify_payload(model, loaded, reference=unloaded)
figures = result.figures()
mass, mass_std = figures["mass"], figures["mass_std"]
print(f"mass {mass:.4f} +- {mass_std:.4f} kg (true {true_payload.mass:.4f} kg)")
print(
    "centre of mass in the tool frame (m):",
    [f"{c:+.4f}" for c in figures["com"]],
    "(true 0, 0, +0.05)",
)
print("determined:", [name for name, ok in figures["determined"].items() if ok])
for note in result.notes:
    print(textwrap.fill(f"note: {note}", 78, subsequent_indent="  "))
print("RMS of the arm model on the loaded run (N m)")
print(
    "  without the payload:",
    " ".join(f"{r:6.3f}" for r in figures["rms_before"]),
)
print(
    "  with it:            ",
    " ".join(f"{r:6.3f}" for r in figures["rms_after"]),
)

# %%
# What the arm's model missed, and the payload's torque
# -----------------------------------------------------
# On the loaded run, the arm's model leaves the payload's torque (grey); the identified payload
# accounts for it (colour).  Joints 2 and 3 carry most of it against gravity.
fig, axes = plt.subplots(
    3, 1, figsize=(8, 5.5), sharex=True, layout="constrained"
)
for ax, j in zip(axes, [1, 2, 4], strict=True):
    ax.plot(
        result.t,
        result.residual[:, j],
        color="0.6",
        lw=2.5,
        label="arm model's error, loaded run",
    )
    ax.plot(
        result.t,
        result.torque[:, j],
        color="C1",
        lw=1.0,
        label="identified payload's torque",
    )
    ax.set_ylabel(f"joint {j + 1} (N m)")
axes[0].legend(fontsize=8, loc="upper right")
axes[-1].set_xlabel("time (s)")
fig.savefig(out / "payload.png", dpi=90)

# %%
# The arm's model with the payload attached
# -----------------------------------------
# Its base parameters move by exactly the payload's; ``dynid export`` writes the payload as a link
# of its own.
with_payload = dynid.attach_payload(model, result)
dynid.save_model(with_payload, out / "model_with_payload.json")
(out / "payload.json").write_text(json.dumps(figures, indent=1, default=float))
print(f"wrote {out / 'payload.json'} and {out / 'model_with_payload.json'}")
