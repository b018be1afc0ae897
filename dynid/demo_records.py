"""What the stages of ``dynid demo`` hand each other, and the runner that times and records them.

:class:`StageRunner` runs one stage after another (:func:`dynid.demo.run_demo`), shows its counter and
its one-line summary through the progress and keeps a :class:`StageRecord` of each.  The stages read a
:class:`DemoContext` (robot, folder, mode, seed, settings) and return frozen records: :class:`Step`,
:class:`Excitation`, :class:`Runs` (of :class:`SimulatedRun`), :class:`Fits`, :class:`Validation`,
:class:`GapDiagnosis`, :class:`ReportPage`; :class:`Outcome` gathers what the demo returns.

The records hold the objects of every room (robot, trajectory, models, validation results, the
diagnosis) typed as ``Any``: this module imports no room, so that it may sit below them all beside
:mod:`dynid.demo`.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, Protocol, TypeVar, overload

from dynid.exceptions import DynidError

__all__ = [
    "FULL",
    "DemoContext",
    "Excitation",
    "Fits",
    "GapDiagnosis",
    "Outcome",
    "ReportPage",
    "Runs",
    "SimulatedRun",
    "StageRecord",
    "StageRunner",
    "Step",
    "Summarised",
    "Validation",
]


class Summarised(Protocol):
    """A stage's result: it says what the stage did in one line."""

    @property
    def summary(self) -> str: ...


_R = TypeVar("_R", bound=Summarised)


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


FULL = "full"
"""The label of the full method among the compared ones (:data:`dynid.validation.validate.COMPARISON`)."""


class StageRunner:
    """Runs named stages, reports progress, keeps a record of each."""

    def __init__(self, total: int, progress: Callable[[str], None]) -> None:
        self.total = total
        self.progress = progress
        self.records: list[StageRecord] = []

    @overload
    def run(self, label: str, fn: Callable[[], _R], *, may_fail: Literal[False] = ...) -> _R: ...
    @overload
    def run(self, label: str, fn: Callable[[], _R], *, may_fail: bool) -> _R | None: ...

    def run(self, label: str, fn: Callable[[], _R], *, may_fail: bool = False) -> _R | None:
        """Run one stage: ``fn`` does the work and returns its result, whose ``summary`` is one line.

        ``may_fail``: a :class:`~dynid.exceptions.DynidError` of this stage is recorded as a failure,
        None is returned and the next stages still run.
        """
        self.progress(f"[{len(self.records) + 1}/{self.total}] {label}...")
        start = time.perf_counter()
        try:
            result = fn()
        except DynidError as err:
            if not may_fail:
                raise
            elapsed = time.perf_counter() - start
            self.records.append(StageRecord(label, "failed", f"failed: {err}", elapsed))
            self.progress(f"      failed: {err} ({elapsed:.1f} s)")
            return None
        elapsed = time.perf_counter() - start
        self.records.append(StageRecord(label, "done", result.summary, elapsed))
        self.progress(f"      {result.summary} ({elapsed:.1f} s)")
        return result

    @property
    def failed(self) -> list[str]:
        """Names of the stages that failed so far."""
        return [r.stage for r in self.records if r.status == "failed"]


@dataclass(frozen=True)
class DemoContext:
    """What every stage reads: the robot, the folder, the mode, the seed, its settings and the progress."""

    robot: Any
    out: Path
    mode: str
    seed: int
    first_build: bool  # the symbolic generator is built in this run
    progress: Callable[[str], None]
    settings: dict[str, Any]  # the mode's settings (:data:`dynid.demo.SETTINGS`)

    def say(self, message: str) -> None:
        """A long step's news, indented under its stage's counter."""
        self.progress(f"      {message}")


@dataclass(frozen=True)
class Step:
    """A stage that hands nothing on but its summary line and its figures for the demo's JSON."""

    summary: str
    figures: dict[str, Any]


@dataclass(frozen=True)
class Excitation:
    """The excitation design: the problem (its limits give the held-out run's trajectory too) and its result."""

    problem: Any
    design: Any
    trajectory: Any
    summary: str
    figures: dict[str, Any]


@dataclass(frozen=True)
class SimulatedRun:
    """One simulated run and the dataset file written from it."""

    result: Any
    path: Path


@dataclass(frozen=True)
class Runs:
    """The simulated truth and the two runs, read back from their files."""

    truth: Any
    identification: Any
    validation: Any
    validation_period: float
    identification_file: Path
    summary: str
    figures: dict[str, Any]


@dataclass(frozen=True)
class Fits:
    """The models of the compared methods, in :data:`~dynid.validation.validate.COMPARISON`'s order."""

    fitted: tuple[Any, ...]
    files: dict[str, str]  # model file name by label
    summary: str
    figures: dict[str, Any]


@dataclass(frozen=True)
class Validation:
    """Every model on the held-out run, side by side, and against the simulated truth."""

    results: tuple[Any, ...]  # ValidationResult of each model, in the order of Fits.fitted
    rows: list[dict[str, Any]]
    truth_errors: dict[str, dict[str, float]]
    summary: str

    def labelled(self, label: str) -> Any:
        """The validation of the model with this label."""
        return next(r for r in self.results if r.label == label)

    @property
    def full(self) -> Any:
        """The validation of the full method."""
        return self.labelled(FULL)


@dataclass(frozen=True)
class GapDiagnosis:
    """The gap diagnosis of the full method and its page."""

    result: Any  # the dynid.diagnosis.Diagnosis
    report: Path
    summary: str
    figures: dict[str, Any]


@dataclass(frozen=True)
class ReportPage:
    """The HTML report and the figures it adds to the demo's JSON."""

    path: Path
    summary: str
    figures: dict[str, Any]


@dataclass(frozen=True)
class Outcome:
    """What the stages made: the figures so far (in stage order) and the results the demo returns."""

    figures: dict[str, Any]
    validation: Validation
    diagnosis: GapDiagnosis | None
    report: ReportPage
