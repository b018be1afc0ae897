"""``dynid validate``: how well identified models predict held-out data, against the measured noise floor."""

from __future__ import annotations

import argparse
import warnings
from pathlib import Path

from dynid.commands.common import (
    add_degrees_argument,
    add_json_argument,
    add_topic_argument,
    check_data_fits_model,
    check_outputs,
    check_period_option,
    output,
    read_dataset,
    robot_file,
    training_match,
    write_figures,
)
from dynid.exceptions import DataWarning, IdentificationWarning

__all__ = ["HELP", "add_arguments", "run"]

HELP = "validate identified models on held-out data: RMS, NRMS, R^2 per joint, noise floor, HTML report"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--model",
        required=True,
        metavar="M.json",
        help="model file written by 'dynid identify', or a simulator's robot description (.urdf, MuJoCo .xml) "
        "scored as it stands: rigid body, armature, damping and Coulomb friction from the file, nothing identified",
    )
    parser.add_argument(
        "--data",
        required=True,
        metavar="V.csv",
        help="held-out dataset (.csv or .npz), not the identification data",
    )
    add_degrees_argument(parser)
    add_topic_argument(parser)
    parser.add_argument(
        "--compare",
        nargs="+",
        action="extend",
        default=[],
        metavar="M2.json",
        help="more models (or .urdf / .xml descriptions) to compare on the same data, in one table and the "
        "same figures",
    )
    parser.add_argument(
        "--report", metavar="R.html", help="write a self-contained HTML report (or a PDF: R.pdf)"
    )
    parser.add_argument(
        "--predictions",
        metavar="P.csv",
        help="write t, tau_i (the measured torque as compared) and tau_pred_i of the model",
    )
    parser.add_argument(
        "--period",
        type=float,
        metavar="S",
        help="period (s) of the motion if it repeats, for the noise floor (default: from a simulated "
        "dataset's sidecar, else detected from the angles; without one, the spectrum)",
    )
    parser.add_argument(
        "--robot",
        help="robot to load the models with (default: the one recorded in each model file); it must be the "
        "robot the models were identified for",
    )
    add_json_argument(parser)


def _row(values, fmt: str = "{:>10.4g}") -> str:
    return " ".join("         -" if v is None else fmt.format(v) for v in values)


def run(args: argparse.Namespace) -> int:
    from dynid._io import to_jsonable
    from dynid._progress import say
    from dynid.data.periodic import check_period
    from dynid.data.preparation import Preprocessing
    from dynid.identify.model import load_model
    from dynid.simmodel.nominal import description_model, is_description
    from dynid.symbolic.robot import load_robot
    from dynid.validation.report import check_report_path, render_report
    from dynid.validation.validate import compare, validate, write_predictions

    # Every output is checked before any work, and written only once everything is computed.
    report_path = None if args.report is None else check_report_path(args.report)
    check_outputs(
        [
            output("report", args.report, (".html", ".htm", ".pdf")),
            output("predictions", args.predictions, (".csv",)),
            output("json", args.json, (".json",)),
        ],
        {"model": args.model, "compare": args.compare, "data": args.data, "robot": robot_file(args)},
    )
    predictions_path = None if args.predictions is None else Path(args.predictions)
    json_path = None if args.json is None else Path(args.json)
    check_period_option(args.period)

    robot = None
    if args.robot is not None:
        robot = load_robot(args.robot)
    files = [args.model, *args.compare]
    # a simulator description (URDF, MuJoCo .xml) is scored as it stands, nothing identified
    loaded = [None if is_description(path) else load_model(path, robot=robot) for path in files]
    first_robot = loaded[0].robot if loaded[0] is not None else load_robot(args.model)
    data = read_dataset(
        args.data, degrees=args.degrees, topic=args.topic, robot=first_robot, model_path=args.model
    )
    if args.period is not None:
        check_period(data.t, data.q, args.period, source=Path(args.data).name)
    # compared with identified models, a description is seen through their preprocessing
    settings = next((model.preprocessing for model in loaded if model is not None), None)
    prep = None if settings is None else Preprocessing.from_settings(settings)
    models = [
        model if model is not None else description_model(path, data, preprocessing=prep)
        for model, path in zip(loaded, files, strict=True)
    ]
    for path, model in zip(files, models, strict=True):
        check_data_fits_model(model, data, model_path=path, data_option="data")
    for path, model in zip(files, loaded, strict=True):
        match = None if model is None else training_match(model, data)
        if match is not None:
            what = (
                f"one of the recordings {path} was identified on"
                if match == "part"
                else f"the data {path} was identified on (the same {model.info['n_samples']} samples and torque range)"
            )
            warnings.warn(
                f"--data {args.data} is {what}, so its scores are optimistic, not held-out figures; validate on "
                "a recording the model was not fitted to",
                DataWarning,
                stacklevel=2,
            )
    stems = [Path(f).stem for f in files]
    labels = [s if stems.count(s) == 1 else str(f) for s, f in zip(stems, files, strict=True)]
    results = []
    for model, label, path in zip(models, labels, files, strict=True):
        say(f"predicting with {Path(path).name} and measuring the noise floor")
        caught: list[warnings.WarningMessage] = []
        try:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                results.append(
                    validate(model, data, period=args.period, label=label, info={"model_file": Path(path).name})
                )
        finally:  # said even when the validation then fails
            for w in caught:  # with --compare, a model's own warnings say which model they are about
                if len(files) > 1 and issubclass(w.category, IdentificationWarning):
                    warnings.warn(f"{Path(path).name}: {w.message}", w.category, stacklevel=2)
                else:
                    warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    rows = compare(results)
    first = results[0]
    figures = {
        **first.figures(),
        "model": str(args.model),
        "data": str(args.data),
        "models": rows,
        "report": None if report_path is None else str(report_path),
        "predictions": None if predictions_path is None else str(predictions_path),
    }
    figures = to_jsonable(figures)
    report = None
    if report_path is not None:
        say(f"drawing the report {report_path}")
        report = render_report(results, figures=figures, pdf=report_path.suffix.lower() == ".pdf")

    n = first.n
    print(
        f"{first.model.robot.name}: '{first.label}' ({figures['description']}) on {first.data}, "
        f"{figures['n_samples']} samples over {figures['duration_s']:.4g} s, torque {first.reference}"
    )
    print(f"noise floor: {first.noise.method} ({first.noise.detail})")
    print(f"{'joint':>5} {'rms':>10} {'nrms':>10} {'r2':>10} {'max err':>10} {'noise':>10} {'rms/noise':>10}")
    for j in range(n):
        print(
            f"{j + 1:>5} "
            + _row(
                [figures[k][j] for k in ("rms", "nrms", "r2", "max_error", "noise_floor", "rms_over_noise")]
            )
        )
    # Mean row: rms under rms, noise under noise (three 11-character columns between them).
    # A figure that could not be computed (no measurable noise floor, an infinite error) prints as "-".
    print(f"{'mean':>5} " + _row([figures["rms_mean"]]) + " " * 34 + _row([figures["noise_floor_mean"]]))
    if len(results) > 1:
        width = max(len(r["label"]) for r in rows)
        print(
            f"\n{'model':<{width}} "
            + " ".join(f"{'rms ' + str(j + 1):>10}" for j in range(n))
            + f" {'mean':>10}"
        )
        for r in rows:
            print(f"{r['label']:<{width}} " + _row([*r["rms"], r["rms_mean"]]))

    if predictions_path is not None:
        write_predictions(first, predictions_path)
        print(f"wrote {predictions_path}")
    if report is not None and report_path is not None:
        report.write(report_path)
        print(f"wrote {report_path}")
    write_figures(json_path, figures)
    return 0
