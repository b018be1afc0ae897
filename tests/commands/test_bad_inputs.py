"""Bad inputs end in one sentence: exit code 2, one line on stderr, no traceback, no file touched.

Every dataset command (identify, validate, diagnose) reads its data through the one reader
(:func:`dynid.data.files.load_dataset`) and every robot command through
:func:`dynid.symbolic.robot.load_robot`, so each bad file is tried through each command that reads it,
then through the API.  The folder a command runs in holds its inputs and a pre-existing output; after a
refusal every file in it is byte-identical and nothing was added (no stray temporary file).

The property-based layer (Hypothesis) at the end mutates valid files and asserts the same contract:
either a clean result or one sentence, never a traceback, never a damaged file.
"""

from __future__ import annotations

import re
import shutil
import warnings
import zipfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from dynid.cli import main
from dynid.data.files import load_dataset
from dynid.exceptions import DataError, DataWarning, DynidError, RobotModelError, RobotModelWarning
from dynid.symbolic.robot import check_inertias, check_simulable, load_robot
from tests.conftest import DH_TABLE, assert_refused, snapshot

ROWS = 1100  # 1.1 s at 1 kHz: enough for identify's trimming, small enough to be quick

GOOD_TOML = DH_TABLE

TWO_LINK_URDF = """\
<?xml version="1.0"?>
<robot name="two">
  <link name="base"/>
  <link name="l1">
    <inertial><origin xyz="0 0 0.1"/><mass value="2.0"/>
      <inertia ixx="0.02" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.01"/></inertial>
  </link>
  <link name="l2">
    <inertial><origin xyz="0.1 0 0"/><mass value="1.0"/>
      <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial>
  </link>
  <link name="tip"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><axis xyz="0 0 1"/>
    <limit lower="-2" upper="2" effort="10" velocity="2"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0 0 0.2"/>
    <axis xyz="0 1 0"/><limit lower="-2" upper="2" effort="10" velocity="2"/></joint>
  <joint name="jt" type="fixed"><parent link="l2"/><child link="tip"/><origin xyz="0.2 0 0"/></joint>
</robot>
"""


# ---------------------------------------------------------------------- fixtures
@pytest.fixture(scope="module")
def base(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A UR5 trajectory, a short simulated dataset and a model fitted to it; a 3-joint table and its trajectory."""
    from dynid.identify.model import identify, save_model
    from dynid.optim.excitation import ExcitationProblem
    from dynid.sim.simulator import build_truth, simulate, write_simulation

    folder = tmp_path_factory.mktemp("bad-inputs")
    robot = load_robot("ur5")
    problem = ExcitationProblem(robot=robot, harmonics=2, base_freq=0.5)
    trajectory = problem.random_trajectory(np.random.default_rng(0))
    trajectory.save(folder / "T.json")
    truth = build_truth(robot, friction="linear", truth_seed=0)
    run = simulate(robot, trajectory, truth=truth, seed=1, duration=(ROWS - 1) / 1000.0)
    data_path, _ = write_simulation(run, folder / "D.csv")
    (folder / "D.csv.truth.json").unlink()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = identify(robot, load_dataset(data_path, 6), method="ols", friction="linear", gmm="off")
    save_model(model, folder / "M.json")
    (folder / "arm.toml").write_text(GOOD_TOML)
    arm = load_robot(folder / "arm.toml")
    ExcitationProblem(robot=arm, harmonics=2, base_freq=0.5).random_trajectory(np.random.default_rng(1)).save(
        folder / "T3.json"
    )
    (folder / "two.urdf").write_text(TWO_LINK_URDF)
    return folder


@pytest.fixture
def work(base: Path, tmp_path: Path) -> Path:
    """A fresh folder holding copies of the good inputs and pre-existing outputs (copies of inputs)."""
    for p in base.iterdir():
        if p.is_file():
            shutil.copy2(p, tmp_path / p.name)
        elif p.is_dir():  # a model saved as a folder
            shutil.copytree(p, tmp_path / p.name)
    shutil.copy2(base / "M.json", tmp_path / "OUT.json")
    model_npz = next(base.glob("M*.npz"), None)
    if model_npz is not None:  # a model saved as a pair: the output pair exists too
        shutil.copy2(model_npz, tmp_path / model_npz.name.replace("M", "OUT", 1))
    shutil.copy2(base / "D.csv", tmp_path / "P.csv")
    shutil.copy2(base / "D.csv", tmp_path / "OUT.csv")
    shutil.copy2(base / "T.json", tmp_path / "T2.json")
    (tmp_path / "R.html").write_text("<html>an older report</html>\n")
    return tmp_path






# ---------------------------------------------------------------------- bad datasets
def _table(base: Path) -> tuple[str, np.ndarray]:
    text = (base / "D.csv").read_text()
    header = text.splitlines()[0]
    return header, np.loadtxt(base / "D.csv", delimiter=",", skiprows=1)


def _write(path: Path, header: str, table: np.ndarray) -> None:
    np.savetxt(path, table, delimiter=",", header=header, comments="", fmt="%.17g")


def _cell(folder: Path, value: str) -> str:
    lines = (folder / "D.csv").read_text().splitlines()
    cells = lines[40].split(",")
    cells[8] = value  # tau_2 at row 38
    lines[40] = ",".join(cells)
    (folder / "BAD.csv").write_text("\n".join(lines) + "\n")
    return "BAD.csv"


def _scaled(folder: Path, rows: slice | None, col: slice, factor: float) -> str:
    header, table = _table(folder)
    table[rows if rows is not None else slice(None), col] *= factor
    _write(folder / "BAD.csv", header, table)
    return "BAD.csv"


def _rows(folder: Path, order: Callable[[np.ndarray], np.ndarray]) -> str:
    header, table = _table(folder)
    _write(folder / "BAD.csv", header, order(table))
    return "BAD.csv"


def _text(folder: Path, transform: Callable[[str], str], name: str = "BAD.csv") -> str:
    (folder / name).write_text(transform((folder / "D.csv").read_text()))
    return name


def _bytes(folder: Path, data: bytes, name: str = "BAD.csv") -> str:
    (folder / name).write_bytes(data)
    return name


def _npz(folder: Path, name: str = "BAD.npz", **arrays: np.ndarray) -> str:
    np.savez(folder / name, **arrays)
    return name


def _object_npz(folder: Path) -> str:
    _, table = _table(folder)
    return _npz(folder, t=table[:, 0].astype(object), q=table[:, 1:7], tau=table[:, 7:13])


def _zip_as_csv(folder: Path) -> str:
    with zipfile.ZipFile(folder / "BAD.csv", "w") as z:
        z.writestr("D.csv", (folder / "D.csv").read_text())
    return "BAD.csv"


def _swap_rows(table: np.ndarray) -> np.ndarray:
    out = table.copy()
    out[[10, 11]] = out[[11, 10]]
    return out


def _repeat_stamp(table: np.ndarray) -> np.ndarray:
    out = table.copy()
    out[20, 0] = out[19, 0]  # same time, other values
    return out


def _three_joints(folder: Path) -> str:
    _, table = _table(folder)
    _write(folder / "BAD.csv", "t,q_1,q_2,q_3,tau_1,tau_2,tau_3", table[:, [0, 1, 2, 3, 7, 8, 9]])
    return "BAD.csv"


def _tail_cut(text: str) -> str:
    return text[: len(text) // 2]  # ends mid-line


def _missing_tau6(text: str) -> str:
    return "\n".join(",".join(line.split(",")[:-1]) for line in text.splitlines()) + "\n"


BAD_DATA: list[tuple[str, Callable[[Path], str], str]] = [
    (
        "binary",
        lambda f: _bytes(f, bytes(range(256)) * 8),
        r"BAD\.csv is a binary file .*give a CSV text file",
    ),
    (
        "latin1",
        lambda f: _bytes(f, (f / "D.csv").read_bytes().replace(b"q_1", b"q\xe9_1", 1)),
        r"BAD\.csv is not UTF-8 text \(byte 0xe9 at offset \d+\); give a comma-separated text file in UTF-8",
    ),
    ("zip_as_csv", _zip_as_csv, r"BAD\.csv is a zip archive, not comma-separated text; .*name it \.npz"),
    (
        "semicolons",
        lambda f: _text(f, lambda s: s.replace(",", ";")),
        r"separated by semicolons, but dynid reads comma-separated CSV; export it with commas",
    ),
    ("tabs", lambda f: _text(f, lambda s: s.replace(",", "\t")), r"separated by tabs, but dynid reads comma"),
    (
        "spaces",
        lambda f: _text(f, lambda s: s.replace(",", " ")),
        r"separated by spaces, but dynid reads comma",
    ),
    ("empty", lambda f: _bytes(f, b""), r"BAD\.csv is empty; a dataset CSV starts with a header line"),
    ("header_only", lambda f: _text(f, lambda s: s.splitlines()[0] + "\n"), r"has a header but no data rows"),
    (
        "no_header",
        lambda f: _text(f, lambda s: s.split("\n", 1)[1]),
        r"has no header: its first line holds numbers",
    ),
    (
        "missing_column",
        lambda f: _text(f, _missing_tau6),
        r"has no column 'tau_6'; a dataset needs t, q_1\.\.q_n",
    ),
    (
        "cut_mid_line",
        lambda f: _text(f, _tail_cut),
        r"could not be read as numbers \(line \d+ holds \d+ comma-sep",
    ),
    ("text_cell", lambda f: _cell(f, "abc"), r"could not be read as numbers \(line 41, column 9 holds 'abc'"),
    ("nan_cell", lambda f: _cell(f, "nan"), r"tau_2 is nan at row 39 \(t = 0\.039 s; 1 bad row in all\)"),
    ("inf_cell", lambda f: _cell(f, "-inf"), r"tau_2 is -inf at row 39"),
    (
        "huge_torque",
        lambda f: _cell(f, "1e300"),
        r"tau_2 is 1e\+300 at row 39, beyond 1e\+06 N m .*check the col",
    ),
    (
        "degrees",
        lambda f: _scaled(f, None, slice(1, 7), 180 / np.pi),
        r"q_\d reaches [\d.]+, more than 10 rad, so the angles look like degrees.*pass --degrees",
    ),
    (
        "milliseconds",
        lambda f: _scaled(f, None, slice(0, 1), 1e3),
        r"the median time step is 1, but t must be in seconds.*milliseconds / 1e3",
    ),
    (
        "nanoseconds",
        lambda f: _scaled(f, None, slice(0, 1), 1e9),
        r"the median time step is 1e\+06, but t must be in seconds",
    ),
    (
        "rows_swapped",
        lambda f: _rows(f, _swap_rows),
        r"t must increase strictly, but t\[11\] = 0\.01 s is not after t\[10\] = 0\.011 s \(rows repeating or "
        r"going back in time: 11, 1 in all\)",
    ),
    ("stamp_repeated", lambda f: _rows(f, _repeat_stamp), r"t must increase strictly, but t\[20\]"),
    ("three_joints", _three_joints, r"(?=.*\b3 (columns|joints))(?=.*'ur5')"),
    (
        "object_npz",
        _object_npz,
        r"BAD\.npz holds 't' as Python objects, but dynid reads numeric arrays only; save it with np\.savez",
    ),
    (
        "text_named_npz",
        lambda f: _text(f, lambda s: s, name="BAD.npz"),
        r"BAD\.npz is a text file, not an \.npz archive of numeric arrays; if it is a CSV dataset, name it \.csv",
    ),
    (
        "npy_named_npz",
        lambda f: _bytes(f, b"\x93NUMPY\x01\x00" + bytes(100), name="BAD.npz"),
        r"BAD\.npz is not a zip archive, not an \.npz archive",
    ),
    (
        "npz_without_tau",
        lambda f: _npz(f, t=np.arange(5) * 0.01, q=np.zeros((5, 6))),
        r"BAD\.npz has no column 'tau_1'",
    ),
    (
        "npz_strings",
        lambda f: _npz(f, t=np.array(["a", "b"]), q=np.zeros((2, 6)), tau=np.zeros((2, 6))),
        r"t could not be read as numbers",
    ),
    (
        "a_folder",
        lambda f: (f / "BAD.csv").mkdir() or "BAD.csv",
        r"BAD\.csv is a folder; give the path of a \.csv",
    ),
    ("absent", lambda f: "ABSENT.csv", r"no dataset file at .*ABSENT\.csv; check the path"),
    ("extension", lambda f: _text(f, lambda s: s, name="BAD.txt"), r"unknown extension '\.txt'.*docs/commands\.md"),
]

DATA_COMMANDS = {
    "identify": lambda f, bad: [
        "identify",
        "--robot",
        "ur5",
        "--data",
        str(f / bad),
        "--method",
        "ols",
        "--friction",
        "linear",
        "--gmm",
        "off",
        "--out",
        str(f / "OUT.json"),
    ],
    "validate": lambda f, bad: [
        "validate",
        "--model",
        str(f / "M.json"),
        "--data",
        str(f / bad),
        "--predictions",
        str(f / "P.csv"),
        "--report",
        str(f / "R.html"),
    ],
    "diagnose_data": lambda f, bad: [
        "diagnose",
        "--model",
        str(f / "M.json"),
        "--data",
        str(f / bad),
        "--heldout",
        str(f / "D.csv"),
        "--report",
        str(f / "R.html"),
    ],
    "diagnose_heldout": lambda f, bad: [
        "diagnose",
        "--model",
        str(f / "M.json"),
        "--data",
        str(f / "D.csv"),
        "--heldout",
        str(f / bad),
        "--report",
        str(f / "R.html"),
    ],
}


@pytest.mark.parametrize("command", list(DATA_COMMANDS))
@pytest.mark.parametrize(("case", "make", "pattern"), BAD_DATA, ids=[c[0] for c in BAD_DATA])
def test_bad_dataset_is_refused_by_every_command(
    work: Path, capsys: pytest.CaptureFixture[str], command: str, case: str, make, pattern: str
) -> None:
    bad = make(work)
    line = assert_refused(DATA_COMMANDS[command](work, bad), work, pattern, capsys)
    assert line.startswith(f"dynid {command.split('_')[0]}: error: ")


@pytest.mark.parametrize(("case", "make", "pattern"), BAD_DATA, ids=[c[0] for c in BAD_DATA])
def test_bad_dataset_is_refused_by_the_api(work: Path, case: str, make, pattern: str) -> None:
    bad = make(work)
    before = snapshot(work)
    with pytest.raises(DataError, match=pattern) as err:
        load_dataset(work / bad, 6, robot_name="ur5")
    assert "\n" not in str(err.value)
    assert snapshot(work) == before


def test_byte_order_mark_is_read(base: Path, tmp_path: Path) -> None:
    path = tmp_path / "bom.csv"
    path.write_bytes(b"\xef\xbb\xbf" + (base / "D.csv").read_bytes())
    ds, ref = load_dataset(path, 6), load_dataset(base / "D.csv", 6)
    np.testing.assert_array_equal(ds.q, ref.q)
    np.testing.assert_array_equal(ds.tau, ref.tau)


def test_windows_line_ends_and_quoted_header_are_read(base: Path, tmp_path: Path) -> None:
    lines = (base / "D.csv").read_text().splitlines()
    lines[0] = ",".join(f'"{name}"' for name in lines[0].split(","))
    path = tmp_path / "crlf.csv"
    path.write_bytes("\r\n".join(lines).encode() + b"\r\n")
    np.testing.assert_array_equal(load_dataset(path, 6).tau, load_dataset(base / "D.csv", 6).tau)


def test_sample_logged_twice_is_dropped_with_a_warning(base: Path, tmp_path: Path) -> None:
    header, table = _table(base)
    _write(tmp_path / "dup.csv", header, np.insert(table, [5, 5, 300], table[[5, 5, 300]], axis=0))
    with pytest.warns(DataWarning, match=r"dup\.csv: 3 rows repeat the row before exactly \(first: row 6\)"):
        ds = load_dataset(tmp_path / "dup.csv", 6)
    np.testing.assert_array_equal(ds.q, load_dataset(base / "D.csv", 6).q)
    assert ds.meta["dropped_repeats"] == 3


def test_degrees_are_converted_when_asked(base: Path, tmp_path: Path) -> None:
    header, table = _table(base)
    table[:, 1:7] = np.rad2deg(table[:, 1:7])
    _write(tmp_path / "deg.csv", header, table)
    with warnings.catch_warnings():
        warnings.filterwarnings("error", message=".*degrees were asked for", category=DataWarning)
        ds = load_dataset(tmp_path / "deg.csv", 6, degrees=True)
    np.testing.assert_allclose(ds.q, load_dataset(base / "D.csv", 6).q, rtol=1e-14, atol=1e-15)
    assert ds.meta["converted_from_degrees"] is True
    np.testing.assert_array_equal(ds.tau, load_dataset(base / "D.csv", 6).tau)  # torques untouched


def test_degrees_asked_for_angles_in_radians_says_so(base: Path) -> None:
    """--degrees on a file in radians read every angle 57 times too small without a word."""
    with pytest.warns(DataWarning, match=r"D.csv: degrees were asked for \(--degrees\), but every angle lies within "
                      r"\+-[\d.]+, as angles in radians do; if the file is in radians, drop --degrees"):  # fmt: skip
        load_dataset(base / "D.csv", 6, degrees=True)


# One wrist joint alone: joint 5.  Joint 6 peaks at 0.12 N m on this short run, and in mN m (122) it stays
# under its bound (20 times a tenth of the largest joint's scale: 200 N m, room for a payload), which no
# check by magnitude can tell from a heavy tool.
@pytest.mark.parametrize(("columns", "joint"), [(slice(7, 13), 2), (slice(11, 12), 5)], ids=["all", "wrist"])
def test_torques_in_millinewton_metres_are_refused_given_the_robot(
    base: Path, tmp_path: Path, columns: slice, joint: int
) -> None:
    header, table = _table(base)
    table[:, columns] *= 1e3
    _write(tmp_path / "mNm.csv", header, table)
    ur5 = load_robot("ur5")
    pattern = (
        rf"mNm\.csv: tau_{joint} is .* N m at row \d+, more than 20 times the [\d.]+ N m the model of 'ur5'"
    )
    with pytest.raises(DataError, match=pattern):
        load_dataset(tmp_path / "mNm.csv", robot=ur5)
    assert load_dataset(tmp_path / "mNm.csv").m == ROWS  # without the robot nothing can tell
    assert load_dataset(base / "D.csv", robot=ur5).n == 6


def test_torque_scale_accepts_the_real_recordings(shared_data: Path) -> None:
    from dynid.data.adapters import load_recording, recording_model_path
    from dynid.data.files import check_torque_scale

    for name in ("panda_gaz2019", "tx40"):
        ds = load_recording(name)
        assert check_torque_scale(ds, load_robot(recording_model_path(name)), source=name) is ds


# ---------------------------------------------------------------------- bad robot descriptions
def _toml(folder: Path, old: str, new: str) -> str:
    text = (folder / "arm.toml").read_text()
    assert old in text
    (folder / "bad.toml").write_text(text.replace(old, new, 1))
    return "bad.toml"


def _urdf(folder: Path, old: str, new: str) -> str:
    text = (folder / "two.urdf").read_text()
    assert old in text
    (folder / "bad.urdf").write_text(text.replace(old, new, 1))
    return "bad.urdf"


BAD_ROBOTS: list[tuple[str, Callable[[Path], str], str]] = [
    (
        "negative_mass",
        lambda f: _toml(f, "m   = [5.0", "m   = [-5.0"),
        r"the link of joint 1 \('joint_1'\) of the robot 'my_arm' has mass -5 kg; a mass must be positive",
    ),
    (
        "negative_inertia",
        lambda f: _toml(f, "Ixx = [0.06", "Ixx = [-0.06"),
        r"principal moments of inertia \[-0\.06, 0\.03, 0\.05\].*has none negative.*fix Ixx\.\.Iyz",
    ),
    (
        "triangle_inequality",
        lambda f: _toml(f, "Izz = [0.03", "Izz = [0.2"),
        r"0\.2 exceeds the sum of the other two \(0\.11\), which no body can have \(the triangle inequality\)",
    ),
    (
        "short_alpha",
        lambda f: _toml(f, "alpha = [0.0, -1.5707963267948966, 1.5707963267948966]", "alpha = [0.0, -1.5707963267948966]"),
        r"column 'joints\.alpha' of the table '.*bad\.toml' has 2 values; the table has 3 joints",
    ),
    (
        "short_mass",
        lambda f: _toml(f, "m   = [5.0, 3.5, 2.0]", "m   = [5.0, 3.5]"),
        r"column 'links\.m' of the table '.*bad\.toml' has 2 values; the table has 3 joints",
    ),
    (
        "text_mass",
        lambda f: _toml(f, "m   = [5.0", 'm   = ["heavy"'),
        r"column 'links\.m' .* not a list of numbers",
    ),
    (
        "gravity_text",
        lambda f: _toml(f, 'name = "my_arm"', 'name = "my_arm"\ngravity = "down"'),
        r"'gravity'",
    ),
    ("tool_text", lambda f: _toml(f, "d = 0.06", 'd = "long"'), r"'tool\.d' in the table .* give a number"),
    (
        "joints_value",
        lambda f: _toml(f, "[joints]\n", "joints = 3\n[joints2]\n"),
        r"'joints' in the table .*value",
    ),
    ("types_value", lambda f: _toml(f, 'type  = ["R", "R", "P"]', 'type  = "RRP"'), r"must hold 'R' or 'P'"),
    ("bad_toml", lambda f: _toml(f, "[links]", "[links"), r"is not valid TOML"),
    (
        "alpha_in_degrees",
        lambda f: _toml(f, "alpha = [0.0, -1.5707963267948966, 1.5707963267948966]", "alpha = [0.0, -90.0, 90.0]"),
        r"column 'joints\.alpha' of the table '.*bad\.toml' holds -90 for joint 2, beyond the 6\.28319 rad of any "
        r"arm; give radians \(the angles look like degrees\)",
    ),
    (
        "length_in_millimetres",
        lambda f: _toml(f, "a     = [0.0, 0.05, 0.3]", "a     = [0.0, 50.0, 300.0]"),
        r"column 'joints\.a' .* holds 300 for joint 3, beyond the 100 m of any arm; give it in m",
    ),
    (
        "nan_theta",
        lambda f: _toml(f, "theta = [0.0", "theta = [nan"),
        r"column 'joints\.theta' of the table '.*bad\.toml' holds nan; give finite numbers",
    ),
    (
        "urdf_mimic",
        lambda f: _urdf(f, '<axis xyz="0 1 0"/>', '<axis xyz="0 1 0"/><mimic joint="j1" multiplier="1"/>'),
        r"joint 'j2' of the URDF file '.*bad\.urdf' mimics joint 'j1', but dynid models independent joints",
    ),
    (
        "urdf_negative_mass",
        lambda f: _urdf(f, '<mass value="1.0"/>', '<mass value="-1.0"/>'),
        r"has mass -1 kg",
    ),
    (
        "urdf_triangle",
        lambda f: _urdf(f, 'iyy="0.02" iyz="0" izz="0.01"', 'iyy="0.02" iyz="0" izz="0.09"'),
        r"joint 1 \('j1'\) .* 0\.09 exceeds the sum of the other two \(0\.04\)",
    ),
    ("urdf_broken", lambda f: _urdf(f, "</robot>", ""), r"could not be read"),
]

ROBOT_COMMANDS = {
    "info": lambda f, robot: ["info", "--robot", str(f / robot), "--json", str(f / "OUT.json")],
    "simulate": lambda f, robot: [
        "simulate",
        "--robot",
        str(f / robot),
        "--trajectory",
        str(f / "T3.json"),
        "--out",
        str(f / "OUT.csv"),
    ],
    "excite": lambda f, robot: [
        "excite",
        "--robot",
        str(f / robot),
        "--harmonics",
        "2",
        "--base-freq",
        "0.5",
        "--criterion",
        "seed",
        "--out",
        str(f / "T2.json"),
    ],
    "identify": lambda f, robot: [
        "identify",
        "--robot",
        str(f / robot),
        "--data",
        str(f / "D.csv"),
        "--out",
        str(f / "OUT.json"),
    ],
}


@pytest.mark.parametrize("command", list(ROBOT_COMMANDS))
@pytest.mark.parametrize(("case", "make", "pattern"), BAD_ROBOTS, ids=[c[0] for c in BAD_ROBOTS])
def test_bad_robot_is_refused_by_every_command(
    work: Path, capsys: pytest.CaptureFixture[str], command: str, case: str, make, pattern: str
) -> None:
    robot = make(work)
    assert_refused(ROBOT_COMMANDS[command](work, robot), work, pattern, capsys)


@pytest.mark.parametrize(("case", "make", "pattern"), BAD_ROBOTS, ids=[c[0] for c in BAD_ROBOTS])
def test_bad_robot_is_refused_by_the_api(work: Path, case: str, make, pattern: str) -> None:
    robot = make(work)
    with pytest.raises(RobotModelError, match=pattern) as err:
        load_robot(work / robot)
    assert "\n" not in str(err.value)


@pytest.mark.parametrize(
    ("argv", "pattern"),
    [
        (
            ["info", "--robot", "ur5", "--tool", "nosuchframe"],
            r"the model 'ur5' has no frame 'nosuchframe'; give --tool one of its frames: .*wrist_3_link.*tool0",
        ),
        (
            ["excite", "--robot", "ur5", "--tool", "nosuchframe", "--out", "{work}/T2.json"],
            r"has no frame 'nosuchframe'",
        ),
        (
            ["info", "--robot", "{work}/two.urdf", "--tool", "l3"],
            r"the model '.*two\.urdf' has no frame 'l3'; give --tool one of its frames: base, l1, l2, tip",
        ),
        (
            ["info", "--robot", "{work}/arm.toml", "--tool", "flange"],
            r"has one tool frame, 'tool', not 'flange'",
        ),
    ],
)
def test_unknown_tool_frame_is_refused(work: Path, capsys: pytest.CaptureFixture[str], argv, pattern) -> None:
    assert_refused([a.replace("{work}", str(work)) for a in argv], work, pattern, capsys)


def test_zero_mass_last_link_is_described_but_not_simulated(
    work: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    robot = _toml(work, "m   = [5.0, 3.5, 2.0]", "m   = [5.0, 3.5, 0.0]")
    text = (work / robot).read_text()
    for key, values in (("Ixx", "0.06, 0.02"), ("Iyy", "0.05, 0.07"), ("Izz", "0.03, 0.06")):
        text = re.sub(rf"^{key} = \[.*\]$", f"{key} = [{values}, 0.0]", text, flags=re.M)
    (work / robot).write_text(text)
    model = load_robot(work / robot)  # fine for info, excite and identify: they use the regressor only
    with pytest.raises(
        RobotModelError, match=r"joint 3 \('joint_3'\) .* carries no mass, inertia or armature"
    ):
        check_simulable(model)
    assert_refused(ROBOT_COMMANDS["simulate"](work, robot), work, r"joint 3 .* cannot be simulated", capsys)
    check_simulable(model.with_params(armature=np.array([0.1, 0.08, 0.01])))  # an armature moves it


def test_slightly_rounded_inertia_warns_and_loads(work: Path) -> None:
    robot = _toml(work, "Izz = [0.03", "Izz = [0.1105")
    with pytest.warns(
        RobotModelWarning, match=r"0\.1105 exceeds the sum of the other two \(0\.11\) by 0\.23%"
    ):
        model = load_robot(work / robot)
    assert model.params[9] == pytest.approx(0.1105 + 5.0 * (0.0**2 + 0.02**2))  # about the origin


def test_the_command_prints_a_warning_as_one_line_once(work: Path) -> None:
    """The console command shows dynid's warnings as ``dynid CMD: warning: ...``, one line each, once."""
    import subprocess
    import sys

    robot = _toml(work, "Izz = [0.03", "Izz = [0.1105")
    entry = "import sys; from dynid.cli import main; sys.exit(main())"
    proc = subprocess.run(
        [sys.executable, "-c", entry, "info", "--robot", str(work / robot)],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=work,
    )
    assert proc.returncode == 0, proc.stderr
    lines = [ln for ln in proc.stderr.splitlines() if "warning" in ln.lower()]
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith("dynid info: warning: ") and "0.1105 exceeds the sum of the other two" in lines[0]
    assert "RobotModelWarning" not in proc.stderr and ".py:" not in proc.stderr


def test_builtin_robots_are_physical() -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error", RobotModelWarning)
        for name in ("ur5", "ur10", "panda"):
            check_inertias(load_robot(name))


# ---------------------------------------------------------------------- property-based layer
def _settings(max_examples: int) -> settings:
    """Bounded, reproducible runs (the same examples every time), no per-example deadline."""
    return settings(
        max_examples=max_examples,
        deadline=None,
        derandomize=True,
        database=None,
        suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
    )


_CELL_VALUES = ["abc", "nan", "inf", "-inf", "1e308", "1e300", "", " ", "0x10", "1,5", "--1", "1e-320"]


def _mutate_text(text: str, data: st.DataObject, ops: list[str], *, separator: str = ",") -> str:
    """One to three random edits of a text table: the mutations a file meets on its way to dynid.

    The names of the edits made are appended to ``ops`` (for the statistics of the run).
    """
    for _ in range(data.draw(st.integers(1, 3), label="edits")):
        lines = text.split("\n")
        body = max(len(lines) - 2, 1)
        op = data.draw(
            st.sampled_from(
                [
                    "cell",
                    "delete_column",
                    "truncate",
                    "bom",
                    "separator",
                    "duplicate",
                    "swap",
                    "drop_line",
                    "blank_line",
                    "scale_column",
                    "bytes",
                ]
            ),
            label="op",
        )
        ops.append(op)
        row = data.draw(st.integers(0, body), label="row")
        if op == "cell":
            cells = lines[row].split(separator)
            cells[data.draw(st.integers(0, len(cells) - 1))] = data.draw(st.sampled_from(_CELL_VALUES))
            lines[row] = separator.join(cells)
        elif op == "delete_column":
            k = data.draw(st.integers(0, 20))
            lines = [
                separator.join(c for j, c in enumerate(line.split(separator)) if j != k) for line in lines
            ]
        elif op == "truncate":
            return text[: data.draw(st.integers(0, len(text)))]
        elif op == "bom":
            text = "\ufeff" + text
            continue
        elif op == "separator":
            new = data.draw(st.sampled_from([";", "\t", " ", "|"]))
            lines = [line.replace(separator, new) for line in lines]
        elif op == "duplicate":
            lines.insert(row, lines[data.draw(st.integers(0, body))])
        elif op == "swap":
            other = data.draw(st.integers(0, body))
            lines[row], lines[other] = lines[other], lines[row]
        elif op == "drop_line":
            del lines[row]
        elif op == "blank_line":
            lines.insert(row, "")
        elif op == "scale_column":
            k, factor = (
                data.draw(st.integers(0, 12)),
                data.draw(st.sampled_from([1e3, 57.29577951308232, -1.0])),
            )
            out = [lines[0]]
            for line in lines[1:]:
                cells = line.split(separator)
                try:
                    cells[k] = repr(float(cells[k]) * factor)
                except (IndexError, ValueError):
                    pass
                out.append(separator.join(cells))
            lines = out
        else:
            at = data.draw(st.integers(0, len(text)))
            junk = data.draw(st.binary(min_size=1, max_size=8)).decode("latin-1")
            text = text[:at] + junk + text[at:]
            continue
        text = "\n".join(lines)
    return text


@pytest.fixture(scope="module")
def small_csv(base: Path) -> str:
    """The dataset cut to its first rows: a small text to mutate (the API reads any length)."""
    return "\n".join((base / "D.csv").read_text().split("\n")[:60]) + "\n"


@_settings(400)
@given(data=st.data())
def test_property_mutated_csv_reads_or_is_refused(small_csv: str, tmp_path_factory, data) -> None:
    folder = tmp_path_factory.mktemp("csv")
    ops: list[str] = []
    text = _mutate_text(small_csv, data, ops)
    path = folder / "X.csv"
    path.write_bytes(
        text.encode("utf-8", errors="surrogateescape")
        if data.draw(st.booleans())
        else text.encode("latin-1", errors="replace")
    )
    before = snapshot(folder)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DataWarning)
            ds = load_dataset(path, 6, robot_name="ur5")
    except DynidError as err:
        event("outcome: refused in one sentence")
        assert "\n" not in str(err), str(err)
    else:  # accepted: what was read obeys the stated rule
        event(f"read after: {'+'.join(sorted(ops))}")
        assert ds.n == 6 and ds.m >= 2
        assert np.all(np.diff(ds.t) > 0) and np.median(np.diff(ds.t)) < 1.0
        assert np.abs(ds.q).max() <= 10.0 and np.abs(ds.tau).max() <= 1e6
    assert snapshot(folder) == before


@_settings(40)
@given(data=st.data())
def test_property_mutated_dataset_through_the_commands(
    base: Path, tmp_path_factory, capsys: pytest.CaptureFixture[str], data
) -> None:
    """identify or validate on a mutated dataset: exit 0 with a valid output, or exit 2 with one line."""
    from dynid.identify.model import load_model

    folder = tmp_path_factory.mktemp("cli")
    for name in ("M.json", *(p.name for p in base.glob("M*.npz"))):
        shutil.copy2(base / name, folder / name)
    ops: list[str] = []
    (folder / "X.csv").write_text(_mutate_text((base / "D.csv").read_text(), data, ops))
    shutil.copy2(base / "D.csv", folder / "P.csv")
    command = data.draw(st.sampled_from(["identify", "validate"]))
    if command == "identify":
        argv = [
            "identify",
            "--robot",
            "ur5",
            "--data",
            str(folder / "X.csv"),
            "--method",
            "ols",
            "--friction",
            "linear",
            "--gmm",
            "off",
            "--out",
            str(folder / "OUT.json"),
        ]
    else:
        argv = [
            "validate",
            "--model",
            str(folder / "M.json"),
            "--data",
            str(folder / "X.csv"),
            "--predictions",
            str(folder / "P.csv"),
        ]
    before = snapshot(folder)
    capsys.readouterr()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        code = main(argv)
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert code in (0, 2), err
    after = snapshot(folder)
    assert after["X.csv"] == before["X.csv"] and after["M.json"] == before["M.json"]
    assert not [name for name in after if name.endswith(".tmp")]
    event(f"outcome: {command} exit {code}" + (f" after {'+'.join(sorted(ops))}" if code == 0 else ""))
    if code == 2:
        assert len([line for line in err.splitlines() if line.strip()]) == 1, err
        assert after == before
    elif command == "identify":
        load_model(folder / "OUT.json")
    else:
        assert np.loadtxt(folder / "P.csv", delimiter=",", skiprows=1).shape[0] >= 2


@_settings(400)
@given(data=st.data())
def test_property_mutated_table_loads_or_is_refused(tmp_path_factory, data) -> None:
    folder = tmp_path_factory.mktemp("toml")
    text, ops = GOOD_TOML, []
    for _ in range(data.draw(st.integers(1, 3))):
        lines = text.split("\n")
        k = data.draw(st.integers(0, len(lines) - 1))
        op = data.draw(
            st.sampled_from(["value", "delete", "shorten", "truncate", "bom", "duplicate", "bytes"])
        )
        ops.append(op)
        if op == "value" and "[" in lines[k] and "=" in lines[k]:
            key, values = lines[k].split("=", 1)
            items = values.strip().strip("[]").split(",")
            j = data.draw(st.integers(0, len(items) - 1))
            items[j] = data.draw(
                st.sampled_from(["-1.0", "nan", "inf", "1e308", '"x"', "0.0", "-0.2", "10.0"])
            )
            lines[k] = f"{key}= [{', '.join(items)}]"
            ops[-1] = f"{key.strip()}[{j}]={items[j].strip()}"
        elif op == "delete":
            del lines[k]
        elif op == "shorten" and "," in lines[k]:
            lines[k] = lines[k].rsplit(",", 1)[0] + "]"
        elif op == "truncate":
            text = text[: data.draw(st.integers(0, len(text)))]
            continue
        elif op == "bom":
            text = "\ufeff" + text
            continue
        elif op == "duplicate":
            lines.insert(k, lines[k])
        elif op == "bytes":
            lines.insert(k, data.draw(st.binary(min_size=1, max_size=6)).decode("latin-1"))
        text = "\n".join(lines)
    path = folder / "arm.toml"
    path.write_text(text)
    before = snapshot(folder)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RobotModelWarning)
            model = load_robot(path)
    except DynidError as err:
        event("outcome: refused in one sentence")
        assert "\n" not in str(err), str(err)
    else:  # accepted: every link is a physical body
        event(f"loaded after: {'+'.join(sorted(ops))}")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RobotModelWarning)
            check_inertias(model)
        assert np.all(np.isfinite(model.params))
        assert all(np.isfinite(j.rotation).all() and np.isfinite(j.translation).all() for j in model.joints)
    assert snapshot(folder) == before


@_settings(150)
@given(data=st.data())
def test_property_mutated_model_file_loads_or_is_refused(base: Path, tmp_path_factory, data) -> None:
    from dynid.identify.model import load_model

    folder = tmp_path_factory.mktemp("model")
    for p in base.glob("M*"):
        (shutil.copytree if p.is_dir() else shutil.copy2)(p, folder / p.name)
    files = sorted(str(p.relative_to(folder)) for p in folder.rglob("*") if p.is_file())
    target = folder / data.draw(st.sampled_from(files))
    raw = target.read_bytes()
    op = data.draw(st.sampled_from(["truncate", "flip", "delete_key", "number"]))
    if op == "truncate":
        raw = raw[: data.draw(st.integers(0, len(raw) - 1))]
    elif op == "flip":
        at = data.draw(st.integers(0, len(raw) - 1))
        raw = raw[:at] + bytes([raw[at] ^ 0xFF]) + raw[at + 1 :]
    elif op == "delete_key" and target.suffix == ".json":
        keys = re.findall(rb'"(\w+)":', raw)
        key = data.draw(st.sampled_from(keys))
        raw = re.sub(rb'"' + key + rb'":', b'"renamed_' + key + b'":', raw, count=1)
    elif op == "number" and target.suffix == ".json":
        numbers = list(re.finditer(rb"-?\d+\.\d+(e-?\d+)?", raw)) or [None]
        found = data.draw(st.sampled_from(numbers))
        if found is not None:
            raw = (
                raw[: found.start()]
                + data.draw(st.sampled_from([b"NaN", b"1e999", b'"x"']))
                + raw[found.end() :]
            )
    target.write_bytes(raw)
    before = snapshot(folder)
    try:
        load_model(folder / "M.json")
    except DynidError as err:
        event("outcome: refused in one sentence")
        assert "\n" not in str(err), str(err)
    else:
        event(f"loaded after: {op} of {target.name}")
    assert snapshot(folder) == before


def test_a_model_file_with_any_one_key_renamed_loads_or_is_refused(base: Path, tmp_path: Path) -> None:
    """Every key of M.json renamed in turn (its first occurrence): a load or one sentence, never a traceback."""
    from dynid.identify.model import load_model

    raw = (base / "M.json").read_bytes()
    keys = sorted(set(re.findall(rb'"(\w+)":', raw)))
    assert b"source" in keys and len(keys) > 20
    unexpected, refused = [], 0
    for key in keys:
        folder = tmp_path / key.decode()
        folder.mkdir()
        for p in base.glob("M*"):
            (shutil.copytree if p.is_dir() else shutil.copy2)(p, folder / p.name)
        (folder / "M.json").write_bytes(re.sub(rb'"' + key + rb'":', b'"renamed_' + key + b'":', raw, count=1))
        try:
            load_model(folder / "M.json")
        except DynidError as err:
            refused += 1
            assert "\n" not in str(err), str(err)
        except Exception as err:  # the point: nothing else may escape
            unexpected.append(f"{key.decode()}: {type(err).__name__}: {err}")
    assert unexpected == []
    assert refused > 0  # the required keys are refused, not silently defaulted
