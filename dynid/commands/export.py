"""``dynid export``: an identified model written into a URDF or MJCF for simulators, reload-checked."""

from __future__ import annotations

import argparse
from pathlib import Path

from dynid.commands.common import (
    add_degrees_argument,
    add_json_argument,
    add_topic_argument,
    check_data_fits_model,
    check_outputs,
    output,
    read_dataset,
    same_file,
    write_figures,
)

__all__ = ["HELP", "add_arguments", "run"]

HELP = "write an identified model into a URDF or MuJoCo MJCF (consistent inertials, friction), reload-checked"

_SUFFIX = {"urdf": (".urdf",), "mjcf": (".xml", ".mjcf")}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--model", required=True, metavar="M.json", help="model file written by 'dynid identify'")
    parser.add_argument(
        "--format", required=True, metavar="{urdf,mjcf}", help="urdf (Pinocchio, Gazebo, Isaac) or mjcf (MuJoCo)"
    )
    parser.add_argument(
        "--template",
        metavar="robot.urdf|robot.xml",
        help="robot description to copy (visuals, collisions, meshes and limits are kept; default: the one the "
        "model was identified on): a URDF (for mjcf MuJoCo builds the MJCF from it) or, for mjcf, the robot's "
        "own MJCF (filled in place through MuJoCo's MjSpec)",
    )
    parser.add_argument("--out", required=True, metavar="FILE", help="file to write (.urdf, or .xml for mjcf)")
    parser.add_argument(
        "--heldout",
        metavar="V.csv",
        help="held-out data on which to measure the share of what the format cannot carry (default: the "
        "model file's figures where they tell it)",
    )
    add_degrees_argument(parser)
    add_topic_argument(parser)
    add_json_argument(parser)


def run(args: argparse.Namespace) -> int:
    from dynid.exceptions import UsageError

    if args.format not in _SUFFIX:
        raise UsageError(f"--format is '{args.format}'; choose urdf or mjcf")
    suffix = None if args.template is None else Path(args.template).suffix.lower()
    if suffix is not None and suffix != ".urdf" and not (args.format == "mjcf" and suffix in (".xml", ".mjcf")):
        wanted = "URDF" if args.format == "urdf" else "URDF or MuJoCo .xml"
        raise UsageError(
            f"--template '{args.template}' is not a {wanted} file; give the robot's {wanted} (a URDF is written "
            "from a URDF)"
        )
    check_outputs(
        [
            output("out", args.out, _SUFFIX[args.format], hint=f"the format is {args.format}"),
            output("json", args.json, (".json",)),
        ],
        {"model": args.model, "template": args.template, "heldout": args.heldout},
    )
    if args.format == "mjcf":
        from dynid.simmodel.mjcf import import_mujoco

        import_mujoco()
    from dynid._progress import say
    from dynid.identify.model import load_model
    from dynid.simmodel.export import export_model

    model = load_model(args.model)
    if args.template is None:
        # the description the model was identified on is export's template: an input, never an output
        from dynid.simmodel.export import default_template

        try:
            source = default_template(model.robot)
        except UsageError:
            source = None  # no URDF to copy: export_model says so
        if source is not None and same_file(args.out, source):
            raise UsageError(
                f"--out '{args.out}' is the robot description the model was identified on, which export reads "
                "as its template; give the output another name."
            )
    heldout = None
    if args.heldout is not None:
        heldout = read_dataset(
            args.heldout, degrees=args.degrees, topic=args.topic, robot=model.robot, option="heldout"
        )
        check_data_fits_model(model, heldout, model_path=args.model, data_option="heldout")
    say(f"writing the {args.format.upper()} description and reloading it to check")
    result = export_model(
        model,
        args.format,
        args.out,
        template=args.template,
        model_name=Path(args.model).name,
        heldout=heldout,
    )
    figures = result.figures()
    p = result.params
    origin = (
        f"a URDF written from the table {result.template}"
        if result.template.suffix.lower() == ".toml"
        else str(result.template)
    )
    print(f"wrote {result.path} ({args.format}, from {origin})")
    print(f"  link inertials: {p.source}; physically consistent")
    if p.projection.get("relative"):
        print(
            f"  moved {p.projection['relative']:.3g} (relative) from the identified parameters, "
            f"{p.projection['mahalanobis']:.3g} standard deviations"
        )
    if "note" in p.projection:
        print(f"  note: {p.projection['note']}")
    u = p.unidentifiable
    print(
        f"  {u['dimension']} directions the data cannot see pulled toward the template"
        + (
            f" ({len(u['unseen'])} parameters never seen at all: {', '.join(u['unseen'])}; the other "
            f"{u['dimension'] - len(u['unseen'])} are combinations of parameters the data see only together)"
            if u["unseen"]
            else ""
        )
    )
    print(f"{'joint':>5} {'mass kg':>10} {'armature':>10} {'damping':>10} {'frictionloss':>12}")
    for row in figures["joints"]:
        print(
            f"{row['joint']:>5} {row['mass']:>10.4g} {row['armature']:>10.4g} {row['damping']:>10.4g} "
            f"{row['frictionloss']:>12.4g}"
        )
    print("reload checks:")
    for c in result.checks:
        figure = f"error {c['relative_error']:.2g} <= {c['tolerance']:.0e}" if "relative_error" in c else (
            f"{len(c['joints'])} joints" if c["joints"] else "no joint has a Coulomb level"
        )
        print(f"  passed: {c['check']} ({figure})")
    if result.heldout is not None:
        h = result.heldout
        print(
            f"held-out RMS (mean over joints): dynid's model {h['rms_full_mean']:.4g} N m, the exported "
            f"{args.format.upper()} {h['rms_exported_mean']:.4g} N m"
        )
    if result.not_carried:
        print("not carried (listed in the file's comment too):")
        for it in result.not_carried:
            joints = ",".join(str(j) for j in it["joints"])
            print(f"  {it['what']} (joints {joints or '-'}): {it['share']}")
    write_figures(args.json, figures)
    return 0
