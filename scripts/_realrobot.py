"""What the scripts on the real recordings share: the time split, the held-out table, the outputs.

Imported by ``identify_panda.py``, ``identify_tx40.py`` and ``diagnose_real_robots.py`` (which put this
folder on ``sys.path`` first); not a script itself.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from dynid.data.adapters import load_recording, recording_model_path
from dynid.data.dataset import Dataset
from dynid.identify.model import save_model
from dynid.symbolic import RobotModel, load_robot
from dynid.validation.report import render_report
from dynid.validation.validate import ValidationResult


def load_with_robot(name: str, root: Path | None = None) -> tuple[Dataset, RobotModel]:
    """A recording and the robot of its own robot description.

    Parameters
    ----------
    name : str
        The recording (see :func:`dynid.data.adapters.load_recording`).
    root : Path, optional
        The folder of the recordings (found beside the repository by default).
    """
    return load_recording(name, root), load_robot(recording_model_path(name, root))


def split_in_time(data: Dataset, split: float) -> tuple[Dataset, Dataset]:
    """The parts of ``data`` before and after ``split`` (s): (train, heldout).

    A split in time, never a random split of samples: neighbouring samples share their noise and
    filtering.

    Parameters
    ----------
    data : Dataset
        The recording.
    split : float
        Time (s) that separates the identification part (``t < split``) from the held-out one.
    """
    train = data.select_rows(np.flatnonzero(data.t < split))
    heldout = data.select_rows(np.flatnonzero(data.t >= split))
    return train, heldout


def print_heldout_table(results: Sequence[ValidationResult], heldout: Dataset, *, r2: bool = False) -> None:
    """Print the held-out RMS per joint of every model, the noise floor and optionally the full R^2.

    Parameters
    ----------
    results : sequence of ValidationResult
        From :func:`dynid.validation.validate.compare_methods`, the full method first.
    heldout : Dataset
        The held-out part (for its duration).
    r2 : bool
        Add a row with the full method's R^2 per joint.
    """
    full = results[0]
    n = len(full.metrics["rms"])
    print(f"\nheld-out RMS (N m) on the last {heldout.duration:.1f} s; torque {full.reference}")
    print(f"{'model':<6}" + "".join(f"{'joint ' + str(j + 1):>9}" for j in range(n)) + f"{'mean':>9}")
    for r in results:
        print(
            f"{r.label:<6}"
            + "".join(f"{v:>9.4f}" for v in r.metrics["rms"])
            + f"{r.metrics['rms_mean']:>9.4f}"
        )
    print(f"{'noise':<6}" + "".join(f"{v:>9.4f}" for v in full.noise.std) + f"   ({full.noise.method})")
    if r2:
        print(f"{'R^2':<6}" + "".join(f"{v:>9.3f}" for v in full.metrics["r2"]) + "   (full method)")


def write_outputs(
    results: Sequence[ValidationResult], out: Path, stem: str, *, title: str, context: dict[str, Any]
) -> None:
    """Write the full method's model ``<stem>_model.json`` and the report ``<stem>_report.html`` into ``out``.

    Parameters
    ----------
    results : sequence of ValidationResult
        The full method first.
    out : Path
        Output folder (created if missing).
    stem : str
        Start of the file names.
    title : str
        Title of the report.
    context : dict
        Lines of the report's context table.
    """
    out.mkdir(parents=True, exist_ok=True)
    model_path = out / f"{stem}_model.json"
    save_model(results[0].model, model_path)
    report = render_report(results, title=title, context=context)
    path = report.write(out / f"{stem}_report.html")
    print(f"wrote {path} and {model_path}")


def run(main: Callable[[Path], Any], script: str) -> None:
    """Run ``main(OUT_DIR)`` from the command line; a dynid error ends it with one sentence, no traceback.

    Parameters
    ----------
    main : callable
        The script's ``main``, given the output folder (first argument, default ``.``).
    script : str
        The script's file, for the message.
    """
    from dynid.exceptions import DynidError

    try:
        main(Path(sys.argv[1] if len(sys.argv) > 1 else "."))
    except DynidError as err:  # e.g. no recordings here
        sys.exit(f"{Path(script).name}: {err}")
