"""Excitation design: optimised condition numbers against random feasible trajectories, and wall time.

For each robot (UR5, Panda) and criterion (seed, cond, logdet): one design at N = 5 harmonics,
ff = 0.1 Hz, the paper's stopping rule (15 tries without improvement), and the best of 100 random
feasible Fourier trajectories from the same seed as the baseline.  Printed: the exact cond (SVD of
the noise-weighted base regressor on the check grid) of the lowest-cond random trajectory and of the
result, their ratio (the paper: 193 / 329 = 0.59), the criterion's value for the result and for the
best random trajectory by that criterion, the tries, the IPOPT iterations of the kept try, the wall
time of the design and per try (wall time of the stage / tries: with n_jobs = 2, half a try's CPU).

Run:  OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python benchmarks/excitation_benchmark.py
      (--robots ur5 --criteria cond --sharpness inf --n-jobs 2 ... to vary; --json FILE keeps the figures)

Not a test: nothing is asserted.
"""

from __future__ import annotations

import argparse
import json
import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", default="ur5,panda")
    parser.add_argument("--criteria", default="seed,cond,logdet")
    parser.add_argument("--harmonics", type=int, default=5)
    parser.add_argument("--base-freq", type=float, default=0.1)
    parser.add_argument("--grid", type=int, default=None)
    parser.add_argument("--sharpness", type=float, default=16.0)
    parser.add_argument("--patience", type=int, default=15)
    parser.add_argument("--max-tries", type=int, default=60)
    parser.add_argument("--baseline", type=int, default=100)
    parser.add_argument("--n-jobs", type=int, default=2)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--json", default=None)
    args = parser.parse_args()

    from dynid.optim.excitation import ExcitationProblem, design_excitation
    from dynid.symbolic import load_robot

    rows = []
    header = (
        f"{'robot':<6} {'criterion':<8} {'random best':>11} {'optimised':>10} {'ratio':>6} {'objective':>10} "
        f"{'random obj':>10} {'tries':>6} {'iter':>5} {'time s':>7} {'s/try':>6}"
    )
    print(f"N = {args.harmonics}, ff = {args.base_freq} Hz, sharpness p = {args.sharpness}, patience "
          f"{args.patience}, n_jobs {args.n_jobs}, baseline: best of {args.baseline} random feasible trajectories")
    print(header)
    for name in args.robots.split(","):
        robot = load_robot(name)
        for criterion in args.criteria.split(","):
            problem = ExcitationProblem(
                robot=robot,
                harmonics=args.harmonics,
                base_freq=args.base_freq,
                criterion=criterion,
                grid=args.grid,
                sharpness=args.sharpness,
            )
            result = design_excitation(
                problem,
                seed=args.seed,
                patience=args.patience,
                max_tries=args.max_tries,
                baseline=args.baseline,
                n_jobs=args.n_jobs,
            )
            stage = result.stages[0]
            row = {
                "robot": name,
                "criterion": criterion,
                "baseline_cond": result.baseline_cond,
                "cond": result.cond,
                "ratio": result.cond / result.baseline_cond,
                "objective": result.objective,
                "baseline_objective": result.baseline_objective,
                "start_cond": stage.start_cond,
                "tries": stage.tries,
                "iterations": stage.iterations,
                "seconds": result.seconds,
                "seconds_per_try": stage.seconds / stage.tries,
            }
            rows.append(row)
            print(
                f"{name:<6} {criterion:<8} {row['baseline_cond']:>11.4g} {row['cond']:>10.4g} {row['ratio']:>6.3f} "
                f"{row['objective']:>10.4g} {row['baseline_objective']:>10.4g} {row['tries']:>6d} "
                f"{row['iterations']:>5d} {row['seconds']:>7.1f} {row['seconds_per_try']:>6.2f}",
                flush=True,
            )
    if args.json:
        with open(args.json, "w") as handle:
            json.dump(rows, handle, indent=2)


if __name__ == "__main__":
    main()
