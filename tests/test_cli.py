"""The dynid command: subcommands run, figures land in --json, mistakes end in one sentence."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from dynid.cli import main


def test_help_lists_the_commands(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    for command in ("demo", "info", "export-c"):
        assert command in out


def test_info_writes_its_figures(tmp_path, capsys):
    figures = tmp_path / "ur5.json"
    assert main(["info", "--robot", "ur5", "--dq-max", "1.5", "--json", str(figures)]) == 0
    data = json.loads(figures.read_text())
    assert data["n_base"] == 36
    assert data["limits"]["dq_max"] == [1.5] * 6
    assert len(data["base_parameters"]) == 36
    assert "36 base parameters" in capsys.readouterr().out


def test_export_c_command(tmp_path, capsys):
    out = tmp_path / "panda_c"
    assert (
        main(["export-c", "--robot", "panda", "--out", str(out), "--functions", "base_regressor,rnea"]) == 0
    )
    manifest = json.loads((out / "manifest.json").read_text())
    assert [f["name"] for f in manifest["functions"]] == ["base_regressor", "rnea"]
    assert (out / "libdynid_panda.so").is_file()


def test_export_c_of_a_model(tmp_path, capsys):
    """``--model``: the model's prediction as C, reload-checked, its robot functions only when asked for."""
    import numpy as np

    from dynid.identify.columns import column_set
    from dynid.identify.model import identify, save_model
    from dynid.sim.synthetic import random_fourier, synthetic_dataset, true_parameters
    from dynid.symbolic import load_robot
    from dynid.symbolic.export import CompiledLibrary

    robot = load_robot("ur5")
    rng = np.random.default_rng(2)
    cols = column_set(robot)
    data = synthetic_dataset(
        cols, true_parameters(cols, rng), random_fourier(robot, rng), rate=50, rng=rng, noise=0.01
    )
    model = identify(robot, data, method="ols", friction="linear", gmm="off", rounds=0)
    save_model(model, tmp_path / "M.json")
    out = tmp_path / "ur5_model_c"
    capsys.readouterr()
    assert (
        main(["export-c", "--model", str(tmp_path / "M.json"), "--out", str(out), "--functions", "fk"]) == 0
    )
    printed = capsys.readouterr().out
    assert (
        "predict(q, dq, ddq) -> tau carries: rigid body (36 base parameters); armature (layer 1)" in printed
    )
    assert "reload check passed" in printed and "not carried: nothing" in printed
    manifest = json.loads((out / "manifest.json").read_text())
    assert [f["name"] for f in manifest["functions"]] == ["predict", "model_regressor", "fk"]
    assert manifest["model"]["file"] == "M.json" and manifest["check"]["passed"] is True
    q = rng.uniform(robot.q_min, robot.q_max, size=(20, 6))
    dq, ddq = rng.normal(size=(2, 20, 6))
    np.testing.assert_allclose(CompiledLibrary(out).predict(q, dq, ddq), model.predict(q, dq, ddq), rtol=1e-9)


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (
            ["info", "--robot", "ur6"],
            r"dynid info: error: unknown robot 'ur6'; give a built-in name \(ur5, ur10, panda\)",
        ),
        (["info", "--robot", "ur5", "--dq-max", "1,2"], r"dq_max has 2 values; the robot 'ur5' has 6 joints"),
        (
            ["info", "--robot", "ur5", "--dq-max", "fast"],
            r"--dq-max is 'fast'; give numbers separated by commas",
        ),
        (
            ["export-c", "--robot", "ur5", "--out", "/nonexistent/dir/x"],
            r"the folder '/nonexistent/dir' does not exist",
        ),
        (["export-c", "--robot", "ur5", "--out", "{tmp}/x", "--functions", "jac"], r"cannot export jac"),
    ],
)
def test_mistakes_end_in_one_sentence(argv, message, capsys, tmp_path):
    argv = [a.replace("{tmp}", str(tmp_path)) for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "Traceback" not in err
    import re

    assert re.search(message, err), err
    assert not (tmp_path / "x").exists()


def test_the_installed_command_runs():
    """The console script itself (not just main): exit code and no traceback on a mistake."""
    run = subprocess.run(
        [sys.executable, "-m", "dynid.cli", "info", "--robot", "nowhere.urdf"], capture_output=True, text=True
    )
    assert run.returncode == 2
    assert run.stderr.strip().startswith("dynid info: error: the URDF file 'nowhere.urdf' does not exist")
    assert "Traceback" not in run.stderr


def test_python_m_dynid_is_the_command():
    """``python -m dynid`` (dynid/__main__.py) runs the same command line, exit code included."""
    run = subprocess.run([sys.executable, "-m", "dynid", "--help"], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    assert run.stdout.startswith("usage: dynid ")
    assert "identify" in run.stdout and "diagnose" in run.stdout
    run = subprocess.run([sys.executable, "-m", "dynid", "no-such-command"], capture_output=True, text=True)
    assert run.returncode == 2
    assert "Traceback" not in run.stderr


@pytest.mark.slow
def test_demo_runs_what_exists(tmp_path, capsys):
    figures = tmp_path / "demo.json"
    assert main(["demo", "--out", str(tmp_path / "demo"), "--quick", "--json", str(figures)]) == 0
    data = json.loads(figures.read_text())
    assert data["n_base"] == 36
    assert data["c_export_max_error"] < 1e-10


def test_the_settling_command_names_the_robot_as_a_user_types_it_here(tmp_path, monkeypatch):
    """A model file names its description relative to itself; the command diagnose prints to settle an
    undecided effect is run from the working directory, where a path climbing out of it reads worse than
    the absolute one, and a built-in name stays a name."""
    import os

    from dynid.commands.diagnose import _as_typed

    here, elsewhere = tmp_path / "work", tmp_path / "robots"
    here.mkdir()
    (here / "arm.urdf").write_text("<robot/>")
    elsewhere.mkdir()
    (elsewhere / "arm.urdf").write_text("<robot/>")
    monkeypatch.chdir(here)
    assert _as_typed("ur5") == "ur5"
    assert _as_typed(str(here / "arm.urdf")) == "arm.urdf"
    assert _as_typed(os.path.join("..", "robots", "arm.urdf")) == str(elsewhere / "arm.urdf")
