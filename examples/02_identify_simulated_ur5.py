"""
Identify a simulated arm and compare with the truth
===================================================

The loop every identification method should pass before it meets a real robot: simulate an arm
whose parameters are known exactly, identify it from what its sensors recorded, and compare.

The simulated UR5 differs from its URDF: every link's mass, centre of mass and inertia is perturbed
by 10 % (each link stays a physical body) and its joints have Coulomb and viscous friction.  It
tracks an excitation under a closed-loop controller whose model is the URDF, with quantised encoders
and noisy, quantised torque readings, so the identification has to find a truth it is not given.
"""

import json
import sys
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

import dynid
from dynid.sim import write_simulation

out = (
    Path(sys.argv[1])
    if len(sys.argv) > 1
    else Path(tempfile.mkdtemp(prefix="dynid-identify-"))
)
out.mkdir(parents=True, exist_ok=True)

# %%
# Simulate
# --------
# A random feasible Fourier trajectory (5 s period; example 1 designs a better one), run for three
# periods at 1 kHz.  The truth, its friction and the noise settings go to ``D.csv.truth.json`` beside
# the data, never into them.
robot = dynid.load_robot("ur5")
problem = dynid.ExcitationProblem(robot=robot, harmonics=3, base_freq=0.2)
trajectory = problem.random_trajectory(np.random.default_rng(0), amplitude=0.9)
truth = dynid.build_truth(robot, friction="linear", perturb=0.1, truth_seed=0)
run = dynid.simulate(
    robot, trajectory, truth=truth, seed=1, duration=3 * trajectory.period
)
write_simulation(run, out / "D.csv")
print(f"{run.t.size} samples over {run.t[-1]:.1f} s")

# %%
# Identify
# --------
# Layer 1 only, to compare parameters: ordinary least squares on the base parameters, armature and
# linear friction, with the default preprocessing (zero-phase low-pass filter on the angles,
# central differences, the same filter on the torque and on every regressor column).  The data are
# read back from the file, as a recording would be.
data = dynid.load_dataset(out / "D.csv", robot.n)
model = dynid.identify_model(
    robot, data, method="ols", friction="linear", gmm="off"
)
dynid.save_model(model, out / "model.json")
print(f"condition number {model.cond:.3g}")
print("training RMS per joint (N m):", np.round(model.rms, 3))

# %%
# Base parameters against the truth
# ---------------------------------
# Joint torques determine only the base parameters (36 for the UR5: independent combinations of the
# 60 standard ones).  The truth's base parameters come from its standard parameters through the same
# map; so do the URDF's, the starting point of the identification.
base = dynid.base_parameters(dynid.robot_functions(robot))
true_beta = base.to_base(truth.robot.params)
urdf_beta = base.to_base(robot.params)
nb = base.n_base
found, std = model.params[:nb], model.std[:nb]
err_model = np.abs(found - true_beta)
err_urdf = np.abs(urdf_beta - true_beta)
z = (found - true_beta) / std
print(f"largest base-parameter error of the URDF: {err_urdf.max():.3g}")
print(f"largest base-parameter error identified:  {err_model.max():.3g}")
print(f"errors within 2 reported std: {np.mean(np.abs(z) < 2):.0%}")

fig, ax = plt.subplots(figsize=(9, 3.8), layout="constrained")
k = np.arange(nb)
ax.semilogy(k, err_urdf, "s", color="0.6", label="URDF (the description)")
ax.semilogy(k, err_model, "o", color="C0", label="identified")
ax.semilogy(k, 2 * std, "_", color="C3", ms=12, label="2 reported std")
ax.set_xticks(k, base.names, rotation=90, fontsize=7)
ax.set_ylabel("|error| (SI units)")
ax.set_title("UR5 base parameters: distance to the simulated truth")
ax.legend(fontsize=8)
fig.savefig(out / "parameters.png", dpi=90)

# %%
# Friction against the truth
# --------------------------
# The Coulomb (``fc``) and viscous (``fv``) coefficients are identified with the link parameters.
names = list(model.columns.names)
fc = model.params[[names.index(f"fc{j + 1}") for j in range(robot.n)]]
fv = model.params[[names.index(f"fv{j + 1}") for j in range(robot.n)]]
fc_true, fv_true = truth.friction.kc_pos, truth.friction.kv1
print("joint   fc true  fc found   fv true  fv found")
for j in range(robot.n):
    row = [fc_true[j], fc[j], fv_true[j], fv[j]]
    print(f"{j + 1:>5} " + " ".join(f"{v:9.4f}" for v in row))

figures = {
    "max_error_identified": float(err_model.max()),
    "max_error_urdf": float(err_urdf.max()),
    "within_2_std": float(np.mean(np.abs(z) < 2)),
    "fc_relative_error": (np.abs(fc - fc_true) / fc_true).tolist(),
}
(out / "comparison.json").write_text(json.dumps(figures, indent=1))
