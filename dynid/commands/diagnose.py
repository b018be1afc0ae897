"""``dynid diagnose``: where an identified model's held-out error lies, which effect causes it, how far adding it
shrinks the gap.  A simulator's description (URDF, MuJoCo .xml) is diagnosed as its nominal model, and
``--out`` then writes the description corrected from the data (:mod:`dynid.simmodel.correct`)."""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from typing import Any

from dynid.commands.common import (
    add_degrees_argument,
    add_json_argument,
    add_topic_argument,
    check_data_fits_model,
    check_outputs,
    check_period_option,
    model_files,
    output,
    read_dataset,
    read_recordings,
    robot_file,
    same_file,
    training_match,
    write_figures,
)

__all__ = ["HELP", "add_arguments", "run"]

HELP = "diagnose the sim-to-real gap of a model: gap map, the effect behind it, its closure; HTML report"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--model",
        required=True,
        metavar="M.json",
        help="model file written by 'dynid identify', or a simulator's robot description (.urdf, MuJoCo .xml) "
        "diagnosed as its nominal model: rigid body, armature, damping and Coulomb friction from the file",
    )
    parser.add_argument(
        "--data",
        required=True,
        nargs="+",
        action="extend",
        metavar="D.csv",
        help="the training data the model was identified on (the recordings, when it was identified on several)",
    )
    parser.add_argument(
        "--heldout",
        required=True,
        metavar="V.csv",
        help="held-out data of the same robot (best: several periods of a periodic excitation)",
    )
    add_degrees_argument(parser)
    add_topic_argument(parser)
    parser.add_argument(
        "--robot",
        help="robot to load the model with (default: the one recorded in the model file); it must be the robot "
        "the model was identified for",
    )
    parser.add_argument("--report", metavar="R.html", help="write a self-contained HTML report")
    parser.add_argument(
        "--effects",
        metavar="NAME[,NAME...]",
        help="candidate effects to consider (default: the whole catalogue)",
    )
    parser.add_argument(
        "--period", type=float, metavar="S", help="period (s) of the held-out motion (default: detected)"
    )
    parser.add_argument(
        "--alpha", type=float, default=0.05, help="family-wise error rate of the tests (default 0.05)"
    )
    parser.add_argument("--max-effects", type=int, default=3, help="most effects accepted (default 3)")
    parser.add_argument(
        "--out",
        metavar="M2.json",
        help="write the model refitted on --data with the accepted effects added as model terms, and show "
        "both models' held-out error; for a description (--model robot.urdf|robot.xml): the description "
        "corrected from --data (link bodies, armature, damping, frictionloss; same format), reload-checked",
    )
    add_json_argument(parser)


def run(args: argparse.Namespace) -> int:
    from dynid.diagnosis.core import diagnose
    from dynid.simmodel.nominal import is_description

    described = is_description(args.model)
    options = _check_options(args, described)
    inputs = _read_inputs(args, described)
    _check_held_out(args, described, inputs)
    model, train, heldout = inputs.model, inputs.train, inputs.heldout
    result = diagnose(
        model,
        train,
        heldout,
        effects=options.effects,
        period=args.period,
        alpha=args.alpha,
        max_effects=args.max_effects,
    )
    _print_diagnosis(model, result)
    figures = result.to_dict()
    _add_settling(args, model, heldout, result, figures)
    context = _add_corrections(args, described, inputs, result, figures)
    write_figures(args.json, figures)
    if options.report is not None:
        _write_report(args, options.report, model, result, figures, context)
    return 0


@dataclass(frozen=True)
class _Options:
    """The checked options: the report's path (None without --report) and the effects to consider."""

    report: Any
    effects: tuple[str, ...]


@dataclass(frozen=True)
class _Inputs:
    """The model diagnosed, the robot the data are read with, the training and the held-out data."""

    model: Any
    robot: Any
    train: Any
    heldout: Any
    parts: tuple = ()  # the training recordings as read, when several were joined


def _check_options(args, described: bool) -> _Options:
    """Refuse bad options and outputs, before any file is read; the report's path and the effects chosen."""
    from dynid.exceptions import UsageError
    from dynid.validation.html_page import check_report_path

    report = check_report_path(args.report, pdf=False) if args.report else None
    if described and args.out:
        _check_description_out(args)
    _check_output_files(args, described)
    effects = _chosen_effects(args.effects)
    if not 0 < args.alpha < 1:
        raise UsageError(f"--alpha is {args.alpha}; give a probability between 0 and 1, e.g. 0.05.")
    if args.max_effects < 0:
        raise UsageError(
            f"--max-effects is {args.max_effects}; give a whole number of at least 0 (default 3)."
        )
    check_period_option(args.period)
    if any(same_file(args.heldout, path) for path in args.data):
        raise UsageError(_NOT_HELD_OUT.format(heldout=args.heldout, what="the same file as --data"))
    return _Options(report=report, effects=effects)


def _check_output_files(args, described: bool) -> None:
    """Refuse --report, --json and --out paths of the wrong kind, or that would overwrite an input."""
    check_outputs(
        [
            output("report", args.report, (".html", ".htm")),
            output("json", args.json, (".json",)),
            output(
                "out",
                args.out,
                (".json",),
                also=model_files(args.out)[1:] if args.out else (),
                hint="the model is JSON; its arrays go beside it as .npz",
            )
            if not described
            else output("out", args.out, _description_suffixes(args.model), hint="the format of --model"),
        ],
        {"model": args.model, "data": args.data, "heldout": args.heldout, "robot": robot_file(args)},
    )


def _chosen_effects(text: str | None) -> tuple[str, ...]:
    """The effects named by --effects (default: the whole catalogue); a name with joints or a value is refused."""
    from dynid.diagnosis.candidates import effect_names
    from dynid.exceptions import UsageError

    effects = effect_names()
    if text:
        effects = tuple(e.strip() for e in text.split(",") if e.strip())
        placed = next((e for e in effects if "@" in e or ":" in e), None)
        if placed is not None:
            name = placed.split("@")[0].split(":")[0]
            raise UsageError(
                f"--effects names the effect '{placed}' with joints or a value, but the diagnosis tests each "
                f"candidate on every joint and tunes its values on the data; give the name alone: --effects {name}"
            )
    return effects


def _read_inputs(args, described: bool) -> _Inputs:
    """Load the model (a description: its nominal model, seen through the training data's filter) and read
    the training and held-out data with its robot."""
    from dynid.exceptions import UsageError
    from dynid.identify.model import load_model
    from dynid.simmodel.nominal import description_model

    robot = None
    if args.robot is not None:
        if described:
            raise UsageError(
                f"--robot is given with the description '{args.model}', which is the robot itself; leave --robot out"
            )
        from dynid.symbolic.robot import load_robot

        robot = load_robot(args.robot)
    read = {"degrees": args.degrees, "topic": args.topic, "model_path": args.model}
    if described:
        from dynid.symbolic.robot import load_robot

        robot = load_robot(args.model)
        train, parts = read_recordings(args.data, robot=robot, **read)
        # nothing identified: the file as the simulator reads it, seen through the training data's filter
        model = description_model(args.model, train)
    else:
        model = load_model(args.model, robot=robot)
        robot = model.robot
        train, parts = read_recordings(args.data, robot=robot, **read)
    heldout = read_dataset(args.heldout, robot=robot, option="heldout", **read)
    return _Inputs(model=model, robot=robot, train=train, heldout=heldout, parts=parts)


def _check_held_out(args, described: bool, inputs: _Inputs) -> None:
    """Refuse data that do not fit the model, held-out data that are the training data, and a --period the
    held-out motion does not repeat with."""
    from dynid.exceptions import UsageError

    model, train, heldout = inputs.model, inputs.train, inputs.heldout
    check_data_fits_model(model, train, model_path=args.model, data_option="data")
    check_data_fits_model(model, heldout, model_path=args.model, data_option="heldout")
    # data of another joint count are refused by the diagnosis itself, naming both counts
    if train.n == heldout.n == inputs.robot.n:
        if any(_same_data(part, heldout) for part in (train, *inputs.parts)):
            raise UsageError(_NOT_HELD_OUT.format(heldout=args.heldout, what="the same data as --data"))
        match = None if described else training_match(model, heldout)
        if match is not None:
            what = "one of the recordings" if match == "part" else "the data"
            raise UsageError(_NOT_HELD_OUT.format(heldout=args.heldout, what=f"{what} {args.model} was identified on"))
    if args.period is not None:
        from pathlib import Path

        from dynid.data.periodic import check_period

        check_period(heldout.t, heldout.q, args.period, source=Path(args.heldout).name)


def _verdict_line(result) -> str:
    """The verdict with the joints of each accepted effect ("load_friction (joints 1, 5, 6)"), not its name
    once per joint."""
    if not result.accepted:
        return ", ".join(result.verdict)
    joints: dict[str, list[int]] = {}
    for a in result.accepted:
        c = a.candidate
        on = tuple(c.joints or ()) or (() if c.joint is None else (c.joint,))
        joints.setdefault(c.effect, []).extend(j + 1 for j in on)
    out = []
    for effect, js in joints.items():
        js = sorted(set(js))
        out.append(effect if not js else f"{effect} (joint{'s' if len(js) > 1 else ''} {', '.join(map(str, js))})")
    return ", ".join(out)


def _print_diagnosis(model, result) -> None:
    """Print the verdict, the summary and each joint's excess error and closure."""
    print(f"verdict: {_verdict_line(result)}")
    print(result.summary())
    dec = result.decomposition
    print("joint  excess  closure")
    for j in range(model.robot.n):
        c = dec["closure"][j]
        print(f"{j + 1:>5}  {result.excess['ratio'][j]:6.2f}  {'-' if c != c else f'{c:6.2f}'}")


def _add_settling(args, model, heldout, result, figures: dict) -> None:
    """Print the commands that would settle a provisional verdict, and add them to the figures."""
    settle = _settling_commands(args, model, heldout, result)
    if settle:
        figures["settle"] = settle
        print(settle["reason"] + " To settle it, record it like this:")
        for line in settle["commands"]:
            print("  " + line)


def _add_corrections(args, described: bool, inputs: _Inputs, result, figures: dict) -> dict:
    """The description corrected from the data, or with --out the model refitted with the accepted effects:
    added to the figures; the report's context lines that name what was written."""
    from dynid._progress import say

    context = {}
    if described:
        figures["correction"] = _correct_description(args, result, inputs.train, inputs.heldout)
        if args.out and figures["correction"].get("out"):
            context["corrected description"] = f"{args.out} (held-out RMS per joint in the JSON figures)"
    elif args.out:
        say(f"refitting the model with the accepted effects for {args.out}")
        refit = _write_refit(inputs.model, inputs.train, inputs.heldout, result, args.out)
        figures["refit"] = refit
        if refit.get("written"):
            context["refitted model"] = (
                f"{args.out} with {', '.join(refit['effects'])} (held-out RMS per joint below)"
            )
    return context


def _write_report(args, report, model, result, figures: dict, context: dict) -> None:
    """Draw and write the HTML report."""
    from dynid._progress import say
    from dynid.diagnosis.report import write_diagnosis_report

    say("drawing the report")
    write_diagnosis_report(
        result,
        report,
        context={
            "model": args.model,
            "training data": ", ".join(args.data),
            "held-out data": args.heldout,
            "robot": model.robot.name,
            **context,
        },
        refit=figures.get("refit"),
        settle=figures.get("settle"),
    )
    print(f"report written to {report}")


_NOT_HELD_OUT = (
    "--heldout {heldout} is {what}, but the diagnosis measures the gap on data the model was not fitted to "
    "(on its training data the error is fitted away and the gap looks smaller than it is); give another "
    "recording of the robot (another run, or 'dynid simulate' with another --seed)"
)


def _as_typed(source) -> str:
    """A robot's source as a user would type it here: a built-in name as it is, a file by its path from the
    working directory, or by its absolute path where that path climbs out of it (a model file elsewhere
    names its description relative to itself)."""
    import os

    text = str(source)
    if not os.path.exists(text):
        return text
    try:
        relative = os.path.relpath(text)
    except ValueError:  # another drive
        return os.path.abspath(text)
    climbs = relative == os.pardir or relative.startswith(os.pardir + os.sep)
    return os.path.abspath(text) if climbs else relative


def _same_data(a, b) -> bool:
    """Whether two datasets hold the same samples (time, angles and torque)."""
    import numpy as np

    return all(np.array_equal(getattr(a, k), getattr(b, k)) for k in ("t", "q", "tau"))


def _description_suffixes(path: str) -> tuple[str, ...]:
    """The suffixes a corrected description may take: those of its own format."""
    from pathlib import Path

    return (".urdf",) if Path(path).suffix.lower() == ".urdf" else (".xml", ".mjcf")


def _check_description_out(args) -> None:
    """A corrected description is written in the format it was read in; an MJCF needs mujoco to be checked."""
    from pathlib import Path

    from dynid.exceptions import UsageError

    wanted = _description_suffixes(args.model)
    if Path(args.out).suffix.lower() not in wanted:
        fmt = "URDF" if wanted == (".urdf",) else "MuJoCo MJCF"
        raise UsageError(
            f"--out '{args.out}' is not a {fmt}; the corrected description keeps the format of --model "
            f"'{args.model}': give --out ending in {' or '.join(wanted)}"
        )
    if wanted != (".urdf",):
        from dynid.simmodel.mjcf import import_mujoco

        import_mujoco()


def _correct_description(args, result, train, heldout) -> dict:
    """The description's values corrected from the training data: which group separates the file from the
    robot on held-out data, and with --out the corrected file (reload-checked)."""
    import numpy as np

    from dynid.simmodel.correct import correct_description

    dec = result.decomposition
    rm, rr, floor = (np.sqrt(np.asarray(dec[k], dtype=float)) for k in ("mse_model", "mse_refit", "noise"))
    print(
        "\nthe file as it stands is the starting gap; re-identifying its parameters on --data (what the "
        "diagnosis' refit does) closes the parametric part"
    )
    print("held-out RMS (N m)  joint    file  refit   noise floor")
    for j in range(len(rm)):
        print(f"{'':<19} {j + 1:>5}  {rm[j]:6.3g} {rr[j]:6.3g}  {floor[j]:6.3g}")
    corr = correct_description(args.model, train, heldout, out=args.out, floor=floor)
    print(corr.finding())
    print(
        f"held-out RMS (N m, cut-off {corr.cutoff_hz:.3g} Hz as in the diagnosis), one group of the file corrected "
        "at a time:"
    )
    groups = [g for g in corr.groups if g["applies"]]
    print(f"{'joint':>5}  {'file':>7} " + " ".join(f"{g['group']:>12}" for g in groups) + f" {'corrected':>10}")
    for j in range(len(corr.rms_nominal)):
        print(
            f"{j + 1:>5}  {corr.rms_nominal[j]:7.3g} "
            + " ".join(f"{g['rms'][j]:12.3g}" for g in groups)
            + f" {corr.rms_corrected[j]:10.3g}"
        )
    print(f"{'file':>12} " + " ".join(f"{'j' + str(j + 1):>8}" for j in range(len(corr.rms_nominal))))
    for key in ("mass", "armature", "damping", "frictionloss"):
        if key == "armature" and corr.format == "urdf":
            continue
        print(f"{key:>12} " + " ".join(f"{v:8.3g}" for v in corr.nominal[key]))
        print(f"{'-> ' + key:>12} " + " ".join(f"{v:8.3g}" for v in corr.corrected[key]))
    own = corr.rms_validate
    print(
        f"as 'dynid validate --model FILE' scores them (cut-off {own['cutoff_hz']:.3g} Hz chosen on the held-out "
        f"data): mean RMS {np.mean(own['nominal']):.4g} -> {np.mean(own['corrected']):.4g} N m"
    )
    if corr.export is None:
        if args.out is None:
            print("give --out corrected" + _description_suffixes(args.model)[0] + " to write the corrected file")
    else:
        checks = ", ".join(c["check"] for c in corr.export.checks)
        print(f"wrote {corr.export.path} (reload checks passed: {checks})")
        for it in corr.not_carried:
            joints = ",".join(str(j) for j in it.get("joints", []))
            print(f"  not carried: {it['what']} (joints {joints or '-'})")
    return corr.figures()


def _settling_commands(args, model, heldout, result) -> dict | None:
    """The exact commands that would record held-out data to settle a provisional or undecided verdict:
    the excitation (:func:`dynid.diagnosis.result.settling_excitation`), how to record it, and the
    diagnosis to run on it."""
    import shlex

    import numpy as np

    from dynid.diagnosis.result import settling_excitation

    rate = 1.0 / float(np.median(np.diff(heldout.t)))
    settle = settling_excitation(result, robot=_as_typed(model.robot.source), dq_max=model.robot.dq_max, rate=rate)
    if settle is None:
        return None
    return {
        "reason": settle["reason"],
        "heldout_seconds": settle["heldout_seconds"],
        "candidate": settle["candidate"],
        "commands": [
            settle["excite"],
            settle["play"],
            f"dynid diagnose --model {shlex.quote(args.model)} --data {' '.join(shlex.quote(d) for d in args.data)} "
            "--heldout heldout.csv" + _forwarded(args),
        ],
    }


def _forwarded(args) -> str:
    """The options of this run that the settling run's diagnosis must repeat (the robot, the effects
    screened, the tests' level, the data's units and topic), as command-line text."""
    import shlex

    out = ""
    for flag, value in (
        ("--robot", getattr(args, "robot", None)),
        ("--effects", getattr(args, "effects", None)),
        ("--topic", getattr(args, "topic", None)),
    ):
        if value:
            out += f" {flag} {shlex.quote(str(value))}"
    if getattr(args, "alpha", 0.05) != 0.05:
        out += f" --alpha {args.alpha:g}"
    if getattr(args, "max_effects", 3) != 3:
        out += f" --max-effects {args.max_effects}"
    if getattr(args, "degrees", False):
        out += " --degrees"
    return out


def _write_refit(model, train, heldout, result, out: str) -> dict:
    """Refit the model with the accepted effects, write it, print both models' held-out RMS per joint."""
    import numpy as np

    from dynid.diagnosis.model_refit import refit_with_effects
    from dynid.identify.model import save_model
    from dynid.validation.validate import validate

    if not result.accepted:
        print(f"--out: no effect was accepted; {out} is not written (the model stays as it is)")
        return {"written": False, "effects": []}
    # Each effect goes in only if it mends the model on the held-out data (cross-fitted on its joints, and
    # no joint's held-out RMS raised by more than 2 %); a delay at the delay the diagnosis measured.
    refitted, notes = refit_with_effects(model, train, result.accepted, heldout=heldout)
    for note in notes:
        print(f"  refit note: {note}")
    if refitted is model:
        print(f"--out: no accepted effect is added to the model (the notes say why); {out} is not written")
        return {"written": False, "effects": [], "notes": notes}
    json_path, arrays_path = save_model(refitted, out)
    before = validate(model, heldout)
    after = validate(refitted, heldout)
    rb, ra = (np.sqrt(np.mean((v.tau - v.tau_pred) ** 2, axis=0)) for v in (before, after))
    keys = [t.key for t in refitted.effects]
    print(f"refitted with {', '.join(keys)}: wrote {json_path} and {arrays_path}")
    print("held-out RMS (N m)  joint  before   after   ratio")
    for j in range(len(rb)):
        print(
            f"{'':<19} {j + 1:>5}  {rb[j]:6.3g}  {ra[j]:6.3g}  {ra[j] / rb[j] if rb[j] > 0 else float('nan'):6.2f}"
        )
    return {
        "written": True,
        "path": str(json_path),
        "effects": keys,
        "notes": notes,
        "rms_before": rb.tolist(),
        "rms_after": ra.tolist(),
    }
