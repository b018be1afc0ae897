"""ROS 2 recordings (rosbag2 folders and MCAP files of sensor_msgs/JointState) read as datasets.

The bags are written with rosbags' own writer, in both storages it writes (sqlite3 .db3 and MCAP), from
a simulated UR5 run; reading them back must give the run's arrays in the robot's joint order, whatever
the order of the names in the messages and whatever extra joints they carry.  A bag and the CSV of the
same run give the same identified model (base parameters to a relative 1e-9) and the same validation.
Each refusal (a joint missing, a wrong or ambiguous topic, a message of the wrong length, no robot,
rosbags not installed) is one sentence, and exit code 2 on the command line; irregular stamps are
resampled onto the median interval and checked against the signal they sample.
"""

from __future__ import annotations

import json
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("rosbags", reason="ROS 2 recordings are read with the optional rosbags package (dynid[ros])")

from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from dynid.cli import main
from dynid.data.files import load_dataset, save_dataset
from dynid.exceptions import DataError, DataWarning

STORE = get_typestore(Stores.LATEST)
JOINT_STATE = "sensor_msgs/msg/JointState"
T0_NS = 1_763_900_000_123_456_789  # an epoch stamp (ns): the reader counts time from the first message
RATE = 200.0
FINGERS = ("panda_finger_joint1", "gripper_finger_joint")


def message(stamp_ns: int, names, position, effort, velocity=()):
    """A serialised JointState message (CDR)."""
    types = STORE.types
    stamp = types["builtin_interfaces/msg/Time"](sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9)
    msg = types[JOINT_STATE](
        header=types["std_msgs/msg/Header"](stamp=stamp, frame_id=""),
        name=[str(n) for n in names],
        position=np.asarray(position, dtype=np.float64),
        velocity=np.asarray(velocity, dtype=np.float64),
        effort=np.asarray(effort, dtype=np.float64),
    )
    return STORE.serialize_cdr(msg, JOINT_STATE)


def write_bag(path: Path, topics: dict, *, storage: str = "mcap") -> Path:
    """A rosbag2 folder: ``topics`` maps a topic to a list of (receive time ns, serialised message).

    A list of strings instead is written as std_msgs/String messages (a topic of another type).
    """
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    with Writer(path, version=9, storage_plugin=plugin) as writer:
        for topic, items in topics.items():
            if items and isinstance(items[0], str):
                conn = writer.add_connection(topic, "std_msgs/msg/String", typestore=STORE)
                for k, text in enumerate(items):
                    raw = STORE.serialize_cdr(STORE.types["std_msgs/msg/String"](data=text), "std_msgs/msg/String")
                    writer.write(conn, T0_NS + k, raw)
                continue
            conn = writer.add_connection(topic, JOINT_STATE, typestore=STORE)
            for received, raw in items:
                writer.write(conn, received, raw)
    return path


def joint_messages(ds, names, *, rng=None, extra=(), stamps=None, velocity=True, tau_scale=1.0):
    """One message per sample of ``ds``; names shuffled per message when ``rng`` is given, ``extra`` joints added."""
    stamps = T0_NS + np.round(ds.t * 1e9).astype(np.int64) if stamps is None else stamps
    items = []
    for k in range(ds.m):
        all_names = [*names, *extra]
        pos = np.concatenate([ds.q[k], np.full(len(extra), 0.02)])
        eff = np.concatenate([tau_scale * ds.tau[k], np.full(len(extra), 5.0)])
        vel = np.concatenate([ds.dq[k], np.zeros(len(extra))]) if velocity else np.zeros(0)
        if rng is not None:
            order = rng.permutation(len(all_names))
            all_names = [all_names[i] for i in order]
            pos, eff = pos[order], eff[order]
            vel = vel[order] if velocity else vel
        items.append((int(stamps[k]) + 250_000, message(int(stamps[k]), all_names, pos, eff, vel)))
    return items


@pytest.fixture(scope="module")
def run(ur5):
    """A simulated UR5 run: 10 s at 200 Hz, with the true joint velocities as measured dq."""
    from dynid.sim import random_fourier, simulate

    result = simulate(ur5, random_fourier(ur5, np.random.default_rng(11)), rate=RATE, duration=10.0, seed=3)
    return result.to_dataset(true_states=True)._derive(ddq=None)


@pytest.fixture(scope="module")
def files(run, ur5, tmp_path_factory) -> dict[str, Path]:
    """The run as CSV, and as bags: both storages, and one with shuffled names and finger joints."""
    folder = tmp_path_factory.mktemp("bags")
    names = ur5.joint_names
    out = {"csv": save_dataset(run, folder / "run.csv")}
    for storage in ("mcap", "sqlite3"):
        out[storage] = write_bag(folder / f"run_{storage}", {"/joint_states": joint_messages(run, names)},
                                 storage=storage)
    out["shuffled"] = write_bag(
        folder / "shuffled",
        {"/joint_states": joint_messages(run, names, rng=np.random.default_rng(2), extra=FINGERS)},
    )
    out["two_topics"] = write_bag(
        folder / "two_topics",
        {
            "/joint_states": joint_messages(run, names),
            "/arm/joint_states": joint_messages(run, names, tau_scale=2.0),
            "/chatter": ["hello", "world"],
        },
    )
    return out


def read(path, robot, **kwargs):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", DataWarning)
        ds = load_dataset(path, robot=robot, **kwargs)
    return ds, [str(w.message) for w in caught if issubclass(w.category, DataWarning)]


def cli(argv, capsys) -> tuple[int, str, str]:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    assert "Traceback" not in out + err
    return code, out, err


# ---------------------------------------------------------------------- reading back
@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
@pytest.mark.parametrize("what", ["folder", "storage file"])
def test_bag_reads_back_as_the_run(files, run, ur5, storage, what):
    path = files[storage]
    if what == "storage file":
        path = next(path.glob("*.mcap" if storage == "mcap" else "*.db3"))
    ds, notes = read(path, ur5)
    assert notes == []
    assert ds.m == run.m and ds.is_uniform
    np.testing.assert_allclose(ds.t, run.t, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(ds.q, run.q)
    np.testing.assert_array_equal(ds.tau, run.tau)
    np.testing.assert_array_equal(ds.dq, run.dq)
    assert ds.meta["topic"] == "/joint_states" and ds.meta["stamps"] == "header"
    assert ds.meta["t0_ns"] == T0_NS and ds.meta["joint_names"] == list(ur5.joint_names)


def test_shuffled_names_map_to_the_robot_order_and_extra_joints_are_said_once(files, run, ur5):
    ds, notes = read(files["shuffled"], ur5)
    np.testing.assert_array_equal(ds.q, run.q)
    np.testing.assert_array_equal(ds.tau, run.tau)
    np.testing.assert_array_equal(ds.dq, run.dq)
    assert len(notes) == 1, notes
    assert f"joints {FINGERS[0]}, {FINGERS[1]} are not joints of the robot 'ur5' and are ignored" in notes[0]
    assert ds.meta["ignored_joints"] == list(FINGERS)


def test_topic_picks_one_of_two(files, run, ur5):
    with pytest.raises(DataError, match=r"two_topics holds 2 sensor_msgs/msg/JointState topics "
                                        r"\(/arm/joint_states, /joint_states\); pick one with --topic NAME"):
        load_dataset(files["two_topics"], robot=ur5)
    arm, _ = read(files["two_topics"], ur5, topic="/arm/joint_states")
    plain, _ = read(files["two_topics"], ur5, topic="/joint_states")
    np.testing.assert_array_equal(arm.tau, 2.0 * run.tau)
    np.testing.assert_array_equal(plain.tau, run.tau)


def test_wrong_topic_is_one_sentence(files, ur5):
    with pytest.raises(DataError, match=r"has no topic /nope; its sensor_msgs/msg/JointState topics are: "
                                        r"/arm/joint_states, /joint_states; give one of them with --topic"):
        load_dataset(files["two_topics"], robot=ur5, topic="/nope")
    with pytest.raises(DataError, match=r"the topic /chatter holds std_msgs/msg/String, not "
                                        r"sensor_msgs/msg/JointState; pick a JointState topic with --topic"):
        load_dataset(files["two_topics"], robot=ur5, topic="/chatter")


def test_missing_joint_and_wrong_lengths_are_refused(run, ur5, tmp_path):
    names = list(ur5.joint_names)
    short = run.select_rows(np.arange(20))
    items = joint_messages(short, names)
    items[7] = (items[7][0], message(T0_NS + 7, names[:-1], short.q[7, :-1], short.tau[7, :-1]))
    with pytest.raises(DataError, match=r"message 7 on /joint_states has no joint 'wrist_3_joint' of the robot "
                                        r"'ur5' \(it names shoulder_pan_joint, .*wrist_2_joint; .*record all "
                                        r"of the robot's joints"):
        load_dataset(write_bag(tmp_path / "missing", {"/joint_states": items}), robot=ur5)
    items = joint_messages(short, names)
    items[3] = (items[3][0], message(T0_NS + 3, names, short.q[3], short.tau[3, :5]))
    with pytest.raises(DataError, match=r"message 3 on /joint_states names 6 joints but holds 5 effort values; "
                                        r"every message must give one value per name"):
        load_dataset(write_bag(tmp_path / "length", {"/joint_states": items}), robot=ur5)
    items = [(r, message(T0_NS + k, names, short.q[k], ())) for k, (r, _) in enumerate(joint_messages(short, names))]
    with pytest.raises(DataError, match=r"holds 0 effort values; efforts are the joint torques dynid identifies"):
        load_dataset(write_bag(tmp_path / "no_effort", {"/joint_states": items}), robot=ur5)


def test_a_namespace_prefix_on_the_joint_names_is_dropped_when_only_one_fits(run, ur5, panda, tmp_path):
    short = run.select_rows(np.arange(40))
    prefixed = [f"ur5/{j}" for j in ur5.joint_names]
    ds, notes = read(write_bag(tmp_path / "prefixed", {"/joint_states": joint_messages(short, prefixed)}), ur5)
    np.testing.assert_array_equal(ds.q, short.q)
    assert ds.meta["joint_prefix"] == "ur5/"
    assert notes == ["prefixed (/joint_states): the joint names carry the prefix 'ur5/' "
                     "(ur5/shoulder_pan_joint is shoulder_pan_joint)"]
    two = [*prefixed, *(f"left_{j}" for j in ur5.joint_names)]
    items = [(r, message(T0_NS + k, two, np.tile(short.q[k], 2), np.tile(short.tau[k], 2)))
             for k, (r, _) in enumerate(joint_messages(short, prefixed))]
    with pytest.raises(DataError, match=r"message 0 on /joint_states names the joints of the robot 'ur5' under 2 "
                                        r"prefixes \(left_, ur5/\), one arm each; dynid reads one arm"):
        load_dataset(write_bag(tmp_path / "two_arms", {"/joint_states": items}), robot=ur5)
    with pytest.raises(DataError, match=r"prefixed: no message on /joint_states names a joint of the robot "
                                        r"'panda' \(they name ur5/elbow_joint, .*; give the robot \(--robot\) the "
                                        r"bag was recorded on"):
        load_dataset(tmp_path / "prefixed", robot=panda)


def test_no_joint_state_no_robot_no_rosbags(files, ur5, tmp_path, monkeypatch):
    chatter = write_bag(tmp_path / "chatter", {"/chatter": ["a", "b"]})
    with pytest.raises(DataError, match=r"chatter holds no sensor_msgs/msg/JointState messages \(it holds "
                                        r"/chatter \(std_msgs/msg/String\)\); record the robot's joint states"):
        load_dataset(chatter, robot=ur5)
    with pytest.raises(DataError, match=r"run_mcap is a ROS 2 recording, whose joints are known by name, but no "
                                        r"robot was given to put them in order; pass robot="):
        load_dataset(files["mcap"])
    for module in ("rosbags", "rosbags.rosbag2", "rosbags.typesys"):
        monkeypatch.setitem(sys.modules, module, None)  # as if the optional package were not installed
    with pytest.raises(DataError, match=r"needs the 'rosbags' package, which is not installed; install it with "
                                        r'pip install (-e )?"[^"]*\[ros\]"'):
        load_dataset(files["mcap"], robot=ur5)


# ---------------------------------------------------------------------- time stamps
def sine_run(t):
    """Joint angles, velocities and torques sampled from smooth signals at stamps ``t`` (s)."""
    w = 2 * np.pi * np.array([0.5, 0.3, 0.7, 0.4, 0.6, 0.2])
    q = 0.8 * np.sin(np.outer(t, w) + 0.3)
    dq = 0.8 * w * np.cos(np.outer(t, w) + 0.3)
    tau = 10.0 * np.cos(np.outer(t, w))
    return q, dq, tau


def test_irregular_stamps_are_resampled_at_the_median_interval(ur5, tmp_path):
    rng = np.random.default_rng(4)
    m = 3000
    ns = T0_NS + np.arange(m, dtype=np.int64) * 5_000_000 + rng.integers(-1_500_000, 1_500_001, m)
    ns[1200] = ns[1199]  # a repeated stamp (another sample): dropped
    ns[2000:] += 500_000_000  # a 0.5 s gap: the data split there, not interpolated across
    t_true = (ns - ns[0]) * 1e-9
    q, dq, tau = sine_run(t_true)
    received = ns + 100_000
    received[10] = ns[11] + 200_000  # stored after the next one: put back in stamp order
    items = [(int(received[k]), message(int(ns[k]), ur5.joint_names, q[k], tau[k], dq[k])) for k in range(m)]
    ds, notes = read(write_bag(tmp_path / "jitter", {"/joint_states": items}), ur5)
    assert len(notes) == 1, notes
    note = notes[0]
    assert "1 message stamped before the message stored ahead of it: the messages are put in stamp order" in note
    assert "1 message repeating an earlier stamp dropped" in note
    steps = np.diff(np.unique(ns)) * 1e-9
    dt = round(float(np.median(steps)), 6)  # the median interval to the microsecond
    assert f"q, tau and dq are resampled linearly onto a uniform grid at {1 / dt:.6g} Hz (the median interval" in note
    assert "split there into separate runs, not interpolated across the gap" in note
    assert ds.is_uniform and abs(ds.dt - dt) < 1e-12 and len(ds.runs) == 2
    assert ds.meta["resampled"]["gaps"][0][1] == pytest.approx(t_true[2000] - t_true[1999], abs=1e-12)
    assert ds.t[ds.runs[1].start] == pytest.approx(t_true[2000], abs=1e-12)  # the run after the gap keeps its time
    # Linear interpolation of the true signals: within h^2 max|f''| / 8 of them at every grid point.
    q_ref, dq_ref, tau_ref = sine_run(ds.t)
    h = steps[steps < 0.1].max()
    w = 2 * np.pi * 0.7
    q_err, dq_err, tau_err = (np.abs(a - b).max() for a, b in ((ds.q, q_ref), (ds.dq, dq_ref), (ds.tau, tau_ref)))
    assert q_err < 0.8 * w**2 * h**2 / 8
    assert dq_err < 0.8 * w**3 * h**2 / 8
    assert tau_err < 10.0 * w**2 * h**2 / 8
    assert q_err > 1e-9  # the grid is not the stamps: the values were interpolated
    # ... and linearly, between the two stamps around each grid point.
    t_src, first = np.unique(t_true, return_index=True)
    for name, src in (("q", q), ("dq", dq), ("tau", tau)):
        linear = np.column_stack([np.interp(ds.t, t_src, src[first, j]) for j in range(6)])
        np.testing.assert_allclose(getattr(ds, name), linear, rtol=0, atol=1e-12 * np.abs(src).max(), err_msg=name)


def test_zero_stamps_fall_back_to_receive_time_and_dq_only_when_measured(ur5, tmp_path):
    t = np.arange(400) / RATE
    q, _, tau = sine_run(t)
    received = T0_NS + np.round(t * 1e9).astype(np.int64)
    items = [(int(received[k]), message(0, ur5.joint_names, q[k], tau[k])) for k in range(len(t))]
    ds, notes = read(write_bag(tmp_path / "zero", {"/joint_states": items}), ur5)
    assert ds.meta["stamps"] == "receive" and ds.dq is None
    assert notes == [
        "zero (/joint_states): the header stamps are zero, so the bag's receive times are used as the time"
    ]
    np.testing.assert_allclose(ds.t, t, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(ds.q, q)


def test_gripper_messages_are_skipped_and_dq_is_kept_only_when_every_message_has_it(ur5, tmp_path):
    t = np.arange(300) / RATE
    q, dq, tau = sine_run(t)
    stamps = T0_NS + np.round(t * 1e9).astype(np.int64)
    items = []
    for k in range(len(t)):
        velocity = dq[k] if k % 50 else ()  # every 50th message without velocities
        items.append((int(stamps[k]), message(int(stamps[k]), ur5.joint_names, q[k], tau[k], velocity)))
        if k % 10 == 0:  # the gripper's own message on the same topic
            items.append((int(stamps[k]) + 1, message(int(stamps[k]) + 1, FINGERS[1:], [0.01], [2.0], [0.0])))
    ds, notes = read(write_bag(tmp_path / "gripper", {"/joint_states": items}), ur5)
    assert ds.dq is None and ds.m == len(t) and ds.meta["skipped_messages"] == 30
    np.testing.assert_array_equal(ds.q, q)
    np.testing.assert_array_equal(ds.tau, tau)
    assert notes == [
        "gripper (/joint_states): 30 messages naming none of the robot's joints skipped; some messages carry "
        "no velocities, so dq is left out (it is derived from q)"
    ]


# ---------------------------------------------------------------------- the commands
def test_bag_and_csv_give_the_same_model_and_validation(files, tmp_path, capsys):
    options = ["--robot", "ur5", "--method", "ols", "--friction", "linear", "--gmm", "off"]
    figures = {}
    for name in ("csv", "mcap"):
        model, js = tmp_path / f"M_{name}.json", tmp_path / f"id_{name}.json"
        code, _, err = cli(["identify", *options, "--data", files[name], "--out", model, "--json", js], capsys)
        assert code == 0, err
        figures[name] = json.loads(js.read_text())
    csv, bag = (np.array(list(figures[k]["base_params"].values())) for k in ("csv", "mcap"))
    assert list(figures["csv"]["base_params"]) == list(figures["mcap"]["base_params"])
    np.testing.assert_allclose(bag, csv, rtol=1e-9, atol=1e-9 * np.abs(csv).max())
    rms = {}
    for name in ("csv", "shuffled"):
        js = tmp_path / f"val_{name}.json"
        code, _, err = cli(["validate", "--model", tmp_path / "M_csv.json", "--data", files[name], "--json", js],
                           capsys)
        assert code == 0, err
        rms[name] = json.loads(js.read_text())["rms"]
    np.testing.assert_allclose(rms["shuffled"], rms["csv"], rtol=1e-9)


def test_commands_refuse_an_ambiguous_or_wrong_topic_in_one_sentence(files, tmp_path, capsys):
    code, out, err = cli(["identify", "--robot", "ur5", "--data", files["two_topics"], "--out", tmp_path / "M.json"],
                         capsys)
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and "pick one with --topic NAME" in err
    assert not (tmp_path / "M.json").exists()
    code, out, err = cli(["identify", "--robot", "ur5", "--data", files["two_topics"], "--topic", "/nope",
                          "--out", tmp_path / "M.json"], capsys)
    assert code == 2 and "has no topic /nope" in err and err.count("\n") == 1
    model = tmp_path / "M_csv.json"
    code, _, err = cli(["identify", "--robot", "ur5", "--method", "ols", "--friction", "linear", "--gmm", "off",
                        "--data", files["csv"], "--out", model], capsys)
    assert code == 0, err
    code, out, err = cli(["diagnose", "--model", model, "--data", files["two_topics"], "--heldout", files["mcap"]],
                         capsys)
    assert code == 2 and "two_topics holds 2 sensor_msgs/msg/JointState topics" in err and err.count("\n") == 1


def test_export_reads_the_held_out_topic_it_is_given(files, tmp_path, capsys):
    """``export --heldout BAG --topic``: the topic named is the one measured (its torques doubled on the other)."""
    model = tmp_path / "M.json"
    code, _, err = cli(["identify", "--robot", "ur5", "--method", "ols", "--friction", "linear", "--gmm", "off",
                        "--data", files["csv"], "--out", model], capsys)
    assert code == 0, err
    base = ["export", "--model", model, "--format", "urdf"]
    code, out, err = cli([*base, "--out", tmp_path / "none.urdf", "--heldout", files["two_topics"]], capsys)
    assert code == 2 and out == "" and err.count("\n") == 1 and "pick one with --topic NAME" in err
    assert not (tmp_path / "none.urdf").exists()
    rms = {}
    for name, heldout, topic in (("csv", files["csv"], []), ("plain", files["two_topics"], ["--topic", "/joint_states"]),
                                 ("arm", files["two_topics"], ["--topic", "/arm/joint_states"])):
        js = tmp_path / f"{name}.json"
        code, _, err = cli([*base, "--out", tmp_path / f"{name}.urdf", "--heldout", heldout, *topic, "--json", js],
                           capsys)
        assert code == 0, err
        rms[name] = json.loads(js.read_text())["heldout"]["rms_full_mean"]
    assert rms["plain"] == pytest.approx(rms["csv"], rel=1e-9)
    assert rms["arm"] > 10 * rms["csv"]  # the model fits tau; the other topic carries 2 tau
