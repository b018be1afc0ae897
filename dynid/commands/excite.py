"""``dynid excite``: design an optimised excitation trajectory (Fourier series, IPOPT) and its executable CSV."""

from __future__ import annotations

import argparse
from pathlib import Path

from dynid.commands.common import (
    add_json_argument,
    add_robot_arguments,
    check_outputs,
    output,
    robot_file,
    robot_from_args,
)
from dynid.exceptions import DynidError, UsageError

__all__ = ["HELP", "add_arguments", "output_paths", "run"]

HELP = "design an excitation trajectory (Fourier series optimised with IPOPT) and write it as JSON and CSV"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_robot_arguments(parser)
    parser.add_argument("--harmonics", type=int, default=5, help="harmonics N per joint (default 5)")
    parser.add_argument("--base-freq", type=float, default=0.1, metavar="HZ", help="base frequency (default 0.1 Hz)")
    parser.add_argument(
        "--criterion",
        choices=("seed", "cond", "logdet"),
        default="seed",
        help="seed: the paper's weighted condition numbers; cond: cond(H*); logdet: D-optimality (default seed)",
    )
    parser.add_argument("--trajectories", type=int, default=1, metavar="K", help="design K complementary trajectories")
    parser.add_argument("--seed", type=int, default=0, help="seed of the random starts (default 0)")
    parser.add_argument(
        "--out",
        required=True,
        metavar="T.json",
        help="Fourier coefficients and metadata (JSON); with --trajectories K also T-2.json .. T-K.json",
    )
    parser.add_argument("--csv", metavar="T.csv", help="also write approach, excitation(s) and retreat sampled at --rate")
    parser.add_argument("--rate", type=float, default=500.0, metavar="HZ", help="controller rate of the CSV (default 500)")
    add_json_argument(parser)
    group = parser.add_argument_group("problem")
    group.add_argument("--grid", type=int, metavar="M", help="optimisation samples per period (default max(40, 12 N))")
    group.add_argument("--noise-std", metavar="V[,V...]", help="torque noise std per joint (N m) weighting H*; default 1")
    group.add_argument("--z-min", type=float, metavar="Z", help="keep the tool above this height (m, base frame)")
    group.add_argument(
        "--box", metavar="X0,Y0,Z0,X1,Y1,Z1", help="keep the tool inside this box (m, base frame): low and high corners"
    )
    group = parser.add_argument_group("search")
    group.add_argument("--patience", type=int, default=15, help="tries without improvement before stopping (default 15)")
    group.add_argument("--max-tries", type=int, default=60, help="most tries per trajectory (default 60)")
    group.add_argument(
        "--screen-iter",
        type=int,
        default=40,
        metavar="N",
        help="IPOPT iterations of each try's screening solve; only the best --polish tries are solved to the end "
        "(default 40; 0: every try solved to the end)",
    )
    group.add_argument("--polish", type=int, default=2, help="screened tries solved to the end (default 2)")
    group.add_argument(
        "--n-jobs",
        type=int,
        help="parallel tries (joblib; -1: every core, or every worker thread with --scheduler; default 2, -1 "
        "with --scheduler)",
    )
    group.add_argument("--backend", help="joblib backend (loky, threading, ...; default joblib's)")
    group.add_argument(
        "--scheduler",
        metavar="ADDRESS|FILE",
        help="run the tries on a running Dask scheduler (tcp://HOST:8786, or a scheduler file .json) through "
        "joblib's dask backend; the design is the same as without it",
    )
    group.add_argument(
        "--baseline", type=int, default=100, help="random feasible trajectories to compare with (default 100)"
    )
    group = parser.add_argument_group("payload motion")
    group.add_argument(
        "--payload",
        action="store_true",
        help="design a short motion that determines a payload's ten parameters (for 'dynid payload'), starting "
        "and ending at rest at --home, instead of a full excitation",
    )
    group.add_argument(
        "--duration", type=float, default=10.0, metavar="S", help="length of the payload motion (s, at most 15; default 10)"
    )
    group.add_argument("--frame", metavar="F", help="the payload's frame (default: the tool frame)")
    group.add_argument(
        "--payload-speed",
        type=float,
        default=0.5,
        metavar="FRACTION",
        help="fraction of the velocity and acceleration limits the payload motion may use (default 0.5)",
    )
    group = parser.add_argument_group("executable CSV")
    group.add_argument("--home", metavar="Q[,Q...]", help="start and end pose (rad); default the middle of the ranges")
    group.add_argument(
        "--periods",
        type=int,
        default=3,
        help="periods of each excitation in the CSV (default 3: the noise floor and the diagnosis need repeats)",
    )
    group.add_argument(
        "--rest",
        type=float,
        default=2.0,
        metavar="S",
        help="seconds held still at home before the approach and after the retreat in the CSV (default 2)",
    )
    group.add_argument(
        "--speed-fraction", type=float, default=0.5, help="fraction of the velocity/acceleration limits for approach"
    )
    group.add_argument("--jerk-factor", type=float, default=5.0, help="jerk limit of the approach as a multiple of ddq_max")


def _floats(option: str, text: str | None, count: int | None = None) -> list[float] | None:
    if text is None:
        return None
    try:
        values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise UsageError(f"--{option} is '{text}'; give numbers separated by commas.") from None
    if count is not None and len(values) != count:
        raise UsageError(f"--{option} has {len(values)} values; give {count}, separated by commas.")
    return values


def output_paths(out: Path, count: int) -> list[Path]:
    """``T.json`` for the first trajectory, ``T-2.json``, ``T-3.json``, ... for the others."""
    return [out] + [out.with_name(f"{out.stem}-{k}{out.suffix}") for k in range(2, count + 1)]


def _show(line: str) -> None:
    """A line of the design's progress (stdout, as before), which also resets the heartbeat."""
    from dynid import _progress

    print("  " + line, flush=True)
    _progress.touch()


def _write_outputs(trajectories, csv, sampled, json_path, figures) -> None:
    """Every output of the command, replacing the old files together or not at all (a full disk while
    writing the CSV leaves the old trajectory in place)."""
    from dynid._io import dumps_json, write_together

    writers = [(path, traj.save) for path, traj in trajectories]
    if sampled is not None:
        writers.append((csv, sampled.to_csv))
    if json_path is not None:
        text = dumps_json(figures)
        writers.append((json_path, lambda tmp: Path(tmp).write_text(text, encoding="utf-8")))
    write_together(writers)


def _run_payload(args: argparse.Namespace, robot, out: Path, csv: Path | None, home) -> int:
    """``--payload``: a short motion that determines the payload at the tool frame (or --frame)."""
    import numpy as np

    from dynid.optim.approach import executable_trajectory
    from dynid.optim.payload_motion import design_payload_motion
    from dynid.symbolic.bodies import frame_transform, payload_frame

    place = payload_frame(robot, args.frame)
    noise = _floats("noise-std", args.noise_std)
    result = design_payload_motion(
        robot,
        place.link,
        frame_transform(place),
        pose=home,
        duration=args.duration,
        harmonics=args.harmonics,
        speed_fraction=args.payload_speed,
        noise_std=noise,
        seed=args.seed,
    )
    traj = result.trajectory
    traj.meta["files"] = [out.name]
    traj.meta["frame"] = place.name
    sampled = None
    if csv is not None:
        sampled = executable_trajectory(
            robot, [traj], rate=args.rate, home=result.pose, periods=1, rest=args.rest,
            speed_fraction=args.speed_fraction, jerk_factor=args.jerk_factor,
        )  # fmt: skip
    figures = {**result.to_dict(), "frame": place.name, "files": [str(out)]}
    if sampled is not None:
        figures["csv"] = {"path": str(csv), "rate": args.rate, "segments": sampled.meta["segments"]}
    _write_outputs([(out, traj)], csv, sampled, args.json, figures)
    std = figures["relative_std"]
    print(
        f"{robot.name}: payload motion at frame '{place.name}', {args.duration:g} s from pose "
        f"{np.round(result.pose, 3)} and back; cond {result.cond:.4g} (best random start {result.baseline_cond:.4g}); "
        f"feasible: {result.feasible}; {result.seconds:.1f} s"
    )
    print(
        "std at unit noise (mass kg, com kg x 10 cm, inertia kg x (10 cm)^2): "
        + ", ".join(f"{k} {v:.3g}" for k, v in std.items())
    )
    print(f"wrote {out}" + (f" and {csv}" if csv is not None else ""))
    return 0


def _check_csv_options(args: argparse.Namespace) -> None:
    """Refuse --periods, --rest, --speed-fraction and --jerk-factor the CSV cannot use, and a CSV too long."""
    import math

    from dynid.optim.approach import check_length

    if args.periods < 1:
        raise UsageError(f"--periods is {args.periods}; give a whole number of at least 1 (default 3).")
    if not (math.isfinite(args.rest) and args.rest >= 0):
        raise UsageError(f"--rest is {args.rest} s; give a duration of at least 0 s (default 2).")
    if not (0.01 <= args.speed_fraction <= 1):
        raise UsageError(
            f"--speed-fraction is {args.speed_fraction:g}; give a fraction of the robot's limits from 0.01 to 1 "
            "(default 0.5): slower, the approach would last hours."
        )
    if not (math.isfinite(args.jerk_factor) and args.jerk_factor > 0):
        raise UsageError(f"--jerk-factor is {args.jerk_factor}; give a positive factor (default 5).")
    if args.payload:
        seconds = 2 * args.rest + args.duration
    elif math.isfinite(args.base_freq) and args.base_freq > 0:
        seconds = 2 * args.rest + args.trajectories * args.periods / args.base_freq
    else:
        return  # the design names a bad base frequency
    check_length(seconds, args.rate, "the CSV (rests and excitations, before the approach moves)")


def run(args: argparse.Namespace) -> int:
    from dynid.optim.approach import check_pose

    out = Path(args.out)
    csv = None if args.csv is None else Path(args.csv)
    _check_options(args, out, csv)
    robot = robot_from_args(args)
    home = _floats("home", args.home, robot.n)
    home = check_pose(robot, home) if home is not None else None  # before the long design
    if args.payload:
        return _run_payload(args, robot, out, csv, home)
    problem = _problem(args, robot)
    print(
        f"{robot.name}: {args.criterion} criterion, {problem.harmonics} harmonics at {problem.base_freq:g} Hz, "
        f"{args.trajectories} trajectory(ies), {problem.grid} grid points per period"
    )
    result = _design(args, problem)
    sampled = _sampled(args, robot, result, csv, home)
    paths = _write_design(args, out, csv, result, sampled)
    _print_design(args, result, paths, csv, sampled)
    return 0


def _check_options(args: argparse.Namespace, out: Path, csv: Path | None) -> None:
    """Refuse bad options and outputs, before the robot is loaded and the long design starts."""
    from dynid.optim.excitation import check_harmonics

    if args.trajectories < 1:
        raise UsageError(f"--trajectories is {args.trajectories}; give at least 1.")
    check_outputs(
        [
            output(
                "out",
                out,
                (".json",),
                also=output_paths(out, args.trajectories)[1:],
                hint="the Fourier coefficients; the CSV goes to --csv",
            ),
            output("csv", csv, (".csv",)),
            output("json", args.json, (".json",)),
        ],
        {"robot": robot_file(args)},
    )
    if not (args.rate > 0):
        raise UsageError(f"--rate is {args.rate}; give the controller rate in Hz, e.g. 500.")
    if args.scheduler and args.backend:
        raise UsageError(
            f"--scheduler and --backend {args.backend} exclude each other; --scheduler runs the tries through "
            "joblib's dask backend: give one of them."
        )
    if args.seed < 0:
        raise UsageError(f"--seed is {args.seed}; give a whole number of at least 0 (default 0).")
    if args.screen_iter < 0:
        raise UsageError(f"--screen-iter is {args.screen_iter}; give 1 or more iterations, or 0 to solve every try to the end.")
    if args.payload:
        check_harmonics(args.harmonics, 1.0 / args.duration if args.duration > 0 else 1.0, rate=args.rate)
    else:
        check_harmonics(args.harmonics, args.base_freq, rate=args.rate)
    if csv is not None:  # the CSV's options, before the long design
        _check_csv_options(args)


def _problem(args: argparse.Namespace, robot):
    """The excitation problem of the options: harmonics, criterion, grid, noise and the tool's Cartesian limits."""
    from dynid.optim.excitation import CartesianLimits, ExcitationProblem

    box = _floats("box", args.box, 6)
    cartesian = None
    if args.z_min is not None or box is not None:
        cartesian = CartesianLimits(
            z_min=args.z_min, box_min=None if box is None else box[:3], box_max=None if box is None else box[3:]
        )
    noise = _floats("noise-std", args.noise_std)
    return ExcitationProblem(
        robot=robot,
        harmonics=args.harmonics,
        base_freq=args.base_freq,
        criterion=args.criterion,
        grid=args.grid,
        noise_std=noise,
        cartesian=cartesian,
    )


def _design(args: argparse.Namespace, problem):
    """Design the trajectories, here (joblib) or on a Dask cluster with --scheduler."""
    from dynid._progress import say
    from dynid.optim.excitation import design_excitation

    options = {
        "trajectories": args.trajectories,
        "seed": args.seed,
        "patience": args.patience,
        "max_tries": args.max_tries,
        "baseline": args.baseline,
        "screen_iter": args.screen_iter or None,
        "polish": args.polish,
        "progress": _show,
    }
    say(
        f"designing {args.trajectories} trajectory(ies) for {problem.robot.name} "
        f"({args.harmonics} harmonics, criterion {args.criterion})"
    )
    if args.scheduler:
        return _design_on_cluster(args, problem, options)
    return design_excitation(
        problem, n_jobs=2 if args.n_jobs is None else args.n_jobs, backend=args.backend, **options
    )


def _design_on_cluster(args: argparse.Namespace, problem, options: dict):
    """Design the trajectories with the tries on the Dask scheduler of --scheduler; its failure is a usage error."""
    import joblib

    from dynid._cluster import cluster_client
    from dynid.optim.excitation import design_excitation

    with cluster_client(args.scheduler) as client, joblib.parallel_config(backend="dask"):
        threads = sum(client.nthreads().values())
        print(f"  tries on the Dask cluster at {args.scheduler} ({threads} worker threads)", flush=True)
        try:
            return design_excitation(problem, n_jobs=-1 if args.n_jobs is None else args.n_jobs, **options)
        except (DynidError, KeyboardInterrupt):
            raise
        except Exception as exc:  # a worker lost, or one without dynid: the cluster's fault, not a bug here
            raise UsageError(
                f"the Dask cluster at {args.scheduler} failed during the design ({type(exc).__name__}: {exc}); "
                "check that its workers run and have dynid installed, or run without --scheduler"
            ) from None


def _sampled(args: argparse.Namespace, robot, result, csv: Path | None, home):
    """The executable CSV's samples (None without --csv), built before anything is written: a failure
    leaves no file behind."""
    from dynid.optim.approach import executable_trajectory

    if csv is None:
        return None
    return executable_trajectory(
        robot,
        result.trajectories,
        rate=args.rate,
        home=home,
        periods=args.periods,
        rest=args.rest,
        speed_fraction=args.speed_fraction,
        jerk_factor=args.jerk_factor,
    )


def _write_design(args: argparse.Namespace, out: Path, csv: Path | None, result, sampled) -> list[Path]:
    """Write the trajectories, the CSV and the figures together; the trajectories' paths."""
    paths = output_paths(out, len(result.trajectories))
    figures = result.to_dict()
    figures["files"] = [str(p) for p in paths]
    for traj in result.trajectories:
        traj.meta["files"] = [p.name for p in paths]
    if sampled is not None:
        figures["csv"] = {"path": str(csv), "rate": args.rate, "segments": sampled.meta["segments"]}
    _write_outputs(list(zip(paths, result.trajectories, strict=True)), csv, sampled, args.json, figures)
    return paths


def _print_design(args: argparse.Namespace, result, paths: list[Path], csv: Path | None, sampled) -> None:
    """Print the design's condition against the random baseline, and the files written."""
    import numpy as np

    ratio = result.cond / result.baseline_cond
    k = len(result.trajectories)
    print(
        f"cond {result.cond:.4g}{f' (the {k} trajectories stacked)' if k > 1 else ''} (best of {args.baseline} "
        f"random feasible: {result.baseline_cond:.4g}, ratio "
        f"{ratio:.2f}); {args.criterion} objective {result.objective:.4g}; feasible: {result.feasible}; "
        f"{result.seconds:.1f} s"
    )
    print(f"wrote {', '.join(str(p) for p in paths)}")
    if sampled is not None:
        parts = ", ".join(f"{s['kind']} {s['duration']:.2f} s" for s in sampled.meta["segments"])
        print(f"wrote {csv}: {sampled.t.size} samples at {args.rate:g} Hz ({parts}); home {np.round(sampled.q[0], 3)}")
