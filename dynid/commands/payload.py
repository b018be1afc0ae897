"""``dynid payload``: what the gripper holds, identified on an identified arm (and the drive gains, given its mass)."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from dynid.commands.common import (
    add_degrees_argument,
    add_json_argument,
    add_topic_argument,
    check_data_fits_model,
    check_outputs,
    model_files,
    output,
    read_dataset,
)

__all__ = ["HELP", "add_arguments", "run"]

HELP = "identify a payload (mass, centre of mass, inertia) on an identified arm; with its mass known, the drive gains"


def _mass(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"expected the payload's mass in kg (> 0), got {text!r}")
    return value


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--model", required=True, metavar="M.json", help="the arm's model, identified without the payload"
    )
    parser.add_argument(
        "--data",
        required=True,
        metavar="loaded.csv",
        help="a run with the payload: any motion (a full excitation, 'dynid excite --payload', or still poses: "
        "then only the mass and the centre of mass)",
    )
    parser.add_argument(
        "--reference",
        metavar="unloaded.csv",
        help="the same motion run without the payload: the difference cancels most of what the arm's model gets "
        "wrong (default: the model's prediction stands in)",
    )
    parser.add_argument(
        "--frame",
        metavar="F",
        help="frame of the robot's description the payload is written in (default: the tool frame)",
    )
    parser.add_argument(
        "--mass",
        type=_mass,
        metavar="KG",
        help="the payload's known mass: calibrate each joint's drive gain (measured / true torque) from it",
    )
    parser.add_argument(
        "--no-friction-change",
        action="store_true",
        help="do not fit a change of each joint's Coulomb and viscous friction and offset beside the payload",
    )
    parser.add_argument("--out", metavar="M2.json", help="write the arm's model with the payload attached")
    parser.add_argument(
        "--report", metavar="R.html", help="write an HTML report (torque error, the payload on the flange)"
    )
    add_degrees_argument(parser)
    add_topic_argument(parser)
    add_json_argument(parser)


def _num(value, fmt: str = "{:.4g}") -> str:
    return "-" if value is None else fmt.format(value)


def run(args: argparse.Namespace) -> int:
    from dynid.identify.model import load_model

    report_path = _check_options(args)
    model = load_model(args.model)
    loaded = _read(args, model, args.data, "data")
    reference = None if args.reference is None else _read(args, model, args.reference, "reference")
    result = _identify(args, model, loaded, reference)
    figures = result.figures()
    figures.update({"model": str(args.model), "data": str(args.data), "out": args.out, "report": args.report})
    _print_header(args, model, figures)
    _print_body(args, figures)
    _print_fit(figures)
    _write_outputs(args, model, result, figures, report_path)
    return 0


def _check_options(args: argparse.Namespace):
    """Refuse a bad --report, --json or --out before any file is read; the report's path (None without one)."""
    from dynid.validation.html_page import check_report_path

    report_path = None if args.report is None else check_report_path(args.report, pdf=False)
    outs = [
        output("json", args.json, (".json",)),
        output("report", args.report, (".html", ".htm")),
    ]
    if args.out is not None:
        outs.append(
            output(
                "out",
                args.out,
                (".json",),
                also=model_files(args.out)[1:],
                hint="the model is JSON; its arrays go beside it as .npz",
            )
        )
    check_outputs(
        outs,
        {"model": args.model, "data": args.data, "reference": args.reference},
    )
    return report_path


def _read(args: argparse.Namespace, model, path: str, option: str):
    """Read a run with the model's robot and refuse one that does not fit the model."""
    data = read_dataset(path, model.robot.n, robot_name=model.robot.name, degrees=args.degrees,
                        topic=args.topic, joint_names=model.robot.joint_names)  # fmt: skip
    check_data_fits_model(model, data, model_path=args.model, data_option=option)
    return data


def _identify(args: argparse.Namespace, model, loaded, reference):
    """Identify the payload on the loaded run (against the reference run, if any)."""
    import dataclasses

    from dynid.identify.payload import identify_payload

    result = identify_payload(
        model,
        loaded,
        reference=reference,
        frame=args.frame,
        mass=args.mass,
        friction=not args.no_friction_change,
    )
    if args.reference is not None:
        result = dataclasses.replace(result, reference=str(args.reference))
    return result


def _print_header(args: argparse.Namespace, model, figures: dict) -> None:
    """Print where the payload was identified, from which run and against which reference."""
    print(
        f"{model.robot.name}: payload at frame '{figures['frame']}' (link {figures['link']}) from {args.data}, "
        f"{figures['samples']} samples; "
        + (
            "difference with the reference run"
            if args.reference
            else "the arm model's prediction as reference"
        )
    )


def _print_body(args: argparse.Namespace, figures: dict) -> None:
    """Print the payload's mass, centre of mass and inertia, with their standard deviations."""
    mass_line = f"mass {_num(figures['mass'])} kg +- {_num(figures['mass_std'], '{:.2g}')}"
    if args.mass is not None:
        mass_line = (
            f"mass {args.mass:.4g} kg (given); fitted with unit gains: {figures['mass_free']:.4g} "
            f"+- {figures['mass_free_std']:.2g} kg"
        )
    print(mass_line)
    com = ", ".join(
        f"{_num(None if c is None else 1000 * c, '{:.4g}')} +- {_num(None if s is None else 1000 * s, '{:.2g}')}"
        for c, s in zip(figures["com"], figures["com_std"], strict=True)
    )
    print(f"centre of mass (mm, in {figures['frame']}): {com}")
    print("inertia about the centre of mass (kg m^2; - where the motion did not determine it):")
    for row, srow in zip(figures["inertia"], figures["inertia_std"], strict=True):
        print(
            "   "
            + " ".join(
                f"{_num(v, '{:>10.3g}'):>10} +- {_num(s, '{:.2g}'):<8}"
                for v, s in zip(row, srow, strict=True)
            )
        )


def _print_fit(figures: dict) -> None:
    """Print the drive gains (with --mass), the arm model's error on the loaded run and the notes."""
    gains = figures["drive_gains"]
    if gains is not None:
        print(
            "drive gains (measured / true torque): "
            + ", ".join(
                f"j{j + 1} {_num(g)} +- {_num(s, '{:.2g}')}"
                for j, (g, s) in enumerate(zip(gains["gain"], gains["std"], strict=True))
            )
        )
        print(f"  {gains['meaning']}")
    print(
        "loaded run, rms of the arm model (N m): before "
        + " ".join(f"{v:.3g}" for v in figures["rms_before"])
        + "; with the payload "
        + " ".join(f"{v:.3g}" for v in figures["rms_after"])
    )
    for note in figures["notes"]:
        print(f"  note: {note}")


def _write_outputs(args: argparse.Namespace, model, result, figures: dict, report_path) -> None:
    """Every output computed first, then written: the model pair, then the report and the figures together."""
    from dynid._progress import say
    from dynid.identify.model import save_model
    from dynid.identify.payload import attach_payload
    from dynid.validation.payload_report import payload_report

    writers = []
    if report_path is not None:
        say(f"drawing the report {report_path}")
        text = payload_report(
            result, figures, title=f"Payload of {model.robot.name} from {Path(args.data).name}"
        )
        writers.append((report_path, lambda tmp: Path(tmp).write_text(text, encoding="utf-8")))
    if args.json is not None:
        from dynid._io import dumps_json

        figures_text = dumps_json(figures)
        writers.append((Path(args.json), lambda tmp: Path(tmp).write_text(figures_text, encoding="utf-8")))
    if args.out is not None:
        json_path, arrays_path = save_model(attach_payload(model, result), args.out)
        print(f"wrote {json_path} and {arrays_path} (the arm with the payload on link {figures['link']})")
    if writers:
        from dynid._io import write_together

        write_together(writers)
        for path, _ in writers:
            print(f"wrote {path}")
