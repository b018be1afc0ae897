"""The whole path on the built-in default robot (UR5), one stage after another: what ``dynid demo`` runs.

Stages: symbolic model (and its compiled C) -> excitation design -> simulated runs (identification,
and a separate validation run of several periods on another trajectory) -> identification (OLS,
IRLS and the full three-layer method) -> validation -> gap diagnosis -> report.  The simulated robot
is the UR5 with its inertial parameters perturbed by 10 %, the paper's friction model, a tracking
controller and noisy, quantised sensors: identification has to find a truth it is not given.
``quick=True`` shortens the trajectories and the search, never skips a stage.

This module sits at the top of dynid, beside the commands: it uses every layer.  It prints nothing;
``progress`` receives the lines the command shows.

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
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from dynid.exceptions import DynidError, UsageError

if TYPE_CHECKING:
    from dynid.diagnosis import Diagnosis
    from dynid.validation.validate import ValidationResult

__all__ = ["DEFAULT_ROBOT", "DEMO_FILES", "DEMO_MARKER", "PERTURB", "SETTINGS", "DemoResult", "StageRecord", "run_demo"]

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
class StageRecord:
    """One stage of the demo as it ran.

    Attributes
    ----------
    stage : str
        What the stage does, in words.
    status : str
        ``"done"`` or ``"failed"`` (only the diagnosis may fail without stopping the demo).
    summary : str
        One line: the stage's figures, or ``"failed: <why>"``.
    seconds : float
        Wall time of the stage (s).
    """

    stage: str
    status: str
    summary: str
    seconds: float

    def to_dict(self) -> dict[str, Any]:
        """The record as the demo's JSON holds it (keys ``stage``, ``status``, ``summary``, ``seconds``)."""
        return {"stage": self.stage, "status": self.status, "summary": self.summary, "seconds": self.seconds}


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


class _Stages:
    """Runs named stages, reports progress, keeps a record of each."""

    def __init__(self, total: int, progress: Callable[[str], None]) -> None:
        self.total = total
        self.progress = progress
        self.records: list[StageRecord] = []

    def run(self, label: str, fn: Callable[[], str], *, may_fail: bool = False) -> None:
        """Run one stage: ``fn`` does the work and returns a one-line summary.

        ``may_fail``: a :class:`~dynid.exceptions.DynidError` of this stage is recorded as a failure
        and the next stages still run.
        """
        self.progress(f"[{len(self.records) + 1}/{self.total}] {label}...")
        start = time.perf_counter()
        try:
            summary = fn()
        except DynidError as err:
            if not may_fail:
                raise
            elapsed = time.perf_counter() - start
            self.records.append(StageRecord(label, "failed", f"failed: {err}", elapsed))
            self.progress(f"      failed: {err} ({elapsed:.1f} s)")
            return
        elapsed = time.perf_counter() - start
        self.records.append(StageRecord(label, "done", summary, elapsed))
        self.progress(f"      {summary} ({elapsed:.1f} s)")

    @property
    def failed(self) -> list[str]:
        return [r.stage for r in self.records if r.status == "failed"]


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

    def say(message: str) -> None:
        say_line(f"      {message}")

    if isinstance(seed, bool) or int(seed) != seed or seed < 0:
        raise UsageError(f"the seed is {seed}; give a whole number of at least 0.")
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise UsageError(f"out_dir '{out}' is a file; give a folder for the demo's files.")
    if not out.parent.exists():
        raise UsageError(
            f"the folder '{out.parent}' of out_dir does not exist; create it or write elsewhere."
        )

    from dynid.symbolic.build import cache_dir, generator_is_built
    from dynid.symbolic.robot import load_robot

    clash = [f for f in DEMO_FILES if (out / f).exists()]
    if clash and not (out / DEMO_MARKER).is_file():
        raise UsageError(
            f"the folder '{out}' holds '{clash[0]}', which the demo would overwrite and no earlier demo wrote; "
            "give a new or empty folder."
        )
    out.mkdir(exist_ok=True)
    # first of all: the folder is the demo's, so that a later demo may overwrite what this one writes
    (out / DEMO_MARKER).write_text("written by dynid demo; its files may be replaced by the next demo\n")
    mode = "quick" if quick else "full"
    cfg = SETTINGS[mode]
    started = time.perf_counter()
    stages = _Stages(total=_STAGES, progress=say_line)
    # The UR5 at its own limits (URDF; 10 rad/s^2 where the URDF has none), as a user's first run has it.
    robot = load_robot(DEFAULT_ROBOT)
    state: dict[str, Any] = {}
    figures: dict[str, Any] = {"robot": DEFAULT_ROBOT, "mode": mode, "seed": seed}
    first_build = not generator_is_built()
    figures["first_run_build"] = first_build
    say_line(
        f"dynid demo ({mode}): {robot.name}, {robot.n} joints; the simulated robot is the UR5 with its inertial "
        f"parameters perturbed by {100 * PERTURB:g} %, the paper's friction and noisy sensors. Files go to {out}."
    )

    # ------------------------------------------------------------------ 1. symbolic model
    def symbolic() -> str:
        import pinocchio as pin

        from dynid.symbolic.base import base_parameters
        from dynid.symbolic.export import compiled_functions
        from dynid.symbolic.functions import robot_functions

        if first_build:
            say(
                "first run in this environment: building the symbolic generator once (about 40 s on 2 idle cores, "
                f"more on a slow machine), cached in {cache_dir()}; later runs skip this"
            )
        funcs = robot_functions(robot, progress=say)
        base = base_parameters(funcs)
        lib = compiled_functions(robot, progress=say)
        rng = np.random.default_rng([seed, 0])
        q, dq, ddq = rng.uniform(-1, 1, size=(3, 500, robot.n))
        tau = lib.rnea(q, dq, ddq)
        model, data = robot.pin_model, robot.pin_model.createData()
        err = max(
            float(np.abs(tau[k] - pin.rnea(model, data, q[k], dq[k], ddq[k])).max()) for k in range(len(q))
        )
        state["base"] = base
        figures["n_base"] = base.n_base
        figures["c_export_max_error"] = err
        return (
            f"{base.n_base} base parameters ({int(base.gravity_related.sum())} gravity-related); compiled C rnea "
            f"matches numeric Pinocchio to {err:.1e} N m on 500 random states"
        )

    # ------------------------------------------------------------------ 2. excitation
    def excite() -> str:
        from dynid.optim.excitation import ExcitationProblem, design_excitation

        problem = ExcitationProblem(
            robot=robot, harmonics=cfg["harmonics"], base_freq=cfg["base_freq"], criterion="seed"
        )
        result = design_excitation(
            problem,
            seed=seed,
            patience=cfg["patience"],
            max_tries=cfg["max_tries"],
            baseline=cfg["baseline"],
            n_jobs=2,
            progress=say,
        )
        traj = result.trajectories[0]
        traj.save(out / "excitation.json")
        state["problem"], state["excitation"], state["trajectory"] = problem, result, traj
        figures["excitation"] = {
            "cond": result.cond,
            "baseline_cond": result.baseline_cond,
            "feasible": result.feasible,
            "harmonics": cfg["harmonics"],
            "period_s": traj.period,
        }
        return (
            f"{cfg['harmonics']} harmonics, period {traj.period:g} s: cond {result.cond:.4g} against "
            f"{result.baseline_cond:.4g} for the best of {cfg['baseline']} random feasible trajectories; "
            f"wrote {out / 'excitation.json'}"
        )

    # ------------------------------------------------------------------ 3. simulation
    def simulate_runs() -> str:
        from dynid.data.files import load_dataset
        from dynid.sim.simulator import build_truth, simulate, write_simulation

        traj = state["trajectory"]
        truth = build_truth(robot, friction="seed", perturb=PERTURB, truth_seed=seed)
        # The held-out run follows another trajectory (random, within the limits), several periods long.
        other = state["problem"].random_trajectory(np.random.default_rng([seed, 7]), amplitude=0.9)
        runs = {}
        for name, trajectory, periods, run_seed in (
            ("identification", traj, cfg["id_periods"], seed + 1),
            ("validation", other, cfg["val_periods"], seed + 2),
        ):
            result = simulate(
                robot,
                trajectory,
                truth=truth,
                seed=run_seed,
                duration=periods * trajectory.period,
                source=f"the demo's {name} trajectory",
            )
            path, _ = write_simulation(result, out / f"{name}.csv")
            runs[name] = (result, path)
        state["truth"] = truth
        # Read back what was written: the rest of the demo sees the files a user would pass to dynid.
        state["data"] = {k: load_dataset(p, robot.n) for k, (_, p) in runs.items()}
        state["val_period"] = other.period
        state["paths"] = {k: p for k, (_, p) in runs.items()}
        ident, val = runs["identification"][0], runs["validation"][0]
        figures["runs"] = {
            "identification": {"duration_s": float(ident.t[-1]), "samples": int(ident.t.size)},
            "validation": {
                "duration_s": float(val.t[-1]),
                "samples": int(val.t.size),
                "periods": cfg["val_periods"],
            },
        }
        return (
            f"identification run {ident.t[-1]:.0f} s ({cfg['id_periods']} periods of the excitation), validation "
            f"run {val.t[-1]:.0f} s ({cfg['val_periods']} periods of another trajectory), 1 kHz; wrote "
            f"{runs['identification'][1].name} and {runs['validation'][1].name} with their .truth.json"
        )

    # ------------------------------------------------------------------ 4. identification
    def identify_models() -> str:
        from dynid.identify.linear_system import Preprocessing
        from dynid.identify.model import save_model
        from dynid.validation.validate import COMPARISON, identify_methods

        fitted = identify_methods(
            robot,
            state["data"]["identification"],
            methods=COMPARISON,
            preprocessing=Preprocessing(decimate=_DECIMATE),
            random_state=seed,
            progress=say,
        )
        files = {}
        for f in fitted:
            name = "model.json" if f.label == "full" else f"model_{f.label.lower()}.json"
            save_model(f.model, out / name)
            files[f.label] = name
        state["fitted"], state["files"] = fitted, files
        figures["identification"] = {
            f.label: {
                "method": f.model.method,
                "cond": f.model.cond,
                "file": files[f.label],
                "seconds": f.seconds,
                "warnings": f.warnings,
            }
            for f in fitted
        }
        return (
            "the full method (consistent links, the paper's friction, GMM), OLS and IRLS (linear friction) in "
            + ", ".join(f"{f.seconds:.1f} s" for f in fitted)
            + f"; wrote {', '.join(files.values())}"
        )

    # ------------------------------------------------------------------ 5. validation
    def validation() -> str:
        from dynid.validation.validate import compare, validate

        data = state["data"]["validation"]
        results = [
            validate(
                f.model,
                data,
                period=state["val_period"],
                label=f.label,
                info={"model_file": state["files"][f.label], "seconds": f.seconds},
            )
            for f in state["fitted"]
        ]
        state["results"] = results
        state["rows"] = compare(results)
        full = results[0]
        state["truth_errors"] = _truth_errors(state["truth"], {r.label: r.model for r in results})
        return (
            f"held-out mean RMS: full {full.metrics['rms_mean']:.4g}, OLS {results[1].metrics['rms_mean']:.4g}, "
            f"IRLS {results[2].metrics['rms_mean']:.4g} N m; noise floor {full.noise.rms_mean:.4g} N m "
            f"({full.noise.detail})"
        )

    # ------------------------------------------------------------------ 6. diagnosis
    def diagnosis() -> str:
        from dynid.diagnosis import diagnose, write_diagnosis_report

        full = state["results"][0]
        result = diagnose(
            full.model,
            state["data"]["identification"],
            state["data"]["validation"],
            period=state["val_period"],
        )
        state["diagnosis"] = result
        figures["diagnosis"] = result.to_dict()
        path = write_diagnosis_report(
            result, out / "diagnosis.html", title="dynid demo: gap diagnosis of the full method"
        )
        state["diagnosis_report"] = path
        figures["diagnosis_report"] = str(path)
        text = result.summary().splitlines()
        return f"verdict {', '.join(result.verdict)}; wrote {path}: {text[0] if text else ''}"

    # ------------------------------------------------------------------ 7. report
    def report() -> str:
        from dynid._io import to_jsonable
        from dynid.validation.report import html_table, render_report

        results = state["results"]
        full = results[0]
        figures.update(
            {
                **full.figures(),
                "models": state["rows"],
                "truth_relative_error": state["truth_errors"],
                "report": str(out / "report.html"),
            }
        )
        stage_rows = [[r.stage, r.status, r.summary, r.seconds] for r in stages.records]
        truth_rows = [
            [
                r.label,
                state["truth_errors"][r.label]["rigid_body"],
                state["truth_errors"][r.label]["worst_joint_torque"],
            ]
            for r in results
        ]
        sections = [
            (
                "Against the simulated truth",
                '<p class="note">The simulator knows the robot it drove. Relative error of the identified '
                "rigid-body parameters (base parameters and armature, weighted by how much torque each one "
                "makes on the held-out motion): the RMS over joints of Y(x - x_true) over the RMS of Y x_true, "
                "and the largest joint's.</p>"
                + html_table(
                    ["model", "relative error (all joints)", "worst joint"], truth_rows, table_id="truth"
                ),
            ),
            (
                "How this report was made",
                html_table(
                    ["stage", "status", "summary", "seconds"], stage_rows, table_id="stages", text_columns=3
                ),
            ),
        ]
        if "diagnosis" in state:
            fragment = _diagnosis_html(state["diagnosis"], full.label)
            name = html.escape(Path(state["diagnosis_report"]).name)
            fragment += (
                f'<p class="note">The diagnosis in full (gap map, decomposition, every candidate): '
                f'<a href="{name}">{name}</a>, beside this file.</p>'
            )
            sections.insert(0, ("Sim-to-real gap diagnosis", fragment))
        else:
            row = next((r for r in stages.records if r.stage.startswith("sim-to-real")), None)
            why = row.summary if row else "not run"
            sections.insert(0, ("Sim-to-real gap diagnosis", f'<p class="note">{html.escape(why)}.</p>'))
        exc = state["excitation"]
        rep = render_report(
            results,
            figures=to_jsonable(figures),
            title="dynid demo: UR5 identified from a simulated run, validated on another",
            context={
                "identification data": f"{state['paths']['identification'].name} (the optimised excitation)",
                "truth": f"UR5 with inertial parameters perturbed by {100 * PERTURB:g} %, the paper's friction",
                "mode": mode,
            },
            sections=sections,
            conditions=[
                ("excitation design (cond of H* on its grid)", exc.cond),
                (f"best of {cfg['baseline']} random feasible trajectories", exc.baseline_cond),
            ],
        )
        path = rep.write(out / "report.html")
        state["report"] = path
        return f"wrote {path} ({len(rep.figures)} figures, {len(rep.html) / 1e6:.1f} MB)"

    # One BLAS / OpenMP thread: on small matrices a threaded BLAS is many times slower here (the
    # excitation's figures took 5 s instead of 0.1 s on 2 busy cores); joblib's workers set their own.
    import scipy.linalg  # noqa: F401  (loads scipy's BLAS, so that the limit below covers it)
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1):
        stages.run("symbolic dynamics, base parameters and compiled C (Pinocchio on CasADi)", symbolic)
        stages.run("excitation design (Fourier series, IPOPT)", excite)
        stages.run("simulated identification and validation runs", simulate_runs)
        stages.run("identification: the full three-layer method, OLS and IRLS", identify_models)
        stages.run("validation on the held-out run", validation)
        stages.run("sim-to-real gap diagnosis", diagnosis, may_fail=True)
        stages.run("HTML report", report)

    from dynid._io import to_jsonable

    total = time.perf_counter() - started
    figures["stages"] = [r.to_dict() for r in stages.records]
    # Every stage exists now; the key stays so that files written before read the same.
    figures["stages_missing"] = []
    figures["stages_failed"] = stages.failed
    figures["total_s"] = total
    return DemoResult(
        out_dir=out,
        mode=mode,
        stages=tuple(stages.records),
        figures=to_jsonable(figures),
        results=tuple(state["results"]),
        diagnosis=state.get("diagnosis"),
        report=state.get("report"),
        total_s=total,
    )


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
