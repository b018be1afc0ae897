"""Excitation design: optimised condition numbers against random feasible trajectories, and wall time.

For each robot (UR5, Panda) and criterion (seed, cond, logdet): one design at N = 5 harmonics,
ff = 0.1 Hz, the paper's stopping rule (15 tries without improvement), and the best of 100 random
feasible Fourier trajectories from the same seed as the baseline.  Printed: the exact cond (SVD of
the noise-weighted base regressor on the check grid) of the lowest-cond random trajectory and of the
result, their ratio (the paper: 193 / 329 = 0.59), the criterion's value for the result and for the
best random trajectory by that criterion, the tries, the IPOPT iterations of the kept try, the wall
time of the design and its CPU time (the process and its joblib workers; the machine may be shared,
so the load average is printed beside it).

Run:  OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python benchmarks/excitation_benchmark.py
      (--robots ur5 --criteria seed --seeds 0,1,2 --screen-iter 0 --sharpness inf --n-jobs 2 ... to vary;
      --json FILE keeps the figures)

Measured (UR5, seed criterion, shared 2-core machine at load 15-17, so CPU time is the comparable
figure): screening at 40 iterations, 2 polished: ratio 0.349 / 0.335 / 0.326 on seeds 0 / 1 / 2 for
32 / 14 / 17 s of CPU; every try to the end (the previous method, --screen-iter 0 with IPOPT's
Sherman-Morrison update): 0.353 (155 s of CPU) / 0.325 / 0.346.

Not a test: nothing is asserted.
"""

from __future__ import annotations

import argparse
import json
import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from _timing import cpu_seconds


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
    parser.add_argument("--seeds", default="0", help="seeds, separated by commas (one design each)")
    parser.add_argument("--screen-iter", type=int, default=40, help="0: every try solved to the end")
    parser.add_argument("--polish", type=int, default=2)
    parser.add_argument("--json", default=None)
    args = parser.parse_args()

    import time

    from dynid.optim.excitation import ExcitationProblem, design_excitation
    from dynid.symbolic import load_robot

    rows = []
    header = (
        f"{'robot':<6} {'criterion':<8} {'seed':>4} {'random best':>11} {'optimised':>10} {'ratio':>6} "
        f"{'objective':>10} {'random obj':>10} {'tries':>6} {'iter':>5} {'wall s':>7} {'CPU s':>6} {'load':>5}"
    )
    print(f"N = {args.harmonics}, ff = {args.base_freq} Hz, sharpness p = {args.sharpness}, patience "
          f"{args.patience}, screening {args.screen_iter or 'off'} iterations, {args.polish} polished, n_jobs "
          f"{args.n_jobs}, baseline: best of {args.baseline} random feasible trajectories")
    print(header)
    for name in args.robots.split(","):
        robot = load_robot(name)
        for criterion, seed in ((c, int(s)) for c in args.criteria.split(",") for s in args.seeds.split(",")):
            problem = ExcitationProblem(
                robot=robot,
                harmonics=args.harmonics,
                base_freq=args.base_freq,
                criterion=criterion,
                grid=args.grid,
                sharpness=args.sharpness,
            )
            c0, t0 = cpu_seconds(), time.perf_counter()
            result = design_excitation(
                problem,
                seed=seed,
                patience=args.patience,
                max_tries=args.max_tries,
                baseline=args.baseline,
                n_jobs=args.n_jobs,
                screen_iter=args.screen_iter or None,
                polish=args.polish,
            )
            wall, cpu = time.perf_counter() - t0, cpu_seconds() - c0
            stage = result.stages[0]
            row = {
                "robot": name,
                "criterion": criterion,
                "seed": seed,
                "wall": wall,
                "cpu": cpu,
                "load": os.getloadavg()[0],
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
                f"{name:<6} {criterion:<8} {seed:>4d} {row['baseline_cond']:>11.4g} {row['cond']:>10.4g} "
                f"{row['ratio']:>6.3f} {row['objective']:>10.4g} {row['baseline_objective']:>10.4g} "
                f"{row['tries']:>6d} {row['iterations']:>5d} {wall:>7.1f} {cpu:>6.1f} {row['load']:>5.1f}",
                flush=True,
            )
    if args.json:
        with open(args.json, "w") as handle:
            json.dump(rows, handle, indent=2)


if __name__ == "__main__":
    main()
