"""Payload identification: known payloads recovered from simulated runs, still poses, drive gains, the command.

Every recovery identifies a payload that the simulator attached to the UR5's last body (a box turned in
the tool frame), on an arm model identified without it, and compares with the payload that was put
there: an estimator that is wrong (a wrong frame, a wrong sign, a missing column) fails these.
"""

from __future__ import annotations

import dataclasses
import json
import re
import warnings

import numpy as np
import pytest

from dynid.cli import main
from dynid.identify.consistent import pseudo_inertia
from dynid.identify.payload import attach_payload, identify_payload
from dynid.symbolic.bodies import PayloadFrame, body_figures, frame_transform, payload_frame
from dynid.symbolic.robot import standard_from_com

MASS = 1.5
COM = np.array([0.03, -0.02, 0.07])
SIDES = np.array([0.10, 0.06, 0.14])
DURATION = 20.0


def _box(mass: float, sides: np.ndarray) -> np.ndarray:
    a, b, c = sides
    return mass / 12 * np.diag([b * b + c * c, a * a + c * c, a * a + b * b])


def _turned(inertia: np.ndarray) -> np.ndarray:
    angle = 0.4
    R = np.array([[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0], [0, 0, 1]])
    return R @ inertia @ R.T


TRUE = standard_from_com(MASS, COM, _turned(_box(MASS, SIDES)))


def _simulate_runs(robot, effects: str | None) -> dict:
    """Arm model (unloaded 20 s run), a reference run and a loaded run of the same motion, lab noise."""
    import dynid
    from dynid.optim.trajectory import FourierTrajectory
    from dynid.sim.simulator import build_truth, simulate

    rng = np.random.default_rng(3)
    a, b = rng.normal(scale=0.12, size=(5, 6)), rng.normal(scale=0.12, size=(5, 6))
    motion = FourierTrajectory(a=a, b=b, c=np.array([0.0, -1.2, 1.0, -1.0, 0.5, 0.0]), base_freq=0.1)
    truth = build_truth(robot, friction="linear", truth_seed=0, effects=effects)
    place = payload_frame(robot)
    params = np.array(truth.robot.params, dtype=float)
    params[10 * place.link : 10 * place.link + 10] += frame_transform(place) @ TRUE
    loaded_truth = dataclasses.replace(truth, robot=truth.robot.with_params(params))
    train = simulate(robot, motion, truth=truth, seed=1, duration=DURATION).to_dataset()
    reference = simulate(robot, motion, truth=truth, seed=2, duration=DURATION).to_dataset()
    loaded = simulate(robot, motion, truth=loaded_truth, seed=3, duration=DURATION).to_dataset()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = dynid.identify_model(
            robot, train, method="ols", friction="linear", gmm="off", reference_weight=0
        )
    gain = truth.effect("drive_gain")
    gains = None if gain is None else np.asarray(gain.gain, dtype=float)
    return {
        "model": model,
        "train": train,
        "reference": reference,
        "loaded": loaded,
        "gains": gains,
        "motion": motion,
    }


@pytest.fixture(scope="module")
def runs(ur5):
    return _simulate_runs(ur5, None)


@pytest.fixture(scope="module")
def gain_runs(ur5):
    """The same, each joint's measured torque scaled by the simulator's drive gain (1 +- 5 %)."""
    return _simulate_runs(ur5, "drive_gain")


def _errors(params: np.ndarray) -> tuple[float, float]:
    t, e = body_figures(TRUE), body_figures(params)
    return abs(e[0] - t[0]) / t[0], float(np.linalg.norm(e[1:4] - t[1:4]))


# ---------------------------------------------------------------------- frames
def test_frame_transform_moves_a_body_into_the_link_frame(rng):
    """T maps a body written in F to the same body in the link frame (standard_from_com there)."""
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    w, x, y, z = q
    R = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )
    p = rng.normal(scale=0.1, size=3)
    inertia = _turned(_box(2.0, np.array([0.1, 0.2, 0.05])))
    in_f = standard_from_com(2.0, COM, inertia)
    in_link = standard_from_com(2.0, p + R @ COM, R @ inertia @ R.T)
    T = frame_transform(PayloadFrame("F", 0, R, p))
    np.testing.assert_allclose(T @ in_f, in_link, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(body_figures(in_f)[1:4], COM, atol=1e-12)


def test_the_default_frame_is_the_tool_frame(ur5):
    place = payload_frame(ur5)
    assert place.name == ur5.tool_name and place.link == ur5.tool_parent - 1
    other = payload_frame(ur5, "wrist_3_link")
    assert other.link == place.link and not np.allclose(other.translation, place.translation)


def test_an_unknown_frame_is_refused_with_the_frames_listed(ur5):
    from dynid.exceptions import UsageError

    with pytest.raises(UsageError, match=r"no frame 'nowhere'.*tool0"):
        payload_frame(ur5, "nowhere")


# ---------------------------------------------------------------------- recovery
def test_a_payload_is_recovered_with_a_reference_run(runs):
    res = identify_payload(runs["model"], runs["loaded"], reference=runs["reference"])
    mass_err, com_err = _errors(res.params)
    assert mass_err < 0.01, res.figures()
    assert com_err < 0.003, res.figures()
    # the standard deviations are honest: the error is within a few of them
    assert abs(res.params[0] - MASS) < 5 * res.std[0] + 1e-3
    assert res.determined[:4].all()
    # attached, the payload takes away most of the loaded run's error on the shoulder and elbow
    assert np.all(res.rms_after[1:3] < 0.1 * res.rms_before[1:3]), (res.rms_before, res.rms_after)
    # a real body: pseudo-inertia positive semi-definite
    assert np.linalg.eigvalsh(pseudo_inertia(res.params)).min() > -1e-9


def test_a_payload_is_recovered_without_a_reference_run(runs):
    res = identify_payload(runs["model"], runs["loaded"])
    mass_err, com_err = _errors(res.params)
    assert mass_err < 0.03 and com_err < 0.01, res.figures()


def test_a_determined_inertia_is_the_true_one_within_its_standard_deviations(runs):
    """Where the motion determines the inertia, every entry is within 4 of its standard deviations."""
    res = identify_payload(runs["model"], runs["loaded"], reference=runs["reference"])
    fig = res.figures()
    found, std = np.array(fig["inertia"], dtype=float), np.array(fig["inertia_std"], dtype=float)
    seen = np.isfinite(found)
    assert seen.any(), fig["determined"]
    true = _turned(_box(MASS, SIDES))
    assert np.all(np.abs(found - true)[seen] < 4 * std[seen] + 1e-5), (found, true, std)


def test_still_poses_give_the_mass_and_centre_of_mass(runs, ur5, rng):
    """Eight still poses (the industrial way; the moves between them not logged): the mass and the centre
    of mass come out; the inertia, never seen, is reported undetermined."""
    import pinocchio as pin

    from dynid.data.dataset import Dataset

    place = payload_frame(ur5)
    params = np.array(ur5.params, dtype=float)
    params[10 * place.link : 10 * place.link + 10] += frame_transform(place) @ TRUE
    poses = np.array([0.0, -1.2, 1.0, -1.0, 0.5, 0.0]) + rng.uniform(-0.8, 0.8, size=(8, 6))
    fs, hold, move = 500.0, 2.0, 2.5
    q, dq, ddq = [], [], []
    for k, pose in enumerate(poses):
        q.append(np.repeat(pose[None], int(hold * fs), axis=0))
        dq.append(np.zeros_like(q[-1]))
        ddq.append(np.zeros_like(q[-1]))
        if k + 1 < len(poses):  # a minimum-jerk move to the next pose
            s = np.arange(int(move * fs))[:, None] / (move * fs)
            d = poses[k + 1] - pose
            q.append(pose + d * (10 * s**3 - 15 * s**4 + 6 * s**5))
            dq.append(d * (30 * s**2 - 60 * s**3 + 30 * s**4) / move)
            ddq.append(d * (60 * s - 180 * s**2 + 120 * s**3) / move**2)
    q, dq, ddq = np.vstack(q), np.vstack(dq), np.vstack(ddq)
    t = np.arange(len(q)) / fs

    def run(model):
        data = model.createData()
        tau = np.array([pin.rnea(model, data, a, b, c) for a, b, c in zip(q, dq, ddq, strict=True)])
        return Dataset(t, q, tau + rng.normal(scale=0.02, size=q.shape), dq=dq, ddq=ddq)

    still = np.all(dq == 0, axis=1)
    starts = np.flatnonzero(still & ~np.concatenate([[False], still[:-1]]))

    def holds(ds):  # what a still-pose routine logs: the holds alone, one run each
        return Dataset(
            ds.t[still], ds.q[still], ds.tau[still], dq=ds.dq[still], ddq=ds.ddq[still],
            meta={"run_starts": [int(np.sum(still[:a])) for a in starts]},
        )  # fmt: skip

    unloaded, loaded = holds(run(ur5.pin_model)), holds(run(ur5.with_params(params).pin_model))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = identify_payload(runs["model"], loaded, reference=unloaded)
    fig = res.figures()
    assert abs(fig["mass"] - MASS) < 0.02 * MASS, fig
    assert np.linalg.norm(np.array(fig["com"]) - COM) < 0.005, fig
    # still, the inertia is never seen: reported undetermined and null, never a number made of noise
    assert not any(fig["determined"][k] for k in ("Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz"))
    assert all(v is None for row in fig["inertia"] for v in row)
    assert json.loads(json.dumps(fig)) == fig  # strict JSON: no NaN


def test_a_known_mass_calibrates_the_drive_gains(gain_runs):
    """The simulator scales each joint's measured torque by 1 +- 5 %: the known mass recovers those gains."""
    runs = gain_runs
    free = identify_payload(runs["model"], runs["loaded"], reference=runs["reference"])
    res = identify_payload(runs["model"], runs["loaded"], reference=runs["reference"], mass=MASS)
    true = runs["gains"]
    assert np.ptp(true) > 0.02  # the gains differ from joint to joint: a unit guess would fail
    fig = res.figures()["drive_gains"]
    found = np.array([np.nan if g is None else g for g in fig["gain"]])
    for j in (1, 2):  # shoulder and elbow carry the payload's weight
        assert fig["determined"][j]
        assert abs(found[j] - true[j]) < 0.015, (found, true)
    assert res.figures()["mass"] == pytest.approx(MASS)
    # without the known mass, the gains are folded into the payload: its mass is off by about their mean
    assert abs(free.mass / MASS - 1) > 0.005


# ---------------------------------------------------------------------- the model with the payload
def test_the_model_with_the_payload_predicts_the_loaded_run(runs, tmp_path):
    from dynid.identify.model import load_model, save_model
    from dynid.validation.validate import validate

    model, loaded = runs["model"], runs["loaded"]
    res = identify_payload(model, loaded, reference=runs["reference"])
    with_payload = attach_payload(model, res)
    save_model(with_payload, tmp_path / "M2.json")
    again = load_model(tmp_path / "M2.json")
    assert again.info["payload"]["mass"] == pytest.approx(res.mass)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no "leaves the training range" warning on the loaded run
        after = validate(again, loaded).figures()["rms"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        before = validate(model, loaded).figures()["rms"]
    assert after[1] < 0.1 * before[1] and after[2] < 0.1 * before[2], (before, after)


# ---------------------------------------------------------------------- the command
def test_the_command_writes_its_figures_report_and_model(runs, tmp_path, capsys):
    from dynid.data.files import save_dataset
    from dynid.identify.model import save_model

    save_model(runs["model"], tmp_path / "M.json")
    save_dataset(runs["loaded"], tmp_path / "loaded.csv")
    save_dataset(runs["reference"], tmp_path / "unloaded.csv")
    argv = [
        "payload", "--model", str(tmp_path / "M.json"), "--data", str(tmp_path / "loaded.csv"),
        "--reference", str(tmp_path / "unloaded.csv"), "--json", str(tmp_path / "P.json"),
        "--report", str(tmp_path / "R.html"), "--out", str(tmp_path / "M2.json"), "--quiet",
    ]  # fmt: skip
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert re.search(r"mass 1\.\d+ kg", out), out
    fig = json.loads((tmp_path / "P.json").read_text())
    for key in (
        "mass",
        "mass_std",
        "com",
        "com_std",
        "inertia",
        "inertia_std",
        "frame",
        "determined",
        "drive_gains",
    ):
        assert key in fig
    assert fig["frame"] == "tool0" and abs(fig["mass"] - MASS) < 0.015
    html = (tmp_path / "R.html").read_text()
    assert 'id="payload-figures"' in html and html.count("<img") == 3
    assert (tmp_path / "M2.json").exists() and (tmp_path / "M2.npz").exists()


@pytest.mark.parametrize(
    ("extra", "pattern"),
    [
        (["--mass", "-1"], r"--mass.*expected the payload's mass in kg"),
        (["--frame", "nowhere"], r"--frame nowhere: .*no frame 'nowhere'"),
        (["--out", "{tmp}/M.json"], r"--out .* would overwrite the --model file"),
        (["--reference", "{tmp}/other.csv"], r"reference run does not follow the loaded run's motion"),
    ],
)
def test_mistakes_end_in_one_sentence(runs, tmp_path, capsys, extra, pattern):
    import dynid
    from dynid.data.files import save_dataset
    from dynid.identify.model import save_model
    from dynid.sim.simulator import simulate

    save_model(runs["model"], tmp_path / "M.json")
    save_dataset(runs["loaded"], tmp_path / "loaded.csv")
    if "{tmp}/other.csv" in extra:
        other = dataclasses.replace(runs["motion"], a=-runs["motion"].a)
        save_dataset(
            simulate(dynid.load_robot("ur5"), other, seed=5, duration=DURATION).to_dataset(),
            tmp_path / "other.csv",
        )
    extra = [e.replace("{tmp}", str(tmp_path)) for e in extra]
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    capsys.readouterr()
    try:
        code = main(
            [
                "payload",
                "--model",
                str(tmp_path / "M.json"),
                "--data",
                str(tmp_path / "loaded.csv"),
                "--quiet",
                *extra,
            ]
        )
    except SystemExit as exc:  # an option's value refused by argparse
        code = exc.code
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 2 and "Traceback" not in err, err
    assert len(lines) == 1 and re.search(pattern, lines[0]), err
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before


def test_export_writes_the_payload_as_a_link_of_its_own(runs, tmp_path):
    """The model with the payload, exported: a fixed payload link at the tool frame, reload-checked, the
    description's tool frame unchanged."""
    import xml.etree.ElementTree as ET

    from dynid.simmodel.export import export_model
    from dynid.symbolic.robot import load_robot

    res = identify_payload(runs["model"], runs["loaded"], reference=runs["reference"])
    result = export_model(attach_payload(runs["model"], res), "urdf", tmp_path / "ur5_payload.urdf")
    assert all(c["passed"] for c in result.checks)
    root = ET.parse(tmp_path / "ur5_payload.urdf").getroot()
    link = root.find("link[@name='payload']")
    assert link is not None
    assert float(link.find("inertial/mass").get("value")) == pytest.approx(res.mass, rel=1e-9)
    joint = root.find("joint[@name='payload_joint']")
    assert joint.get("type") == "fixed" and joint.find("parent").get("link") == "wrist_3_link"
    again = load_robot(tmp_path / "ur5_payload.urdf")
    assert again.tool_name == "tool0"
    # loaded back, the payload link merges into the carrying link: the identified body, the payload once
    assert again.params[50] == pytest.approx(result.params.standard[50], rel=1e-9)
    assert result.params.standard[50] > res.mass


# ---------------------------------------------------------------------- the payload motion
@pytest.fixture(scope="module")
def payload_motion(ur5):
    from dynid.optim.payload_motion import design_payload_motion

    place = payload_frame(ur5)
    pose = np.array([0.0, -1.2, 1.0, -1.0, 0.5, 0.0])
    return design_payload_motion(ur5, place.link, frame_transform(place), pose=pose, duration=10.0)


def test_the_payload_motion_is_short_at_rest_at_its_pose_and_within_the_limits(payload_motion, ur5):
    from dynid.optim.excitation import ExcitationProblem

    traj = payload_motion.trajectory
    assert 1.0 / traj.base_freq <= 15.0 and payload_motion.feasible
    q, dq, ddq = traj.evaluate(np.array([0.0, 1.0 / traj.base_freq]))
    np.testing.assert_allclose(q, np.tile(payload_motion.pose, (2, 1)), atol=1e-9)
    np.testing.assert_allclose(dq, 0.0, atol=1e-9)
    np.testing.assert_allclose(ddq, 0.0, atol=1e-9)
    check = ExcitationProblem(robot=ur5, harmonics=traj.a.shape[0], base_freq=traj.base_freq)
    assert check.is_feasible(traj)
    # far better conditioned for the payload than the random starts it began from
    assert payload_motion.cond < payload_motion.baseline_cond / 3


def test_the_payload_motion_determines_every_parameter(payload_motion, runs, ur5):
    """On the designed 10 s motion the whole inertia comes out (the generic motion leaves Ixx, Iyy
    undetermined): principal moments within 10 % of the largest."""
    from dynid.sim.simulator import build_truth, simulate

    truth = build_truth(ur5, friction="linear", truth_seed=0)
    place = payload_frame(ur5)
    params = np.array(truth.robot.params, dtype=float)
    params[10 * place.link : 10 * place.link + 10] += frame_transform(place) @ TRUE
    loaded_truth = dataclasses.replace(truth, robot=truth.robot.with_params(params))
    motion = payload_motion.trajectory
    loaded = simulate(ur5, motion, truth=loaded_truth, seed=3).to_dataset()
    unloaded = simulate(ur5, motion, truth=truth, seed=4).to_dataset()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = identify_payload(runs["model"], loaded, reference=unloaded)
    assert res.determined.all(), res.figures()["determined"]
    mass_err, com_err = _errors(res.params)
    assert mass_err < 0.01 and com_err < 0.003
    found = np.linalg.eigvalsh(np.array(res.figures()["inertia"]))
    true = np.linalg.eigvalsh(_turned(_box(MASS, SIDES)))
    assert np.max(np.abs(found - true)) < 0.10 * true.max(), (found, true)


def test_excite_payload_writes_the_motion_and_its_csv(tmp_path, capsys):
    argv = [
        "excite", "--robot", "ur5", "--payload", "--duration", "6", "--home", "0,-1.2,1,-1,0.5,0",
        "--out", str(tmp_path / "P.json"), "--csv", str(tmp_path / "P.csv"), "--json", str(tmp_path / "E.json"),
        "--quiet",
    ]  # fmt: skip
    assert main(argv) == 0
    from dynid.optim.trajectory import load_trajectory

    traj = load_trajectory(tmp_path / "P.json")
    assert traj.base_freq == pytest.approx(1 / 6)
    fig = json.loads((tmp_path / "E.json").read_text())
    assert fig["criterion"] == "payload" and fig["feasible"] and fig["duration_s"] == pytest.approx(6)
    header = (tmp_path / "P.csv").read_text().splitlines()[0]
    assert header.startswith("t,q_1")


def test_a_payload_motion_longer_than_15_s_is_refused(tmp_path, capsys):
    code = main(
        [
            "excite",
            "--robot",
            "ur5",
            "--payload",
            "--duration",
            "20",
            "--out",
            str(tmp_path / "P.json"),
            "--quiet",
        ]
    )
    err = capsys.readouterr().err
    assert code == 2 and "--duration is 20" in err and "Traceback" not in err
    assert not (tmp_path / "P.json").exists()


def test_outputs_written_together_or_not_at_all(tmp_path):
    """A failure while writing the second file leaves the first one's old content (issue: a full disk
    during excite replaced T.json and wrote no CSV)."""
    from dynid._io import write_together

    first, second = tmp_path / "T.json", tmp_path / "T.csv"
    first.write_text("old trajectory")

    def full_disk(tmp):
        raise OSError(28, "No space left on device")

    with pytest.raises(OSError, match="No space left"):
        write_together([(first, lambda tmp: tmp.write_text("new trajectory")), (second, full_disk)])
    assert first.read_text() == "old trajectory" and not second.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["T.json"]  # no temporary file left
    write_together([(first, lambda tmp: tmp.write_text("new")), (second, lambda tmp: tmp.write_text("csv"))])
    assert first.read_text() == "new" and second.read_text() == "csv"
