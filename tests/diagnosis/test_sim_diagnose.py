"""``dynid diagnose --model robot.urdf|robot.xml``: a simulator's own description diagnosed and corrected.

The robot is the UR5 with known armature and friction; its simulator description is the UR5's own URDF
(right bodies, no friction; the robot without armature) or an MJCF built from it with the right friction
and the wrong armature.  Data are
simulated from the true robot; the diagnosis must name what the file misses and ``--out`` must write a
description that closes most of the gap on held-out data, with the true values in it.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from dynid.cli import main
from dynid.data.files import save_dataset
from dynid.identify.columns import column_set
from dynid.sim.synthetic import random_fourier, synthetic_dataset
from dynid.simmodel.export import default_template
from dynid.simmodel.nominal import description_friction, description_model

ARMATURE = np.array([0.4, 0.5, 0.3, 0.1, 0.12, 0.08])  # kg m^2
COULOMB = np.array([2.0, 2.5, 1.5, 0.8, 0.6, 0.5])  # N m
VISCOUS = np.array([1.2, 1.5, 0.8, 0.4, 0.3, 0.2])  # N m s/rad
NOISE = 0.05  # N m


def _data(robot, folder: Path, armature) -> tuple[Path, Path]:
    """Training (one period) and held-out (three periods) data of the UR5 with the true extras."""
    n = robot.n
    cols = column_set(robot, friction=True, armature=True)
    x = cols.P @ np.concatenate([robot.params, armature, COULOMB, VISCOUS, np.zeros(n)])
    paths = []
    for name, seed, periods in (("train", 5, 2), ("heldout", 6, 3)):
        rng = np.random.default_rng(seed)
        traj = random_fourier(robot, rng, periods=periods, base_freq=0.2)
        ds = synthetic_dataset(cols, x, traj, rate=200, rng=rng, noise=NOISE)
        paths.append(save_dataset(ds, folder / f"{name}.csv"))
    return paths[0], paths[1]


@pytest.fixture(scope="module")
def ur5_urdf(tmp_path_factory, ur5) -> tuple[Path, Path, Path]:
    """The UR5's own URDF as the nominal description (no friction, URDF has no armature) and data of the
    UR5 with friction and no armature."""
    folder = tmp_path_factory.mktemp("ur5_urdf")
    nominal = folder / "nominal.urdf"
    nominal.write_text(default_template(ur5).read_text(encoding="utf-8"), encoding="utf-8")
    train, heldout = _data(ur5, folder, np.zeros(ur5.n))
    return nominal, train, heldout


def _nrms(path: Path, heldout: Path) -> float:
    from dynid.data.files import load_dataset

    data = load_dataset(heldout)
    model = description_model(path, data)
    prep = model.prepare(data)
    r = prep.tau_reference - model.predict(data)
    return float(np.mean(np.sqrt(np.mean(r**2, axis=0))))


def test_a_urdf_without_friction_is_named_and_corrected(ur5_urdf, tmp_path, capsys):
    nominal, train, heldout = ur5_urdf
    out, figures = tmp_path / "corrected.urdf", tmp_path / "d.json"
    code = main(
        [
            "diagnose",
            "--model", str(nominal),
            "--data", str(train),
            "--heldout", str(heldout),
            "--effects", "stribeck",
            "--out", str(out),
            "--json", str(figures),
        ]
    )  # fmt: skip
    text = capsys.readouterr().out
    assert code == 0, text
    corr = json.loads(figures.read_text())["correction"]
    groups = {g["group"]: g["closure"] for g in corr["groups"]}
    # the file's bodies are right: friction is what separates it from the robot
    assert "What separates the file from the robot: its friction" in text
    assert groups["friction"] > 0.95 and abs(groups["link bodies"]) < 0.05
    assert corr["closure_overall"] > 0.97
    # recovery: the written file holds the true friction (Coulomb 3 %, viscous 5 %), its reload check passed, and validate agrees
    damping, coulomb = description_friction(out, _joint_names(out))
    np.testing.assert_allclose(coulomb, COULOMB, rtol=0.03)
    np.testing.assert_allclose(damping, VISCOUS, rtol=0.05)
    assert "wrote " + str(out) in text and "reload checks passed" in text
    before, after = _nrms(nominal, heldout), _nrms(out, heldout)
    assert (after / before) ** 2 < 0.02
    assert np.mean(corr["rms_validate"]["corrected"]) == pytest.approx(after, rel=1e-9)


def _joint_names(path: Path) -> list[str]:
    from dynid.symbolic.robot import load_robot

    return load_robot(path).joint_names


def test_an_mjcf_with_the_wrong_armature_is_named_and_corrected(ur5, tmp_path, capsys):
    pytest.importorskip("mujoco", reason="an MJCF description needs mujoco (pip install dynid[mujoco])")
    from dynid.simmodel.mjcf import build_mjcf
    from dynid.simmodel.parameters import SimParameters

    wrong = SimParameters(
        standard=ur5.params,
        armature=0.3 * ARMATURE,
        damping=VISCOUS,
        frictionloss=COULOMB,
        identified=np.zeros(0),
        source="nominal",
    )
    nominal = tmp_path / "nominal.xml"
    nominal.write_text(build_mjcf(default_template(ur5).read_text(), ur5, wrong, " nominal "), encoding="utf-8")
    train, heldout = _data(ur5, tmp_path, ARMATURE)
    out, figures = tmp_path / "corrected.xml", tmp_path / "d.json"
    code = main(
        [
            "diagnose",
            "--model", str(nominal),
            "--data", str(train),
            "--heldout", str(heldout),
            "--effects", "stribeck",
            "--out", str(out),
            "--json", str(figures),
        ]
    )  # fmt: skip
    text = capsys.readouterr().out
    assert code == 0, text
    corr = json.loads(figures.read_text())["correction"]
    groups = {g["group"]: g["closure"] for g in corr["groups"]}
    assert "What separates the file from the robot: its armature" in text
    # link 1's inertia about its vertical axis and joint 1's armature are seen only together: the corrected
    # bodies take part of joint 1's armature, so they close a little of the gap on their own
    assert groups["armature"] > 0.95 and abs(groups["friction"]) < 0.01 and abs(groups["link bodies"]) < 0.1
    assert corr["closure_overall"] > 0.97
    # the parameter-change test of the diagnosis names the armature against the file's values
    par = json.loads(figures.read_text())["parametric"]
    assert par["finding"] == "armature"
    # joints 1 and 2's armatures are folded into base parameters; those of joints 3-6 are tested alone
    assert {r["joint"] for r in par["armatures"] if r["p_value"] < 1e-3} == {3, 4, 5, 6}
    # recovery: the true armature (joint 1's is seen only with link 1's inertia about its axis) and friction
    # are in the written MJCF
    np.testing.assert_allclose(corr["corrected"]["armature"][1:], ARMATURE[1:], rtol=0.03)
    np.testing.assert_allclose(corr["corrected"]["frictionloss"], COULOMB, rtol=0.03)
    from dynid.symbolic.robot import load_robot

    np.testing.assert_allclose(load_robot(out).armature, corr["corrected"]["armature"], rtol=1e-9)
    # as validate scores them, the corrected file closes at least 98 % of the mean squared gap
    assert (_nrms(out, heldout) / _nrms(nominal, heldout)) ** 2 < 0.02


def test_bad_inputs_end_in_one_sentence(ur5_urdf, tmp_path, capsys):
    nominal, train, heldout = ur5_urdf
    cases = [
        (["--out", str(tmp_path / "c.xml")], "keeps the format of --model"),
        (["--out", str(tmp_path / "c.json")], "keeps the format of --model"),
        (["--robot", "ur5"], "leave --robot out"),
    ]
    for extra, message in cases:
        code = main(["diagnose", "--model", str(nominal), "--data", str(train), "--heldout", str(heldout), *extra])
        err = capsys.readouterr().err
        assert code == 2 and message in err and "Traceback" not in err, err
        assert err.strip().count("\n") == 0, err
    assert not list(tmp_path.glob("c.*"))


def test_mujoco_tracks_a_trajectory_as_dynids_simulator_does(ur5, tmp_path):
    """The same commanded motion, controller and robot in MuJoCo and in dynid's simulator.

    With viscous friction both integrate the same semi-implicit Euler with the velocity terms implicit:
    they agree to rounding.  With Coulomb friction (MuJoCo's frictionloss constraint against dynid's smoothed
    sign) the drive torques agree to a few % of their RMS (the reversals).
    """
    pytest.importorskip("mujoco", reason="the forward check needs mujoco (pip install dynid[mujoco])")
    from dynid.sim.effects import TruthFriction
    from dynid.sim.truth import build_truth
    from dynid.simmodel.mjcf import build_mjcf
    from dynid.simmodel.parameters import SimParameters
    from dynid.simmodel.rollout import forward_agreement

    n = ur5.n
    robot = ur5.with_params(armature=ARMATURE)
    traj = random_fourier(robot, np.random.default_rng(1), periods=1, base_freq=0.2)
    zero = np.zeros(n)
    figures = {}
    for kind, coulomb in (("viscous", zero), ("coulomb", COULOMB)):
        friction = TruthFriction("linear", coulomb, coulomb, VISCOUS, zero, zero, zero, zero)
        truth = build_truth(robot, friction=friction)
        params = SimParameters(
            standard=robot.params,
            armature=ARMATURE,
            damping=VISCOUS,
            frictionloss=coulomb,
            identified=np.zeros(0),
            source="truth",
        )
        path = tmp_path / f"{kind}.xml"
        path.write_text(build_mjcf(default_template(ur5).read_text(), robot, params, " truth "), encoding="utf-8")
        figures[kind] = forward_agreement(truth, traj, path, duration=2.0)
    viscous, coulomb = figures["viscous"], figures["coulomb"]
    assert max(viscous["torque_relative"]) < 1e-9
    assert max(viscous["tracking_difference_rms"]) < 1e-12
    assert max(coulomb["torque_relative"]) < 0.05
    # the tracking errors differ by a small part of their size
    diff = np.array(coulomb["tracking_difference_rms"]) / np.array(coulomb["tracking_rms_dynid"])
    assert diff.max() < 0.2
    # the check can fail: a plant with 10 % more armature than the truth is seen in the torque
    wrong = tmp_path / "wrong.xml"
    params = SimParameters(
        standard=robot.params,
        armature=1.1 * ARMATURE,
        damping=VISCOUS,
        frictionloss=zero,
        identified=np.zeros(0),
        source="wrong",
    )
    wrong.write_text(build_mjcf(default_template(ur5).read_text(), robot, params, " wrong "), encoding="utf-8")
    truth = build_truth(robot, friction=TruthFriction("linear", zero, zero, VISCOUS, zero, zero, zero, zero))
    assert max(forward_agreement(truth, traj, wrong, duration=2.0)["torque_relative"]) > 1e-3


@pytest.mark.slow
def test_real_panda_nominal_urdf_diagnosed_and_corrected(shared_data, tmp_path, capsys):
    """The Gaz URDF against the Panda recording (first 70 % to fit, the rest held out): the diagnosis names
    friction (the file has none) and the corrected URDF closes at least half of the held-out gap, as the
    diagnosis measures it; validate scores the written file as the command reported it."""
    from dynid.data.adapters import load_recording, recording_model_path

    data = load_recording("panda_gaz2019", shared_data)
    urdf = recording_model_path("panda_gaz2019", shared_data)
    split = data.t[0] + 0.7 * (data.t[-1] - data.t[0])
    train = save_dataset(data.select_rows(np.flatnonzero(data.t < split)), tmp_path / "train.csv")
    heldout = save_dataset(data.select_rows(np.flatnonzero(data.t >= split)), tmp_path / "real.csv")
    out, figures = tmp_path / "corrected.urdf", tmp_path / "d.json"
    code = main(
        ["diagnose", "--model", str(urdf), "--data", str(train), "--heldout", str(heldout), "--out", str(out),
         "--json", str(figures)]
    )  # fmt: skip
    text = capsys.readouterr().out
    assert code == 0, text
    assert "What separates the file from the robot: its friction" in text
    corr = json.loads(figures.read_text())["correction"]
    # measured: 0.79 over the joints, every joint at least 0.46; mean RMS 0.423 -> 0.201 N m
    assert corr["closure_overall"] >= 0.5
    assert min(corr["closure"]) > 0.3
    assert np.all(np.array(corr["rms_corrected"]) < np.array(corr["rms_nominal"]))
    # as validate scores the written file (its own cut-off): lower on every joint (0.563 -> 0.387 N m)
    own = corr["rms_validate"]
    assert np.all(np.array(own["corrected"]) < np.array(own["nominal"]))
    assert _nrms(out, heldout) == pytest.approx(np.mean(own["corrected"]), rel=1e-9)
