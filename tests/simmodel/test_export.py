"""``dynid export``: identified models written into URDF and MJCF, reloaded by Pinocchio and MuJoCo."""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from dynid.cli import main
from dynid.identify.columns import column_set
from dynid.identify.consistent import is_consistent
from dynid.identify.model import identify, load_model, save_model
from dynid.sim.synthetic import random_fourier, synthetic_dataset, true_parameters
from dynid.simmodel.checks import URDF_TOLERANCE, check_urdf
from dynid.simmodel.export import default_template, export_model


def _identified(robot, folder: Path, name: str, *, seed: int = 1, friction: str = "linear"):
    """A model identified on simulated data with known armature and friction; returns (model file, truth x)."""
    rng = np.random.default_rng(seed)
    cols = column_set(robot, friction=True, armature=True)
    x = true_parameters(cols, rng)
    traj = random_fourier(robot, rng, periods=1, base_freq=0.2)
    ds = synthetic_dataset(cols, x, traj, rate=200, rng=rng, noise=0.02)
    model = identify(robot, ds, method="irls", friction=friction, gmm="off")
    path = folder / f"{name}.json"
    save_model(model, path)
    return path, dict(zip(cols.names, x, strict=True))


@pytest.fixture(scope="module")
def ur5_model(tmp_path_factory, ur5):
    return _identified(ur5, tmp_path_factory.mktemp("ur5"), "ur5")


def _count(path: Path, tag: str) -> int:
    return len(ET.parse(path).getroot().findall(f".//{tag}"))


def test_urdf_export_reloads_in_pinocchio_and_keeps_the_template(ur5_model, tmp_path):
    path, _ = ur5_model
    model = load_model(path)
    out = tmp_path / "ur5.urdf"
    result = export_model(model, "urdf", out)
    (check,) = result.checks
    assert check["passed"] and check["relative_error"] <= URDF_TOLERANCE
    template = default_template(model.robot)
    assert _count(out, "visual") == _count(template, "visual") > 0
    assert _count(out, "collision") == _count(template, "collision") > 0
    assert _count(out, "limit") == _count(template, "limit")
    assert is_consistent(result.params.standard).all()
    text = out.read_text()
    assert "dynid export (urdf)" in text and "armature" in text and "friction offset" in text
    # the data cannot see link 1's mass: it was pulled to the template's value
    assert "m1" in result.params.unidentifiable["unseen"]
    assert result.params.standard[0] == pytest.approx(model.robot.params[0], rel=1e-2)
    assert {it["what"] for it in result.not_carried} >= {"friction offset", "armature"}


def test_a_relative_mesh_path_still_points_at_the_template_s_mesh(ur5_model, tmp_path):
    path, _ = ur5_model
    model = load_model(path)
    root = ET.parse(default_template(model.robot)).getroot()
    meshes = list(root.iter("mesh"))
    assert meshes
    meshes[0].set("filename", "meshes/base.stl")
    (tmp_path / "tpl").mkdir()
    (tmp_path / "out").mkdir()
    template = tmp_path / "tpl" / "ur5.urdf"
    ET.ElementTree(root).write(template)
    out = tmp_path / "out" / "ur5.urdf"
    export_model(model, "urdf", out, template=template)
    names = [m.get("filename") for m in ET.parse(out).getroot().iter("mesh")]
    assert names[0] == str((tmp_path / "tpl" / "meshes" / "base.stl").resolve())
    assert names[1:] == [m.get("filename") for m in meshes[1:]]  # package:// and absolute names stay


def test_an_unconstrained_fit_gets_the_closest_consistent_bodies(ur5, tmp_path):
    """Without stored consistent bodies the export computes the closest ones (Mahalanobis) and says so."""
    rng = np.random.default_rng(3)
    cols = column_set(ur5, friction=True, armature=True)
    x = true_parameters(cols, rng)
    ds = synthetic_dataset(cols, x, random_fourier(ur5, rng, periods=1, base_freq=0.2), rate=200, rng=rng, noise=0.5)
    model = identify(ur5, ds, method="ols", friction="linear", gmm="off", physical=False)
    assert "consistency" not in model.info
    result = export_model(model, "urdf", tmp_path / "ur5.urdf")
    p = result.params
    assert p.source == "closest consistent set" and is_consistent(p.standard).all()
    assert result.checks[0]["passed"]
    # the projection moves the base parameters by at most a few standard deviations of their estimate
    assert 0 < p.projection["mahalanobis"] < 10  # this estimate was not consistent: it moved
    rel = p.projection["relative"]
    assert 0 <= rel < 0.05


def test_a_file_that_does_not_hold_the_values_fails_the_check(ur5_model, tmp_path):
    path, _ = ur5_model
    model = load_model(path)
    out = tmp_path / "ur5.urdf"
    result = export_model(model, "urdf", out)
    standard = result.params.standard.copy()
    standard[20] *= 1.001  # link 3's mass, 0.1 % more than the file holds
    assert not check_urdf(out, model, replace(result.params, standard=standard))["passed"]
    mujoco = pytest.importorskip("mujoco", reason="the MJCF export needs mujoco (pip install dynid[mujoco])")
    del mujoco
    from dynid.simmodel.checks import check_mjcf

    xml = tmp_path / "ur5.xml"
    result = export_model(model, "mjcf", xml)
    wrong = replace(result.params, armature=result.params.armature + 1e-3)
    inverse, _ = check_mjcf(xml, model, wrong)
    assert not inverse["passed"]


def test_mjcf_export_reloads_in_mujoco_with_the_identified_friction(ur5_model, tmp_path):
    mujoco = pytest.importorskip("mujoco", reason="the MJCF export needs mujoco (pip install dynid[mujoco])")
    path, truth = ur5_model
    model = load_model(path)
    out = tmp_path / "ur5.xml"
    result = export_model(model, "mjcf", out)
    inverse, friction = result.checks
    assert inverse["passed"] and inverse["relative_error"] <= 1e-6
    assert friction["passed"] and len(friction["joints"]) == 6
    m = mujoco.MjModel.from_xml_path(str(out))
    dofs = [m.jnt_dofadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, nm)] for nm in model.robot.joint_names]
    fc = np.array([truth[f"fc{j + 1}"] for j in range(6)])
    fv = np.array([truth[f"fv{j + 1}"] for j in range(6)])
    # recovery: the simulated Coulomb and viscous friction come back in MuJoCo's fields
    np.testing.assert_allclose(m.dof_frictionloss[dofs], fc, rtol=0.03)
    np.testing.assert_allclose(m.dof_damping[dofs], fv, rtol=0.03)
    np.testing.assert_allclose(m.dof_armature[dofs], result.params.armature, rtol=1e-12)
    assert "dynid export (mjcf)" in out.read_text()


def test_an_mjcf_template_is_filled_in_place(ur5_model, tmp_path, capsys):
    """The robot's own MJCF as the template: its geoms and actuators stay, the values are the model's."""
    mujoco = pytest.importorskip("mujoco", reason="the MJCF export needs mujoco (pip install dynid[mujoco])")
    path, _ = ur5_model
    model = load_model(path)
    first = tmp_path / "first.xml"
    export_model(model, "mjcf", first)
    root = ET.parse(first).getroot()
    body = next(b for b in root.iter("body") if b.get("name") == "forearm_link")
    ET.SubElement(body, "geom", {"name": "forearm_shape", "type": "capsule", "size": "0.04 0.2", "mass": "0"})
    actuators = ET.SubElement(root, "actuator")
    ET.SubElement(actuators, "motor", {"name": "elbow_motor", "joint": "elbow_joint"})
    template = tmp_path / "robot.xml"
    ET.ElementTree(root).write(template)
    out = tmp_path / "filled.xml"
    assert main(["export", "--model", str(path), "--format", "mjcf", "--template", str(template), "--out", str(out)]) == 0
    m = mujoco.MjModel.from_xml_path(str(out))
    assert m.ngeom == 1 and m.nu == 1
    assert "visual and collision geometry" not in capsys.readouterr().out
    _one_line_error(
        capsys,
        ["export", "--model", str(path), "--format", "urdf", "--template", str(template), "--out", str(tmp_path / "x.urdf")],
        "a URDF is written from a URDF",
        tmp_path / "x.urdf",
    )


def test_panda_with_locked_fingers_keeps_them(panda, tmp_path):
    mujoco = pytest.importorskip("mujoco", reason="the MJCF export needs mujoco (pip install dynid[mujoco])")
    path, _ = _identified(panda, tmp_path, "panda")
    model = load_model(path)
    urdf = export_model(model, "urdf", tmp_path / "panda.urdf")
    assert urdf.checks[0]["passed"]
    assert set(urdf.locked) == {"panda_finger_joint1", "panda_finger_joint2"}
    joints = {j.get("name"): j.get("type") for j in ET.parse(tmp_path / "panda.urdf").getroot().iter("joint")}
    assert joints["panda_finger_joint1"] == "prismatic"
    mjcf = export_model(model, "mjcf", tmp_path / "panda.xml")
    assert all(c["passed"] for c in mjcf.checks)
    assert mujoco.MjModel.from_xml_path(str(tmp_path / "panda.xml")).nv == 9


def test_gaz_panda_urdf_as_the_template(shared_data, tmp_path):
    from dynid.symbolic import load_robot

    urdf = shared_data / "panda_gaz2019" / "model" / "panda_arm_gaz2019_nohand.urdf"
    if not urdf.is_file():
        pytest.skip(f"the Gaz Panda URDF is not at {urdf}")
    path, _ = _identified(load_robot(urdf), tmp_path, "gaz", friction="stribeck")
    result = export_model(load_model(path), "urdf", tmp_path / "gaz.urdf", template=urdf)
    assert result.checks[0]["passed"]
    assert "Stribeck friction" in {it["what"] for it in result.not_carried}


def test_a_modified_dh_table_gets_a_urdf_of_its_own(tmp_path):
    """A table robot (revolute and prismatic joints, armature in the table) exports to both formats."""
    pytest.importorskip("mujoco", reason="the MJCF export needs mujoco (pip install dynid[mujoco])")
    from dynid.symbolic import load_robot

    robot = load_robot(Path(__file__).resolve().parents[1] / "fixtures" / "rrpr_mdh.toml")
    path, _ = _identified(robot, tmp_path, "rrpr")
    model = load_model(path)
    for fmt, name in (("urdf", "rrpr.urdf"), ("mjcf", "rrpr.xml")):
        result = export_model(model, fmt, tmp_path / name)
        assert all(c["passed"] for c in result.checks), result.checks
    kinds = {j.get("name"): j.get("type") for j in ET.parse(tmp_path / "rrpr.urdf").getroot().iter("joint")}
    assert sorted(kinds.values()).count("prismatic") == 1


def test_tx40_with_its_coupled_wrist(shared_data, tmp_path):
    """The coupled motor's cross terms are listed as not carried; what is carried reloads exactly."""
    pytest.importorskip("mujoco", reason="the MJCF export needs mujoco (pip install dynid[mujoco])")
    from dynid.data.adapters import tx40_transmission
    from dynid.symbolic import load_robot

    urdf = shared_data / "tx40" / "model" / "tx40_mdh_modified.urdf"
    if not urdf.is_file():
        pytest.skip(f"the TX40 URDF is not at {urdf}")
    robot = load_robot(urdf).with_transmission(tx40_transmission())
    path, _ = _identified(robot, tmp_path, "tx40")
    model = load_model(path)
    for fmt, name in (("urdf", "tx40.urdf"), ("mjcf", "tx40.xml")):
        result = export_model(model, fmt, tmp_path / name)
        assert all(c["passed"] for c in result.checks)
        coupled = next(it for it in result.not_carried if it["what"] == "coupled transmission")
        assert coupled["joints"] == [6]


def _one_line_error(capsys, argv, pattern: str, leftover: Path) -> None:
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and re.search(pattern, err), err
    assert not leftover.exists()


def test_bad_inputs_end_in_one_sentence(ur5_model, tmp_path, capsys):
    path, _ = ur5_model
    out = tmp_path / "x.urdf"
    _one_line_error(
        capsys, ["export", "--model", str(path), "--format", "sdf", "--out", str(out)], "choose urdf or mjcf", out
    )
    from dynid.symbolic.robot import BUILTIN_ROBOTS, example_robot_data_dir

    ur10 = example_robot_data_dir() / BUILTIN_ROBOTS["ur10"]["urdf"]
    _one_line_error(
        capsys,
        ["export", "--model", str(path), "--format", "urdf", "--template", str(ur10), "--out", str(out)],
        "describes another robot",
        out,
    )
    renamed = tmp_path / "renamed.urdf"
    renamed.write_text(default_template(load_model(path).robot).read_text().replace("elbow_joint", "elbow"))
    _one_line_error(
        capsys,
        ["export", "--model", str(path), "--format", "urdf", "--template", str(renamed), "--out", str(out)],
        "has no joint 'elbow_joint'",
        out,
    )
    not_a_model = tmp_path / "n.json"
    not_a_model.write_text('{"hello": 1}')
    _one_line_error(
        capsys,
        ["export", "--model", str(not_a_model), "--format", "urdf", "--out", str(out)],
        "not a readable dynid model file",
        out,
    )


def test_the_command_writes_checks_and_not_carried(ur5_model, tmp_path, capsys):
    import json

    path, _ = ur5_model
    out, js = tmp_path / "ur5.urdf", tmp_path / "e.json"
    assert main(["export", "--model", str(path), "--format", "urdf", "--out", str(out), "--json", str(js)]) == 0
    doc = json.loads(js.read_text())
    assert doc["checks"][0]["passed"] and doc["not_carried"]
    assert "reload checks:" in capsys.readouterr().out


def test_validate_scores_a_simulator_description_as_it_stands(ur5_model, tmp_path, capsys):
    """Data simulated from the exported values: the MJCF (with armature) predicts them to the noise."""
    pytest.importorskip("mujoco", reason="the MJCF export needs mujoco (pip install dynid[mujoco])")
    import json

    from dynid.simmodel.nominal import description_model
    from dynid.validation.validate import validate

    path, _ = ur5_model
    model = load_model(path)
    xml, urdf = tmp_path / "ur5.xml", tmp_path / "ur5.urdf"
    p = export_model(model, "mjcf", xml).params
    export_model(model, "urdf", urdf)
    robot = model.robot
    cols = column_set(robot, friction=True, armature=True)
    x = cols.P @ np.concatenate([p.standard, p.armature, p.frictionloss, p.damping, np.zeros(robot.n)])
    rng = np.random.default_rng(7)
    traj = random_fourier(robot, rng, periods=2, base_freq=0.2)
    noise = 0.02
    ds = synthetic_dataset(cols, x, traj, rate=200, rng=rng, noise=noise)
    rms_xml = np.asarray(validate(description_model(xml, ds), ds).figures()["rms"])
    rms_urdf = np.asarray(validate(description_model(urdf, ds), ds).figures()["rms"])
    np.testing.assert_allclose(rms_xml, noise, rtol=0.15)
    # the URDF has no armature: the joints with a sizeable one are predicted worse
    big = p.armature > 0.01
    assert big.any() and np.all(rms_urdf[big] > 1.5 * noise)

    data = tmp_path / "V.csv"
    header = ["t", *(f"q_{j + 1}" for j in range(robot.n)), *(f"tau_{j + 1}" for j in range(robot.n))]
    rows = np.column_stack([ds.t, ds.q, ds.tau])
    data.write_text(",".join(header) + "\n" + "\n".join(",".join(repr(float(v)) for v in r) for r in rows) + "\n")
    js = tmp_path / "v.json"
    assert main(["validate", "--model", str(xml), "--data", str(data), "--json", str(js)]) == 0
    # read from the CSV without dq, ddq: filtered and differentiated, the noise is partly filtered out
    assert np.all(np.asarray(json.loads(js.read_text())["rms"]) < noise)
    assert "nominal" in capsys.readouterr().out


def test_heldout_shares_agree_with_the_exported_description(ur5_model, tmp_path):
    """The export's held-out RMS (regressor) equals the exported MJCF's read back by Pinocchio's parser."""
    pytest.importorskip("mujoco", reason="the MJCF export needs mujoco (pip install dynid[mujoco])")
    from dynid.simmodel.nominal import description_model
    from dynid.validation.validate import validate

    path, truth = ur5_model
    model = load_model(path)
    robot = model.robot
    cols = column_set(robot, friction=True, armature=True)
    x = np.array([truth[name] for name in cols.names])
    rng = np.random.default_rng(11)
    ds = synthetic_dataset(cols, x, random_fourier(robot, rng, periods=2, base_freq=0.2), rate=200, rng=rng, noise=0.02)
    xml = tmp_path / "ur5.xml"
    result = export_model(model, "mjcf", xml, heldout=ds)
    h = result.heldout
    assert h["closure"] < 1e-9
    nominal = validate(description_model(xml, ds, preprocessing=None), ds).figures()["rms"]
    np.testing.assert_allclose(h["rms_exported"], nominal, rtol=1e-6)
    # the simulated offsets (|fo| up to 0.5 N m) are what MJCF cannot carry
    fo = np.abs([truth[f"fo{j + 1}"] for j in range(robot.n)])
    np.testing.assert_allclose(h["rms_exported"], np.sqrt(fo**2 + 0.02**2), rtol=0.1, atol=0.01)
    (part,) = h["parts"]
    assert part["part"].startswith("friction beyond") and part["rise_mean"] > 0.1
    offset = next(it for it in result.not_carried if it["what"] == "friction offset")
    assert offset["share"].startswith("held-out RMS")
    # friction terms are removed together: the one figure says so, not "without it" term by term
    assert "without the friction terms the file cannot carry (all of them together, not this one alone)" in offset[
        "share"
    ]


@pytest.mark.slow
def test_real_panda_round_trip(shared_data, tmp_path):
    """The Panda recording: identified on 70 %, exported to MJCF with the Gaz URDF as template and
    reloaded; on the held-out 30 % the export beats the nominal URDF on every joint."""
    pytest.importorskip("mujoco", reason="the MJCF export needs mujoco (pip install dynid[mujoco])")
    from dynid.data.adapters import load_recording, recording_model_path
    from dynid.data.preparation import Preprocessing
    from dynid.simmodel.nominal import description_model
    from dynid.symbolic import load_robot
    from dynid.validation.validate import validate

    data = load_recording("panda_gaz2019", shared_data)
    urdf = recording_model_path("panda_gaz2019", shared_data)
    robot = load_robot(urdf)
    split = data.t[0] + 0.7 * (data.t[-1] - data.t[0])
    train = data.select_rows(np.flatnonzero(data.t < split))
    heldout = data.select_rows(np.flatnonzero(data.t >= split))
    model = identify(robot, train)
    result = export_model(model, "mjcf", tmp_path / "panda.xml", template=urdf, heldout=heldout)
    assert all(c["passed"] for c in result.checks)
    h = result.heldout
    assert h["closure"] < 1e-9
    nominal = description_model(urdf, heldout, preprocessing=Preprocessing.from_settings(model.preprocessing))
    rms_nominal = np.asarray(validate(nominal, heldout).figures()["rms"])
    assert np.all(np.asarray(h["rms_exported"]) < rms_nominal)


def test_a_nonlinear_friction_is_written_as_the_line_closest_to_it_where_the_arm_moved(tmp_path, ur5):
    """A simulator holds one viscous coefficient and one Coulomb level per joint. Of a seed model (its
    dq |dq| and dq^3 terms, its static levels) the export writes the least-squares line over the training
    speeds the model file keeps, which predicts the model's friction at those speeds far better than the
    model's linear coefficients alone (what was written before); a file without the speeds keeps those."""
    from dynid.identify.friction import SeedFriction

    rng = np.random.default_rng(3)
    cols = column_set(ur5, friction=False, armature=True)
    x = true_parameters(cols, rng)
    truth = []
    for j in range(ur5.n):
        f = SeedFriction()
        f.coef_ = np.array([1.0, 0.9, 0.3, 0.8, 0.4, 1.3, 1.2, 0.05]) * (1 + 0.1 * j)
        truth.append(f)

    def extra(q, dq):
        return np.column_stack([f.predict(dq[:, j]) for j, f in enumerate(truth)])

    ds = synthetic_dataset(cols, x, random_fourier(ur5, rng, periods=2, base_freq=0.2), rate=200, rng=rng,
                           noise=0.02, extra=extra)  # fmt: skip
    model = identify(ur5, ds, method="irls", friction="seed", gmm="off")
    speeds = np.asarray(model.info["speed_quantiles"])
    assert speeds.shape == (ur5.n, 40) and np.all(np.diff(speeds, axis=1) >= 0)
    path = tmp_path / "M.json"
    save_model(model, path)
    again = load_model(path)
    np.testing.assert_allclose(again.info["speed_quantiles"], speeds)
    result = export_model(again, "urdf", tmp_path / "ur5.urdf")
    p = result.params
    v = speeds  # the training speeds, both directions
    for j, mdl in enumerate(model.friction.models_):
        odd = 0.5 * (mdl.predict(v[j]) - mdl.predict(-v[j]))
        written = p.frictionloss[j] + p.damping[j] * v[j]
        c = mdl.to_dict()["coef"]
        before = 0.5 * (c["kc_pos"] + c["kc_neg"]) + c["kv1"] * v[j]
        err, err_before = (float(np.sqrt(np.mean((odd - w) ** 2))) for w in (written, before))
        assert err < 0.5 * err_before, (j, err, err_before)
        # the least-squares line: no other (damping, frictionloss) >= 0 is closer
        A = np.column_stack([np.ones_like(v[j]), v[j]])
        best = np.linalg.lstsq(A, odd, rcond=None)[0]
        if np.all(best >= 0):
            np.testing.assert_allclose([p.frictionloss[j], p.damping[j]], best, rtol=1e-6, atol=1e-9)
    assert any("closest to the identified friction" in item["detail"] for item in p.not_carried)
    # a file written before the speeds were kept: the model's own linear coefficients
    old = replace(again, info={k: v for k, v in again.info.items() if k != "speed_quantiles"})
    q = export_model(old, "urdf", tmp_path / "old.urdf").params
    c = [m.to_dict()["coef"] for m in model.friction.models_]
    np.testing.assert_allclose(q.damping, [cj["kv1"] for cj in c])


def test_the_line_is_fitted_where_the_arm_moved_not_where_it_stood(rng):
    """A recording standing still for 40 % of its samples: the speeds kept for the export are the moving
    ones, so a seed model that is a line (no square, cube or static excess) is written as that very line;
    counted with the rest samples (odd part 0 there) it came out as frictionloss 0.27, damping 0.84."""
    from dynid.identify.fit_figures import speed_quantiles
    from dynid.identify.friction import FrictionLayer

    dq = rng.uniform(-2.0, 2.0, (5000, 2))
    dq[:2000] = rng.normal(scale=3e-5, size=(2000, 2))  # creeping at rest
    speeds = np.asarray(speed_quantiles(dq))
    assert speeds.shape == (2, 40) and np.all(speeds >= 1e-3)
    line = {"kc_pos": 1.0, "kc_neg": 1.0, "kv1": 0.3, "kv2": 0.0, "kv3": 0.0, "ks_pos": 1.0, "ks_neg": 1.0}
    seed = FrictionLayer.from_dict({"model": "seed", "joints": [{**line, "lam": 0.01}]})
    damping, loss = seed.models_[0].simulator_line(speeds[0])
    assert damping == pytest.approx(0.3, rel=1e-6) and loss == pytest.approx(1.0, rel=1e-6)
