"""Bad inputs that exited 0 silently, held: each is now one sentence and exit 2, or a one-line warning.

The contract is that of ``tests/commands/test_bad_inputs.py``: a refusal is exit code 2, one line on stderr naming
what was expected, what came and the fix, no traceback, every file of the folder byte-identical and
nothing added.  Where the data cannot tell (a period the recording is too short to confirm, a torque
channel stuck over part of a run, angles somewhat past the limits, a model scored on its own training
data), the command finishes (exit 0) and warns in one :class:`~dynid.exceptions.DataWarning`.

The cases: torques in mN m read with the robot at hand (validate, diagnose, fleet, ROS 2 bags); DH
tables with a prismatic limit in mm, a negative armature, gravity of 1e6 m/s^2; trajectory files whose
``harmonics`` / ``n_joints`` contradict their coefficients; a ``--period`` the recording does not have;
the training data given as held-out data; fleet manifests with a repeated row, a missing file, dates and
indices mixed for one robot; dead torque sensors and angles far beyond the joint limits.
"""

from __future__ import annotations

import dataclasses
import json
import os
import re
import shutil
import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from dynid.cli import main
from dynid.exceptions import DataError, DataWarning, ModelFileError, RobotModelError, UsageError
from dynid.symbolic.robot import load_robot
from tests.conftest import DH_TABLE
from tests.conftest import assert_refused as _assert_refused


def assert_refused(argv, folder, pattern, capsys):
    """The shared check, with the warnings raised on the way silenced."""
    return _assert_refused(argv, folder, pattern, capsys, ignore_warnings=True)


ROWS = 1100  # training run: 1.1 s at 1 kHz, enough for identify's trimming
HELD_SECONDS = 4.2  # held-out run: two periods of the 2 s excitation (base frequency 0.5 Hz)



# ---------------------------------------------------------------------- fixtures
@pytest.fixture(scope="module")
def base(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A UR5 trajectory (period 2 s), a short training run, a model fitted to it, a held-out run of two periods."""
    from dynid.data.files import load_dataset
    from dynid.identify.model import identify, save_model
    from dynid.optim.excitation import ExcitationProblem
    from dynid.sim.simulator import build_truth, simulate, write_simulation

    folder = tmp_path_factory.mktemp("fuzz-inputs")
    robot = load_robot("ur5")
    trajectory = ExcitationProblem(robot=robot, harmonics=2, base_freq=0.5).random_trajectory(
        np.random.default_rng(0)
    )
    trajectory.save(folder / "T.json")
    truth = build_truth(robot, friction="linear", truth_seed=0)
    for name, seed, seconds in (("D.csv", 1, (ROWS - 1) / 1000.0), ("V.csv", 2, HELD_SECONDS)):
        write_simulation(simulate(robot, trajectory, truth=truth, seed=seed, duration=seconds), folder / name)
        (folder / f"{name}.truth.json").unlink()  # the period comes from the data, not a sidecar
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = identify(robot, load_dataset(folder / "D.csv", 6), method="ols", friction="linear", gmm="off")
    save_model(model, folder / "M.json")
    (folder / "arm.toml").write_text(DH_TABLE)
    return folder


@pytest.fixture
def work(base: Path, tmp_path: Path) -> Path:
    """Copies of the good inputs and a pre-existing output (a copy of an input)."""
    for p in base.iterdir():
        (shutil.copytree if p.is_dir() else shutil.copy2)(p, tmp_path / p.name)
    shutil.copy2(base / "V.csv", tmp_path / "OUT.csv")
    return tmp_path






def assert_warned(argv: list[str], pattern: str, capsys: pytest.CaptureFixture[str]) -> str:
    """Run the command; assert exit 0 and exactly one DataWarning, matching ``pattern``."""
    capsys.readouterr()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        code = main(argv)
    err = capsys.readouterr().err
    assert code == 0, err
    texts = list(dict.fromkeys(str(w.message) for w in caught if issubclass(w.category, DataWarning)))
    assert len(texts) == 1, texts
    assert re.search(pattern, texts[0]), texts[0]
    assert "\n" not in texts[0]
    return texts[0]


def quiet_warnings(argv: list[str], capsys: pytest.CaptureFixture[str]) -> list[str]:
    """Run the command; assert exit 0; the DataWarnings it gave."""
    capsys.readouterr()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        code = main(argv)
    assert code == 0, capsys.readouterr().err
    return [str(w.message) for w in caught if issubclass(w.category, DataWarning)]


# ---------------------------------------------------------------------- helpers making bad inputs
def _table(folder: Path, name: str) -> tuple[list[str], np.ndarray]:
    header = (folder / name).read_text().splitlines()[0].split(",")
    return header, np.loadtxt(folder / name, delimiter=",", skiprows=1)


def _edited(folder: Path, source: str, target: str, edit: Callable[[list[str], np.ndarray], None]) -> str:
    """``target``: the dataset ``source`` with ``edit(header, table)`` applied to its numbers."""
    header, table = _table(folder, source)
    edit(header, table)
    np.savetxt(folder / target, table, delimiter=",", header=",".join(header), comments="", fmt="%.17g")
    return str(folder / target)


def _millinewton(folder: Path, source: str = "V.csv", target: str = "mNm.csv") -> str:
    def edit(header: list[str], table: np.ndarray) -> None:
        table[:, [k for k, h in enumerate(header) if h.startswith("tau_")]] *= 1e3

    return _edited(folder, source, target, edit)


def _column(header: list[str], name: str) -> int:
    return header.index(name)


def _dead(folder: Path) -> str:
    def edit(header: list[str], table: np.ndarray) -> None:
        table[:, _column(header, "tau_3")] = 1.5

    return _edited(folder, "V.csv", "dead.csv", edit)


def _stuck(folder: Path) -> str:
    def edit(header: list[str], table: np.ndarray) -> None:
        k, row = _column(header, "tau_3"), int(0.6 * len(table))
        table[row:, k] = table[row, k]  # the sensor stops updating for the last 40 % of the run

    return _edited(folder, "V.csv", "stuck.csv", edit)


def _beyond_limits(folder: Path) -> str:
    """q_1 of the UR5 (limits +-2 pi, a vertical axis: its offset changes no torque) raised to end at 9.3 rad,
    24 % of its range beyond its upper limit (but under 10 rad, where angles are taken for degrees)."""

    def edit(header: list[str], table: np.ndarray) -> None:
        k = _column(header, "q_1")
        table[:, k] += 9.3 - table[:, k].max()

    return _edited(folder, "V.csv", "beyond.csv", edit)


def _toml(folder: Path, name: str, old: str, new: str) -> str:
    text = DH_TABLE.replace(old, new)
    assert text != DH_TABLE
    (folder / name).write_text(text)
    return str(folder / name)


def _trajectory(folder: Path, name: str, **changes) -> str:
    data = json.loads((folder / "T.json").read_text())
    data.update(changes)
    (folder / name).write_text(json.dumps(data))
    return str(folder / name)


def _validate(f: Path, data: str, *extra: str) -> list[str]:
    return ["validate", "--model", str(f / "M.json"), "--data", data, "--json", str(f / "OUT.csv.json"), *extra]


def _diagnose(f: Path, data: str, heldout: str, *extra: str) -> list[str]:
    return ["diagnose", "--model", str(f / "M.json"), "--data", data, "--heldout", heldout,
            "--report", str(f / "R.html"), *extra]  # fmt: skip


def _simulate(f: Path, trajectory: str) -> list[str]:
    return ["simulate", "--robot", "ur5", "--trajectory", trajectory, "--out", str(f / "OUT.csv")]


def _manifest(f: Path, rows: str) -> list[str]:
    (f / "rec" / "r1").mkdir(parents=True, exist_ok=True)
    for date in ("2024-01-01", "2024-02-01"):
        shutil.copy2(f / "D.csv", f / "rec" / "r1" / f"{date}.csv")
    (f / "fleet.csv").write_text("path,robot,time\n" + rows)
    return ["fleet", "--robot", "ur5", "--data", str(f / "rec" / "**" / "*.csv"), "--manifest", str(f / "fleet.csv"),
            "--serial", "--out", str(f / "fleet")]  # fmt: skip


_TWO_ROWS = "rec/r1/2024-01-01.csv,r1,2024-01-01\nrec/r1/2024-02-01.csv,r1,2024-02-01\n"

MN_M = r"tau_\d is -?[\d.e+]+ N m at row \d+, more than 20 times the [\d.]+ N m the model of 'ur5' gives within " \
    r"its limits; give torques in N m \(not mN m or motor current\)"  # fmt: skip

CASES: list[tuple[str, Callable[[Path], list[str]], str]] = [
    # -- 1. torques in mN m, read with the robot at hand
    ("validate_mNm", lambda f: _validate(f, _millinewton(f)), rf"mNm\.csv: {MN_M}"),
    ("diagnose_data_mNm", lambda f: _diagnose(f, _millinewton(f, "D.csv"), str(f / "V.csv")), rf"mNm\.csv: {MN_M}"),
    ("diagnose_heldout_mNm", lambda f: _diagnose(f, str(f / "D.csv"), _millinewton(f)), rf"mNm\.csv: {MN_M}"),
    # -- 2. DH tables
    (
        "dh_prismatic_limit_in_mm",
        lambda f: ["info", "--robot", _toml(f, "mm.toml", "q_max = [2.8, 1.9, 0.3]", "q_max = [2.8, 1.9, 300.0]")],
        r"column 'joints\.q_max' of the table '.*mm\.toml' holds 300 for joint 3, a prismatic joint, beyond the "
        r"20 m of any arm; give metres \(it looks like mm\)",
    ),
    (
        "dh_revolute_limit_in_degrees",
        lambda f: ["info", "--robot", _toml(f, "deg.toml", "q_min = [-2.8,", "q_min = [-160.0,")],
        r"column 'joints\.q_min' of the table '.*deg\.toml' holds -160 for joint 1, a revolute joint, beyond the "
        r"12\.57 rad \(two turns\) of any arm; give radians",
    ),
    (
        "dh_negative_armature",
        lambda f: ["info", "--robot", _toml(f, "arm2.toml", "armature = [0.1, 0.08", "armature = [0.1, -0.08")],
        r"column 'links\.armature' of the table '.*arm2\.toml' holds -0\.08 for joint 2, but an armature is a rotor "
        r"inertia .*0 or more \(kg m\^2\)",
    ),
    (
        "dh_gravity_1e6",
        lambda f: ["info", "--robot", _toml(f, "g.toml", 'name = "my_arm"', 'name = "my_arm"\ngravity = [0, 0, -9.81e6]')],
        r"'gravity' in the table '.*g\.toml' is \[0, 0, -9\.81e\+06\], of magnitude 9\.81e\+06 m/s\^2, outside the 0 "
        r"to 100 m/s\^2 an arm is used in; give it in m/s\^2",
    ),
    # -- 3. trajectory files whose fields contradict their coefficients
    (
        "trajectory_harmonics_5",
        lambda f: _simulate(f, _trajectory(f, "H.json", harmonics=5)),
        r"the trajectory file '.*H\.json' states harmonics = 5, but its coefficients hold 2 rows of a and b \(one "
        r"per harmonic\); correct harmonics to 2",
    ),
    (
        "trajectory_n_joints_7",
        lambda f: _simulate(f, _trajectory(f, "N.json", n_joints=7)),
        r"states n_joints = 7, but its coefficients hold 6 values of c \(one per joint\); correct n_joints to 6",
    ),
    (
        "trajectory_harmonics_text",
        lambda f: _simulate(f, _trajectory(f, "S.json", harmonics="two")),
        r"states harmonics = 'two', but its coefficients hold 2 rows",
    ),
    (
        "trajectory_ragged_rows",
        lambda f: _simulate(f, _trajectory(f, "R.json", a=[[0.1, 0.2], [0.3]])),
        r"the field 'a' of the trajectory file '.*R\.json' is not a table of numbers \(rows of equal length\)",
    ),
    # -- 4. a period the recording does not have
    (
        "validate_period_one_sample",
        lambda f: _validate(f, str(f / "V.csv"), "--period", "0.001"),
        r"--period 0\.001 s is 1 sample of V\.csv, over which its angles hardly move \(they first move apart by a "
        r"tenth of their spread after [\d.]+ s\), so it cannot be the motion's period",
    ),
    (
        "validate_period_other",
        lambda f: _validate(f, str(f / "V.csv"), "--period", "1.37"),
        r"--period 1\.37 s does not fit V\.csv: its angles repeat every 2 s, and 1\.37 s is 0\.685 of those periods, "
        r"not a whole number; give --period 2 \(or a whole multiple of it\)",
    ),
    ("validate_period_inf", lambda f: _validate(f, str(f / "V.csv"), "--period", "inf"), r"--period is inf; give"),
    (
        "diagnose_period_0",
        lambda f: _diagnose(f, str(f / "D.csv"), str(f / "V.csv"), "--period", "0"),
        r"^dynid diagnose: error: --period is 0\.0; give the period of the motion in seconds \(> 0\)\.$",
    ),
    (
        "diagnose_period_one_sample",
        lambda f: _diagnose(f, str(f / "D.csv"), str(f / "V.csv"), "--period", "0.001"),
        r"--period 0\.001 s is 1 sample of V\.csv, over which its angles hardly move",
    ),
    # -- 5. the training data as held-out data
    (
        "diagnose_heldout_is_data",
        lambda f: _diagnose(f, str(f / "D.csv"), str(f / "D.csv")),
        r"--heldout .*D\.csv is the same file as --data, but the diagnosis measures the gap on data the model was "
        r"not fitted to .*; give another recording of the robot",
    ),
    (
        "diagnose_heldout_is_one_of_the_data",
        lambda f: ["diagnose", "--model", str(f / "M.json"), "--data", str(f / "V.csv"), str(f / "D.csv"),
                   "--heldout", str(f / "D.csv"), "--report", str(f / "R.html")],
        r"--heldout .*D\.csv is the same file as --data, but the diagnosis measures the gap on data the model was "
        r"not fitted to",
    ),
    (
        "diagnose_heldout_is_training_copy",
        lambda f: _diagnose(f, str(f / "V.csv"), str(shutil.copy2(f / "D.csv", f / "D2.csv"))),
        r"--heldout .*D2\.csv is the data .*M\.json was identified on, but the diagnosis measures the gap on data",
    ),
    # -- 6. fleet manifests
    (
        "manifest_repeated_row",
        lambda f: _manifest(f, _TWO_ROWS + "rec/r1/2024-01-01.csv,r1,2024-01-01\n"),
        r"line 4 of the manifest '.*fleet\.csv' names the recording 'rec/r1/2024-01-01\.csv' again \(line 2 names it "
        r"already\); give each recording one row",
    ),
    (
        "manifest_missing_file",
        lambda f: _manifest(f, _TWO_ROWS + "rec/r1/2024-03-01.csv,r1,2024-03-01\n"),
        r"line 4 of the manifest '.*fleet\.csv' names the recording 'rec/r1/2024-03-01\.csv', but there is no such "
        r"file .*; correct its path .* or drop the row",
    ),
    (
        "manifest_dates_and_indices",
        lambda f: _manifest(f, "rec/r1/2024-01-01.csv,r1,2024-01-01\nrec/r1/2024-02-01.csv,r1,7\n"),
        r"the robot 'r1' has recordings timed by ISO date \(line 2 of the manifest '.*fleet\.csv': '2024-01-01'\) "
        r"and by index \(line 3 of the manifest '.*': '7'\), which do not order",
    ),
    # -- 7. a dead torque sensor
    (
        "validate_dead_channel",
        lambda f: _validate(f, _dead(f)),
        r"dead\.csv: tau_3 holds 1\.5 N m in every one of its \d+ rows.*dead or unplugged",
    ),
]


@pytest.mark.parametrize(("case", "make", "pattern"), CASES, ids=[c[0] for c in CASES])
def test_bad_input_is_refused_in_one_sentence(
    work: Path, capsys: pytest.CaptureFixture[str], case: str, make, pattern: str
) -> None:
    assert_refused(make(work), work, pattern, capsys)


# ---------------------------------------------------------------------- 1. torque units, every reader
def test_the_api_reader_with_the_robot_refuses_torques_in_mn_m(base: Path, tmp_path: Path) -> None:
    from dynid.commands.common import read_dataset
    from dynid.data.files import load_dataset

    shutil.copy2(base / "V.csv", tmp_path / "V.csv")
    path = _millinewton(tmp_path)
    robot = load_robot("ur5")
    assert load_dataset(path, 6).n == 6  # without the robot nothing tells the units
    with pytest.raises(DataError, match=rf"^mNm\.csv: {MN_M}"):
        load_dataset(path, robot=robot)
    with pytest.raises(DataError, match=rf"^mNm\.csv: {MN_M}"):
        read_dataset(path, robot=robot)


def test_identify_refuses_torques_in_mn_m(work: Path, capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["identify", "--robot", "ur5", "--data", _millinewton(work, "D.csv"), "--method", "ols", "--gmm", "off",
            "--out", str(work / "OUT.json")]  # fmt: skip
    assert_refused(argv, work, rf"mNm\.csv: {MN_M}", capsys)


def test_the_fleet_refuses_a_recording_in_mn_m_in_its_row(base: Path, tmp_path: Path) -> None:
    """One bad recording does not stop a fleet: its row carries the sentence (and no parameters)."""
    from dynid.fleet.core import FleetSettings, identify_recording
    from dynid.fleet.recordings import find_recordings

    shutil.copy2(base / "D.csv", tmp_path / "D.csv")
    (tmp_path / "r1").mkdir()
    _millinewton(tmp_path, "D.csv", "r1/0.csv")
    recording = find_recordings(str(tmp_path / "r1" / "0.csv"))[0]
    out = identify_recording(load_robot("ur5"), recording, FleetSettings(gmm="off", holdout=0.0))
    assert out["parameters"] is None
    assert re.search(rf"^0\.csv: {MN_M}", out["row"]["error"]), out["row"]["error"]


def test_a_ros2_bag_in_mn_m_is_refused_by_validate(work: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A bag's joints are mapped by name, then checked like a file: validate reads it with the model's robot."""
    pytest.importorskip("rosbags.rosbag2", reason="ROS 2 recordings are read with rosbags")
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    from dynid.data.files import load_dataset

    store = get_typestore(Stores.LATEST)
    types, kind = store.types, "sensor_msgs/msg/JointState"
    ds = load_dataset(work / "V.csv", 6).slice_time(0.0, 1.0)
    names = load_robot("ur5").joint_names
    with Writer(work / "bag", version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection("/joint_states", kind, typestore=store)
        for k in range(ds.m):
            stamp_ns = 1_700_000_000_000_000_000 + round(ds.t[k] * 1e9)
            msg = types[kind](
                header=types["std_msgs/msg/Header"](
                    stamp=types["builtin_interfaces/msg/Time"](sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9),
                    frame_id="",
                ),
                name=list(names),
                position=ds.q[k].copy(),
                velocity=np.zeros(0),
                effort=1e3 * ds.tau[k],
            )
            writer.write(conn, stamp_ns, store.serialize_cdr(msg, kind))
    assert_refused(_validate(work, str(work / "bag")), work, rf"bag: {MN_M}", capsys)


# ---------------------------------------------------------------------- 2. DH tables that hold
@pytest.mark.parametrize("gravity", ["[0, 0, 0]", "[0, 0, -1.62]", "[0, 9.81, 0]", "[0, 0, -99]"])
def test_a_table_with_gravity_within_range_loads(tmp_path: Path, gravity: str) -> None:
    path = _toml(tmp_path, "g.toml", 'name = "my_arm"', f'name = "my_arm"\ngravity = {gravity}')
    np.testing.assert_allclose(load_robot(path).gravity, json.loads(gravity), rtol=0, atol=0)


def test_table_limits_at_the_bounds_load_and_beyond_are_refused(tmp_path: Path) -> None:
    ok = _toml(tmp_path, "ok.toml", "q_max = [2.8, 1.9, 0.3]", "q_max = [12.5, 1.9, 19.9]")
    robot = load_robot(ok)
    np.testing.assert_allclose(robot.q_max, [12.5, 1.9, 19.9], rtol=0, atol=0)
    bad = _toml(tmp_path, "bad.toml", "q_max = [2.8, 1.9, 0.3]", "q_max = [2.8, 1.9, 20.5]")
    with pytest.raises(RobotModelError, match=r"holds 20\.5 for joint 3, a prismatic joint, beyond the 20 m"):
        load_robot(bad)


# ---------------------------------------------------------------------- 3. trajectory files
def test_a_trajectory_whose_fields_agree_loads(base: Path, tmp_path: Path) -> None:
    from dynid.optim.trajectory import load_trajectory

    shutil.copy2(base / "T.json", tmp_path / "T.json")
    good = load_trajectory(_trajectory(tmp_path, "G.json", harmonics=2.0, n_joints=6))
    assert (good.harmonics, good.n) == (2, 6)
    with pytest.raises(ModelFileError, match=r"states n_joints = True, but its coefficients hold 6 values"):
        load_trajectory(_trajectory(tmp_path, "B.json", n_joints=True))


# ---------------------------------------------------------------------- 4. --period against the recording
def test_a_period_that_fits_is_used_silently(work: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert quiet_warnings(_validate(work, str(work / "V.csv"), "--period", "2"), capsys) == []
    figures = json.loads((work / "OUT.csv.json").read_text())
    assert figures["noise_floor_method"] == "periods", figures["noise_floor_detail"]


def test_check_period_warns_where_the_data_cannot_tell() -> None:
    """An aperiodic run: the period is warned about (the noise floor does not use it); a run shorter than two
    periods cannot confirm one; a periodic stretch between rests confirms it without a word."""
    from dynid.data.periodic import check_period

    t = np.arange(8000) / 1000.0
    aperiodic = np.column_stack([np.sin(0.7 * t) + 0.3 * np.sin(2.3 * t), np.cos(1.13 * t)])
    with pytest.warns(DataWarning, match=r"the angles of A\.csv do not repeat after --period 3 s \(one period "
                                         r"apart they differ by [\d.]+ % of their spread"):  # fmt: skip
        check_period(t, aperiodic, 3.0, source="A.csv")
    with pytest.warns(DataWarning, match=r"A\.csv lasts 7\.999 s, less than two periods of --period 5 s"):
        check_period(t, aperiodic, 5.0, source="A.csv")
    played = np.outer(np.sin(2 * np.pi * t / 1.5), [1.0, 0.5])
    played[:1000] = 0.0  # a rest before, a rest after
    played[-1000:] = played[-1001]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_period(t, played, 1.5, source="P.csv")
        check_period(t, played, 3.0, source="P.csv")  # two periods at a time repeat too
    with pytest.raises(UsageError, match=r"--period 0\.02 s is 20 samples of P\.csv"):
        check_period(t, played, 0.02, source="P.csv")


def test_diagnosis_settings_refuse_a_period_that_is_not_positive() -> None:
    from dynid.diagnosis.settings import DiagnosisSettings

    for bad in (0.0, -2.0, float("nan"), float("inf"), "2"):
        with pytest.raises(UsageError, match=r"period is .*; give the period of the held-out motion in seconds"):
            DiagnosisSettings(period=bad)  # type: ignore[arg-type]
    assert DiagnosisSettings(period=np.float64(2.0)).period == 2.0


# ---------------------------------------------------------------------- 5. training data as held-out data
def test_two_recordings_identified_together_are_each_training_data(
    work: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``identify --data D.csv --data V.csv`` (or ``--data D.csv V.csv``): one model of both; validating it
    on either says so."""
    argv = ["identify", "--robot", "ur5", "--data", str(work / "D.csv"), "--data", str(work / "V.csv"), "--out",
            str(work / "J.json"), "--method", "ols", "--friction", "linear", "--gmm", "off", "--quiet"]  # fmt: skip
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert main(argv) == 0, capsys.readouterr().err
    doc = json.loads((work / "J.json").read_text())
    assert len(doc["data_parts_sha256"]) == 2 and doc["data_sha256"] not in doc["data_parts_sha256"]
    for name in ("D.csv", "V.csv"):
        assert_warned(
            ["validate", "--model", str(work / "J.json"), "--data", str(work / name), "--quiet"],
            rf"--data .*{name[0]}\.csv is one of the recordings .*J\.json was identified on, so its scores are "
            "optimistic, not held-out figures",
            capsys,
        )


def test_a_recording_named_twice_is_refused(work: Path, capsys) -> None:
    assert_refused(
        ["identify", "--robot", "ur5", "--data", str(work / "D.csv"), str(work / "D.csv"), "--out", str(work / "J.json")],
        work,
        r"^dynid identify: error: --data names one file twice '.*D\.csv'; each recording counts once: give it once\.$",
        capsys,
    )


def test_recordings_identified_together_need_the_same_signals(work: Path, capsys) -> None:
    header, table = _table(work, "V.csv")
    n = sum(h.startswith("q_") for h in header)
    dq = np.gradient(table[:, 1 : 1 + n], table[:, 0], axis=0)
    with_dq = work / "W.csv"
    np.savetxt(with_dq, np.hstack([table, dq]), delimiter=",", header=",".join(header + [f"dq_{j + 1}" for j in
               range(n)]), comments="")  # fmt: skip
    assert_refused(
        ["identify", "--robot", "ur5", "--data", str(work / "D.csv"), str(with_dq), "--out", str(work / "J.json")],
        work,
        r"--data: '.*W\.csv' has measured velocities \(dq_i\) and '.*D\.csv' has not; recordings identified "
        r"together need the same signals: give them in every recording or in none\.",
        capsys,
    )


def test_validate_on_the_training_data_warns_that_the_score_is_optimistic(
    work: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert_warned(
        _validate(work, str(work / "D.csv")),
        r"--data .*D\.csv is the data .*M\.json was identified on \(the same \d+ samples and torque range\), so its "
        r"scores are optimistic, not held-out figures",
        capsys,
    )
    assert quiet_warnings(_validate(work, str(work / "V.csv")), capsys) == []


def test_only_the_training_data_match_the_model(base: Path) -> None:
    from dynid.commands.common import is_training_data
    from dynid.data.files import load_dataset
    from dynid.identify.model import load_model

    model = load_model(base / "M.json")
    train = load_dataset(base / "D.csv", 6)
    assert is_training_data(model, train)
    assert not is_training_data(model, load_dataset(base / "V.csv", 6))
    assert not is_training_data(model, train.select_rows(np.arange(1, train.m)))  # one sample fewer
    assert not is_training_data(model, train._derive(tau=1.001 * train.tau))  # a gain 0.1 % off
    assert "data_sha256" in model.info
    older = dataclasses.replace(model, info={k: v for k, v in model.info.items() if k != "data_sha256"})
    assert is_training_data(older, train)  # a file written before the checksum: the samples and range
    assert not is_training_data(older, load_dataset(base / "V.csv", 6))


# ---------------------------------------------------------------------- 6. fleet manifests (API)
def test_find_recordings_refuses_dates_and_indices_mixed_by_path(tmp_path: Path) -> None:
    from dynid.fleet.recordings import find_recordings

    (tmp_path / "arm").mkdir()
    for name in ("2024-01-01.csv", "3.csv"):
        (tmp_path / "arm" / name).write_text("t\n")
    with pytest.raises(UsageError, match=r"the robot 'arm' has recordings timed by ISO date \('.*2024-01-01\.csv': "
                                         r"'2024-01-01'\) and by index \('.*3\.csv': '3'\)"):  # fmt: skip
        find_recordings(str(tmp_path / "arm" / "*.csv"))
    found = find_recordings(str(tmp_path / "arm" / "3.csv"))  # one kind per robot: fine
    assert [(r.robot, r.time) for r in found] == [("arm", "3")]


def test_a_manifest_may_name_recordings_the_pattern_leaves_out(tmp_path: Path) -> None:
    from dynid.fleet.recordings import find_recordings

    (tmp_path / "arm").mkdir()
    for name in ("a.csv", "b.csv"):
        (tmp_path / "arm" / name).write_text("t\n")
    (tmp_path / "m.csv").write_text("path,robot,time\narm/a.csv,x,0\narm/b.csv,x,1\n")
    found = find_recordings(str(tmp_path / "arm" / "b.csv"), tmp_path / "m.csv")
    assert [(os.path.basename(r.path), r.order) for r in found] == [("b.csv", 0)]


# ---------------------------------------------------------------------- 7. dead sensors and joint limits
def test_a_torque_channel_stuck_over_part_of_the_run_is_warned_about(
    work: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from dynid.data.files import load_dataset

    path = _stuck(work)
    pattern = (
        r"stuck\.csv: tau_3 holds -?[\d.e+-]+ N m unchanged over rows \d+\.\.\d+ \(40 % of the recording\) while the "
        r"arm moves, as a torque sensor that stuck does; check joint 3's channel"
    )
    with pytest.warns(DataWarning, match=pattern):
        load_dataset(path, 6)
    assert_warned(_validate(work, path), pattern, capsys)


def test_a_resting_arm_may_hold_its_torque(base: Path, tmp_path: Path) -> None:
    """A noise-free rest holds one torque exactly: not a stuck sensor, since nothing moves."""
    from dynid.data.dataset import Dataset
    from dynid.data.files import load_dataset, save_dataset

    ds = load_dataset(base / "V.csv", 6)
    rest = 0.5 * ds.m
    q = np.where(np.arange(ds.m)[:, None] < rest, ds.q, ds.q[int(rest)])
    tau = np.where(np.arange(ds.m)[:, None] < rest, ds.tau, ds.tau[int(rest)])
    save_dataset(Dataset(ds.t, q, tau), tmp_path / "rest.csv")
    with warnings.catch_warnings():
        warnings.simplefilter("error", DataWarning)
        load_dataset(tmp_path / "rest.csv", 6)


def test_angles_far_beyond_the_limits_are_warned_about(work: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from dynid.data.files import load_dataset

    path = _beyond_limits(work)
    pattern = (
        r"beyond\.csv: q_1 moves over \[[\d.-]+, 9\.3\], 24 % of its range beyond the limits \[-6\.283, 6\.283\] of "
        r"'ur5'; check the joint's offset and units"
    )
    with warnings.catch_warnings():
        warnings.simplefilter("error", DataWarning)
        load_dataset(path, 6)  # without the robot the limits are unknown
    with pytest.warns(DataWarning, match=pattern):
        load_dataset(path, robot=load_robot("ur5"))
    assert_warned(_validate(work, path), pattern, capsys)


# ---------------------------------------------------------------------- 8. the fuzz's remaining cases
def test_a_replaced_folder_gets_the_umask_mode_and_a_killed_runs_leftovers_go(tmp_path: Path) -> None:
    """export-c, fleet and the compiled cache write through atomic_dir: the folder is 0777 less the umask
    (not mkdtemp's 0700), and a temporary folder a killed run left (its process gone) is removed, one of a
    run still going is not."""
    import subprocess
    import sys

    from dynid._io import atomic_dir

    gone = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    orphan = tmp_path / f".c.{int(gone.stdout)}.abcd1234.tmp"
    live = tmp_path / f".c.{os.getpid()}.efgh5678.tmp"
    other = tmp_path / ".c.12.x.ijkl9012.tmp"  # the folder 'c.12' of another output: not c's
    for d in (orphan, live, other):
        d.mkdir()
    old = os.umask(0o027)
    try:
        with atomic_dir(tmp_path / "c") as work:
            (work / "f.txt").write_text("x")
    finally:
        os.umask(old)
    assert (tmp_path / "c" / "f.txt").read_text() == "x"
    assert (tmp_path / "c").stat().st_mode & 0o777 == 0o750
    assert not orphan.exists() and live.is_dir() and other.is_dir()


def test_export_c_into_a_symbolic_link_is_refused_before_any_work(tmp_path: Path, capsys) -> None:
    (tmp_path / "real").mkdir()
    (tmp_path / "link").symlink_to(tmp_path / "real")
    assert_refused(
        ["export-c", "--robot", "ur5", "--out", str(tmp_path / "link")],
        tmp_path,
        r"--out '.*link' is a symbolic link \(to '.*real'\), but the folder is replaced as a whole, link included; "
        r"give the folder itself: --out .*real\.$",
        capsys,
    )


def test_a_scheduler_without_workers_is_named(tmp_path: Path) -> None:
    """Before: a scatter waited, then 'cannot use: No valid workers found; check the path ... free space'."""
    distributed = pytest.importorskip("distributed")
    from dynid._cluster import cluster_client

    with distributed.LocalCluster(n_workers=0, dashboard_address=":0", silence_logs=40) as cluster:
        address = cluster.scheduler_address
        with pytest.raises(UsageError, match=rf"the Dask scheduler at '{address}' has no worker \(none joined "
                                             rf"within 1s\); start workers on it \(dask worker tcp://"):  # fmt: skip
            with cluster_client(address, timeout="1s"):
                pass


def _bag(path: Path, source: Path, *, one_stamp: bool) -> None:
    pytest.importorskip("rosbags.rosbag2", reason="ROS 2 recordings are read with rosbags")
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    from dynid.data.files import load_dataset

    store = get_typestore(Stores.LATEST)
    types, kind = store.types, "sensor_msgs/msg/JointState"
    ds = load_dataset(source, 6).slice_time(0.0, 0.2)
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection("/joint_states", kind, typestore=store)
        for k in range(ds.m):
            ns = 1_700_000_000_000_000_000 + (0 if one_stamp else round(ds.t[k] * 1e9))
            stamp = types["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)
            msg = types[kind](header=types["std_msgs/msg/Header"](stamp=stamp, frame_id=""),
                              name=list(load_robot("ur5").joint_names), position=ds.q[k].copy(),
                              velocity=np.zeros(0), effort=ds.tau[k].copy())  # fmt: skip
            writer.write(conn, ns + k, store.serialize_cdr(msg, kind))


def test_a_bag_whose_stamps_are_all_equal_is_refused_as_such(work: Path, capsys) -> None:
    """Before: 'a dataset needs at least 2 samples; got 1'."""
    _bag(work / "bag", work / "V.csv", one_stamp=True)
    assert_refused(
        _validate(work, str(work / "bag")),
        work,
        r"bag: the 201 JointState messages on /joint_states all carry one stamp \(1\.7e\+09 s\), so they make 1 "
        r"sample, not a run in time; record with a driver that stamps each message",
        capsys,
    )


def test_a_bag_with_broken_metadata_is_one_line(work: Path, capsys) -> None:
    """Before: the YAML parser's eight lines, pointer and all."""
    pytest.importorskip("rosbags.rosbag2", reason="ROS 2 recordings are read with rosbags")
    (work / "bag").mkdir()
    (work / "bag" / "metadata.yaml").write_text("rosbag2_bagfile_information:\n  version: [unclosed\n\t: x\n")
    assert_refused(
        _validate(work, str(work / "bag")),
        work,
        r"bag could not be read as a ROS 2 recording \(ReaderError: .*metadata\.yaml.*\); give a rosbag2 folder",
        capsys,
    )


def test_comment_lines_above_the_header_are_comments(base: Path, tmp_path: Path) -> None:
    """Before: a first line '# recorded on arm 3' was called 'separated by spaces'."""
    from dynid.data.files import load_dataset

    text = (base / "V.csv").read_text()
    (tmp_path / "c.csv").write_text("# recorded on arm 3\n# 2024-05-01\n" + text)
    np.testing.assert_array_equal(load_dataset(tmp_path / "c.csv", 6).tau, load_dataset(base / "V.csv", 6).tau)
    header, body = text.split("\n", 1)
    (tmp_path / "h.csv").write_text(f"# {header}\n{body}")
    with pytest.raises(DataError, match=r"^h\.csv has its header commented out \('# t,q_1,.*'\), so its first "
                                         r"line holds numbers; remove the '#'"):  # fmt: skip
        load_dataset(tmp_path / "h.csv", 6)
    (tmp_path / "o.csv").write_text("# nothing but a note\n")
    with pytest.raises(DataError, match=r"^o\.csv holds only comment lines; a dataset CSV starts with a header"):
        load_dataset(tmp_path / "o.csv", 6)


def test_a_trajectory_too_fast_to_sample_is_named(work: Path, capsys) -> None:
    """Before: 'a dataset needs at least 2 samples; got 1', blaming the data."""
    assert_refused(
        _simulate(work, _trajectory(work, "F.json", base_freq=1e6)),
        work,
        r"the run lasts 3e-06 s, 3 period\(s\) of the trajectory '.*F\.json' at its base frequency 1e\+06 Hz, 1 "
        r"sample at 1000 Hz, but a dataset needs at least 2; give a trajectory whose period spans many samples",
        capsys,
    )


def test_an_mjcf_template_of_another_joint_count_is_named(work: Path, capsys) -> None:
    """Before: 'params of the robot 'ur5' has shape (10,); expected (60,) for 6 joints'."""
    pytest.importorskip("mujoco", reason="MJCF templates are read with MuJoCo")
    (work / "one.xml").write_text(
        '<mujoco model="one"><worldbody><body name="l1"><joint name="j1" type="hinge" axis="0 0 1" range="-1 1"/>'
        '<geom type="sphere" size="0.1" mass="1"/></body></worldbody></mujoco>'
    )
    argv = ["export", "--model", str(work / "M.json"), "--format", "mjcf", "--template", str(work / "one.xml"),
            "--out", str(work / "o.xml")]  # fmt: skip
    assert_refused(
        argv,
        work,
        r"the template '.*one\.xml' has 1 joint\(s\) \(j1\), but the model's robot 'ur5' has 6 \(shoulder_pan_joint, "
        r".*\); give the MJCF of the robot the model was identified for",
        capsys,
    )


def test_diagnose_effects_with_joints_say_the_name_alone(work: Path, capsys) -> None:
    """Before: 'unknown effect 'stribeck@3''."""
    assert_refused(
        _diagnose(work, str(work / "D.csv"), str(work / "V.csv"), "--effects", "offset,stribeck@3"),
        work,
        r"--effects names the effect 'stribeck@3' with joints or a value, but the diagnosis tests each candidate on "
        r"every joint and tunes its values on the data; give the name alone: --effects stribeck$",
        capsys,
    )


def test_a_recording_shorter_than_the_filters_transient_names_no_missing_option(work: Path, capsys) -> None:
    """Before: '... leaves 0 of run 0 (59 samples); trim less' (validate has no trim option)."""
    (work / "short.csv").write_text("".join((work / "V.csv").read_text().splitlines(keepends=True)[:60]))
    assert_refused(
        _validate(work, str(work / "short.csv")),
        work,
        r"trimming \d+ samples from both ends leaves 0 of run 0 \(59 samples\); give a recording of at least \d+ "
        r"samples a run \(the trim cuts the low-pass filter's transient",
        capsys,
    )


def test_the_fleets_own_output_is_no_recording(tmp_path: Path) -> None:
    """Before: an --out inside the pattern had its drift.csv read as a recording on the next run."""
    from dynid.fleet.recordings import find_recordings

    for name in ("arm/0.csv", "arm/1.csv", "arm/out/drift.csv", "arm/out/fleet.csv"):
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text("t\n")
    found = find_recordings(str(tmp_path / "**" / "*.csv"), out=tmp_path / "arm" / "out")
    assert [os.path.basename(r.path) for r in found] == ["0.csv", "1.csv"]


FOLDER_INPUTS = [
    ("trajectory", lambda f: _simulate(f, str(f / "sub")), r"--trajectory '.*sub' is a folder; give the file itself\."),
    ("model", lambda f: ["validate", "--model", str(f / "sub"), "--data", str(f / "V.csv")],
     r"--model '.*sub' is a folder; give the file itself\."),
    ("transmission", lambda f: ["identify", "--robot", "ur5", "--data", str(f / "D.csv"), "--transmission",
                                str(f / "sub"), "--out", str(f / "OUT.json")],
     r"--transmission '.*sub' is a folder; give the file itself\."),
    ("data", lambda f: _validate(f, str(f / "sub")),
     r"sub is a folder; give the path of a \.csv or \.npz dataset file \(a ROS 2 rosbag2 folder holds a "
     r"metadata\.yaml\)"),
    ("manifest", lambda f: ["fleet", "--robot", "ur5", "--data", str(f / "*.csv"), "--manifest", str(f / "sub"),
                            "--serial", "--out", str(f / "fleet")],
     r"the manifest '.*sub' is a folder; give a CSV file with the columns path, robot, time\."),
    ("robot", lambda f: ["identify", "--robot", str(f / "sub"), "--data", str(f / "D.csv"), "--out", str(f / "OUT.json")],
     r"--robot '.*sub' is a folder; give the robot's description file itself \(a \.urdf, .*or a built-in name"),
]  # fmt: skip


@pytest.mark.parametrize(("make", "pattern"), [c[1:] for c in FOLDER_INPUTS], ids=[c[0] for c in FOLDER_INPUTS])
def test_a_folder_given_for_a_file_is_called_a_folder(work: Path, capsys, make, pattern: str) -> None:
    """Before: 'does not exist', 'no model file at', 'unknown extension '''."""
    (work / "sub").mkdir()
    assert_refused(make(work), work, pattern, capsys)


def test_a_build_on_a_full_disk_says_so(tmp_path: Path, monkeypatch) -> None:
    """Before: a minute of compiling, then 22 to 60 lines of compiler output and never 'no space'."""
    import shutil as shutil_module

    from dynid.symbolic import build

    usage = shutil_module.disk_usage(tmp_path)
    assert build.full_disk("compiling x", tmp_path) is None or usage.free < build.LOW_SPACE
    monkeypatch.setattr(build.shutil, "disk_usage", lambda p: usage._replace(free=300 * 1024))
    err = build.full_disk("compiling libdynid_ur5.so", tmp_path / "not" / "made")
    where = re.escape(str(tmp_path))
    assert re.fullmatch(rf"compiling libdynid_ur5\.so failed: no space left on the disk of '{where}' "
                        r"\(0\.293 MB free, 100 MB needed\); free space there, or set DYNID_CACHE_DIR to a folder on "
                        r"a disk with room, and run again", str(err))  # fmt: skip


def test_a_full_disk_met_while_writing_says_so(monkeypatch, capsys) -> None:
    """A write to an open file fails without a file name: the line said 'cannot use: No space left on device'."""
    import errno

    from dynid.commands import info

    def full(args):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(info, "run", full)
    assert main(["info", "--robot", "ur5"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == ("dynid info: error: cannot write its files: No space left on device; check the path, its "
                   "permissions and the free space, then run the command again")  # fmt: skip


def test_a_demo_that_fails_removes_the_folder_it_made(tmp_path: Path, monkeypatch, capsys) -> None:
    """Before: a demo stopped by a full disk left a half-filled folder behind."""
    import errno

    import dynid.demo

    def stops(out, **_):
        Path(out).mkdir()
        (Path(out) / "excitation.json").write_text("{}")
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(dynid.demo, "run_demo", stops)
    assert main(["demo", "--quick", "--out", str(tmp_path / "demo")]) == 2
    assert "No space left on device" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []
    (tmp_path / "kept").mkdir()  # a folder that was there before stays
    assert main(["demo", "--quick", "--out", str(tmp_path / "kept")]) == 2
    assert (tmp_path / "kept").is_dir()
