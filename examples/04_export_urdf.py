"""
Physical bodies, the description's prior, and a URDF for a simulator
====================================================================

A simulator needs a mass, a centre of mass and an inertia for every link, each a real body.  Joint
torques determine only the base parameters, some of them weakly, so dynid identifies the links as
physically consistent bodies (every link's pseudo-inertia positive definite) and keeps the robot's
own description (the URDF) in the directions the data do not determine: a prior whose strength is
chosen from the training recording by blocked cross-validation.

The identified model is then written into a copy of the URDF: link inertials, and per joint
``<dynamics damping= friction=>`` (viscous, Coulomb), reloaded by Pinocchio and checked against
dynid's own torque before the file is kept.  This is ``dynid export --model model.json --format urdf
--out ur5_identified.urdf``.
"""

import importlib.util
import sys
import tempfile
import xml.etree.ElementTree as ET
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

import dynid
from dynid.sim import write_simulation
from dynid.simmodel import export_model

out = (
    Path(sys.argv[1])
    if len(sys.argv) > 1
    else Path(tempfile.mkdtemp(prefix="dynid-export-"))
)
out.mkdir(parents=True, exist_ok=True)

# %%
# Identify with the defaults
# --------------------------
# A simulated UR5 whose links differ from the URDF by 10 %, with linear friction
# (the truth goes to ``D.csv.truth.json``), identified with the defaults and
# saved as ``dynid identify`` would.
robot = dynid.load_robot("ur5")
problem = dynid.ExcitationProblem(robot=robot, harmonics=3, base_freq=0.2)
trajectory = problem.random_trajectory(np.random.default_rng(0), amplitude=0.9)
truth = dynid.build_truth(robot, friction="linear", perturb=0.1, truth_seed=0)
run = dynid.simulate(
    robot, trajectory, truth=truth, seed=1, duration=3 * trajectory.period
)
write_simulation(run, out / "D.csv")
model = dynid.identify_model(
    robot, run.to_dataset(), friction="linear", gmm="off"
)
dynid.save_model(model, out / "model.json")
print("prior:", model.info["prior"]["rule"])

# %%
# Who decided each link: the data or the description
# --------------------------------------------------
# ``data_share`` is how much of a link's uncertainty the recording removed (0: the description
# decided it alone, 1: the data did).  The UR5's first link turns about a vertical axis: its mass
# never reaches a joint torque, so it stays the URDF's.
true_mass = truth.robot.params[0::10]
print("link   URDF  truth  identified  data share  decided by")
for j, link in enumerate(model.links()):
    urdf, mass, share = (
        link["mass_description"],
        link["mass"],
        link["data_share"],
    )
    print(
        f"{j + 1:>4} {urdf:6.3f} {true_mass[j]:6.3f} {mass:11.3f} {share:11.2f}"
        f"  {link['decided_by']}"
    )

# %%
# The masses side by side, each link's bar labelled with its data share.
links = model.links()
x = np.arange(1, robot.n + 1)
fig, ax = plt.subplots(figsize=(8, 3.4), layout="constrained")
ax.bar(x - 0.27, [k["mass_description"] for k in links], 0.27, label="URDF")
ax.bar(x, true_mass, 0.27, label="simulated truth")
bars = ax.bar(x + 0.27, [k["mass"] for k in links], 0.27, label="identified")
ax.bar_label(bars, labels=[f"{k['data_share']:.2f}" for k in links], fontsize=7)
ax.set_xticks(x, [f"link {j}" for j in x])
ax.set_ylabel("mass (kg)")
ax.set_title("Link masses; above each identified bar, the data's share")
ax.legend(fontsize=8)
fig.savefig(out / "masses.png", dpi=90)

# %%
# Write the URDF
# --------------
# The export reloads the file with Pinocchio and compares its inverse dynamics with dynid's rigid
# body and armature torque on random states (1e-8 relative); a failing check leaves no file.  What
# URDF cannot hold (armature, torque offsets) is listed, never dropped silently.
exported = export_model(model, "urdf", out / "ur5_identified.urdf")
for check in exported.checks:
    error, passed = check["relative_error"], check["passed"]
    print(f"check: {check['check']}")
    print(f"  relative error {error:.1e}, passed: {passed}")
for item in exported.not_carried:
    print(f"not carried: {item['what']} (joints {item['joints']})")
for joint in ET.parse(exported.path).getroot().iter("joint"):
    dynamics = joint.find("dynamics")
    if dynamics is not None:
        damping = float(dynamics.get("damping"))
        friction = float(dynamics.get("friction"))
        name = joint.get("name")
        print(f"  {name:<20} damping {damping:.4f}  friction {friction:.4f}")

# %%
# Reload it as a robot
# --------------------
# The exported file is an ordinary URDF: dynid (or any simulator) loads it.  Its base parameters are
# the identified ones, much closer to the truth than the original URDF's.
reloaded = dynid.load_robot(exported.path)
base = dynid.base_parameters(dynid.robot_functions(robot))
truth_beta = base.to_base(truth.robot.params)
for name, params in [("original", robot.params), ("exported", reloaded.params)]:
    error = np.abs(base.to_base(params) - truth_beta).max()
    print(f"{name} URDF: largest base-parameter error {error:.4f}")

# %%
# MuJoCo
# ------
# With ``pip install "dynid[mujoco]"`` the same model goes into an MJCF, with armature and
# ``frictionloss`` too, checked with ``mj_inverse`` and a forward rollout.
if importlib.util.find_spec("mujoco") is not None:
    mjcf = export_model(model, "mjcf", out / "ur5_identified.xml")
    passed = sum(c["passed"] for c in mjcf.checks)
    print(
        f"wrote {mjcf.path.name}: {passed} of {len(mjcf.checks)} checks passed"
    )
