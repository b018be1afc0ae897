"""The cases of issue 39's fuzz (hangs, crashes, memory, tracebacks, bad input that exited 0), held as a table.

Each case is a command line on a folder of inputs with a pre-existing output; the contract is that of
``tests/commands/test_bad_inputs.py``: exit code 2, one line on stderr naming what was expected, no traceback,
every file of the folder byte-identical and nothing added.  Cases that need the environment (a matplotlib
backend, a file-descriptor limit, dynid's cache) follow the table.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from dynid.cli import main
from dynid.exceptions import CacheWarning, DataError, RobotModelError, UsageError
from dynid.symbolic.robot import load_robot
from tests.conftest import DH_TABLE, assert_refused, snapshot

ROWS = 1100

LOOP_URDF = """\
<?xml version="1.0"?>
<robot name="loop">
  <link name="base_link"/>
  <link name="l1"><inertial><mass value="1"/>
    <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>
  <link name="l2"><inertial><mass value="1"/>
    <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>
  <joint name="j1" type="revolute"><parent link="base_link"/><child link="l1"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><axis xyz="0 1 0"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
  JOINT
</robot>
"""


EMPTY_TABLE = (
    'name = "none"\n[joints]\ntype = []\nalpha = []\na = []\nd = []\ntheta = []\n[links]\nm = []\ncx = []\n'
    "cy = []\ncz = []\nIxx = []\nIyy = []\nIzz = []\nIxy = []\nIxz = []\nIyz = []\n"
)


# ---------------------------------------------------------------------- fixtures
@pytest.fixture(scope="module")
def base(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A UR5 trajectory, a short simulated dataset, a copy of the UR5's URDF and a 3-joint table."""
    from dynid.optim.excitation import ExcitationProblem
    from dynid.sim.simulator import build_truth, simulate, write_simulation
    from dynid.symbolic.robot import BUILTIN_ROBOTS, example_robot_data_dir

    folder = tmp_path_factory.mktemp("fuzz")
    robot = load_robot("ur5")
    trajectory = ExcitationProblem(robot=robot, harmonics=2, base_freq=0.5).random_trajectory(
        np.random.default_rng(0)
    )
    trajectory.save(folder / "T.json")
    truth = build_truth(robot, friction="linear", truth_seed=0)
    run = simulate(robot, trajectory, truth=truth, seed=1, duration=(ROWS - 1) / 1000.0)
    write_simulation(run, folder / "D.csv")
    (folder / "D.csv.truth.json").unlink()
    shutil.copy2(example_robot_data_dir() / BUILTIN_ROBOTS["ur5"]["urdf"], folder / "ur5.urdf")
    (folder / "M.json").write_text("{}\n")  # only read after the checks these cases fail
    (folder / "rec" / "r1").mkdir(parents=True)  # a fleet: <robot>/<date>.csv
    for date in ("2024-01-01", "2024-02-01"):
        shutil.copy2(folder / "D.csv", folder / "rec" / "r1" / f"{date}.csv")
    return folder


@pytest.fixture
def work(base: Path, tmp_path: Path) -> Path:
    for p in base.iterdir():
        (shutil.copytree if p.is_dir() else shutil.copy2)(p, tmp_path / p.name)
    shutil.copy2(base / "D.csv", tmp_path / "OUT.csv")
    shutil.copy2(base / "T.json", tmp_path / "OUT.json")
    return tmp_path






# ---------------------------------------------------------------------- helpers making bad inputs
def _write(folder: Path, name: str, text: str) -> str:
    (folder / name).write_text(text)
    return str(folder / name)


def _urdf_edit(folder: Path, pattern: str, new: str) -> str:
    text = (folder / "ur5.urdf").read_text()
    changed = re.sub(pattern, new, text, count=1)
    assert changed != text
    return _write(folder, "bad.urdf", changed)


def _zero_torques(folder: Path) -> str:
    lines = (folder / "D.csv").read_text().splitlines()
    header = lines[0].split(",")
    cols = [k for k, name in enumerate(header) if name.startswith("tau_")]
    out = [lines[0]]
    for line in lines[1:]:
        cells = line.split(",")
        for k in cols:
            cells[k] = "0"
        out.append(",".join(cells))
    return _write(folder, "Z.csv", "\n".join(out) + "\n")


def _fifo(folder: Path) -> str:
    os.mkfifo(folder / "F.csv")
    return str(folder / "F.csv")


def _dev_zero(folder: Path) -> str:
    (folder / "Z.csv").symlink_to("/dev/zero")
    return str(folder / "Z.csv")


def _transmission(folder: Path, body: str) -> str:
    return _write(folder, "tr.toml", "[transmission]\n" + body + "\n")


def _identify(folder: Path, *extra: str, data: str | None = None) -> list[str]:
    return [
        "identify",
        "--robot",
        "ur5",
        "--data",
        data or str(folder / "D.csv"),
        "--method",
        "ols",
        "--friction",
        "linear",
        "--gmm",
        "off",
        "--out",
        str(folder / "OUT.json"),
        *extra,
    ]


def _simulate(folder: Path, *extra: str) -> list[str]:
    return [
        "simulate",
        "--robot",
        "ur5",
        "--trajectory",
        str(folder / "T.json"),
        "--out",
        str(folder / "OUT.csv"),
        *extra,
    ]


def _excite(folder: Path, *extra: str) -> list[str]:
    return [
        "excite",
        "--robot",
        "ur5",
        "--harmonics",
        "2",
        "--base-freq",
        "0.5",
        "--out",
        str(folder / "OUT.json"),
        *extra,
    ]


# (id, argv maker(folder) -> argv, pattern of the one line)
CASES = [
    # -- hang, crashes, memory
    (
        "simulate_elasticity_1e-9",
        lambda f: _simulate(f, "--effects", "elasticity@2:1e-9"),
        r"the size of the effect 'elasticity' is 1e-09; it must be at least 0\.01 \(the locked-motor resonance",
    ),
    (
        "excite_base_freq_1e-6",
        lambda f: [*_excite(f), "--base-freq", "1e-6"],
        r"base_freq is 1e-06 Hz, a period of 1e\+06 s; give at least 0\.01 Hz",
    ),
    (
        "urdf_joint_child_is_base_link",
        lambda f: [
            "info",
            "--robot",
            _urdf_edit(
                f,
                r"</robot>",
                '<joint name="loop" type="revolute"><parent '
                'link="wrist_3_link"/><child link="base_link"/><axis xyz="0 0 1"/><limit lower="-1" upper="1" '
                'effort="1" velocity="1"/></joint></robot>',
            ),
        ],
        r"link 'base_link' of the URDF file '.*bad\.urdf' is the child of two joints, 'world_joint' and 'loop'",
    ),
    (
        "urdf_loop",
        lambda f: [
            "info",
            "--robot",
            _write(
                f,
                "loop.urdf",
                LOOP_URDF.replace(
                    "JOINT",
                    (
                        '<joint name="j3" type="revolute"><parent link="l2"/><child link="base_link"/><axis xyz="0 0 1"/>'
                        '<limit lower="-1" upper="1" effort="1" velocity="1"/></joint>'
                    ),
                ),
            ),
        ],
        r"joint '.*' of the URDF file '.*loop\.urdf' closes a loop: .*a URDF is a tree",
    ),
    (
        "data_symlink_to_dev_zero",
        lambda f: _identify(f, data=_dev_zero(f)),
        r"Z\.csv is not a regular file but a device, pipe or socket.*save the recording to a \.csv",
    ),
    (
        "data_fifo",
        lambda f: _identify(f, data=_fifo(f)),
        r"F\.csv is not a regular file but a device, pipe or socket",
    ),
    (
        "simulate_duration_1e6",
        lambda f: _simulate(f, "--duration", "1e6"),
        r"the duration 1e\+06 s .* beyond the 1,000,000 that one run holds in memory; give at most 999\.999 s",
    ),
    (
        "simulate_duration_1e9",
        lambda f: _simulate(f, "--duration", "1e9"),
        r"beyond the 1,000,000 that one run holds",
    ),
    (
        "excite_rest_1e6_csv",
        lambda f: _excite(f, "--rest", "1e6", "--csv", str(f / "OUT.csv")),
        r"the CSV .* would last 2e\+06 s, 1e\+09 samples at 500 Hz, beyond the 1,000,000 dynid writes in one file",
    ),
    # -- tracebacks
    (
        "transmission_ratio_1e300",
        lambda f: _identify(f, "--transmission", _transmission(f, "coupled = [[5, 6, 1e300]]")),
        r"couples motor 6 to joint 5 at ratio 1e\+300, beyond \+-1000",
    ),
    (
        "identify_stribeck_vs_nan",
        lambda f: _identify(f, "--effects", "stribeck@3:vs=nan"),
        r"the hyper-parameter vs of the effect 'stribeck@3:vs=nan' is nan; give a positive Stribeck speed",
    ),
    (
        "identify_coupled_friction_sign_nan",
        lambda f: _identify(f, "--effects", "coupled_friction@5+6:sign=nan"),
        r"the hyper-parameter sign of .* is nan; give the coupling sign, 1 or -1",
    ),
    (
        "identify_torques_all_zero",
        lambda f: _identify(f, data=_zero_torques(f)),
        r"Z\.csv: tau_1 \(and 5 more\) holds 0 N m in every one of its 1100 rows.*dead or unplugged",
    ),
    (
        "simulate_seed_-1",
        lambda f: _simulate(f, "--seed", "-1"),
        r"the seed is -1; give a whole number of at least 0",
    ),
    (
        "demo_seed_-1",
        lambda f: ["demo", "--quick", "--seed", "-1", "--out", str(f / "demo")],
        r"--seed is -1; give a whole number of at least 0",
    ),
    (
        "excite_seed_-1",
        lambda f: _excite(f, "--seed", "-1"),
        r"--seed is -1; give a whole number of at least 0",
    ),
    (
        "dh_table_zero_joints",
        lambda f: ["info", "--robot", _write(f, "none.toml", EMPTY_TABLE)],
        r"the table '.*none\.toml' lists no joint",
    ),
    (
        "excite_backend_nonexistent",
        lambda f: _excite(f, "--backend", "nonexistent"),
        r"the joblib backend 'nonexistent' is unknown; give one of .*loky",
    ),
    (
        "excite_speed_fraction_1e-6_csv",
        lambda f: _excite(f, "--speed-fraction", "1e-6", "--csv", str(f / "OUT.csv")),
        r"--speed-fraction is 1e-06; give a fraction of the robot's limits from 0\.01 to 1",
    ),
    (
        "fleet_scheduler_invalid_json",
        lambda f: [
            "fleet",
            "--robot",
            "ur5",
            "--data",
            str(f / "rec" / "**" / "*.csv"),
            "--out",
            str(f / "fleet"),
            "--scheduler",
            _write(f, "sched.json", "{bad"),
        ],
        r"the scheduler file '.*sched\.json' is not valid JSON",
    ),
    (
        "fleet_scheduler_json_list",
        lambda f: [
            "fleet",
            "--robot",
            "ur5",
            "--data",
            str(f / "rec" / "**" / "*.csv"),
            "--out",
            str(f / "fleet"),
            "--scheduler",
            _write(f, "sched.json", "[1, 2]\n"),
        ],
        r"the scheduler file '.*sched\.json' holds a JSON list, not the object with the 'address'",
    ),
    (
        "diagnose_max_effects_-1",
        lambda f: [
            "diagnose",
            "--model",
            str(f / "M.json"),
            "--data",
            str(f / "D.csv"),
            "--heldout",
            str(f / "D.csv"),
            "--max-effects",
            "-1",
        ],
        r"--max-effects is -1; give a whole number of at least 0",
    ),
    # -- exit 0 on bad input: effect sizes and hyper-parameters
    (
        "identify_stribeck_vs_-1",
        lambda f: _identify(f, "--effects", "stribeck@3:vs=-1"),
        r"vs of .* is -1; give a positive",
    ),
    (
        "identify_unknown_hyper",
        lambda f: _identify(f, "--effects", "stribeck@3:foo=1"),
        r"has the hyper-parameter 'foo', which stribeck does not take \(it takes: vs\)",
    ),
    (
        "identify_cogging_N_0",
        lambda f: _identify(f, "--effects", "cogging@2:N=0"),
        r"N of .* is 0; give the ripple",
    ),
    (
        "identify_cogging_N_inf",
        lambda f: _identify(f, "--effects", "cogging@2:N=inf"),
        r"N of .* is inf; give",
    ),
    (
        "identify_temperature_T_0",
        lambda f: _identify(f, "--effects", "temperature@1:T=0"),
        r"T of .* is 0; give",
    ),
    (
        "identify_delay_d_1e9",
        lambda f: _identify(f, "--effects", "delay@1:d=1e9"),
        r"d of .* is 1e\+09; give a delay",
    ),
    (
        "identify_delay_d_beyond_a_second_early",  # -0.01 is an actuator delay (the torque leads): allowed
        lambda f: _identify(f, "--effects", "delay@1:d=-2"),
        r"d of .* is -2; give a delay",
    ),
    (
        "identify_backlash_eps_0",
        lambda f: _identify(f, "--effects", "backlash@4:eps=0"),
        r"eps of .* is 0; give",
    ),
    (
        "identify_elasticity_w_0",
        lambda f: _identify(f, "--effects", "elasticity@3:w=0"),
        r"w of .* is 0; give",
    ),
    (
        "simulate_offset_1e300",
        lambda f: _simulate(f, "--effects", "offset:1e300"),
        r"the size of the effect 'offset' is 1e\+300; it must stay below 100",
    ),
    (
        "simulate_delay_1e6",
        lambda f: _simulate(f, "--effects", "delay:1e6"),
        r"the size of the effect 'delay' is 1e\+06; it must stay below 250 \(a delay of 4 ms VALUE must stay below 1 s",
    ),
    # -- URDF limits the TOML and the command line refuse
    (
        "urdf_lower_above_upper",
        lambda f: ["info", "--robot", _urdf_edit(f, r'lower="[^"]*" upper="[^"]*"', 'lower="3" upper="-3"')],
        r"joint 'shoulder_pan_joint' of the URDF file '.*bad\.urdf' has the lower limit 3 rad above its upper limit -3",
    ),
    (
        "urdf_velocity_0",
        lambda f: ["info", "--robot", _urdf_edit(f, r'velocity="[^"]*"', 'velocity="0"')],
        r"joint 'shoulder_pan_joint' .* has the velocity limit 0 rad/s; give a positive velocity",
    ),
    # -- transmission tables
    (
        "transmission_singular",
        lambda f: _identify(f, "--transmission", _transmission(f, "coupled = [[5, 6, 1], [6, 5, 1]]")),
        r"the transmission of '.*tr\.toml' is singular \(condition number",
    ),
    (
        "transmission_duplicate",
        lambda f: _identify(f, "--transmission", _transmission(f, "coupled = [[5, 6, 1], [5, 6, 2]]")),
        r"couples motor 6 to joint 5 twice; give each pair once",
    ),
    (
        "transmission_boolean_joint",
        lambda f: _identify(f, "--transmission", _transmission(f, "coupled = [[true, 6, 1]]")),
        r"the entry \[True, 6, 1\] of 'transmission\.coupled' .* \(numbers, not text or true/false\)",
    ),
    (
        "transmission_string_ratio",
        lambda f: _identify(f, "--transmission", _transmission(f, 'coupled = [[5, 6, "1"]]')),
        r"the entry \[5, 6, '1'\] of 'transmission\.coupled'",
    ),
    (
        "transmission_matrix_with_strings",
        lambda f: _identify(
            f,
            "--transmission",
            _transmission(
                f,
                "matrix = ["
                + ", ".join(
                    "["
                    + ", ".join('"1"' if i == j == 0 else ("1" if i == j else "0") for j in range(6))
                    + "]"
                    for i in range(6)
                )
                + "]",
            ),
        ),
        r"the transmission of '.*tr\.toml' is not a matrix of numbers",
    ),
    (
        "transmission_unknown_key",
        lambda f: _identify(f, "--transmission", _transmission(f, "coupled = [[5, 6, 1]]\ncouple = 3")),
        r"has the unknown key 'couple'; it holds 'coupled' or 'matrix' only",
    ),
    (
        "transmission_coupled_empty",
        lambda f: _identify(f, "--transmission", _transmission(f, "coupled = []")),
        r"'transmission\.coupled' in '.*tr\.toml' is empty",
    ),
]


@pytest.mark.parametrize(("case", "make", "pattern"), CASES, ids=[c[0] for c in CASES])
def test_issue_case_is_refused_in_one_sentence(
    work: Path, capsys: pytest.CaptureFixture[str], case: str, make, pattern: str
) -> None:
    argv = make(work)
    line = assert_refused(argv, work, pattern, capsys)
    assert line.startswith(f"dynid {argv[0]}: error: ")


# ---------------------------------------------------------------------- the APIs behind the commands
def test_effect_hyper_parameters_keep_their_case() -> None:
    """``cogging@2:N=100`` sets N (it was read as an unknown 'n' and N tuned instead)."""
    from dynid.identify.effect_terms import parse_effect_terms

    cog, temp = parse_effect_terms("cogging@2:N=100,temperature@1:t=5", 6)
    assert cog.hyper == {"N": 100.0}
    assert temp.hyper == {"T": 5.0}


def test_simulation_effect_bounds_are_stated() -> None:
    from dynid.sim.effects import parse_effects

    assert parse_effects("elasticity@2:0.01,offset:99,delay:249")[0].value == 0.01
    with pytest.raises(UsageError, match=r"'armature' is 100; it must stay below 100"):
        parse_effects("armature:100")


def test_simulate_api_refuses_long_runs_and_negative_seeds(base: Path) -> None:
    from dynid.optim.trajectory import load_trajectory
    from dynid.sim.simulator import MAX_TICKS, simulate

    robot, trajectory = load_robot("ur5"), load_trajectory(base / "T.json")
    with pytest.raises(UsageError, match=rf"beyond the {MAX_TICKS:,} that one run holds"):
        simulate(robot, trajectory, duration=MAX_TICKS / 1000.0)
    with pytest.raises(UsageError, match=r"the truth seed is -3"):
        simulate(robot, trajectory, duration=0.01, truth_seed=-3)


def test_dead_torque_channel_is_refused_by_the_reader(base: Path, tmp_path: Path) -> None:
    from dynid.data.files import load_dataset

    lines = (base / "D.csv").read_text().splitlines()
    k = lines[0].split(",").index("tau_4")
    out = [lines[0]] + [
        ",".join(c if j != k else "0.25" for j, c in enumerate(line.split(","))) for line in lines[1:]
    ]
    (tmp_path / "stuck.csv").write_text("\n".join(out) + "\n")
    with pytest.raises(DataError, match=r"stuck\.csv: tau_4 holds 0\.25 N m in every one of its 1100 rows"):
        load_dataset(tmp_path / "stuck.csv", 6)


def test_transmission_tables_that_hold() -> None:
    """A valid coupling still loads; a matrix given in full too."""
    from dynid.symbolic.transmission import transmission_table

    R = transmission_table({"coupled": [[5, 6, 1.0]]}, 6, "t")
    assert R[5, 4] == 1.0 and np.trace(R) == 6
    np.testing.assert_array_equal(transmission_table({"matrix": np.eye(3).tolist()}, 3, "t"), np.eye(3))
    with pytest.raises(RobotModelError, match=r"has both 'matrix' and 'coupled'"):
        transmission_table({"matrix": np.eye(3).tolist(), "coupled": [[1, 2, 1.0]]}, 3, "t")


def test_robot_names_become_c_identifiers_and_c_text() -> None:
    from dynid.symbolic.export import _c_text, c_identifier

    assert c_identifier("ur5") == "ur5" and c_identifier("tx40-mdh") == "tx40_mdh"
    assert c_identifier("bras-é") == "bras"
    assert c_identifier('we"ird*/x') == "we_ird_x"
    assert c_identifier("é") == "robot" and c_identifier("3dof") == "r_3dof"
    assert "*/" not in _c_text("a */ b")
    assert _c_text('a"b%c\\', literal=True) == 'a\\"b%%c\\\\'


@pytest.mark.parametrize("name", ["bras-é", 'x */ y \\" %s'], ids=["non_ascii", "quote_comment_percent"])
def test_export_c_of_a_robot_with_an_odd_name(
    tmp_path: Path, name: str, capsys: pytest.CaptureFixture[str]
) -> None:
    robot = tmp_path / "arm.toml"
    robot.write_text(DH_TABLE.replace("my_arm", name))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        code = main(["export-c", "--robot", str(robot), "--out", str(tmp_path / "c")])
    err = capsys.readouterr().err
    assert code == 0 and "Traceback" not in err, err
    example = (tmp_path / "c" / "example.c").read_text()
    assert example.count("/*") == example.count("*/")  # the name closes no comment
    cc = shutil.which("cc") or shutil.which("gcc")
    if cc is not None:  # the example compiles: the name is safe in its comment and its printf
        lib = next((tmp_path / "c").glob("dynid_*.c")).name
        proc = subprocess.run(
            [cc, "-O0", "example.c", lib, "-o", "example", "-lm"],
            cwd=tmp_path / "c",
            capture_output=True,
            text=True,
        )
        assert proc.returncode == 0, proc.stderr
        run = subprocess.run(["./example"], cwd=tmp_path / "c", capture_output=True, text=True)
        assert run.stdout.startswith(f"Y_b of {name.replace('*/', '* /').replace(chr(92), '')}")


def test_too_few_open_files_for_a_local_cluster_is_refused(monkeypatch: pytest.MonkeyPatch) -> None:
    import resource

    from dynid._cluster import _ensure_open_files

    monkeypatch.setattr(resource, "getrlimit", lambda kind: (40, 40))
    monkeypatch.setattr(resource, "setrlimit", lambda kind, limits: None)
    with pytest.raises(
        UsageError, match=r"the limit of open files is 40 \(ulimit -n\).* needs at least 96.*--serial"
    ):
        _ensure_open_files(2)
    raised = []
    monkeypatch.setattr(resource, "getrlimit", lambda kind: (40, 100_000))
    monkeypatch.setattr(resource, "setrlimit", lambda kind, limits: raised.append(limits))
    _ensure_open_files(2)  # a soft limit below the need is raised to it, within the hard limit
    assert raised == [(384, 100_000)]


def _command(args: list[str], cwd: Path, **env: str) -> subprocess.CompletedProcess[str]:
    entry = "import sys; from dynid.cli import main; sys.exit(main())"
    return subprocess.run(
        [sys.executable, "-c", entry, *args],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=cwd,
        env={**os.environ, **env},
    )


def test_unknown_matplotlib_backend_is_refused(work: Path) -> None:
    before = snapshot(work)
    proc = _command(
        [
            "validate",
            "--model",
            str(work / "M.json"),
            "--data",
            str(work / "D.csv"),
            "--report",
            str(work / "R.html"),
        ],
        work,
        MPLBACKEND="nope",
    )
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert proc.returncode == 2 and len(lines) == 1, proc.stderr
    assert re.match(
        r"dynid validate: error: the environment variable MPLBACKEND is 'nope'.*set it to Agg", lines[0]
    )
    assert snapshot(work) == before


def test_fleet_with_40_open_files_is_refused(work: Path) -> None:
    """``ulimit -n 40`` then fleet: one sentence, not hundreds of event-loop tracebacks."""
    import resource

    before = snapshot(work)
    entry = (
        "import resource, sys; resource.setrlimit(resource.RLIMIT_NOFILE, (40, 40)); "
        "from dynid.cli import main; sys.exit(main())"
    )
    proc = subprocess.run(
        [
            sys.executable,
            "-c",
            entry,
            "fleet",
            "--robot",
            "ur5",
            "--data",
            str(work / "rec" / "**" / "*.csv"),
            "--out",
            str(work / "fl"),
        ],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=work,
    )
    del resource
    lines = [line for line in proc.stderr.splitlines() if line.strip() and "working" not in line]
    assert proc.returncode == 2, proc.stderr[-2000:]
    assert len(lines) == 1 and "the limit of open files is 40" in lines[0], proc.stderr[-2000:]
    assert snapshot(work) == before


# ---------------------------------------------------------------------- a damaged cache
def test_truncated_library_is_detected() -> None:
    from dynid.symbolic.export import _elf_damage, compiled_functions

    lib = compiled_functions(load_robot("ur5"), progress=None)
    data = (lib.folder / lib.manifest["library"]).read_bytes()
    assert _elf_damage(data, "lib.so") is None
    for size in (10, 100, len(data) // 2, len(data) - 1):
        assert re.search(r"cut short|not a shared library", _elf_damage(data[:size], "lib.so") or ""), size


@pytest.fixture
def private_cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A copy of dynid's cache (the generator and the UR5's files) as $DYNID_CACHE_DIR, in-process caches empty."""
    from dynid.symbolic import export, functions
    from dynid.symbolic.build import cache_dir

    ur5 = load_robot("ur5")
    lib = export.compiled_functions(ur5, progress=None)
    funcs = functions.robot_functions(ur5, progress=None)
    root = cache_dir()
    cache = tmp_path / "cache"
    shutil.copytree(root / "generator", cache / "generator")
    shutil.copytree(funcs.folder, cache / "robots" / funcs.folder.name)
    shutil.copytree(lib.folder, cache / "compiled" / lib.folder.name)
    monkeypatch.setenv("DYNID_CACHE_DIR", str(cache))
    monkeypatch.setattr(functions, "_CACHE", {})
    monkeypatch.setattr(export, "_COMPILED", {})
    return cache


def test_truncated_compiled_library_is_rebuilt_and_said(private_cache: Path) -> None:
    from dynid.symbolic.export import compiled_functions

    (so,) = private_cache.glob("compiled/*/lib*.so")
    so.write_bytes(so.read_bytes()[: so.stat().st_size // 2])
    with pytest.warns(
        CacheWarning, match=r"the compiled library cached in .* was damaged \(.*cut short\); it was built"
    ):
        lib = compiled_functions(load_robot("ur5"), progress=None)
    q = np.full((3, 6), 0.1)
    assert lib.base_regressor(q, q, q).shape[:2] == (3, 6)


def test_garbage_casadi_file_is_regenerated_and_said(private_cache: Path) -> None:
    from dynid.symbolic.functions import robot_functions

    first = sorted(private_cache.glob("robots/*/*.casadi"))[0]
    first.write_bytes(b"garbage, not a CasADi function\n" * 10)
    with pytest.warns(
        CacheWarning, match=r"the cached CasADi functions of the robot 'ur5' .* generated again"
    ):
        funcs = robot_functions(load_robot("ur5"), progress=None)
    assert funcs.regressor_numeric(np.zeros(6), np.zeros(6), np.zeros(6)).shape[-2:] == (6, 60)


@pytest.mark.parametrize("version", [-1, 0, 3.5, True, "3"])
def test_a_model_file_with_a_version_dynid_never_wrote_is_refused(tmp_path: Path, version) -> None:
    """The fuzz's model files of version -1, 0 and 3.5 loaded (exit 0); they are refused in one sentence."""
    import json

    from dynid.exceptions import ModelFileError
    from dynid.identify.model import load_model

    doc = {"format": "dynid-model", "version": version, "robot": {"source": "ur5"}, "arrays": "M.npz"}
    (tmp_path / "M.json").write_text(json.dumps(doc))
    with pytest.raises(ModelFileError, match=r"says it is model file version .*; dynid writes whole versions 1 to"):
        load_model(tmp_path / "M.json")
