"""``dynid demo``: the whole path on the built-in default robot (UR5), one stage after another.

Stages: symbolic model -> excitation design -> simulated runs (identification and validation) ->
identification (three layers and OLS) -> validation -> gap diagnosis -> report.  A stage whose part
of dynid is not built yet is listed as such, never faked.
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
import time
from collections.abc import Callable
from pathlib import Path

from dynid.commands.common import add_json_argument

HELP = "run the whole path on the built-in default robot (UR5) and print a summary"

DEFAULT_ROBOT = "ur5"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--out", default="dynid-demo", metavar="DIR", help="folder for every file the demo writes"
    )
    parser.add_argument("--quick", action="store_true", help="shorter runs (every stage still runs)")
    parser.add_argument("--seed", type=int, default=0, help="seed of every random choice")
    add_json_argument(parser)


class Stages:
    """Runs named stages, shows progress, keeps the figures for the summary."""

    def __init__(self) -> None:
        self.rows: list[tuple[str, str, float]] = []
        self.missing: list[str] = []

    def run(self, label: str, fn: Callable[[], str]) -> None:
        print(f"[{len(self.rows) + len(self.missing) + 1}] {label}...", flush=True)
        start = time.perf_counter()
        summary = fn()
        elapsed = time.perf_counter() - start
        self.rows.append((label, summary, elapsed))
        print(f"    {summary} ({elapsed:.1f} s)", flush=True)

    def not_built(self, label: str, module: str) -> None:
        self.missing.append(label)
        print(
            f"[{len(self.rows) + len(self.missing)}] {label}: not built yet ({module} does not exist)",
            flush=True,
        )


def _exists(module: str) -> bool:
    try:
        return importlib.util.find_spec(module) is not None
    except ModuleNotFoundError:
        return False


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from dynid.cli import write_json
    from dynid.symbolic.build import cache_dir, generator_is_built
    from dynid.symbolic.robot import load_robot

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    stages = Stages()
    figures: dict = {"robot": DEFAULT_ROBOT}
    robot = load_robot(DEFAULT_ROBOT)
    state: dict = {}

    def symbolic() -> str:
        from dynid.symbolic.base import base_parameters
        from dynid.symbolic.functions import robot_functions

        if not generator_is_built():
            print(
                "    first run in this environment: building the symbolic generator once (1-2 minutes on 2 cores), "
                f"cached in {cache_dir()}",
                flush=True,
            )
        funcs = robot_functions(robot)
        base = base_parameters(funcs)
        state["funcs"], state["base"] = funcs, base
        figures["n_base"] = base.n_base
        return (
            f"{robot.name}: {robot.n} joints, {base.n_base} base parameters "
            f"({int(base.gravity_related.sum())} gravity-related)"
        )

    def export() -> str:
        import pinocchio as pin

        from dynid.symbolic.export import export_c

        result = export_c(robot, out / "c_export", progress=None)
        from dynid.symbolic._export.loader import CompiledLibrary

        lib = CompiledLibrary(result.folder)
        rng = np.random.default_rng(args.seed)
        q, dq, ddq = rng.uniform(-1, 1, size=(3, 1000, robot.n))
        tau = lib.rnea(q, dq, ddq)
        model, data = robot.pin_model, robot.pin_model.createData()
        err = max(
            float(np.abs(tau[k] - pin.rnea(model, data, q[k], dq[k], ddq[k])).max()) for k in range(len(q))
        )
        figures["c_export_max_error"] = err
        return f"C export in {result.folder}: compiled rnea vs numeric Pinocchio on 1000 states, max error {err:.1e} N m"

    stages.run("symbolic dynamics and base parameters (Pinocchio on CasADi)", symbolic)
    stages.run("C export of the regressors, checked against numeric Pinocchio", export)

    pending = [
        ("excitation design (IPOPT)", "dynid.optim.excitation"),
        ("simulated identification and validation runs", "dynid.identify.simulate"),
        ("identification: three layers and OLS", "dynid.identify.estimators"),
        ("validation on the held-out run", "dynid.validation.metrics"),
        ("sim-to-real gap diagnosis", "dynid.validation.diagnosis"),
        ("HTML report", "dynid.validation.report"),
    ]
    for label, module in pending:
        stages.not_built(label, module)

    print("\nsummary")
    for label, summary, elapsed in stages.rows:
        print(f"  {label:<62} {elapsed:6.1f} s  {summary}")
    if stages.missing:
        print(f"  not built yet: {', '.join(stages.missing)}")
    figures["stages_missing"] = stages.missing
    write_json(args.json, figures)
    print(f"files in {out.resolve()}", file=sys.stdout)
    return 0
