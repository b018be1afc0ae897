"""``dynid simulate``: synthetic measured data from a truth robot that follows a trajectory like a real one."""

from __future__ import annotations

import argparse

from dynid.commands.common import add_robot_arguments, check_outputs, output, robot_file, robot_from_args

__all__ = ["HELP", "add_arguments", "run"]

HELP = "simulate a robot following a trajectory: measured t, q, tau and a sidecar with the truth"


def _effect_help() -> str:
    """The ``--effects`` help, its names and their words read from the catalogue (registered effects too)."""
    from dynid.sim.effects import EFFECTS

    names = ", ".join(f"{name} ({cls.summary})" if cls.summary else name for name, cls in EFFECTS.items())
    return (
        "unmodelled effects, NAME[@J|@J-K][:VALUE],... with VALUE scaling the documented default size (1.0) "
        f"and @J / @J-K choosing joints (numbered from 1). Names: {names}. Example: offset,elasticity@3:2,"
        "delay:1.5"
    ).replace("%", "%%")


_NOISE_HELP = (
    "sensor model, key=value,... or 'off': torque (white std, fraction of the joint's torque scale, default "
    "0.01), coloured (AR(1) std, 0.005), colour (AR(1) coefficient per ms, 0.9), encoder_bits (logged "
    "angle, counts per rev = 2^bits, 18; 0 exact), current_lsb (torque quantisation step, fraction of the torque scale, 0.001), control_bits (resolution of "
    "the motor encoders the controller reads, per joint revolution, 24)"
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_robot_arguments(parser)
    parser.add_argument(
        "--trajectory", required=True, metavar="T.json", help="trajectory file (.json or .csv)"
    )
    parser.add_argument("--effects", default=None, metavar="NAME[:VALUE],...", help=_effect_help())
    parser.add_argument("--noise", default=None, metavar="KEY=VALUE,...", help=_NOISE_HELP)
    parser.add_argument("--seed", type=int, default=0, help="seed of the noise and of the truth (default 0)")
    parser.add_argument(
        "--truth-seed",
        type=int,
        default=None,
        help="seed of the truth alone (perturbation, effect signs and phases); default --seed",
    )
    parser.add_argument(
        "--rate",
        type=float,
        default=1000.0,
        metavar="HZ",
        help="output rate, dividing 1000 Hz (default 1000)",
    )
    parser.add_argument(
        "--duration",
        type=float,
        default=None,
        metavar="S",
        help="length of the run (default: --periods periods of a Fourier trajectory, else the trajectory's length)",
    )
    parser.add_argument(
        "--periods",
        type=int,
        default=None,
        metavar="N",
        help="periods of a Fourier trajectory to run when --duration is not given (default: the trajectory's "
        "own, at least 3: the diagnosis measures the noise floor from the spread across repeated periods)",
    )
    parser.add_argument(
        "--perturb",
        type=float,
        default=0.0,
        metavar="FRACTION",
        help="relative perturbation of the truth's inertial parameters, physically consistent (default 0)",
    )
    parser.add_argument(
        "--friction",
        choices=("none", "linear", "seed", "stribeck"),
        default="linear",
        help="truth friction: Coulomb + viscous (linear, default), the paper's low/high-speed model (seed), "
        "Stribeck, or none",
    )
    parser.add_argument(
        "--true-states",
        action="store_true",
        help="also write the true dq_i, ddq_i (debugging; a robot gives none)",
    )
    parser.add_argument("--out", required=True, metavar="D.csv", help="dataset to write (.csv or .npz)")


def run(args: argparse.Namespace) -> int:
    from dynid.exceptions import UsageError
    from dynid.optim.trajectory import FourierTrajectory, load_trajectory
    from dynid.sim.effects import parse_effects
    from dynid.sim.simulator import NoiseModel, check_output_path, simulate, truth_path, write_simulation

    check_outputs(
        [output("out", args.out, (".csv", ".npz"), also=[truth_path(args.out)], hint="the dataset")],
        {"trajectory": args.trajectory, "robot": robot_file(args)},
    )
    effects = parse_effects(args.effects)
    noise = NoiseModel.parse(args.noise)
    out = check_output_path(args.out)
    robot = robot_from_args(args)
    trajectory = load_trajectory(args.trajectory)
    duration = args.duration
    if args.periods is not None and args.periods < 1:
        raise UsageError(f"--periods is {args.periods}; give a whole number of at least 1 (default 3).")
    if duration is None and isinstance(trajectory, FourierTrajectory):
        # Repeated periods are what the noise floor, the periodic averaging and the diagnosis need.
        periods = max(3, int(trajectory.periods)) if args.periods is None else args.periods
        duration = periods / trajectory.base_freq
    result = simulate(
        robot,
        trajectory,
        effects=effects,
        friction=args.friction,
        noise=noise,
        seed=args.seed,
        truth_seed=args.truth_seed,
        perturb=args.perturb,
        rate=args.rate,
        duration=duration,
        source=f"the trajectory '{args.trajectory}'",
    )
    data, sidecar = write_simulation(result, out, true_states=args.true_states)
    err = (result.q_true - result.q_desired) * 1e3
    names = ", ".join(str(e) for e in effects) or "none"
    print(
        f"wrote {data} ({result.t.size} samples, {robot.n} joints, {result.t[-1]:.3g} s at {result.rate:g} Hz) "
        f"and {sidecar.name}"
    )
    print(f"  robot {robot.name}, friction {args.friction}, perturb {args.perturb:g}, effects: {names}")
    print(
        f"  tracking error rms {', '.join(f'{v:.3g}' for v in (err**2).mean(axis=0) ** 0.5)} mrad; "
        f"simulated in {result.elapsed:.2f} s ({result.substeps} substeps per {1e3 / result.control_rate:g} ms)"
    )
    return 0
