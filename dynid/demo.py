"""The whole path on the built-in default robot (UR5), one stage after another: what ``dynid demo`` runs.

Stages: symbolic model (and its compiled C) -> excitation design -> simulated runs (identification,
and a separate validation run of several periods on another trajectory) -> identification (OLS,
IRLS and the full three-layer method) -> validation -> gap diagnosis -> report.  The simulated robot
is the UR5 with its inertial parameters perturbed by 10 %, the paper's friction model, a tracking
controller and noisy, quantised sensors: identification has to find a truth it is not given.
``quick=True`` shortens the trajectories and the search, never skips a stage.

This module sits at the top of dynid, beside the commands: it uses every layer.  It prints nothing;
``progress`` receives the lines the command shows.  The records the stages hand each other and the
runner that times them are in :mod:`dynid.demo_records`.

Examples
--------
>>> from dynid.demo import run_demo
>>> result = run_demo("dynid-demo", quick=True, progress=print)  # doctest: +SKIP
>>> result.figures["rms_mean"], result.report  # doctest: +SKIP
"""

from __future__ import annotations

import html
import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from dynid.demo_records import (
    FULL,
    DemoContext,
    Excitation,
    Fits,
    GapDiagnosis,
    Outcome,
    ReportPage,
    Runs,
    SimulatedRun,
    StageRecord,
    StageRunner,
    Step,
    Validation,
)
from dynid.exceptions import UsageError

if TYPE_CHECKING:
    from dynid.diagnosis import Diagnosis
    from dynid.validation.validate import ValidationResult

__all__ = [
    "DEFAULT_ROBOT",
    "DEMO_FILES",
    "DEMO_MARKER",
    "PERTURB",
    "SETTINGS",
    "DemoResult",
    "StageRecord",
    "run_demo",
]

DEFAULT_ROBOT = "ur5"

DEMO_MARKER = "dynid-demo.txt"
"""The file that marks a folder as the demo's: a later demo overwrites :data:`DEMO_FILES` only beside it."""

DEMO_FILES = (
    DEMO_MARKER,
    "excitation.json",
    "identification.csv",
    "identification.csv.truth.json",
    "validation.csv",
    "validation.csv.truth.json",
    "model.json",
    "model.npz",
    "model_ols.json",
    "model_ols.npz",
    "model_irls.json",
    "model_irls.npz",
    "report.html",
    "diagnosis.html",
)
"""The files :func:`run_demo` may write in its folder (``dynid demo --json`` may not take one of these names)."""

#: Settings of the two modes.
SETTINGS: dict[str, dict[str, Any]] = {
    "full": {
        "harmonics": 5,
        "base_freq": 0.1,
        "patience": 1,
        "max_tries": 2,
        "baseline": 20,
        "id_periods": 2,
        "val_periods": 3,
    },
    "quick": {
        "harmonics": 3,
        "base_freq": 0.2,
        "patience": 1,
        "max_tries": 1,
        "baseline": 5,
        "id_periods": 2,
        "val_periods": 3,
    },
}
#: Relative perturbation of the simulated robot's inertial parameters.
PERTURB = 0.1
_DECIMATE = 4  # 1 kHz -> 250 Hz after the 20 Hz filter: the same information, a quarter of the work
_STAGES = 7


@dataclass(frozen=True)
class DemoResult:
    """What :func:`run_demo` made.

    Attributes
    ----------
    out_dir : Path
        Folder of every file written (trajectory, datasets with their truth, models, reports).
    mode : str
        ``"full"`` or ``"quick"``.
    stages : tuple of StageRecord
        The stages in the order they ran.
    figures : dict
        JSON-ready figures: the ``dynid validate`` keys of the full method, every model side by side
        (``models``), the error against the simulated truth, the diagnosis, the stages and their times.
        ``dynid demo --json`` writes exactly this.
    results : tuple of ValidationResult
        Held-out validation of the full method, OLS and IRLS (in this order).
    diagnosis : Diagnosis or None
        The gap diagnosis of the full method; None when that stage failed.
    report : Path or None
        The HTML report; None when its stage did not run.
    total_s : float
        Wall time of the whole demo (s).
    """

    out_dir: Path
    mode: str
    stages: tuple[StageRecord, ...]
    figures: dict[str, Any]
    results: tuple[ValidationResult, ...]
    diagnosis: Diagnosis | None
    report: Path | None
    total_s: float

    @property
    def failed(self) -> list[str]:
        """Names of the stages that failed (the command then exits with code 1)."""
        return [s.stage for s in self.stages if s.status == "failed"]


def _silent(line: str) -> None:
    """The default progress: nothing."""


def run_demo(
    out_dir: str | os.PathLike[str],
    *,
    quick: bool = False,
    seed: int = 0,
    progress: Callable[[str], None] | None = None,
) -> DemoResult:
    """Run the whole path on the UR5: excite, simulate, identify, validate, diagnose, report.

    Parameters
    ----------
    out_dir : str or path-like
        Folder for every file the demo writes; made if absent (its parent must exist).
    quick : bool, default False
        Shorter trajectories and search (every stage still runs).
    seed : int, default 0
        Seed of every random choice.
    progress : callable, optional
        Called with each line of progress (stage counters, stage summaries, long steps' news).

    Returns
    -------
    DemoResult
        The stages, the figures, the validation results, the diagnosis and the report's path.

    Raises
    ------
    UsageError
        ``out_dir`` is a file, its parent folder does not exist, or it holds one of :data:`DEMO_FILES`
        that no earlier demo wrote (no :data:`DEMO_MARKER` beside it).
    DynidError
        A stage other than the diagnosis failed (a failed diagnosis is recorded in the result).
    """
    say_line = _silent if progress is None else progress
    if isinstance(seed, bool) or int(seed) != seed or seed < 0:
        raise UsageError(f"the seed is {seed}; give a whole number of at least 0.")
    out = _claim_folder(Path(out_dir))
    mode = "quick" if quick else "full"
    started = time.perf_counter()
    stages = StageRunner(total=_STAGES, progress=say_line)
    demo = _start(out, mode, seed, say_line)
    outcome = _run_stages(demo, stages)
    return _result(demo, stages, outcome, total=time.perf_counter() - started)


def _claim_folder(out: Path) -> Path:
    """Check the demo's folder, make it and mark it as the demo's (see :data:`DEMO_MARKER`)."""
    if out.exists() and not out.is_dir():
        raise UsageError(f"out_dir '{out}' is a file; give a folder for the demo's files.")
    if not out.parent.exists():
        raise UsageError(
            f"the folder '{out.parent}' of out_dir does not exist; create it or write elsewhere."
        )
    clash = [f for f in DEMO_FILES if (out / f).exists()]
    if clash and not (out / DEMO_MARKER).is_file():
        raise UsageError(
            f"the folder '{out}' holds '{clash[0]}', which the demo would overwrite and no earlier demo wrote; "
            "give a new or empty folder."
        )
    out.mkdir(exist_ok=True)
    # first of all: the folder is the demo's, so that a later demo may overwrite what this one writes
    (out / DEMO_MARKER).write_text("written by dynid demo; its files may be replaced by the next demo\n")
    return out


def _start(out: Path, mode: str, seed: int, progress: Callable[[str], None]) -> DemoContext:
    """The demo's robot and settings, announced."""
    from dynid.symbolic.build import generator_is_built
    from dynid.symbolic.robot import load_robot

    # The UR5 at its own limits (URDF; 10 rad/s^2 where the URDF has none), as a user's first run has it.
    robot = load_robot(DEFAULT_ROBOT)
    demo = DemoContext(
        robot=robot,
        out=out,
        mode=mode,
        seed=seed,
        first_build=not generator_is_built(),
        progress=progress,
        settings=SETTINGS[mode],
    )
    progress(
        f"dynid demo ({mode}): {robot.name}, {robot.n} joints; the simulated robot is the UR5 with its inertial "
        f"parameters perturbed by {100 * PERTURB:g} %, the paper's friction and noisy sensors. Files go to {out}."
    )
    return demo


def _result(demo: DemoContext, stages: StageRunner, outcome: Outcome, *, total: float) -> DemoResult:
    """The demo's result: its figures completed with the stages and the total time (s)."""
    from dynid._io import to_jsonable

    figures = {
        **outcome.figures,
        "stages": [r.to_dict() for r in stages.records],
        # Every stage exists now; the key stays so that files written before read the same.
        "stages_missing": [],
        "stages_failed": stages.failed,
        "total_s": total,
    }
    return DemoResult(
        out_dir=demo.out,
        mode=demo.mode,
        stages=tuple(stages.records),
        figures=to_jsonable(figures),
        results=outcome.validation.results,
        diagnosis=None if outcome.diagnosis is None else outcome.diagnosis.result,
        report=outcome.report.path,
        total_s=total,
    )


def _run_stages(demo: DemoContext, stages: StageRunner) -> Outcome:
    """The seven stages in order, each handing its result to those after it."""
    # One BLAS / OpenMP thread: on small matrices a threaded BLAS is many times slower here (the
    # excitation's figures took 5 s instead of 0.1 s on 2 busy cores); joblib's workers set their own.
    import scipy.linalg  # noqa: F401  (loads scipy's BLAS, so that the limit below covers it)
    from threadpoolctl import threadpool_limits

    figures: dict[str, Any] = {
        "robot": DEFAULT_ROBOT,
        "mode": demo.mode,
        "seed": demo.seed,
        "first_run_build": demo.first_build,
    }
    with threadpool_limits(limits=1):
        symbolic = stages.run(
            "symbolic dynamics, base parameters and compiled C (Pinocchio on CasADi)",
            partial(_symbolic, demo),
        )
        figures.update(symbolic.figures)
        excitation = stages.run("excitation design (Fourier series, IPOPT)", partial(_excite, demo))
        figures.update(excitation.figures)
        runs = stages.run(
            "simulated identification and validation runs", partial(_simulate, demo, excitation)
        )
        figures.update(runs.figures)
        fits = stages.run(
            "identification: the full three-layer method, OLS and IRLS", partial(_identify, demo, runs)
        )
        figures.update(fits.figures)
        validation = stages.run("validation on the held-out run", partial(_validate, demo, runs, fits))
        diagnosis = stages.run(
            "sim-to-real gap diagnosis", partial(_diagnose, demo, runs, validation), may_fail=True
        )
        if diagnosis is not None:
            figures.update(diagnosis.figures)
        report = stages.run(
            "HTML report",
            partial(
                _report, demo, excitation, runs, validation, diagnosis, tuple(stages.records), dict(figures)
            ),
        )
        figures.update(report.figures)
    return Outcome(figures=figures, validation=validation, diagnosis=diagnosis, report=report)


# ---------------------------------------------------------------------- 1. symbolic model
def _symbolic(demo: DemoContext) -> Step:
    """Symbolic functions, base parameters, and the compiled C's rnea checked against Pinocchio."""
    import pinocchio as pin

    from dynid.symbolic.base import base_parameters
    from dynid.symbolic.build import cache_dir
    from dynid.symbolic.export import compiled_functions
    from dynid.symbolic.functions import robot_functions

    robot = demo.robot
    if demo.first_build:
        demo.say(
            "first run in this environment: building the symbolic generator once (about 40 s on 2 idle cores, "
            f"more on a slow machine), cached in {cache_dir()}; later runs skip this"
        )
    funcs = robot_functions(robot, progress=demo.say)
    base = base_parameters(funcs)
    lib = compiled_functions(robot, progress=demo.say)
    rng = np.random.default_rng([demo.seed, 0])
    q, dq, ddq = rng.uniform(-1, 1, size=(3, 500, robot.n))
    tau = lib.rnea(q, dq, ddq)
    model, data = robot.pin_model, robot.pin_model.createData()
    err = max(float(np.abs(tau[k] - pin.rnea(model, data, q[k], dq[k], ddq[k])).max()) for k in range(len(q)))
    return Step(
        summary=(
            f"{base.n_base} base parameters ({int(base.gravity_related.sum())} gravity-related); compiled C rnea "
            f"matches numeric Pinocchio to {err:.1e} N m on 500 random states"
        ),
        figures={"n_base": base.n_base, "c_export_max_error": err},
    )


# ---------------------------------------------------------------------- 2. excitation
def _excite(demo: DemoContext) -> Excitation:
    """The optimised excitation trajectory, written to ``excitation.json``."""
    from dynid.optim.excitation import ExcitationProblem, design_excitation

    cfg = demo.settings
    problem = ExcitationProblem(
        robot=demo.robot, harmonics=cfg["harmonics"], base_freq=cfg["base_freq"], criterion="seed"
    )
    result = design_excitation(
        problem,
        seed=demo.seed,
        patience=cfg["patience"],
        max_tries=cfg["max_tries"],
        baseline=cfg["baseline"],
        n_jobs=2,
        progress=demo.say,
    )
    traj = result.trajectories[0]
    traj.save(demo.out / "excitation.json")
    return Excitation(
        problem=problem,
        design=result,
        trajectory=traj,
        summary=(
            f"{cfg['harmonics']} harmonics, period {traj.period:g} s: cond {result.cond:.4g} against "
            f"{result.baseline_cond:.4g} for the best of {cfg['baseline']} random feasible trajectories; "
            f"wrote {demo.out / 'excitation.json'}"
        ),
        figures={
            "excitation": {
                "cond": result.cond,
                "baseline_cond": result.baseline_cond,
                "feasible": result.feasible,
                "harmonics": cfg["harmonics"],
                "period_s": traj.period,
            }
        },
    )


# ---------------------------------------------------------------------- 3. simulation
def _simulate(demo: DemoContext, excitation: Excitation) -> Runs:
    """The identification run on the excitation and a held-out run on another trajectory, as files."""
    from dynid.data.files import load_dataset
    from dynid.sim.simulator import build_truth

    cfg = demo.settings
    truth = build_truth(demo.robot, friction="seed", perturb=PERTURB, truth_seed=demo.seed)
    # The held-out run follows another trajectory (random, within the limits), several periods long.
    other = excitation.problem.random_trajectory(np.random.default_rng([demo.seed, 7]), amplitude=0.9)
    ident = _simulate_run(
        demo, truth, "identification", excitation.trajectory, cfg["id_periods"], demo.seed + 1
    )
    val = _simulate_run(demo, truth, "validation", other, cfg["val_periods"], demo.seed + 2)
    # Read back what was written: the rest of the demo sees the files a user would pass to dynid.
    return Runs(
        truth=truth,
        identification=load_dataset(ident.path, demo.robot.n),
        validation=load_dataset(val.path, demo.robot.n),
        validation_period=other.period,
        identification_file=ident.path,
        summary=(
            f"identification run {ident.result.t[-1]:.0f} s ({cfg['id_periods']} periods of the excitation), "
            f"validation run {val.result.t[-1]:.0f} s ({cfg['val_periods']} periods of another trajectory), "
            f"1 kHz; wrote {ident.path.name} and {val.path.name} with their .truth.json"
        ),
        figures={
            "runs": {
                "identification": {
                    "duration_s": float(ident.result.t[-1]),
                    "samples": int(ident.result.t.size),
                },
                "validation": {
                    "duration_s": float(val.result.t[-1]),
                    "samples": int(val.result.t.size),
                    "periods": cfg["val_periods"],
                },
            }
        },
    )


def _simulate_run(
    demo: DemoContext, truth: Any, name: str, trajectory: Any, periods: int, seed: int
) -> SimulatedRun:
    """One simulated run of ``periods`` periods of ``trajectory``, written to ``<name>.csv`` with its truth."""
    from dynid.sim.simulator import simulate, write_simulation

    result = simulate(
        demo.robot,
        trajectory,
        truth=truth,
        seed=seed,
        duration=periods * trajectory.period,
        source=f"the demo's {name} trajectory",
    )
    path, _ = write_simulation(result, demo.out / f"{name}.csv")
    return SimulatedRun(result=result, path=path)


# ---------------------------------------------------------------------- 4. identification
def _identify(demo: DemoContext, runs: Runs) -> Fits:
    """The full method, OLS and IRLS on the identification run, each written to its model file."""
    from dynid.identify.linear_system import Preprocessing
    from dynid.identify.model import save_model
    from dynid.validation.validate import COMPARISON, identify_methods

    fitted = identify_methods(
        demo.robot,
        runs.identification,
        methods=COMPARISON,
        preprocessing=Preprocessing(decimate=_DECIMATE),
        random_state=demo.seed,
        progress=demo.say,
    )
    files = {}
    for f in fitted:
        name = "model.json" if f.label == FULL else f"model_{f.label.lower()}.json"
        save_model(f.model, demo.out / name)
        files[f.label] = name
    return Fits(
        fitted=tuple(fitted),
        files=files,
        summary=(
            "the full method (consistent links, the paper's friction, GMM), OLS and IRLS (linear friction) in "
            + ", ".join(f"{f.seconds:.1f} s" for f in fitted)
            + f"; wrote {', '.join(files.values())}"
        ),
        figures={
            "identification": {
                f.label: {
                    "method": f.model.method,
                    "cond": f.model.cond,
                    "file": files[f.label],
                    "seconds": f.seconds,
                    "warnings": f.warnings,
                }
                for f in fitted
            }
        },
    )


# ---------------------------------------------------------------------- 5. validation
def _validate(demo: DemoContext, runs: Runs, fits: Fits) -> Validation:
    """Every model on the held-out run, and its rigid body against the simulated truth."""
    from dynid.validation.validate import compare, validate

    results = tuple(
        validate(
            f.model,
            runs.validation,
            period=runs.validation_period,
            label=f.label,
            info={"model_file": fits.files[f.label], "seconds": f.seconds},
        )
        for f in fits.fitted
    )
    rows = compare(list(results))
    truth_errors = _truth_errors(runs.truth, {r.label: r.model for r in results})
    by_label = {r.label: r for r in results}
    full, ols, irls = by_label[FULL], by_label["OLS"], by_label["IRLS"]
    return Validation(
        results=results,
        rows=rows,
        truth_errors=truth_errors,
        summary=(
            f"held-out mean RMS: full {full.metrics['rms_mean']:.4g}, OLS {ols.metrics['rms_mean']:.4g}, "
            f"IRLS {irls.metrics['rms_mean']:.4g} N m; noise floor {full.noise.rms_mean:.4g} N m "
            f"({full.noise.detail})"
        ),
    )


# ---------------------------------------------------------------------- 6. diagnosis
def _diagnose(demo: DemoContext, runs: Runs, validation: Validation) -> GapDiagnosis:
    """The gap diagnosis of the full method, with its own page ``diagnosis.html``."""
    from dynid.diagnosis import diagnose, write_diagnosis_report

    result = diagnose(
        validation.full.model,
        runs.identification,
        runs.validation,
        period=runs.validation_period,
    )
    path = write_diagnosis_report(
        result, demo.out / "diagnosis.html", title="dynid demo: gap diagnosis of the full method"
    )
    text = result.summary().splitlines()
    return GapDiagnosis(
        result=result,
        report=path,
        summary=f"verdict {', '.join(result.verdict)}; wrote {path}: {text[0] if text else ''}",
        figures={"diagnosis": result.to_dict(), "diagnosis_report": str(path)},
    )


# ---------------------------------------------------------------------- 7. report
def _report(
    demo: DemoContext,
    excitation: Excitation,
    runs: Runs,
    validation: Validation,
    diagnosis: GapDiagnosis | None,
    records: tuple[StageRecord, ...],
    figures: dict[str, Any],
) -> ReportPage:
    """The HTML report: every model on the held-out run, the diagnosis, the truth and the stages before it."""
    from dynid._io import to_jsonable
    from dynid.validation.report import render_report

    full = validation.full
    added = {
        **full.figures(),
        "models": validation.rows,
        "truth_relative_error": validation.truth_errors,
        "report": str(demo.out / "report.html"),
    }
    rep = render_report(
        list(validation.results),
        figures=to_jsonable({**figures, **added}),
        title="dynid demo: UR5 identified from a simulated run, validated on another",
        context={
            "identification data": f"{runs.identification_file.name} (the optimised excitation)",
            "truth": f"UR5 with inertial parameters perturbed by {100 * PERTURB:g} %, the paper's friction",
            "mode": demo.mode,
        },
        sections=[
            _diagnosis_section(diagnosis, full.label, records),
            _truth_section(validation),
            ("How this report was made", _stages_table(records)),
        ],
        conditions=[
            ("excitation design (cond of H* on its grid)", excitation.design.cond),
            (
                f"best of {demo.settings['baseline']} random feasible trajectories",
                excitation.design.baseline_cond,
            ),
        ],
    )
    path = rep.write(demo.out / "report.html")
    return ReportPage(
        path=path,
        summary=f"wrote {path} ({len(rep.figures)} figures, {len(rep.html) / 1e6:.1f} MB)",
        figures=added,
    )


def _diagnosis_section(
    diagnosis: GapDiagnosis | None, label: str, records: tuple[StageRecord, ...]
) -> tuple[str, str]:
    """The report's section on the diagnosis: its verdict and candidates, or why it failed."""
    title = "Sim-to-real gap diagnosis"
    if diagnosis is None:
        row = next((r for r in records if r.stage.startswith("sim-to-real")), None)
        why = row.summary if row else "not run"
        return title, f'<p class="note">{html.escape(why)}.</p>'
    name = html.escape(Path(diagnosis.report).name)
    return title, _diagnosis_html(diagnosis.result, label) + (
        f'<p class="note">The diagnosis in full (gap map, decomposition, every candidate): '
        f'<a href="{name}">{name}</a>, beside this file.</p>'
    )


def _truth_section(validation: Validation) -> tuple[str, str]:
    """The report's section on each model's rigid body against the simulated truth."""
    from dynid.validation.report import html_table

    errors = validation.truth_errors
    rows = [
        [r.label, errors[r.label]["rigid_body"], errors[r.label]["worst_joint_torque"]]
        for r in validation.results
    ]
    return (
        "Against the simulated truth",
        '<p class="note">The simulator knows the robot it drove. Relative error of the identified '
        "rigid-body parameters (base parameters and armature, weighted by how much torque each one "
        "makes on the held-out motion): the RMS over joints of Y(x - x_true) over the RMS of Y x_true, "
        "and the largest joint's.</p>"
        + html_table(["model", "relative error (all joints)", "worst joint"], rows, table_id="truth"),
    )


def _stages_table(records: tuple[StageRecord, ...]) -> str:
    """The stages that ran before the report, as an HTML table."""
    from dynid.validation.report import html_table

    rows = [[r.stage, r.status, r.summary, r.seconds] for r in records]
    return html_table(["stage", "status", "summary", "seconds"], rows, table_id="stages", text_columns=3)


def _truth_errors(truth: Any, models: dict[str, Any]) -> dict[str, dict[str, float]]:
    """How far each model's rigid body is from the simulated truth, in torque on random states."""
    from dynid.identify.linear_system import linear_torque

    out = {}
    robot = truth.nominal
    rng = np.random.default_rng(0)
    q = rng.uniform(robot.q_min, robot.q_max, size=(2000, robot.n))
    dq = rng.uniform(-robot.dq_max, robot.dq_max, size=q.shape)
    ddq = rng.uniform(-robot.ddq_max, robot.ddq_max, size=q.shape)
    for label, model in models.items():
        cols = model.columns
        n = robot.n
        phi = np.concatenate([truth.robot.params, truth.robot.armature, np.zeros(3 * n)])
        x_true = cols.P @ phi
        tau_true = linear_torque(cols, x_true, q, dq, ddq, mask=cols.link_mask)
        err = linear_torque(cols, model.params - x_true, q, dq, ddq, mask=cols.link_mask)
        per_joint = np.sqrt(np.mean(err**2, axis=0)) / np.sqrt(np.mean(tau_true**2, axis=0))
        total = float(np.sqrt(np.mean(err**2)) / np.sqrt(np.mean(tau_true**2)))
        out[label] = {"rigid_body": total, "worst_joint_torque": float(per_joint.max())}
    return out


def _diagnosis_html(result: Any, label: str) -> str:
    """The diagnosis as a report section: its verdict in words and the best-ranked candidates."""
    from dynid.validation.report import html_table

    doc = result.to_dict()
    lines = "".join(f"<li>{html.escape(line)}</li>" for line in result.summary().splitlines() if line.strip())
    rows = []
    for r in doc.get("ranking", [])[:10]:
        joint = r.get("joint")
        joint = ", ".join(map(str, joint)) if isinstance(joint, list) else joint
        rows.append(
            [
                str(r.get("effect")),
                "-" if joint is None else str(joint),
                "yes" if r.get("accepted") else "no",
                r.get("closure"),
                r.get("p_value"),
            ]
        )
    return (
        f"<p>Model '{html.escape(label)}' on the held-out run; verdict: "
        f"<strong>{html.escape(', '.join(doc.get('verdict', [])))}</strong>.</p><ul>{lines}</ul>"
        + html_table(
            ["candidate effect", "joint", "accepted", "closure", "p (adjusted)"],
            rows,
            table_id="diagnosis",
            text_columns=3,
        )
    )
