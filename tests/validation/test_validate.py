"""Tests of the validation engine and of ``dynid validate``."""

from __future__ import annotations

import csv
import inspect
import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from dynid.cli import main
from dynid.data.dataset import Dataset
from dynid.data.files import load_dataset, save_dataset
from dynid.data.preparation import Preprocessing, prepare
from dynid.exceptions import DataError, IdentificationWarning, ModelFileError, ShapeError, UsageError
from dynid.identify.model import load_model
from dynid.symbolic.robot import load_robot
from dynid.validation import plots, report
from dynid.validation import validate as validate_module
from dynid.validation.metrics import torque_metrics
from dynid.validation.validate import (
    compare,
    nominal_model,
    reference_noise_floor,
    validate,
    write_predictions,
)
from tests.validation.cases import PERIOD, simulated_case


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    return simulated_case(tmp_path_factory.getbasetemp())


@pytest.fixture(scope="module")
def heldout(case):
    return load_dataset(case.heldout)


@pytest.fixture(scope="module")
def full(case):
    return load_model(case.full)


@pytest.fixture(scope="module")
def result(full, heldout):
    return validate(full, heldout, label="full")


# ---------------------------------------------------------------------------- the engine
def test_layers_add_up_to_the_models_own_prediction(full, heldout, result):
    np.testing.assert_allclose(result.tau_pred, full.predict(heldout), rtol=0, atol=1e-9)
    np.testing.assert_allclose(
        result.tau_link + result.tau_friction + result.tau_gmm, result.tau_pred, atol=1e-12
    )
    prep = full.prepare(heldout)
    np.testing.assert_array_equal(result.tau, prep.tau_reference)
    assert result.reference == prep.reference == "filtered, decimated and trimmed"
    assert result.has_gmm == bool(full.gmr.active_.any())
    np.testing.assert_allclose(result.residual_before_gmm - result.residual, result.tau_gmm, atol=1e-12)


def test_figures_are_the_metrics_of_the_compared_signals(result):
    expected = torque_metrics(result.tau, result.tau_pred)
    figures = result.figures()
    for key in ("rms", "nrms", "r2", "max_error"):
        np.testing.assert_allclose(figures[key], expected[key], rtol=1e-12)
    assert figures["rms_mean"] == pytest.approx(float(np.mean(expected["rms"])), rel=1e-12)
    assert {"rms", "rms_mean", "nrms", "r2", "noise_floor", "reference"} <= figures.keys()
    json.dumps(figures, allow_nan=False)  # JSON-ready: no NaN, no inf, no arrays


def test_noise_floor_uses_the_periods_the_sidecar_names(result):
    # V.csv repeats a 5 s trajectory twice; its sidecar says so.
    assert result.noise.method == "periods"
    assert "2 periods of 5 s" in result.noise.detail
    assert np.all(result.noise.std > 0)
    # No model predicts below the noise floor (here the model is good but not perfect).
    assert np.all(np.asarray(result.metrics["rms"]) > result.noise.std)


def _noisy_sine(rng, *, fs=1000.0, seconds=12.0, sigma=(0.05, 0.2), period=None):
    t = np.arange(int(seconds * fs)) / fs
    q = np.column_stack([0.3 * np.sin(2 * np.pi * t / 3.0), 0.2 * np.cos(2 * np.pi * t / 4.0)])
    clean = np.column_stack(
        [np.sin(2 * np.pi * t / (period or 3.0)), 2 * np.cos(2 * np.pi * t / (period or 4.0))]
    )
    noise = rng.standard_normal(clean.shape) * np.asarray(sigma)
    return t, q, clean, noise


@pytest.mark.parametrize("period", [None, 3.0])
def test_noise_floor_of_a_filtered_torque_is_the_filtered_noise(rng, period):
    t, q, clean, noise = _noisy_sine(rng, period=period)
    ds = Dataset(t, q, clean + noise)
    prep = prepare(ds, Preprocessing(cutoff=20.0, decimate=2))
    floor = reference_noise_floor(prep, period=period)
    assert floor.method == ("periods" if period else "spectrum")
    # What the noise alone becomes through the same filter, trimming and decimation.
    truth = np.std(prep.filter(noise)[prep.rows], axis=0)
    np.testing.assert_allclose(floor.std, truth, rtol=0.15)


def test_a_robot_playing_the_excite_csv_gets_its_floor_from_the_periods(ur5):
    # The CSV of dynid excite is a rest, an approach, three periods, a retreat and a rest: the run as a
    # whole does not repeat, its middle does.  The floor comes from that stretch (it fell back to the
    # spectrum's lower bound before) and agrees with the floor of the same periods recorded alone.
    from dynid.optim.approach import executable_trajectory
    from dynid.sim.cases import case_excitation
    from dynid.sim.simulator import simulate
    from dynid.validation.noise import measure_noise, repeating_stretch

    exc = case_excitation(ur5, 3, base_freq=0.2)  # 5 s period
    played = executable_trajectory(ur5, exc, rate=500.0, periods=3, rest=2.0)
    pre = Preprocessing(cutoff=20.0)
    prep = prepare(simulate(ur5, played, friction="linear", seed=5).to_dataset(), pre)
    floor = measure_noise(prep)
    assert floor.method == "periods" and "the stretch that repeats" in floor.detail, floor.detail
    alone = measure_noise(
        prepare(simulate(ur5, exc, duration=15.0, friction="linear", seed=6).to_dataset(), pre)
    )
    assert alone.method == "periods"
    # Within three standard errors of the two floors' variances (about 5 % and 8 % here).
    tol = 3 * np.hypot(floor.rel_se, alone.rel_se)
    assert np.all(np.abs(floor.std**2 / alone.std**2 - 1) < tol), (floor.std / alone.std, tol)
    # The stretch lies within the excitation (the approach's and the retreat's torque differs), and
    # spans nearly all of its three periods.
    a, b, period = repeating_stretch(prep.q, prep.fs, ddq=prep.ddq)
    excitation = next(s for s in played.meta["segments"] if s["kind"] == "excitation")
    start, stop = excitation["start"], excitation["start"] + excitation["duration"]
    assert period == pytest.approx(5.0, abs=2 / prep.fs)
    assert start - 0.01 <= prep.t[a] and prep.t[b - 1] <= stop + 0.01
    assert prep.t[b - 1] - prep.t[a] > 2.8 * period


def test_the_periodic_deviation_of_a_played_excitation_is_its_noise(ur5):
    # A robot playing the CSV of dynid excite (rest, approach, three periods, retreat, rest): the torque's
    # deviation from its mean over the periods holds the noise's variance (as the floor measures it), and
    # none of the motion's torque.
    from dynid.optim.approach import executable_trajectory
    from dynid.sim.cases import case_excitation
    from dynid.sim.simulator import simulate
    from dynid.validation.noise import measure_noise, periodic_deviation

    exc = case_excitation(ur5, 3, base_freq=0.2)
    played = executable_trajectory(ur5, exc, rate=500.0, periods=3, rest=2.0)
    pre = Preprocessing(cutoff=20.0)
    prep = prepare(simulate(ur5, played, friction="linear", seed=5).to_dataset(), pre)
    dev, start = periodic_deviation(prep)
    assert dev.shape[1] == 6 and dev.shape[0] > 2.8 * 5.0 * prep.fs  # nearly all of the three periods
    floor = measure_noise(prep)
    # The same periods as the floor's spread: their variances agree to a per cent or two (the floor pools
    # the squares over the degrees of freedom, the deviation scales each phase).
    np.testing.assert_allclose(np.mean(dev**2, axis=0), floor.std**2, rtol=0.02)
    # The motion's torque is 2-3 orders of magnitude larger than the noise; none of it is left.
    tau = prep.filter(prep.tau)[start : start + dev.shape[0]]
    assert np.all(np.std(dev, axis=0) < 0.05 * np.std(tau, axis=0))


def test_an_aperiodic_run_has_no_periodic_deviation(ur5):
    from dynid.diagnosis.field_cases import min_jerk_motion
    from dynid.sim.simulator import simulate
    from dynid.validation.noise import periodic_deviation

    motion = min_jerk_motion(ur5, np.random.default_rng(3), 20.0)
    prep = prepare(
        simulate(ur5, motion, duration=20.0, friction="linear", seed=3).to_dataset(),
        Preprocessing(cutoff=20.0),
    )
    assert periodic_deviation(prep) is None


def test_an_aperiodic_run_with_rests_has_no_stretch_that_repeats(ur5):
    # Minimum-jerk moves between random waypoints, with rests: a rest repeats itself, but no motion does.
    from dynid.diagnosis.field_cases import min_jerk_motion
    from dynid.sim.simulator import simulate
    from dynid.validation.noise import measure_noise, repeating_stretch

    motion = min_jerk_motion(ur5, np.random.default_rng(3), 20.0)
    prep = prepare(
        simulate(ur5, motion, duration=20.0, friction="linear", seed=3).to_dataset(),
        Preprocessing(cutoff=20.0),
    )
    assert repeating_stretch(prep.q, prep.fs, ddq=prep.ddq) is None
    assert measure_noise(prep).method == "spectrum"


def test_noise_floor_of_a_raw_torque_is_its_white_level(rng):
    t, q, clean, noise = _noisy_sine(rng)
    prep = prepare(Dataset(t, q, clean + noise, dq=q * 0, ddq=q * 0), Preprocessing(cutoff=None))
    assert prep.reference == "raw"
    floor = reference_noise_floor(prep)
    np.testing.assert_allclose(floor.std, [0.05, 0.2], rtol=0.1)


def test_a_floor_that_cannot_be_measured_is_reported_as_such(full, heldout):
    short = heldout.select_rows(np.arange(2000))  # 2 s: under one period, too short for the spectrum
    result = validate(full, short)
    figures = result.figures()
    assert result.noise.method == "unmeasured"
    assert "cannot measure the noise floor" in figures["noise_floor_detail"]
    assert figures["noise_floor"] == [None] * 6 and figures["noise_floor_mean"] is None
    assert figures["rms_over_noise"] == [None] * 6
    json.dumps(figures, allow_nan=False)
    from dynid.validation.report import gmm_changed, render_report

    report = render_report([result])  # every figure drawn; the GMM's only where it changed the prediction
    expected = 4 if gmm_changed([result]) is not None else 3
    assert report.html.count("data:image/png;base64,") == len(report.figures) == expected


def test_urdf_baseline_predicts_a_robot_that_is_its_urdf(tmp_path):
    from dynid.optim.excitation import ExcitationProblem
    from dynid.sim.simulator import simulate
    from dynid.symbolic import load_robot

    robot = load_robot("ur5")
    traj = ExcitationProblem(robot=robot, harmonics=4, base_freq=0.2).random_trajectory(
        np.random.default_rng(1)
    )
    ds = simulate(robot, traj, friction="linear", noise="off", duration=5.0).to_dataset()
    model = nominal_model(robot, ds)
    assert model.method == "urdf" and model.friction.model == "linear"
    result = validate(model, ds)
    assert np.all(np.asarray(result.metrics["r2"]) > 0.998)
    # Without sensor noise the measured floor is (almost) nothing.
    assert np.all(result.noise.std < 1e-3 * np.std(result.tau, axis=0))


def test_compare_refuses_models_prepared_differently(case, heldout):
    from dynid.identify.model import identify

    robot = load_model(case.full).robot
    other = identify(
        robot, load_dataset(case.train), method="ols", friction="linear", gmm="off"
    )  # no decimation
    a = validate(load_model(case.ols), heldout, label="ols")
    b = validate(other, heldout, label="undecimated")
    with pytest.raises(ShapeError, match="'undecimated' is compared on another torque than 'ols'"):
        compare([a, b])


def test_predictions_file_holds_the_compared_signals(result, tmp_path):
    path = write_predictions(result, tmp_path / "P.csv")
    with path.open() as f:
        header = next(csv.reader(f))
    n = result.n
    assert header == [
        "t",
        *(f"tau_{j}" for j in range(1, n + 1)),
        *(f"tau_pred_{j}" for j in range(1, n + 1)),
    ]
    table = np.loadtxt(path, delimiter=",", skiprows=1)
    np.testing.assert_allclose(table[:, 0], result.t, rtol=1e-9)
    np.testing.assert_allclose(table[:, 1 : n + 1], result.tau, rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(table[:, n + 1 :], result.tau_pred, rtol=1e-8, atol=1e-12)


# ---------------------------------------------------------------------------- bad input (API)
def test_data_of_another_robot_is_refused(full, tmp_path, rng):
    t = np.arange(2000) / 1000.0
    ds = Dataset(t, 0.1 * rng.standard_normal((2000, 7)), rng.standard_normal((2000, 7)))
    with pytest.raises(ModelFileError, match=r"identified for 'ur5' \(6 joints\) but the data has 7 joints"):
        validate(full, ds)


def test_simulated_data_of_another_robot_is_refused_by_its_sidecar(case, full, tmp_path):
    data = tmp_path / "V10.csv"
    shutil.copy(case.heldout, data)
    side = json.loads(Path(str(case.heldout) + ".truth.json").read_text())
    side.update(robot="ur10", source="ur10")  # the same joint names as the UR5's, other bodies
    side["params"]["nominal"] = load_robot("ur10").params.tolist()
    Path(str(data) + ".truth.json").write_text(json.dumps(side))
    with pytest.raises(ModelFileError, match=r"but V10.csv was simulated on 'ur10'"):
        validate(full, load_dataset(data), info={"model_file": "M.json"})


@pytest.mark.parametrize("other", ["kinova", "ur10"])
@pytest.mark.parametrize("command", ["identify", "validate", "export"])
def test_commands_refuse_data_simulated_on_another_robot(case, tmp_path, capsys, command, other):
    """identify took a recording its sidecar says was simulated on another arm of as many joints and fitted
    it (validate refused it): every command that reads data for a robot now refuses it, in one sentence, by
    one rule: another description (source and name) with other joint names (a Kinova's) or other nominal
    bodies (a UR10's, whose joint names are the UR5's)."""
    data = tmp_path / "V10.csv"
    shutil.copy(case.heldout, data)
    side = json.loads(Path(str(case.heldout) + ".truth.json").read_text())
    if other == "kinova":
        side.update(robot="kinova", source="kinova.urdf", joint_names=[f"j2s6s200_joint_{k}" for k in range(1, 7)])
    else:
        side.update(robot="ur10", source="ur10")
        side["params"]["nominal"] = load_robot("ur10").params.tolist()
    Path(str(data) + ".truth.json").write_text(json.dumps(side))
    out = tmp_path / ("M.urdf" if command == "export" else "M.json")
    option = "heldout" if command == "export" else "data"
    argv = {
        "identify": ["identify", "--robot", "ur5", "--data", str(data), "--out", str(out), "--method", "ols"],
        "validate": ["validate", "--model", str(case.full), "--data", str(data)],
        "export": ["export", "--model", str(case.full), "--format", "urdf", "--heldout", str(data), "--out", str(out)],
    }[command]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert f"--{option} V10.csv was simulated on '{other}' (its V10.csv.truth.json says so), not on 'ur5'" in err
    assert "Traceback" not in err and not out.exists()


def test_a_copy_of_the_description_keeps_its_simulated_data(case, tmp_path):
    """The same bodies and joint names under another file and robot name: the same robot, its data read."""
    from dynid.data.files import simulated_on
    from dynid.symbolic.robot import example_robot_data_dir

    copy = tmp_path / "arm.urdf"
    shutil.copy(example_robot_data_dir() / "ur_description" / "urdf" / "ur5_robot.urdf", copy)
    robot = load_robot(copy)
    assert robot.name == "arm" and robot.source != "ur5"
    assert simulated_on(robot, load_dataset(case.heldout)) is None
    assert simulated_on(load_robot("ur10"), load_dataset(case.heldout)) == "ur5"


def test_a_reader_that_stops_does_not_stop_the_command(case, tmp_path):
    """dynid validate ... | head -1: the reader goes, the command writes its report to the end and exits 0
    (a BrokenPipeError on the second line had ended it with 'the system refused an operation')."""
    import os
    import subprocess
    import sys

    report = tmp_path / "R.html"
    r, w = os.pipe()
    proc = subprocess.Popen(
        [sys.executable, "-m", "dynid", "validate", "--model", str(case.full), "--data", str(case.heldout),
         "--report", str(report), "--quiet"],
        stdout=w, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    os.close(w)
    os.close(r)  # the reader is gone before the first line
    _, err = proc.communicate(timeout=600)
    assert proc.returncode == 0, err
    assert "error" not in err and report.is_file() and report.stat().st_size > 10_000


def test_too_short_data_is_refused(full, heldout):
    short = heldout.select_rows(np.arange(100))
    with pytest.raises(
        DataError, match=r"trimming \d+ samples from both ends leaves 0 of run 0 \(100 samples\)"
    ):
        validate(full, short)


def test_validate_needs_a_model(heldout):
    with pytest.raises(UsageError, match="model is a str; give an IdentifiedModel"):
        validate("M.json", heldout)


# ---------------------------------------------------------------------------- the command
def test_validate_command_writes_what_it_prints(case, tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    argv = [
        "validate",
        "--model",
        str(case.full),
        "--compare",
        str(case.ols),
        "--data",
        str(case.heldout),
        "--predictions",
        str(out / "P.csv"),
        "--json",
        str(out / "F.json"),
    ]
    assert main(argv) == 0
    text = capsys.readouterr().out
    figures = json.loads((out / "F.json").read_text())
    assert figures["noise_floor_method"] == "periods"
    assert [m["label"] for m in figures["models"]] == ["M", "M_ols"]
    assert figures["models"][0]["rms"] == figures["rms"]
    # The full method beats OLS on the held-out run.
    assert figures["models"][0]["rms_mean"] < figures["models"][1]["rms_mean"]
    # The predictions file reproduces the RMS of the JSON.
    table = np.loadtxt(out / "P.csv", delimiter=",", skiprows=1)
    n = len(figures["rms"])
    rms = np.sqrt(np.mean((table[:, 1 : n + 1] - table[:, n + 1 :]) ** 2, axis=0))
    np.testing.assert_allclose(rms, figures["rms"], rtol=1e-6)
    assert f"{figures['rms_mean']:.4g}" in text
    assert "noise floor: periods" in text
    assert sorted(p.name for p in out.iterdir()) == ["F.json", "P.csv"]


def test_compared_models_warnings_say_which_model(case, tmp_path):
    """With --compare, a model's warning (here its prediction leaving its training torque's range) names the
    model file it is about; the other model says nothing."""
    ols = Path(case.ols)
    for suffix in (".json", ".npz"):
        shutil.copy(ols.with_suffix(suffix), tmp_path / ols.with_suffix(suffix).name)
    moved = tmp_path / ols.name
    doc = json.loads(moved.read_text())
    doc["torque_range"] = [[1e3, 1e3 + 1.0] for _ in doc["torque_range"]]  # every prediction far below it
    moved.write_text(json.dumps(doc))
    with pytest.warns(IdentificationWarning) as caught:
        assert main(["validate", "--model", str(case.full), "--compare", str(moved), "--data", str(case.heldout)]) == 0
    said = [str(w.message) for w in caught if "training torque's range" in str(w.message)]
    assert len(said) == 1 and said[0].startswith(f"{ols.name}: the prediction leaves the training torque's range")
    assert "down to" in said[0]


def _run_fails(argv, capsys) -> str:
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    return err


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--report", "{tmp}/missing/R.html"], r"the folder '.*missing' of the report does not exist"),
        (["--report", "{tmp}/R.txt"], r"has the extension '.txt'; give a file name ending in .html"),
        (
            ["--predictions", "{tmp}/missing/P.csv"],
            r"the folder '.*missing' does not exist, so --predictions '.*P.csv' cannot be written",
        ),
        (
            ["--json", "{tmp}/missing/F.json"],
            r"the folder '.*missing' does not exist, so --json '.*F.json' cannot be written",
        ),
        (["--period", "-1"], r"--period is -1.0; give the period"),
    ],
)
def test_bad_output_paths_fail_before_any_work(case, tmp_path, capsys, extra, message):
    out = tmp_path / "out"
    out.mkdir()
    argv = ["validate", "--model", str(case.full), "--data", str(case.heldout)]
    argv += [a.format(tmp=out) for a in extra]
    argv += ["--predictions", str(out / "P.csv")] if "--predictions" not in extra else []
    err = _run_fails(argv, capsys)
    assert re.search(message, err), err
    assert err.startswith("dynid validate: error: ")
    assert not any(out.rglob("*")), "nothing may be written"


def test_model_of_another_robot_than_the_data(case, tmp_path, capsys, rng):
    t = np.arange(2000) / 1000.0
    data = save_dataset(
        Dataset(t, 0.1 * rng.standard_normal((2000, 7)), rng.standard_normal((2000, 7))), tmp_path / "V7.csv"
    )
    report = tmp_path / "R.html"
    err = _run_fails(
        ["validate", "--model", str(case.full), "--data", str(data), "--report", str(report)], capsys
    )
    assert re.search(
        r"M.json was identified for 'ur5' \(6 joints\) but V7.csv has 7 joints; validate a model", err
    )
    assert not report.exists()


def test_corrupt_model_file(case, tmp_path, capsys):
    bad = tmp_path / "bad.json"
    bad.write_text('{"format": "dynid-model", "version": 1, "robot": ')
    report = tmp_path / "R.html"
    err = _run_fails(
        ["validate", "--model", str(bad), "--data", str(case.heldout), "--report", str(report)], capsys
    )
    assert re.search(r"bad.json is not a readable dynid model file \(JSONDecodeError", err)
    assert not report.exists()


def test_model_whose_arrays_were_replaced(case, tmp_path, capsys):
    shutil.copy(case.full, tmp_path / "M.json")
    shutil.copy(case.ols.with_suffix(".npz"), tmp_path / "M.npz")
    err = _run_fails(["validate", "--model", str(tmp_path / "M.json"), "--data", str(case.heldout)], capsys)
    assert "M.npz is not the arrays file M.json was written with (checksum differs)" in err


# ---------------------------------------------------------------------------- API hygiene
def _documented(obj) -> set[str]:
    doc = inspect.getdoc(obj) or ""
    names: set[str] = set()
    for section in ("Parameters", "Attributes"):
        match = re.search(rf"^{section}\n-+\n(.*?)(?:\n\n[A-Z][a-z]+\n-+\n|\Z)", doc, flags=re.S | re.M)
        if match:
            for line in match.group(1).splitlines():
                if line and not line.startswith(" ") and " : " in line:
                    names.update(name.strip() for name in line.split(" : ")[0].split(","))
    return names


CASES = [
    (f"{module.__name__}.{name}", getattr(module, name))
    for module in (validate_module, report, plots)
    for name in module.__all__
    if inspect.isfunction(getattr(module, name)) or inspect.isclass(getattr(module, name))
]


@pytest.mark.parametrize(("name", "obj"), CASES, ids=[name for name, _ in CASES])
def test_every_argument_is_documented(name, obj):
    target = obj.__init__ if inspect.isclass(obj) else obj
    wanted = {
        p.name
        for p in inspect.signature(target).parameters.values()
        if p.name not in ("self", "cls") and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)
    }
    missing = wanted - _documented(obj)
    assert not missing, f"{name} does not document {sorted(missing)}"
    if inspect.isclass(obj):
        for attr, member in vars(obj).items():
            if inspect.isfunction(member) and not attr.startswith("_"):
                params = set(inspect.signature(member).parameters) - {"self"}
                assert params <= _documented(member), f"{name}.{attr} does not document {sorted(params)}"


def test_every_module_lists_its_public_names():
    for module in (validate_module, report, plots):
        for name in module.__all__:
            assert hasattr(module, name), f"{module.__name__}.__all__ names {name}, which does not exist"


def test_period_default_is_the_sidecars(heldout):
    from dynid.validation.validate import sidecar_period

    assert sidecar_period(heldout) == pytest.approx(PERIOD)


def test_a_joint_predicted_far_worse_than_its_mean_is_said_in_one_sentence(full, heldout, case, tmp_path):
    """A torque logged with the other sign (R^2 about -3 on that joint): the figures alone say it to nobody;
    one warning names the joint and the usual causes.  The data as recorded get no such line."""
    import warnings
    from dataclasses import replace

    from dynid.exceptions import DataWarning

    with warnings.catch_warnings():
        warnings.simplefilter("error", DataWarning)
        good = validate(full, heldout)
    assert np.all(good.metrics["r2"] > -1)
    tau = np.asarray(heldout.tau).copy()
    tau[:, 1] *= -1.0
    flipped = replace(heldout, tau=tau)
    with pytest.warns(DataWarning, match=r"predicts joint\(s\) 2 worse than their mean torque would, by far") as caught:
        bad = validate(full, flipped)
    assert bad.metrics["r2"][1] < -1 and f"R^2 {bad.metrics['r2'][1]:.3g}" in str(caught[0].message)
    assert "joint order" in str(caught[0].message) and "dynid diagnose" in str(caught[0].message)
    save_dataset(flipped, tmp_path / "V.csv")
    with pytest.warns(DataWarning) as caught:  # main(argv) keeps pytest's capture; the console prints one line
        assert main(["validate", "--model", str(case.full), "--data", str(tmp_path / "V.csv"), "--quiet"]) == 0
    said = [str(w.message) for w in caught if "worse than their mean torque would" in str(w.message)]
    assert len(said) == 1 and said[0].startswith("M.json predicts joint(s) 2 "), said
