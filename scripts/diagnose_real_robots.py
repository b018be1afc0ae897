"""Diagnose the gap of models identified on two real arms: which effects the data show, and how much of
the held-out gap each closes.

Run:  python scripts/diagnose_real_robots.py [OUT_DIR]     (a few minutes on 2 cores; needs ../shared/data)

For each recording (``../shared/data``; see its README):

* Staubli TX40, 9 s at 5 kHz, motor-side data converted to the joint side through a coupled wrist
  (motor 6 turns with joint 5): identified on the first 6 s, held out the last 3 s;
* Franka Panda (Gaz et al. 2019), 21 s at about 1 kHz with joint torque sensors: identified on the
  first 14 s, held out the last 7 s.

The model is dynid's layer 1 (OLS on the parallel-filtered base regressor, with armature and linear
friction per joint: Coulomb, viscous, offset), written to a model file and read back as ``dynid
diagnose`` would.  The diagnosis then measures the held-out noise floor (the runs are not periodic:
the spectral level, scaled by the filter's noise gain), re-identifies the base parameters, screens the
whole catalogue of candidate effects refitted with them on the training part, tests each on the
held-out part, and accepts effects by forward selection.  An HTML report per robot goes to OUT_DIR.

Without ``../shared/data`` the script says so and stops (exit code 0).
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))  # the scripts' shared helpers

RECORDINGS = {
    # name: (split time (s), decimation after the 20 Hz filter)
    "tx40": (6.0, 10),
    "panda_gaz2019": (14.0, 2),
}


def diagnose_recording(name: str, split: float, decimate: int, out: Path, root: Path | None = None) -> dict:
    """Identify on ``t < split``, diagnose on the rest; write the model and the report into ``out``."""
    import numpy as np
    from _realrobot import load_with_robot, split_in_time

    from dynid.data.preparation import Preprocessing
    from dynid.diagnosis.core import diagnose
    from dynid.diagnosis.report import write_diagnosis_report
    from dynid.diagnosis.result import settling_excitation
    from dynid.identify.model import identify, load_model, save_model

    data, robot = load_with_robot(name, root)
    train, heldout = split_in_time(data, split)

    # Layer 1 only: the diagnosis explains what the rigid body and linear friction leave.
    model = identify(
        robot,
        train,
        method="ols",
        friction="linear",
        gmm="off",
        # the 20 Hz filter the decimation above is set for (the default would choose from the data:
        # 52 Hz on the TX40, where the verdict's significance note was written for 20 Hz)
        preprocessing=Preprocessing(cutoff=20.0, decimate=decimate),
    )
    path, _ = save_model(model, out / f"{name}_model.json")
    model = load_model(path, robot=robot)

    result = diagnose(model, train, heldout)
    print(
        f"\n=== {name}: {robot.n} joints, trained on {train.duration:.1f} s, held out {heldout.duration:.1f} s"
    )
    print(f"noise floor: {result.noise.detail}")
    print(f"verdict: {', '.join(result.verdict)}")
    print(result.summary())
    dec = result.decomposition
    print(
        f"{'joint':>5} {'excess':>8} {'param.unc.':>10} {'MSE model':>11} {'re-ident.':>11} {'after':>11} {'noise':>11} "
        f"{'closure':>8}"
    )
    for j in range(robot.n):
        c = dec["closure"][j]
        print(
            f"{j + 1:>5} {result.excess['ratio'][j]:>8.2f} {result.excess['estimation'][j]:>10.3g} "
            f"{dec['mse_model'][j]:>11.4g} {dec['mse_refit'][j]:>11.4g} "
            f"{dec['mse_after'][j]:>11.4g} {dec['noise'][j]:>11.4g} {'-' if c != c else f'{c:.2f}':>8}"
        )
    print("(excess: held-out MSE of the re-identified model over the noise floor; param.unc.: the part of it, in")
    print(" noise variances, that the training data's parameter uncertainty alone is expected to add)")
    print("each accepted effect, in the order of selection (closure on its joints, held-out):")
    for a in result.accepted:
        print(
            f"  {a.candidate.label}: closure {a.closure:.2f}, gain {a.gain:.3g} noise variances, p = {a.p_holm:.2g}"
        )
    print("top of the ranking on the re-identified model:")
    for r in result.ranking[:6]:
        print(f"  {r.candidate.key:<24} gain {r.gain:8.3g}  closure {r.closure:6.2f}  p(adj.) {r.p_holm:.2g}")
    rate = 1.0 / float(np.median(np.diff(heldout.t)))
    settle = settling_excitation(result, robot=str(robot.source), dq_max=robot.dq_max, rate=rate)
    if settle is not None:
        settle["commands"] = [settle["excite"], settle["play"]]
        print(settle["reason"] + " To settle it, record it like this:")
        print("  " + settle["excite"])
    report = write_diagnosis_report(
        result,
        out / f"{name}_diagnosis.html",
        title=f"{name}: gap diagnosis (identified on t < {split:g} s, held out the rest)",
        context={"recording": name, "robot": robot.name, "split (s)": split, "decimation": decimate},
        settle=settle,
    )
    print(f"report: {report}")
    doc = result.to_dict()
    if settle is not None:
        doc["settle"] = settle
    return doc


def main(out: Path) -> int:
    from dynid.data.adapters import find_shared_data
    from dynid.exceptions import DataError

    try:
        root = find_shared_data()
    except DataError as err:
        print(f"skipped: the real recordings are not available ({err})")
        return 0
    out.mkdir(parents=True, exist_ok=True)
    for name, (split, decimate) in RECORDINGS.items():
        diagnose_recording(name, split, decimate, out, root)
    return 0


if __name__ == "__main__":
    sys.exit(main(Path(sys.argv[1] if len(sys.argv) > 1 else ".")))
