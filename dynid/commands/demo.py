"""``dynid demo``: the whole path on the built-in default robot (UR5), one stage after another.

The stages live in :func:`dynid.demo.run_demo`; this command checks its options, shows the progress,
prints the summary table and writes ``--json``.
"""

from __future__ import annotations

import argparse
import shutil
from pathlib import Path
from typing import TYPE_CHECKING

from dynid.commands.common import add_json_argument, check_outputs, output
from dynid.exceptions import UsageError

if TYPE_CHECKING:
    from dynid.demo import DemoResult

__all__ = ["HELP", "add_arguments", "run"]

HELP = "run the whole path on the built-in default robot (UR5): excite, simulate, identify, validate, diagnose, report"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The demo's options: ``--out``, ``--quick``, ``--seed``, ``--json``."""
    parser.add_argument(
        "--out",
        default="dynid-demo",
        metavar="DIR",
        help="folder for every file the demo writes (default dynid-demo)",
    )
    parser.add_argument(
        "--quick", action="store_true", help="shorter trajectories and search (every stage still runs)"
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of every random choice (default 0)")
    add_json_argument(parser)


def _check_out(path: str) -> Path:
    out = Path(path)
    if out.exists() and not out.is_dir():
        raise UsageError(f"--out '{out}' is a file; give a folder for the demo's files.")
    if not out.parent.exists():
        raise UsageError(f"the folder '{out.parent}' of --out does not exist; create it or write elsewhere.")
    return out


def _show(line: str) -> None:
    from dynid import _progress

    print(line, flush=True)
    _progress.touch()


def run(args: argparse.Namespace) -> int:
    """Run the demo; exit code 1 when a stage failed (the diagnosis may fail without stopping it)."""
    from dynid._io import write_json
    from dynid.demo import DEMO_FILES, run_demo

    if args.seed < 0:  # before the folder is made: a refused demo leaves nothing behind
        raise UsageError(f"--seed is {args.seed}; give a whole number of at least 0 (default 0).")
    out = _check_out(args.out)
    check_outputs([output("out", out, folder=True), output("json", args.json, (".json",))])
    json_path = None if args.json is None else Path(args.json)
    if json_path is not None and json_path.parent.resolve() == out.resolve() and json_path.name in DEMO_FILES:
        raise UsageError(
            f"--json '{json_path}' is one of the files the demo writes in --out '{out}'; give another name."
        )
    made = not out.exists()
    try:
        result = run_demo(out, quick=args.quick, seed=args.seed, progress=_show)
    except BaseException:  # a full disk, an interrupt: a folder this run made is not left half filled
        if made:
            shutil.rmtree(out, ignore_errors=True)
        raise
    _print_summary(result)
    if json_path is not None:
        write_json(json_path, result.figures)
    return 1 if result.failed else 0


def _print_summary(result: DemoResult) -> None:
    print("\nsummary")
    for row in result.stages:
        print(f"  {row.stage:<72} {row.status:>9} {row.seconds:6.1f} s")
    results = result.results
    if results:
        n = results[0].n
        print("\nheld-out RMS per joint (N m), validation run on another trajectory")
        print(
            f"  {'model':<12}" + "".join(f"{'joint ' + str(j + 1):>10}" for j in range(n)) + f"{'mean':>10}"
        )
        for r in results:
            print(
                f"  {r.label:<12}"
                + "".join(f"{v:>10.4g}" for v in r.metrics["rms"])
                + f"{r.metrics['rms_mean']:>10.4g}"
            )
        noise = results[0].noise
        print(
            f"  {'noise floor':<12}" + "".join(f"{v:>10.4g}" for v in noise.std) + f"{noise.rms_mean:>10.4g}"
        )
    if result.report is not None:
        print(f"\nreport: {Path(result.report).resolve()}")
    print(f"total {result.total_s:.1f} s")
