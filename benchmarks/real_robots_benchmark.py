"""Held-out error of dynid on two real recordings against a published reference (prints figures; not a test).

Panda (``../shared/data/panda_gaz2019``): identify on t < 15 s, hold out t >= 15 s.  Every prediction
and the RAW held-out torque go through the same 10 Hz zero-phase 4th-order Butterworth, and 0.25 s is
trimmed at both ends of the held-out part.  The reference is Gaz et al.'s published model, computed
here with numeric Pinocchio (``pin.rnea``): the URDF of the recording's ``model/`` folder (their
feasible link parameters) plus their sigmoid friction (RA-L 2019, Table I),

    tau_f,j = phi1_j / (1 + exp(-phi2_j (dq_j + phi3_j))) - phi1_j / (1 + exp(-phi2_j phi3_j)),

with the coefficients of ``matlab/dyn_model_panda/get_FrictionTorque.m`` in their public repository
(``marcocognetti/FrankaEmikaPandaDynModel``, the repository the recording comes from).  Its states are
the measured ``q`` and ``dq`` low-passed at 10 Hz (4th order) and ``ddq`` their central difference.

TX40 (``../shared/data/tx40``): FIGAROH's split, rows [0, 24750) identify, [29250, 45000) held out;
predictions and the raw held-out torque through a 100 Hz zero-phase 4th-order Butterworth, scored at
500 Hz (one sample in 10), 0.02 s trimmed at both ends.  The reference is FIGAROH's own TX40 example on
this split, computed in the same run when ``--figaroh-example DIR --figaroh-python PY`` are given
(figaroh-examples' ``examples/staubli_tx40`` folder and a Python with figaroh installed;
``_figaroh_tx40.py`` identifies on the training rows as the example does and predicts every row): rows
``figaroh``, the example as FIGAROH 1.0.2 runs it, and ``fig+hook``, with the example's wrist-coupling
hook called as it was before 1.0.2, each scored like dynid's models; their own joint torque is checked
to be the recording's.  Without them, FIGAROH 0.2.4's figures on this split are quoted: [5.34 6.94
4.02 1.67 2.49 1.70] N m.

Models, each identified on the training part only:

- ``defaults``: ``identify(robot, train)`` with no options, as ``dynid identify --robot R --data
  train.csv`` runs it;
- ``ols+lin``: OLS with linear friction, unconstrained, no correction (the baseline of the physical layers);
- ``phys``: the default model's link + friction layers alone (no mixture correction);
- ``ref``: the reference above;
- TX40 only: ``wrist``, the defaults with the coupled wrist declared (the recording's robot from
  :func:`dynid.data.adapters.recording_robot`, as ``dynid identify --transmission`` takes it),
  ``wrist+out``, the same with the friction of joint 6's output stage that motor 6 drives
  (``effects="coupled_friction@5+6:mix=0"``: on dq6, felt by joints 5 and 6), and
  ``+cfric``, the defaults with the effect the diagnosis ranks first on this recording added as a model
  term (``identify(..., effects="coupled_friction@5+6")``, as ``dynid identify --effects`` takes it).

With ``--spring`` it also prints what physically consistent links cost a linear model (OLS
with linear friction, no correction) on the held-out part, and what a torque linear in each
joint's own angle, ``k_j (q_j - mean q_j)``, gives back (:func:`spring_check`).

A model predicts from the states of the whole recording prepared as its identification data were
(so the held-out part has no filter edge of its own; the held-out torque is never used), without its
own torque filter; the scoring filter above is then applied to prediction and torque alike.

Run:  OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python benchmarks/real_robots_benchmark.py --robot panda
      (or ``--robot tx40 [--figaroh-example DIR --figaroh-python PY]``, ``--robot kuka``; each takes
      under a minute on 2 cores; ``--spring`` adds half a minute)
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

#: Gaz et al.'s sigmoid friction (Table I; get_FrictionTorque.m): phi1 (N m), phi2 (s/rad), phi3 (rad/s).
GAZ_FRICTION = np.array(
    [
        [0.54615, 0.87224, 0.64068, 1.2794, 0.83904, 0.30301, 0.56489],
        [5.1181, 9.0657, 10.136, 5.5903, 8.3469, 17.133, 10.336],
        [0.039533, 0.025882, -0.04607, 0.036194, 0.026226, -0.021047, 0.0035526],
    ]
)
#: FIGAROH 0.2.4's held-out RMS (N m) on the TX40 split, as published by its example.
FIGAROH_TX40 = np.array([5.34, 6.94, 4.02, 1.67, 2.49, 1.70])

SETUPS = {
    # recording, train rows, held-out rows (by time for the Panda), scoring cut-off (Hz), score step, trim (s)
    "panda": {"recording": "panda_gaz2019", "split_s": 15.0, "cutoff": 10.0, "step": 1, "trim": 0.25},
    # the LWR4+: identify on run 1, hold out run 3 (another motion); torques as recorded (pre-filtered)
    "kuka": {"recording": "kuka_lwr4_flobaroid", "train_run": 1, "heldout_run": 3, "cutoff": 5.0, "step": 1,
             "trim": 0.25},
    "tx40": {
        "recording": "tx40",
        "train": (0, 24750),
        "heldout": (29250, 45000),
        "cutoff": 100.0,
        "step": 10,
        "trim": 0.02,
    },
}


def gaz_friction(dq: np.ndarray) -> np.ndarray:
    """Gaz et al.'s sigmoid friction torque (N m) at joint velocities ``dq`` (m, 7)."""
    p1, p2, p3 = GAZ_FRICTION
    return p1 / (1.0 + np.exp(-p2 * (dq + p3))) - p1 / (1.0 + np.exp(-p2 * p3))


def gaz_reference(urdf: str, full) -> tuple[np.ndarray, np.ndarray]:
    """Published Panda model on the whole recording: (t, tau) at the uniform grid of the prepared states."""
    import pinocchio as pin

    from dynid.data.preparation import Preprocessing, prepare

    prep = prepare(full, Preprocessing(cutoff=10.0, order=4, parallel=False, trim=0.0))
    model = pin.buildModelFromUrdf(urdf)
    data = model.createData()
    tau = np.empty_like(prep.q)
    for k in range(len(prep.q)):
        tau[k] = pin.rnea(model, data, prep.q[k], prep.dq[k], prep.ddq[k])
    return prep.t, tau + gaz_friction(prep.dq)


def plain_least_squares(urdf: str, train, full) -> tuple[np.ndarray, np.ndarray]:
    """A plain least-squares fit, as a user would write it without dynid: (t, tau) on ``full``.

    Numeric Pinocchio's joint-torque regressor (``pin.computeJointTorqueRegressor``) of the URDF, plus
    Coulomb ``sign(dq_j)``, viscous ``dq_j`` and an offset per joint, fitted by ordinary least squares
    (minimum norm, ``numpy.linalg.lstsq``) on filtered states and the torque filtered apart (dynid's
    preprocessing with ``parallel=False``, the paper's way), no constraint, no base-parameter reduction.
    """
    import pinocchio as pin

    from dynid.data.preparation import Preprocessing, prepare

    model = pin.buildModelFromUrdf(urdf)
    data = model.createData()
    settings = Preprocessing(parallel=False)

    def design(ds):
        prep = prepare(ds, settings)
        rows = prep.rows
        q, dq, ddq = prep.q[rows], prep.dq[rows], prep.ddq[rows]
        n = q.shape[1]
        blocks = []
        for k in range(len(q)):
            Y = pin.computeJointTorqueRegressor(model, data, q[k], dq[k], ddq[k])
            blocks.append(np.hstack([Y, np.diag(np.sign(dq[k])), np.diag(dq[k]), np.eye(n)]))
        A = np.stack(blocks)  # (m, n, 10 n + 3 n)
        return prep, rows, A

    prep, rows, A = design(train)
    tau = prep.tau[rows]
    x = np.linalg.lstsq(A.reshape(-1, A.shape[2]), tau.reshape(-1), rcond=None)[0]
    prep_full, rows_full, A_full = design(full)
    return prep_full.t[rows_full], A_full @ x


def model_parts(model, full) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t, physical layers, full model) at full rate on the whole recording, without the model's torque filter."""
    prep = model.prepare(full)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        total = model.predict(prep.q, prep.dq, prep.ddq)
        gmm = np.zeros_like(total) if model.gmr is None else model.gmr.predict(np.hstack([prep.q, prep.dq]))
    return prep.t, total - gmm, total


def spring_check(robot, full, train_end: float, held: tuple[float, float], cutoff: float, step: int) -> None:
    """What consistent links cost an OLS + linear-friction model held out, with and without joint springs.

    The whole recording is prepared once (default preprocessing); the rows before ``train_end`` (less
    the preprocessing's trim, so no filter reaches across) are fitted, the rows in ``held`` scored: the
    residual against the prepared torque through ``cutoff`` Hz zero-phase (order 4), every ``step``
    rows, the trim cut at both ends.  Four fits: unconstrained (the ``ols+lin`` baseline), its
    closest consistent set in its own metric (:func:`dynid.identify.consistent.consistent_solution`),
    and both again with one more column per joint, ``q_j - mean q_j`` in joint j's equation (a
    torque linear in the joint's own angle, free in the projection: its Schur complement gives the
    metric of the rest, and it is refitted after).  Prints the ratios to the baseline per joint, the
    unconstrained armatures, the springs and ``corr(q_j, ddq_j)`` over the training rows.

    Measured with the same column added to the default fit as an effect term (every joint): the Panda's
    physical layers come within 1.02x of ``ols+lin`` on every joint (joint 4: 0.94x), the TX40's keep
    0.65-0.95x; but on the identification benchmark's simulated UR5, whose unmodelled torque is
    ``0.3 sin(2 q_j + 0.5)``, the springs take the part of it the position mixture held, the mixture
    stays on 2 joints of 6, and the full model's held-out RMS goes from 0.220x OLS to 0.688x.  A
    spring is no default term without a test that the data ask for it.
    """
    from dynid.data.preprocess import lowpass
    from dynid.identify.consistent import consistent_solution
    from dynid.identify.linear_system import build_system

    system = build_system(robot, full, friction=True, armature=True)
    prep = system.prepared
    rows = prep.rows
    Z = system.data_matrix()  # the kept rows
    n, p = system.n, system.p
    t = prep.t[rows]
    trim = float(prep.settings["trim_s"])
    train = t < train_end - trim
    test = (t >= held[0]) & (t <= held[1])
    q = prep.filter(prep.q)[rows]
    q_mean = q[train].mean(axis=0)

    def design(sel: np.ndarray, spring: bool) -> tuple[np.ndarray, np.ndarray]:
        m = int(sel.sum())
        A = np.zeros((m * n, p + (n if spring else 0)))
        b = np.zeros(m * n)
        for j in range(n):
            block = slice(j * m, (j + 1) * m)
            for c in np.flatnonzero((system.z_joint == j) & (system.z_param >= 0)):
                A[block, system.z_param[c]] += Z[sel, c]
            b[block] = Z[sel, np.flatnonzero((system.z_joint == j) & (system.z_param < 0))[0]]
            if spring:
                A[block, p + j] = q[sel, j] - q_mean[j]
        return A, b

    def heldout(x: np.ndarray, spring: bool) -> np.ndarray:
        A, b = design(test, spring)
        r = lowpass((b - A @ x).reshape(n, -1).T, fs=float(prep.fs), cutoff=cutoff, order=4)
        edge = round(trim * float(prep.fs))
        return np.sqrt(np.mean(r[edge : len(r) - edge : step] ** 2, axis=0))

    cols = system.columns
    names = list(cols.names)
    rms, notes = {}, []
    for spring in (False, True):
        A, b = design(train, spring)
        x_u = np.linalg.lstsq(A, b, rcond=None)[0]
        R = np.linalg.qr(A, mode="r")
        if spring:  # the springs are no body's parameters: eliminate them (Schur complement), refit after
            H = R.T @ R
            back = np.linalg.solve(H[p:, p:], H[p:, :p])
            R = np.linalg.cholesky(H[:p, :p] - H[:p, p:] @ back).T
        phi, _ = consistent_solution(robot, cols, x_u[:p], R, 1.0)
        x_c = x_u.copy()
        x_c[:p] = cols.P @ phi
        if spring:
            x_c[p:] = x_u[p:] - back @ (x_c[:p] - x_u[:p])
        tag = "+spring" if spring else ""
        rms["ols+lin" + tag], rms["consistent" + tag] = heldout(x_u, spring), heldout(x_c, spring)
        arm = [x_u[names.index(f"ia{j + 1}")] if f"ia{j + 1}" in names else np.nan for j in range(n)]
        notes.append(f"unconstrained armature{tag} (kg m^2): {np.round(arm, 3).tolist()}")
        if spring:
            notes.append(f"springs k_j of the consistent fit (N m/rad): {np.round(x_c[p:], 3).tolist()}")
    corr = [float(np.corrcoef(q[train, j], prep.ddq[rows][train, j])[0, 1]) for j in range(n)]
    notes.append(f"corr(q_j, ddq_j) over the training rows: {np.round(corr, 2).tolist()}")
    print("\nconsistent links on a linear model (OLS, linear friction), held out, ratio to ols+lin:")
    base = rms["ols+lin"]
    for label, v in rms.items():
        print(f"{label:<20}" + "".join(f"{x:>8.3f}" for x in v / base) + f"   max {np.max(v / base):.3f}")
    for note in notes:
        print("  " + note)


def figaroh_rows(example, python, train_end, full, score) -> dict[str, np.ndarray]:
    """FIGAROH's TX40 example identified on the training rows and scored as dynid's models are (see the
    module docstring): ``{"figaroh": rms, "fig+hook": rms}``, or {} (said) without its example."""
    if not example:
        print("FIGAROH: quoted (give --figaroh-example DIR and --figaroh-python PY to run it on the split here)")
        return {}
    import subprocess
    import tempfile

    script = Path(__file__).with_name("_figaroh_tx40.py")
    out: dict[str, np.ndarray] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for label, flags in (("figaroh", ()), ("fig+hook", ("--coupled",))):
            path = Path(tmp, f"{label}.npz")
            run = subprocess.run(
                [python, str(script), str(example), str(path), "--train-end", str(train_end), *flags],
                capture_output=True, text=True,
            )  # fmt: skip
            if run.returncode != 0:
                print(f"FIGAROH ({label}) failed: {run.stderr.strip().splitlines()[-1:]}")
                return out  # the variant that ran, if one did (none: the quoted figures)
            print(run.stdout.strip())
            z = np.load(path)
            rows, tau = z["rows"], z["tau"]
            gap = float(np.max(np.abs(z["tau_measured"] - full.tau[rows])))
            if gap > 1e-9 * max(1.0, float(np.max(np.abs(full.tau)))):
                print(f"FIGAROH ({label}) reads another torque than the recording's (max gap {gap:.3g} N m): not scored")
                return out
            out[label] = score(full.t[rows], tau)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--robot", choices=sorted(SETUPS), default="panda")
    parser.add_argument(
        "--spring", action="store_true", help="also what consistent links cost a linear model (spring_check)"
    )
    parser.add_argument(
        "--figaroh-example",
        metavar="DIR",
        help="TX40: figaroh-examples' examples/staubli_tx40 folder, to run FIGAROH on the split in this run",
    )
    parser.add_argument(
        "--figaroh-python", metavar="PY", default=sys.executable, help="the Python that has figaroh installed"
    )
    args = parser.parse_args()
    setup = SETUPS[args.robot]

    from dynid.data.adapters import load_recording, recording_model_path
    from dynid.data.preparation import Preprocessing, prepare
    from dynid.data.preprocess import lowpass
    from dynid.identify.model import identify
    from dynid.symbolic import load_robot

    warnings.simplefilter("ignore")
    urdf = str(recording_model_path(setup["recording"]))
    robot = load_robot(urdf)
    if "heldout_run" in setup:  # two runs: the held-out one is scored whole
        from dynid.data.adapters import load_kuka_lwr4

        train = load_kuka_lwr4(run=setup["train_run"])
        full = load_kuka_lwr4(run=setup["heldout_run"])
        split_t = full.t[0]
    elif "split_s" in setup:
        full = load_recording(setup["recording"])
        split_t = full.t[0] + setup["split_s"]
        train = full.select_rows(np.flatnonzero(full.t < split_t))
    else:
        full = load_recording(setup["recording"])
        a, b = setup["train"]
        train = full.select_rows(np.arange(a, b))
        split_t = full.t[setup["heldout"][0]]
    t_end = full.t[setup["heldout"][1] - 1] if "heldout" in setup else full.t[-1]

    # the raw torque on the uniform grid (resampled if the stamps are irregular, nothing else)
    raw = prepare(full, Preprocessing(cutoff=None, trim=0.0))
    t_grid, tau_raw = raw.t, raw.tau
    held = (t_grid >= split_t) & (t_grid <= t_end)
    idx = np.flatnonzero(held)
    fs = 1.0 / np.median(np.diff(t_grid))

    def score(t: np.ndarray, tau: np.ndarray) -> np.ndarray:
        if len(t) != len(t_grid) or np.max(np.abs(t - t_grid)) > 1e-9:
            tau = np.column_stack([np.interp(t_grid, t, tau[:, j]) for j in range(tau.shape[1])])
        pred = lowpass(tau[idx], fs=fs, cutoff=setup["cutoff"], order=4)
        ref = lowpass(tau_raw[idx], fs=fs, cutoff=setup["cutoff"], order=4)
        th = t_grid[idx]
        keep = (th >= th[0] + setup["trim"]) & (th <= th[-1] - setup["trim"])
        keep &= np.arange(len(th)) % setup["step"] == 0
        return np.sqrt(np.mean((pred[keep] - ref[keep]) ** 2, axis=0))

    rows: dict[str, np.ndarray] = {}
    print(
        f"{args.robot}: {train.m} training samples ({train.duration:.2f} s), held out {split_t:.3f}..{t_end:.3f} s; "
        f"scoring: raw torque and predictions through {setup['cutoff']:g} Hz zero-phase (order 4), "
        f"{setup['trim']} s trimmed, every {setup['step']} sample(s)",
        flush=True,
    )
    start = time.perf_counter()
    default = identify(robot, train)
    t_default = time.perf_counter() - start
    start = time.perf_counter()
    ols = identify(robot, train, method="ols", friction="linear", gmm="off")
    t_ols = time.perf_counter() - start
    t, phys, total = model_parts(default, full)
    rows["defaults"] = score(t, total)
    rows["phys"] = score(t, phys)
    t, _, total = model_parts(ols, full)
    rows["ols+lin"] = score(t, total)
    # the same flags without the description's prior (reference weight 0: the earlier default)
    ols0 = identify(robot, train, method="ols", friction="linear", gmm="off", reference_weight=0.0)
    t, _, total = model_parts(ols0, full)
    rows["ols+lin/0"] = score(t, total)
    start = time.perf_counter()
    t, total = plain_least_squares(urdf, train, full)
    t_plain = time.perf_counter() - start
    rows["plain"] = score(t, total)
    extra: tuple[str, ...] = ()
    if args.robot == "tx40":
        from dynid.data.adapters import recording_robot

        wrist = recording_robot("tx40")
        t, _, total = model_parts(identify(wrist, train), full)
        rows["wrist"] = score(t, total)
        # and with the friction of joint 6's output stage, which motor 6 drives (on dq6, felt by 5 and 6)
        t, _, total = model_parts(identify(wrist, train, effects="coupled_friction@5+6:mix=0"), full)
        rows["wrist+out"] = score(t, total)
        t, _, total = model_parts(identify(robot, train, effects="coupled_friction@5+6"), full)
        rows["+cfric"] = score(t, total)
        extra = ("wrist", "wrist+out", "+cfric")
    if args.robot == "panda":
        t, tau = gaz_reference(urdf, full)
        rows["ref"] = score(t, tau)
        ref_label = "Gaz et al. 2019 (URDF + Table I friction, pin.rnea)"
    elif args.robot == "tx40":
        peer = figaroh_rows(args.figaroh_example, args.figaroh_python, setup["train"][1], full, score)
        if "figaroh" in peer:
            rows.update(peer)
            rows["ref"] = peer["figaroh"]
            extra = (*extra, *(["fig+hook"] if "fig+hook" in peer else []))
            ref_label = "FIGAROH 1.0.2's TX40 example, run on the split here (figaroh; fig+hook: its wrist hook)"
        else:
            rows["ref"] = FIGAROH_TX40
            ref_label = "FIGAROH 0.2.4 (quoted)"
    else:
        rows["ref"] = rows["plain"]
        ref_label = "the plain least-squares fit above (no published model for this recording)"

    n = robot.n
    print(f"identify: defaults {t_default:.1f} s, ols+lin {t_ols:.1f} s, plain least squares {t_plain:.1f} s")
    print(f"preprocessing of the defaults: {default.preprocessing}")
    fig = default.figures()
    print(
        f"default model: training RMS link+friction {np.round(fig['rms_layers']['friction'], 3).tolist()}, "
        f"full {np.round(fig['rms_layers']['gmm'], 3).tolist()}"
    )
    check = fig.get("physical_check")
    if check:
        print(
            f"physical check: {check['kept']}; ratios {np.round(check['ratio'], 2).tolist()}, "
            f"shares {np.round(check.get('share', []), 3).tolist()}"
        )
    print(f"bounds held at 0: {fig.get('bounds', {}).get('active')}")
    cons = fig.get("consistency")
    if cons:
        rise = cons.get("rms_rise")
        print(
            f"link inertias: held at the consistency bound on links {cons['at_bound']}, "
            f"{cons['mahalanobis']:.3g} std from the unconstrained estimate"
            + ("" if rise is None else f", training RMS x{np.round(rise, 3).tolist()}")
        )
    for note in fig.get("notes", []):
        print(f"  note: {note}")
    print(f"\nheld-out RMS (N m); reference: {ref_label}")
    head = f"{'model':<10}" + "".join(f"{'j' + str(j + 1):>8}" for j in range(n)) + f"{'mean':>8}"
    print(head)
    for label in ("defaults", "phys", "ols+lin", "ols+lin/0", "plain", *extra, "ref"):
        v = rows[label]
        print(f"{label:<10}" + "".join(f"{x:>8.3f}" for x in v) + f"{np.mean(v):>8.3f}")
    print("ratios")
    pairs = [
        ("defaults", "ref"),
        ("defaults", "ols+lin"),
        ("defaults", "plain"),
        ("phys", "ols+lin"),
        ("defaults", "phys"),
        *((e, "ref") for e in extra if e != "fig+hook"),
        *((e, "fig+hook") for e in ("defaults", "wrist", "wrist+out") if "fig+hook" in rows),
    ]
    for num, den in pairs:
        r = rows[num] / rows[den]
        label = f"{num}/{den}"
        print(
            f"{label:<10}" + "".join(f"{x:>8.2f}" for x in r[:n]) + f"   below 1 on {int(np.sum(r < 1))}/{n}"
        )
    urdf_mass = robot.params.reshape(-1, 10)[:, 0]
    print("\nlink masses (kg): the URDF's and the identified bodies' (what dynid export writes)")
    print(f"{'URDF':<10}" + "".join(f"{x:>8.2f}" for x in urdf_mass) + f"{urdf_mass.sum():>8.2f}")
    for label, model in (("defaults", default), ("ols+lin", ols), ("ols+lin/0", ols0)):
        std = model.standard_params
        if std is None:
            continue
        mass = std[:, 0]
        heavy = urdf_mass >= 0.2
        inside = np.sum((mass[heavy] >= 0.5 * urdf_mass[heavy]) & (mass[heavy] <= 2 * urdf_mass[heavy]))
        print(
            f"{label:<10}" + "".join(f"{x:>8.2f}" for x in mass) + f"{mass.sum():>8.2f}"
            + f"   total x{mass.sum() / urdf_mass.sum():.2f}; {inside}/{int(heavy.sum())} links in [0.5, 2]x"
        )
    prior = default.info.get("prior")
    if prior:
        print(f"prior of the defaults: weight {prior['weight']:g} ({prior['rule']})")
    if args.spring:
        spring_check(robot, full, split_t, (split_t, t_end), setup["cutoff"], setup["step"])


if __name__ == "__main__":
    main()
