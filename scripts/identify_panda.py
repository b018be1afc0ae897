"""Identify a real Franka Emika Panda from Gaz et al.'s recording and validate it on the part it never saw.

Run:  python scripts/identify_panda.py [OUT_DIR]        (about a minute on 2 cores; needs ../shared/data)

The recording (``../shared/data/panda_gaz2019``, see its README) is 21 s of an exciting trajectory at
about 1 kHz with irregular time stamps, the link-side joint torque sensors, and a URDF whose inertials
are the ones Gaz et al. identified.  The script trains on the first 70 % of the run and validates on
the last 30 %, compares the full method with OLS, IRLS and the URDF's own parameters (with linear
friction fitted), and writes an HTML report and the identified model.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from dynid.identify.adapters import load_recording, recording_model_path
from dynid.identify.linear_system import Preprocessing
from dynid.identify.model import save_model
from dynid.symbolic import load_robot
from dynid.validation.report import render_report
from dynid.validation.validate import ValidationResult, compare_methods

RECORDING = "panda_gaz2019"
TRAIN_FRACTION = 0.7


def main(out: Path, root: Path | None = None) -> list[ValidationResult]:
    """Identify, validate, write ``panda_report.html`` and ``panda_model.json`` into ``out``."""
    # The data: q and dq from the robot, tau from the joint torque sensors (gravity included).  The
    # adapter drops the ~1255 rows that repeat a stale q; resampling to a uniform grid, the 20 Hz
    # zero-phase filter (on the torque and, in parallel, on every regressor column) and the
    # differentiation for ddq happen inside the identification.
    data = load_recording(RECORDING, root)
    robot = load_robot(recording_model_path(RECORDING, root))

    # Time-based split: the first 70 % to identify, the rest to validate (never a random split of
    # samples: neighbouring samples share their noise and filtering).
    split = data.t[0] + TRAIN_FRACTION * (data.t[-1] - data.t[0])
    train = data.select_rows(np.flatnonzero(data.t < split))
    heldout = data.select_rows(np.flatnonzero(data.t >= split))

    # Every model sees the same preprocessing, so their errors are on the same torque: after the
    # 20 Hz filter, one sample in 4 is plenty (250 Hz).
    results = compare_methods(
        robot, train, heldout, preprocessing=Preprocessing(decimate=4), baseline=True, progress=print
    )

    full = results[0]
    print(f"\nheld-out RMS (N m) on the last {heldout.duration:.1f} s; torque {full.reference}")
    print(f"{'model':<6}" + "".join(f"{'joint ' + str(j + 1):>9}" for j in range(robot.n)) + f"{'mean':>9}")
    for r in results:
        print(
            f"{r.label:<6}"
            + "".join(f"{v:>9.4f}" for v in r.metrics["rms"])
            + f"{r.metrics['rms_mean']:>9.4f}"
        )
    print(f"{'noise':<6}" + "".join(f"{v:>9.4f}" for v in full.noise.std) + f"   ({full.noise.method})")

    out.mkdir(parents=True, exist_ok=True)
    save_model(full.model, out / "panda_model.json")
    report = render_report(
        results,
        title="Franka Emika Panda (Gaz et al. 2019): identified on 70 % of the run, validated on the rest",
        context={
            "recording": f"{RECORDING}: {data.m} samples over {data.duration:.1f} s, joint torque sensors",
            "split": f"identification t < {split:.2f} s ({train.m} samples), validation after ({heldout.m} samples)",
            "URDF": "the robot description's inertials (Gaz et al.'s feasible parameters) with linear friction fitted",
        },
    )
    path = report.write(out / "panda_report.html")
    print(f"wrote {path} and {out / 'panda_model.json'}")
    return results


if __name__ == "__main__":
    from dynid.exceptions import DynidError

    try:
        main(Path(sys.argv[1] if len(sys.argv) > 1 else "."))
    except DynidError as err:  # e.g. no recordings here: one sentence, no traceback
        sys.exit(f"{Path(__file__).name}: {err}")
