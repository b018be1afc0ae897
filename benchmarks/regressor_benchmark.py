"""Regressor speed: compiled batch path vs the CasADi virtual machine vs numeric Pinocchio.

For UR5 and Panda, 100,000 random states, the joint-torque regressor Y and the base regressor Y_b:
microseconds per sample for

* ``compiled``: dynid's generated C, N samples per ctypes call, straight into numpy;
* ``casadi-vm``: the same CasADi function evaluated by CasADi's SX virtual machine (``F.map(N)``);
* ``pinocchio``: numeric ``pin.computeJointTorqueRegressor`` called in a Python loop (the baseline;
  for Y_b its independent columns are selected afterwards).

Also the time of a second request for a robot's functions with the cache warm, measured in a fresh
interpreter (the case that matters: every new script or command).  Run::

    python benchmarks/regressor_benchmark.py [--samples 100000]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402
import pinocchio as pin  # noqa: E402

from dynid.symbolic import base_parameters, load_robot, robot_functions  # noqa: E402
from dynid.symbolic.base import random_states  # noqa: E402
from dynid.symbolic.export import compiled_functions  # noqa: E402


def best_of(fn, repeats: int = 3) -> float:
    """Smallest wall time of ``repeats`` calls (s)."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return min(times)


def pinocchio_loop(robot, q, dq, ddq, columns=None, out=None) -> np.ndarray:
    model = robot.pin_model
    data = model.createData()
    if out is None:
        out = np.empty((len(q), robot.n, 10 * robot.n if columns is None else len(columns)))
    for k in range(len(q)):
        Y = pin.computeJointTorqueRegressor(model, data, q[k], dq[k], ddq[k])
        out[k] = Y if columns is None else Y[:, columns]
    return out


def warm_request_seconds(name: str) -> float:
    """Time for load_robot + functions + base parameters + compiled library in a new interpreter."""
    code = (
        "import time; t = time.perf_counter(); "
        "from dynid.symbolic import load_robot, robot_functions, base_parameters; "
        "from dynid.symbolic.export import compiled_functions; "
        f"r = load_robot({name!r}); f = robot_functions(r); b = base_parameters(f); lib = compiled_functions(r); "
        "print(time.perf_counter() - t)"
    )
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return float(run.stdout.strip().splitlines()[-1])


def bench_robot(name: str, m: int) -> tuple[list[float], int]:
    """Print one robot's rows; return its speed-up ratios and the threads of the compiled path."""
    robot = load_robot(name)
    funcs = robot_functions(robot)
    base = base_parameters(funcs)
    lib = compiled_functions(robot)
    q, dq, ddq = random_states(robot, m, np.random.default_rng(0))
    cases = (
        ("regressor", lib.regressor, lambda: funcs.regressor_numeric(q, dq, ddq), None, 10 * robot.n),
        ("base_regressor", lib.base_regressor, lambda: base.evaluate(q, dq, ddq), base.independent, base.n_base),
    )
    ratios = []
    for label, compiled, vm, columns, width in cases:
        # The three paths give the same numbers; then time them.
        ref = pinocchio_loop(robot, q[:200], dq[:200], ddq[:200], columns)
        assert np.allclose(compiled(q[:200], dq[:200], ddq[:200]), ref, atol=1e-9)
        buffer = np.ones((m, robot.n, width))  # touched: its pages exist
        t_new = best_of(lambda c=compiled: c(q, dq, ddq))
        t_reused = best_of(lambda c=compiled, b=buffer: c(q, dq, ddq, out=b))
        t_pin_new = best_of(lambda c=columns: pinocchio_loop(robot, q, dq, ddq, c), repeats=1)
        t_pin_reused = best_of(lambda c=columns, b=buffer: pinocchio_loop(robot, q, dq, ddq, c, b), repeats=1)
        t_vm = best_of(vm, repeats=1)
        us = [1e6 * t / m for t in (t_new, t_reused, t_pin_new, t_pin_reused, t_vm)]
        print(
            f"{name:<6} {label:<15} " + " ".join(f"{u:>8.2f}u" for u in us) + f"   {t_pin_new / t_new:>11.1f}x "
            f"{t_pin_reused / t_reused:>11.1f}x"
        )
        ratios += [t_pin_new / t_new, t_pin_reused / t_reused]
    return ratios, lib.threads


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=100_000)
    args = parser.parse_args()
    m = args.samples
    print(f"regressor benchmark: {m} random states per robot; best of 3 (Pinocchio loop: 1 run)")
    print("'new': each call allocates its output array (the kernel zeroes every page: included);")
    print("'reused': the output buffer exists already (compiled: out=...; Pinocchio: the same array).\n")
    header = (
        f"{'robot':<6} {'function':<15} {'compiled':>9} {'compiled':>9} {'pinocchio':>9} {'pinocchio':>9} "
        f"{'casadi-vm':>9}   {'pin/compiled':>12} {'pin/compiled':>12}"
    )
    print(header)
    print(f"{'':<22} {'new':>9} {'reused':>9} {'new':>9} {'reused':>9} {'new':>9}   {'new':>12} {'reused':>12}")
    print("-" * len(header))
    ratios = []
    threads = 1
    for name in ("ur5", "panda"):
        robot_ratios, threads = bench_robot(name, m)
        ratios += robot_ratios
    print(f"\n(u = microseconds per sample; the compiled path ran on {threads} thread(s), set DYNID_NUM_THREADS")
    print(" to change; CasADi VM: F.map(N) plus the conversion of its DM result to numpy)")
    print(
        f"target: compiled batch >= 4x faster than numeric Pinocchio: worst ratio {min(ratios):.1f}x -> "
        f"{'met' if min(ratios) >= 4 else 'NOT met'}"
    )
    for name in ("ur5", "panda"):
        warm = warm_request_seconds(name)
        print(
            f"second request for {name}'s functions (cache warm, new interpreter, imports included): "
            f"{warm:.2f} s -> {'met' if warm < 1 else 'NOT met'} (target < 1 s)"
        )


if __name__ == "__main__":
    main()
