"""``dynid identify``: identify a robot's dynamic model from a dataset in three layers."""

from __future__ import annotations

import argparse

from dynid.commands.common import (
    add_degrees_argument,
    add_json_argument,
    add_robot_arguments,
    add_topic_argument,
    check_outputs,
    model_files,
    output,
    read_recordings,
    robot_file,
    robot_from_args,
    write_figures,
)
from dynid.identify.registry import FRICTION_MODELS, method_names

__all__ = ["HELP", "add_arguments", "run"]

HELP = "identify link parameters, friction and a GMM correction from a dataset; write a model file"


def _gmm(text: str) -> str | int:
    if text in ("off", "auto"):
        return text
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"--gmm is '{text}'; give off, auto or a number of components"
        ) from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"--gmm is {value}; give at least 1 component, or off / auto")
    return value


def _cutoff(text: str) -> float | str | None:
    if text in ("auto", "none"):
        return None if text == "none" else "auto"
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"--cutoff is '{text}'; give a frequency in Hz, auto or none"
        ) from None


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_robot_arguments(parser)
    parser.add_argument(
        "--data",
        required=True,
        nargs="+",
        action="extend",
        metavar="D.csv",
        help="dataset (.csv or .npz: t, q_i, tau_i [, dq_i, ddq_i]; or a ROS 2 .mcap / rosbag2 folder); "
        "several are identified together, each a run of its own, and the default pipeline is then chosen "
        "on two folds of whole recordings instead of two halves (recordings of two different excitations "
        "show a pipeline that only fits one motion)",
    )
    add_degrees_argument(parser)
    add_topic_argument(parser)
    parser.add_argument(
        "--method",
        default="auto",
        choices=("auto", *method_names()),
        help="layer-1 method; auto (default): among ols or irls with linear friction, ols with the paper's "
        "seed friction and the paper's irls + seed friction + gmm, the simplest within 5 points of the one "
        "that predicts one half of the recording from the other best (two folds of whole recordings instead of "
        "halves when several --data files of comparable length are given; none with a joint 5 %% worse than "
        "ols with linear friction)",
    )
    parser.add_argument(
        "--friction",
        default="auto",
        choices=("auto", *FRICTION_MODELS.names()),
        help="friction model; auto (default): chosen with --method auto, else seed (the paper's)",
    )
    parser.add_argument(
        "--gmm", default="auto", type=_gmm, metavar="{off,auto,K}", help="layer-3 correction (default auto)"
    )
    parser.add_argument(
        "--cutoff",
        default="auto",
        type=_cutoff,
        metavar="HZ",
        help="low-pass cut-off for torque and regressor (default auto: none if the data have dq and ddq, else "
        "chosen from the spectra of q and torque, at least 20 Hz without dq; the summary says how)",
    )
    parser.add_argument(
        "--decimate",
        default=None,
        type=int,
        metavar="N",
        help="keep one sample in N after filtering (default: every sample, but a recording too long for memory is "
        "thinned, and says so; 1 keeps every sample whatever the memory)",
    )
    parser.add_argument(
        "--rounds",
        default=2,
        type=int,
        metavar="N",
        help="rounds in which link parameters, friction and GMM are refitted together (default 2; 0: the "
        "paper's sequence, one layer after the other)",
    )
    parser.add_argument(
        "--gmm-mode",
        default="position",
        choices=("position", "own", "per_joint", "vector"),
        help="inputs of the GMM: each joint's angle (default), its angle and velocity, all states per joint, "
        "or one mixture over all (the paper's)",
    )
    parser.add_argument(
        "--reference-weight",
        default="auto",
        type=_weight,
        metavar="W",
        help="pull of the consistent links toward the robot description's bodies, in squared standard "
        "deviations per unit of divergence; 'auto' (default): chosen by blocked cross-validation on the "
        "recording; 0: only directions the data cannot see keep the description",
    )
    parser.add_argument(
        "--unconstrained",
        action="store_true",
        help="let armature, Coulomb and viscous coefficients go negative (default: kept >= 0, the summary "
        "names those held at 0)",
    )
    parser.add_argument(
        "--no-drive-gains",
        action="store_true",
        help="give no joint a drive gain (default: a joint whose measured torque reads a constant factor off "
        "the model's gets one when the recording's halves confirm it, unless --effects is given; a URDF "
        "cannot carry it)",
    )
    parser.add_argument(
        "--effects",
        metavar="NAME[@JOINTS],...",
        help="effects of the catalogue identified as model terms with the link parameters, e.g. "
        "coupled_friction@5+6,stribeck@3 (hyper-parameters tuned on the data unless given: cogging@2:N=100; "
        "coupled_friction@5+6:mix=0 is the friction of joint 6's output stage, on dq6, felt by joints 5 and 6)",
    )
    parser.add_argument(
        "--transmission",
        metavar="FILE.toml",
        help="a coupled transmission beside a URDF: a TOML file with [transmission] coupled = [[a, b, r]] "
        "(motor b also turns by r times joint a) or matrix = [[...]]; its motors' armature and friction "
        "are identified on the motor side",
    )
    parser.add_argument(
        "--out", required=True, metavar="M.json", help="model file to write (arrays go to M.npz beside it)"
    )
    add_json_argument(parser)


def _links_line(figures: dict) -> str:
    """One line on the links' physical consistency: as identified, or which links sit at the bound."""
    c = figures.get("consistency")
    if c is None:
        return "link inertias: not checked for physical consistency (--unconstrained)"
    held = c.get("at_bound", [])
    if not held:
        return "link inertias: physically consistent, no link at the consistency bound" + (
            f" (the pull toward the description's bodies put the estimate {c['mahalanobis']:.3g} std from the "
            "unconstrained one)"
            if c["mahalanobis"] > 1e-6
            else ""
        )
    rise = c.get("rms_rise")
    rise_text = "" if rise is None else f"; training RMS x{min(rise):.3g}..x{max(rise):.3g} per joint"
    return (
        f"link inertias: held at the physical-consistency bound on link{'s' if len(held) > 1 else ''} "
        f"{', '.join(str(k) for k in held)} ({c['mahalanobis']:.3g} std from the unconstrained estimate"
        f"{rise_text}; --unconstrained lifts it)"
    )


_DECIDED = {
    "bound": "the consistency bound",
    "shared": "the data through the base parameters it shares with other links",
}


def _bodies_lines(figures: dict) -> list[str]:
    """How far each identified body moved from the description, and whether the data or it decided."""
    links = figures.get("links")
    if not links:
        return []
    prior = figures.get("prior")
    head = (
        f"bodies: pulled toward the description with weight {prior['weight']:g} ({prior['rule']})"
        if prior
        else "bodies: the description keeps only what the data cannot see at all"
    )
    lines = [head]
    for body in links:
        ratio = body.get("mass_ratio")
        decided = body.get("decided_by")
        lines.append(
            f"  {body['joint']:<24} {body['mass_description']:8.3g} -> {body['mass']:8.3g} kg"
            + ("" if ratio is None else f" (x{ratio:.2f})")
            + f", centre of mass moved {1000 * body['com_shift']:.0f} mm"
            + (
                ""
                if decided is None
                else f"; decided by {_DECIDED.get(decided, decided)} "
                f"(data share {100 * body['data_share']:.0f} %)"
            )
        )
    return lines


def _weight(text: str) -> float | str:
    """``--reference-weight``: 'auto' or a number >= 0."""
    if text.strip().lower() == "auto":
        return "auto"
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not (value >= 0 and value < float("inf")):
        raise argparse.ArgumentTypeError(f"expected 'auto' or a number >= 0, got {text!r}")
    return value


def run(args: argparse.Namespace) -> int:
    import time

    import numpy as np

    from dynid.data.preparation import Preprocessing
    from dynid.identify.model import identify, save_model

    check_outputs(
        [
            output(
                "out",
                args.out,
                (".json",),
                also=model_files(args.out)[1:],
                hint="the model is JSON; its arrays go beside it as .npz",
            ),
            output("json", args.json, (".json",)),
        ],
        {"data": args.data, "robot": robot_file(args), "transmission": args.transmission},
    )
    robot = robot_from_args(args)
    if args.transmission:
        from dynid.symbolic.robot import load_transmission

        robot = robot.with_transmission(load_transmission(args.transmission, robot.n))
    if args.effects:  # a malformed term is refused before the data are read
        from dynid.identify.effect_terms import parse_effect_terms

        parse_effect_terms(args.effects, robot.n)
    start = time.perf_counter()
    data, parts = read_recordings(
        args.data, robot.n, robot_name=robot.name, degrees=args.degrees, topic=args.topic,
        joint_names=robot.joint_names, robot=robot,
    )
    model = identify(
        robot,
        data,
        method=args.method,
        friction=args.friction,
        gmm=args.gmm,
        preprocessing=Preprocessing(cutoff=args.cutoff, decimate=1 if args.decimate is None else args.decimate, thin=args.decimate is None),
        reference_weight=args.reference_weight,
        rounds=args.rounds,
        gmm_mode=args.gmm_mode,
        physical=not args.unconstrained,
        effects=args.effects,
        drive_gains=not args.no_drive_gains,
    )
    if parts:  # scoring the model on one of them is scoring it on training data
        from dynid.identify.model import data_fingerprint

        model.info["data_parts_sha256"] = [data_fingerprint(part) for part in parts]
    json_path, arrays_path = save_model(model, args.out)
    elapsed = time.perf_counter() - start
    figures = model.figures()
    print(
        f"{robot.name}: {model.method} on {figures['n_samples']} samples ({figures['reference']}), "
        f"cond {model.cond:.4g}, {elapsed:.1f} s"
    )
    pre = figures["preprocessing"]
    cut = "none" if pre.get("cutoff_hz") is None else f"{pre['cutoff_hz']:.3g} Hz"
    print(f"cut-off {cut}: {pre.get('cutoff_rule', 'given')}")
    if pre.get("dq_evidence"):
        print(f"velocity: {pre['dq_evidence']}")
    for note in figures["notes"]:
        print(f"  note: {note}")
    print(f"{'name':<8} {'value':>13} {'std %':>9}  expression")
    held_at_bound = set((figures.get("bounds") or {}).get("active", []))
    for row in figures["parameters"]:
        pct = "-" if row["std_percent"] is None else f"{row['std_percent']:.3g}"
        if row["name"] in held_at_bound:  # held at its bound (0): a percentage of ~0 says nothing
            pct = "at bound"
        print(f"{row['name']:<8} {row['value']:>13.6g} {pct:>9}  {row['expression']}")
    layers = figures["rms_layers"]
    for key, label in (
        ("link", "link"),
        ("friction", "link + friction (physical layers)"),
        ("gmm", "full model"),
    ):
        print(f"rms {label:<34} (N m): " + " ".join(f"{v:.4g}" for v in layers[key]))
    print(f"friction: {figures['friction']['model']} ({figures['friction']['source']})")
    if figures["robot"].get("transmission") is not None:
        print("transmission: coupled (motor-side armature and friction of the coupled motors)")
        held = {e["key"] for e in figures.get("effects", [])}
        from dynid.identify.columns import coupled_pairs

        for a, b in coupled_pairs(figures["robot"]["transmission"]):
            key = f"coupled_friction@{a + 1}+{b + 1}:mix=0"
            if key not in held:
                print(
                    f"  joint {b + 1}'s output stage, driven by motor {b + 1} (friction on dq{b + 1} felt by joints "
                    f"{a + 1} and {b + 1}), is not modelled: --effects {key} adds it (on the TX40's wrist it lowered "
                    "joints 5 and 6 held out by 6 and 15 %)"
                )
    for effect in figures.get("effects", []):
        hyper = ", ".join(f"{k} {v:.4g}" for k, v in effect["hyper"].items() if k != "exact")
        coefs = ", ".join(f"{k} {v:.4g} +- {effect['std'][k]:.2g}" for k, v in effect["coefficients"].items())
        print(f"effect {effect['key']}{' (' + hyper + ')' if hyper else ''}: {coefs}")
        if effect["name"] == "drive_gain" and "g" in effect["coefficients"]:
            g = effect["coefficients"]["g"]
            print(
                f"  joint {effect['joint']} reads {1 + g:.3g} times the torque of a fit without the gain "
                "(a torque sensor or constant off); a URDF cannot carry it (--no-drive-gains fits without it)"
            )
    bounds = figures.get("bounds", {})
    if bounds.get("physical"):
        active = bounds.get("active", [])
        print(
            "bounds: armature, Coulomb, viscous >= 0; "
            + (f"held at 0: {', '.join(active)}" if active else "none active")
        )
    else:
        print("bounds: none (--unconstrained)")
    rounds = figures.get("refinement", {}).get("rounds", 0)
    print(
        f"layers fitted together in {rounds} round{'s' if rounds != 1 else ''}"
        if rounds
        else "layers fitted in sequence"
    )
    if model.gmr is not None:
        state = "active on joints " + ", ".join(str(j + 1) for j in np.flatnonzero(model.gmr.active_))
        print(
            f"gmm: {state if model.gmr.active_.any() else 'no correction'}; {model.gmr.fallback_ or ''}".rstrip(
                "; "
            )
        )
    print(_links_line(figures))
    for line in _bodies_lines(figures):
        print(line)
    print(f"wrote {json_path} and {arrays_path}")
    write_figures(args.json, {**figures, "elapsed_s": elapsed, "model": str(json_path)})
    return 0
