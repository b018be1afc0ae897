"""The defaults on arms nobody tuned dynid on, from the command line as a user runs it (prints figures).

For each arm of example-robot-data (UR10, UR3, xArm 7, Unitree Z1, a double pendulum) and two kinds of
friction, a training and a held-out run are simulated on two different excitations (``dynid excite``
seeds 0 and 1; ``dynid simulate`` with the links 20 % off the description, ``--truth-seed 42`` so both runs
are one arm, angles and torques only, the simulator's default noise): scenario ``a`` Coulomb and viscous
friction, ``b`` Stribeck friction, and ``b2`` the same arm trained on two excitations of 15 s each instead of
one of 30 s (seeds 0 and 2, given as ``identify --data A.csv B.csv``; the held-out run is ``b``'s).  Each is
identified with the defaults and with dynid's simplest pipeline
(``--method ols --friction linear --gmm off``) and both are validated on the held-out run.  Printed per
case: the pipeline the defaults chose, every joint's held-out RMS ratio defaults / simplest (the promise:
at most 1.05), the exported bodies' total mass against the description's, and the identify times.

The double pendulum's description has zero limits; a copy with +-3.14 rad and 6 rad/s is used.

Run:  OMP_NUM_THREADS=1 python benchmarks/unseen_arms_benchmark.py [--arms ur10 ur3 xarm7 z1 dp] [--out DIR]
      (about 13 minutes on 2 cores for all five)

Measured at the change that added it (load 0.5-2): worst joint ratio per arm, scenario a / b: UR10 0.99 / 0.74,
UR3 0.97 / 0.93, xArm 7 0.99 / 1.37 (joints 2-4), Z1 1.06 / 0.88, double pendulum 0.97 / 1.16: 7 of 10 within 1.05.

With ``b2`` (the pipeline chosen on the two excitations, each predicting the other): a / b / b2 UR10
0.99 / 0.74 / 0.70, UR3 0.97 / 0.93 / 1.00, xArm 7 0.99 / 1.37 / 1.03, Z1 1.06 / 0.88 / 1.02, double pendulum
0.97 / 1.16 / 0.64: 5 of 5 within 1.05 on two excitations, against 3 of 5 on one.  Z1 ``b2`` exports 1.83 times
the description's mass: IRLS with linear friction, chosen there, puts link 2 at 2.3-4.3 kg (truth 1.13) under
every pull from 0 to 10, with the same held-out error; linear friction under Stribeck friction bends the link
parameters the data do see.

Rerun on a fresh install (2026-11-28: numpy 2.4.6, scipy 1.17.1, casadi 3.8.2, pin 4.1.0, scikit-learn 1.9.1;
no identification code changed since the figures above), worst joint ratio a / b / b2: UR10 0.99 / 0.74 / 0.74,
UR3 1.15 / 1.00 / 1.25, xArm 7 0.99 / 1.39 / 1.03, Z1 1.24 / 1.08 / 1.02, double pendulum 0.97 / 1.17 / 0.60; Z1
b2 exports 1.48 times the description's mass.  The one-excitation rows moved with the environment (UR3 a 0.97
-> 1.15, Z1 a 1.06 -> 1.24): the excitations IPOPT designs, and so the motions, differ, and on one motion the
seed friction's gain on the halves says little about another motion (5 of 10 one-excitation cases above 1.05,
each with the seed friction chosen; irls + linear friction would have been within 1.06 on 9 of 10, but 1.55 on
UR3 b, where the seed friction is right).  Two excitations: 3 of 5 within 1.05 (UR3 b2 1.25: ols + seed chosen
on the runs, 0.95 there on joint 3).

With one static level for both directions on a recording of one motion (``seed_shared``, the same install):
a / b / b2 UR10 0.99 / 0.74 / 0.74, UR3 0.95 / 0.97 / 1.25, xArm 7 0.95 / 1.57 / 1.03, Z1 0.99 / 1.16 / 1.02,
double pendulum 0.98 / 1.16 / 0.60: 7 of 10 one-excitation cases within 1.05 (5 before); xArm 7 b worse
(1.39 -> 1.57: its Coulomb levels took the asymmetry the static levels had held), Z1 b worse (1.08 -> 1.16,
the mixture on joint 4); masses x0.97-1.12 but Z1 b2 x1.48.

With a joint slower than 1e-3 rad/s counted at rest for friction (``dynid._rest``; the same install and
excitations): a / b / b2 UR10 0.99 / 0.72 / 0.73, UR3 0.93 / 0.98 / 1.26, xArm 7 1.02 / **2.84** / 1.03, Z1
1.00 / 0.92 / 1.02, double pendulum 1.00 / 1.12 / 0.58: 8 of 10 one-excitation cases within 1.05 (Z1 b 1.16 ->
0.92), but xArm 7 b 1.57 -> 2.84 on joint 3, which its held-out motion holds still at 8 % of its samples.
Without the mixture correction it is 1.14 there (1.57 before the rule): the stick rows of the training
reversals, which no friction direction explains now, went to joint 3's position mixture, which predicts
them wherever the new motion stands still.  With a joint's mixture not fitted on its at-rest samples and
zero there (the same install and excitations): a / b / b2 UR10 0.99 / 0.72 / 0.73, UR3 0.93 / 0.98 / 1.26,
xArm 7 1.02 / 1.14 / 1.03, Z1 1.00 / 0.97 / 1.02, double pendulum 1.00 / 1.12 / 0.58: 8 of 10 one-excitation
cases within 1.05 (xArm 7 b and the double pendulum b above), 4 of 5 on two excitations (UR3 b2 above);
masses x0.97-1.13 but Z1 b2 x1.53.  With the seed model's square and cube going on as secants beyond the
fastest training speed: double pendulum b 1.12 -> 0.99 (its held-out motion ran 25 % faster), the rest
unchanged: **9 of 10 one-excitation cases within 1.05** (xArm 7 b 1.14: joint 3's static level, fitted at
2.9 times its Coulomb level on the training reversals, where the truth is 1.5 times), 4 of 5 on two
(UR3 b2 1.26, joint 3, the same).  A static cap of 2 instead of 3 takes those two to 1.03 and 1.00 but UR3 b
to 1.37 (the choice turns to linear friction there): not adopted.  With the threshold search and the
export's speeds over moving samples only (the same install): the same figures but Z1 b 0.97 -> 1.01 (joint 4).
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

ARMS = {
    "ur10": "ur10",
    "ur3": "ur_description/urdf/ur3_robot.urdf",
    "xarm7": "xarm_description/urdf/xarm7.urdf",
    "z1": "z1_description/urdf/z1.urdf",
    "dp": "double_pendulum_description/urdf/double_pendulum_simple.urdf",
}
EXCITE = ["--harmonics", "3", "--base-freq", "0.2", "--max-tries", "2", "--patience", "1", "--baseline", "5"]
SCENARIOS = {
    "a": ["--friction", "linear"],
    "b": ["--friction", "stribeck", "--effects", "stribeck"],
    "b2": ["--friction", "stribeck", "--effects", "stribeck"],  # b on two excitations of 15 s
}


def dynid(*args: str, cwd: Path) -> float:
    """Run ``dynid ARGS`` quietly in ``cwd``; its wall time (s).  A failure stops the benchmark with its message."""
    start = time.perf_counter()
    proc = subprocess.run(
        [sys.executable, "-m", "dynid", *args, "--quiet"], cwd=cwd, capture_output=True, text=True
    )
    if proc.returncode != 0:
        raise SystemExit(f"dynid {' '.join(args)} failed: {proc.stderr.strip().splitlines()[-1]}")
    return time.perf_counter() - start


def robot_path(name: str, folder: Path) -> str:
    from dynid.symbolic.robot import example_robot_data_dir

    if "/" not in ARMS[name]:
        return ARMS[name]
    path = example_robot_data_dir() / ARMS[name]
    if name != "dp":
        return str(path)
    text = path.read_text().replace('lower="0"', 'lower="-3.14"').replace('upper="0"', 'upper="3.14"')
    text = text.replace('effort="0"', 'effort="5"').replace('velocity="0"', 'velocity="6"')
    patched = folder / "double_pendulum.urdf"
    patched.write_text(text)
    return str(patched)


def urdf_mass(robot: str) -> float:
    from dynid.symbolic import load_robot

    return float(np.sum(load_robot(robot).params.reshape(-1, 10)[:, 0]))


def run_arm(name: str, folder: Path) -> None:
    import warnings

    warnings.simplefilter("ignore")
    folder.mkdir(parents=True, exist_ok=True)
    robot = robot_path(name, folder)
    for seed, out in ((0, "T.json"), (1, "H.json"), (2, "T2.json")):
        dynid("excite", "--robot", robot, *EXCITE, "--seed", str(seed), "--out", out, cwd=folder)
    for sc, friction in SCENARIOS.items():
        runs = [("T.json", 1, 30, "train.csv"), ("H.json", 2, 20, "held.csv")]
        if sc.endswith("2"):  # two excitations of 15 s for training, the same held-out run as the scenario's
            runs = [("T.json", 1, 15, "train.csv"), ("T2.json", 3, 15, "train2.csv"), ("H.json", 2, 20, "held.csv")]
        for traj, seed, duration, out in runs:
            dynid("simulate", "--robot", robot, "--trajectory", traj, *friction, "--perturb", "0.2", "--seed",
                  str(seed), "--truth-seed", "42", "--duration", str(duration), "--out", f"{sc}_{out}", cwd=folder)  # fmt: skip
        train = [f"{sc}_{out}" for _, _, _, out in runs if out.startswith("train")]
        t_def = dynid("identify", "--robot", robot, "--data", *train, "--out", f"{sc}_def.json", cwd=folder)
        t_ols = dynid("identify", "--robot", robot, "--data", *train, "--out", f"{sc}_ols.json",
                      "--method", "ols", "--friction", "linear", "--gmm", "off", cwd=folder)  # fmt: skip
        dynid("validate", "--model", f"{sc}_def.json", "--data", f"{sc}_held.csv", "--compare", f"{sc}_ols.json",
              "--json", f"{sc}_val.json", cwd=folder)  # fmt: skip
        dynid("export", "--model", f"{sc}_def.json", "--format", "urdf", "--out", f"{sc}_def.urdf", cwd=folder)
        val = json.loads((folder / f"{sc}_val.json").read_text())
        rms = [np.asarray(m["rms"], dtype=float) for m in val["models"]]
        ratio = rms[0] / rms[1]
        pipe = json.loads((folder / f"{sc}_def.json").read_text())["pipeline"]
        mass = urdf_mass(str(folder / f"{sc}_def.urdf")) / urdf_mass(robot)
        gains = "".join(f"+gain{j}" for j in pipe.get("drive_gains", []))
        print(
            f"{name:6s} {sc:2s}  {pipe['method']}+{pipe['friction']}+{pipe['gmm']:<5}{gains}  worst {ratio.max():5.2f} "
            f"(joint {int(ratio.argmax()) + 1})  ratios {' '.join(f'{r:.2f}' for r in ratio)}  "
            f"mass x{mass:.2f}  identify {t_def:.0f} s / {t_ols:.0f} s",
            flush=True,
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--arms", nargs="+", choices=sorted(ARMS), default=list(ARMS))
    parser.add_argument("--out", help="folder to keep the runs in (default: a temporary one)")
    args = parser.parse_args()
    print("arm    sc  defaults' pipeline    held-out RMS, defaults / ols + linear per joint (promise: <= 1.05)")
    with tempfile.TemporaryDirectory() as tmp:
        base = Path(args.out) if args.out else Path(tmp)
        for name in args.arms:
            run_arm(name, base / name)


if __name__ == "__main__":
    main()
