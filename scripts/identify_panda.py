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

sys.path.insert(0, str(Path(__file__).resolve().parent))  # the scripts' shared helpers

from _realrobot import load_with_robot, print_heldout_table, run, split_in_time, write_outputs

from dynid.data.preparation import Preprocessing
from dynid.validation.validate import ValidationResult, compare_methods

RECORDING = "panda_gaz2019"
TRAIN_FRACTION = 0.7


def main(out: Path, root: Path | None = None) -> list[ValidationResult]:
    """Identify, validate, write ``panda_report.html`` and ``panda_model.json`` into ``out``."""
    # The data: q and dq from the robot, tau from the joint torque sensors (gravity included).  The
    # adapter drops the ~1255 rows that repeat a stale q; resampling to a uniform grid, the 20 Hz
    # zero-phase filter (on the torque and, in parallel, on every regressor column) and the
    # differentiation for ddq happen inside the identification.
    data, robot = load_with_robot(RECORDING, root)

    # Time-based split: the first 70 % to identify, the rest to validate.
    split = data.t[0] + TRAIN_FRACTION * (data.t[-1] - data.t[0])
    train, heldout = split_in_time(data, split)

    # Every model sees the same preprocessing, so their errors are on the same torque: after the
    # 20 Hz filter, one sample in 4 is plenty (250 Hz).
    results = compare_methods(
        robot, train, heldout, preprocessing=Preprocessing(decimate=4), baseline=True, progress=print
    )
    print_heldout_table(results, heldout)
    write_outputs(
        results,
        out,
        "panda",
        title="Franka Emika Panda (Gaz et al. 2019): identified on 70 % of the run, validated on the rest",
        context={
            "recording": f"{RECORDING}: {data.m} samples over {data.duration:.1f} s, joint torque sensors",
            "split": f"identification t < {split:.2f} s ({train.m} samples), validation after ({heldout.m} samples)",
            "URDF": "the robot description's inertials (Gaz et al.'s feasible parameters) with linear friction fitted",
        },
    )
    return results


if __name__ == "__main__":
    run(main, __file__)
