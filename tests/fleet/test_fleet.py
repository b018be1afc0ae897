"""dynid fleet: recordings found by path or manifest, identified on a real LocalCluster as serially, drift found.

A small simulated fleet (three UR5s within manufacturing tolerance, three short recordings each, one robot's
joint-3 friction raised by half from its third recording on) is made once per module by the fleet's own
simulator; identifications use linear friction and no mixture (what the drift tests read), as the fleet
benchmark does.
"""

from __future__ import annotations

import csv
import json
import os
import re
from dataclasses import replace

import numpy as np
import pytest

pytest.importorskip("distributed", reason="the fleet runs on dask.distributed (pip install 'dynid[fleet]')")
pytest.importorskip("pyarrow", reason="the fleet table is written as Parquet through pyarrow")

from dynid.cli import main
from dynid.exceptions import UsageError
from dynid.fleet.core import FleetResult, identify_fleet
from dynid.fleet.drift import detect_drift, holm
from dynid.fleet.recordings import find_recordings, parse_time
from dynid.fleet.simulated import Change, simulate_fleet

OPTIONS = {"friction": "linear", "gmm": "off"}
CHANGED, JOINT, AT = "robot_01", 3, 2


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    root = tmp_path_factory.mktemp("fleet")
    truth = simulate_fleet(
        "ur5", root, robots=3, recordings=3, duration=6.0, base_freq=0.2, seed=4,
        changes={1: Change("friction", at=AT, joint=JOINT, factor=1.5)},
    )
    pattern = str(root / "**" / "*.csv")
    return {"root": root, "truth": truth, "pattern": pattern, "serial": identify_fleet("ur5", pattern, serial=True, **OPTIONS)}


def _strip(rows):
    return [{k: v for k, v in r.items() if k not in ("elapsed_s", "cpu_s")} for r in rows]


@pytest.mark.slow
def test_a_local_cluster_of_two_workers_gives_the_serial_table(fleet, tmp_path, monkeypatch):
    """Four recordings (two robots) keep it short; the drift tests are a function of the table.

    The caller's environment is left as it was: Dask's nanny sets its workers' variables (one BLAS
    thread, a hash seed, a heap-trim threshold) in the process that starts them.
    """
    monkeypatch.setenv("OMP_NUM_THREADS", "3")
    for key in ("MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MALLOC_TRIM_THRESHOLD_", "PYTHONHASHSEED"):
        monkeypatch.delenv(key, raising=False)
    def ours() -> dict[str, str]:
        # Dask's own bookkeeping (__DASK_PARENT_PID, left by any earlier cluster in this process) aside
        return {k: v for k, v in os.environ.items() if not k.startswith("__DASK")}

    before = ours()
    recordings = find_recordings(fleet["pattern"])[1:5]
    on_cluster = identify_fleet("ur5", recordings, workers=2, **OPTIONS)
    assert ours() == before
    assert on_cluster.info["scheduler"] == "local" and on_cluster.info["workers"] == 2
    assert len(on_cluster.rows) == 4 and not on_cluster.errors
    assert _strip(on_cluster.rows) == _strip(fleet["serial"].rows[1:5])
    out = on_cluster.write(tmp_path / "out")
    import pyarrow.parquet as pq

    table = pq.read_table(out / "fleet.parquet")
    assert table.num_rows == 4 and table.column_names == on_cluster.columns
    np.testing.assert_array_equal(table.column("fc3").to_numpy(), on_cluster.column("fc3"))
    with open(out / "fleet.csv", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    assert [float(r["fc3_std"]) for r in rows] == list(on_cluster.column("fc3_std"))
    assert "robot_01" in (out / "report.html").read_text(encoding="utf-8")
    summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))  # the JSON's per-recording rows
    assert [r["path"] for r in summary["rows"]] == [r["path"] for r in on_cluster.rows]
    assert [r["fc3"] for r in summary["rows"]] == list(on_cluster.column("fc3"))
    on_cluster.write(out)  # its own earlier folder is replaced


def _worker_environment():
    keys = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "DYNID_NUM_THREADS", "MALLOC_TRIM_THRESHOLD_")
    return {k: os.environ.get(k) for k in keys}


def test_local_workers_get_one_blas_thread_and_the_caller_keeps_its_environment(monkeypatch):
    """Dask's default trim threshold (64 KiB) made the workers fault in every large array anew: left out."""
    from dynid._cluster import _spawn_environment, cluster_client

    monkeypatch.setenv("MKL_NUM_THREADS", "4")
    for key in ("OMP_NUM_THREADS", "DYNID_NUM_THREADS", "MALLOC_TRIM_THRESHOLD_"):
        monkeypatch.delenv(key, raising=False)
    caller = _worker_environment()
    with cluster_client(None, workers=1) as client:
        assert _worker_environment() == caller  # already while the cluster runs
        seen = list(client.run(_worker_environment).values())
    one = {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "DYNID_NUM_THREADS": "1", "MALLOC_TRIM_THRESHOLD_": None}
    assert seen == [one]
    assert _worker_environment() == caller
    assert caller == {"OMP_NUM_THREADS": None, "MKL_NUM_THREADS": "4", "DYNID_NUM_THREADS": None, "MALLOC_TRIM_THRESHOLD_": None}
    monkeypatch.setenv("MALLOC_TRIM_THRESHOLD_", "131072")  # one the user sets is theirs to keep
    overrides, saved = _spawn_environment()
    assert saved["MALLOC_TRIM_THRESHOLD_"] == "131072"
    assert not any(key.endswith("MALLOC_TRIM_THRESHOLD_") for key in overrides)


def test_the_table_holds_parameters_with_their_spread_and_the_held_out_error(fleet):
    result = fleet["serial"]
    assert [r["robot"] for r in result.rows] == ["robot_00"] * 3 + ["robot_01"] * 3 + ["robot_02"] * 3
    assert [r["order"] for r in result.rows] == [0, 1, 2] * 3
    assert result.rows[0]["time"] == "2026-01-15"
    for name in ("fc3", "fv3", "Izz1R", "heldout_rms_mean", "heldout_rms_6", "cond"):
        values = result.column(name)
        assert np.all(np.isfinite(values)), name
    std = result.column("fc3_std")
    assert np.all(std > 0) and np.all(std < 0.1 * np.abs(result.column("fc3")))
    # the held-out error is the last 20 %: 1.2 s of a 6 s recording
    assert np.allclose(result.column("heldout_s"), 1.2, atol=0.01)
    assert np.all(result.column("heldout_rms_mean") < 1.0)
    assert all(isinstance(r["warnings"], str) for r in result.rows)  # dynid's warnings per recording, if any


def test_a_friction_jump_is_flagged_at_its_recording_and_the_unchanged_robots_are_not(fleet):
    drift = fleet["serial"].drift
    flagged = drift.flagged_robots
    assert list(flagged) == [CHANGED]
    top = flagged[CHANGED][0]
    assert top.parameter in (f"fc{JOINT}", f"fv{JOINT}")
    assert top.change_order == AT and top.change_time == "2026-03-15"
    # the change is the truth's: +50 % friction (Coulomb, identified as such with the seed model's nonlinearity)
    fc = next(t for t in drift.tests if t.robot == CHANGED and t.parameter == f"fc{JOINT}")
    assert fc.flagged and 1.35 < fc.after / fc.before < 1.65
    assert all(not t.flagged for t in drift.tests if t.robot != CHANGED)


def test_the_drift_test_reads_the_identifications_standard_deviations(fleet):
    """The same values with a hundred times the spread are no evidence of change: no threshold on values."""
    result = fleet["serial"]
    wide = [{k: (v * 100 if k.endswith("_std") else v) for k, v in r.items()} for r in result.rows]
    drift = detect_drift(FleetResult(wide, result.columns, result.parameters, result.settings, info=result.info))
    assert drift.flagged_robots == {}
    assert detect_drift(result).flagged_robots.keys() == {CHANGED}


def test_the_tested_parameters_are_friction_armature_and_what_a_tool_moves(fleet):
    tested = set(fleet["serial"].drift.parameters)
    assert {f"fc{j}" for j in range(1, 7)} | {f"fv{j}" for j in range(1, 7)} <= tested
    assert not any(name.startswith("fo") for name in tested)
    shifts = {p["name"]: p["tool_shift"] for p in fleet["serial"].parameters}
    links = [name for name in tested if shifts[name] != 0]
    assert links and all(abs(shifts[name]) > 0 for name in links)
    assert "Izz1R" in tested  # a tool far from joint 1's axis adds inertia about it


def _report(result, tmp_path) -> str:
    from dynid.fleet.report import write_fleet_report

    return write_fleet_report(result, tmp_path / "report.html").read_text(encoding="utf-8")


def test_the_report_shows_the_flagged_robot_and_no_warning_with_three_recordings(fleet, tmp_path):
    from dynid.fleet.report import few_recordings

    result = fleet["serial"]
    assert few_recordings(result) == {}
    text = _report(result, tmp_path)
    assert 'id="few-recordings"' not in text
    table = text.split('id="flagged">Flagged robots</h2>', 1)[1].split("<h", 1)[0]
    assert f'<td class="text">{CHANGED}</td>' in table and "<thead>" in table


def test_two_recordings_per_robot_are_too_few_and_the_report_says_so(fleet, tmp_path):
    """Two recordings: the inflation factor is measured on the same pairs, so the median robot sits at p = 0.5."""
    from scipy import stats

    from dynid.fleet.report import few_recordings

    result = fleet["serial"]
    pairs = [r for r in result.rows if r["order"] < 2]  # before the change: nothing to find
    two = FleetResult(pairs, result.columns, result.parameters, result.settings, info=result.info)
    two = replace(two, drift=detect_drift(two))
    assert few_recordings(two) == {robot: 2 for robot in two.robots}
    inflated = [name for name, factor in two.drift.inflation.items() if factor > 1]
    # with pairs the factor is the median robot's own statistic over its median under no change
    assert inflated
    for name in inflated:
        chi2 = sorted(t.chi2 for t in two.drift.tests if t.parameter == name)
        assert chi2[len(chi2) // 2] == pytest.approx(stats.chi2.median(1), rel=1e-9)
    text = _report(two, tmp_path)
    warning = re.search(r'<p class="verdict" id="few-recordings"[^>]*>(.*?)</p>', text, flags=re.S).group(1)
    robots = "all 3 robots (robot_00, robot_01, robot_02) have only 2 recordings"
    assert f"Too few recordings for the drift test: {robots}" in warning
    assert "p = 0.5" in warning and "Record at least 3 per robot" in warning
    assert "0 robots flagged for drift: none (see the warning below)." in text
    # no empty table: a sentence
    flagged = text.split('id="flagged">Flagged robots</h2>', 1)[1].split("<h", 1)[0]
    assert "<table" not in flagged
    assert "None: no parameter of the 3 robots tested" in flagged and "family-wise error rate 0.05" in flagged
    # three robots are too few for the comparison with the fleet: said so, not "none"
    assert "Not tested: the fleet has 3 robots; the comparison with the fleet needs at least 5" in text
    # a robot with one recording is not tested, and named
    one = [r for r in pairs if not (r["robot"] == "robot_02" and r["order"] == 1)]
    single = FleetResult(one, result.columns, result.parameters, result.settings, info=result.info)
    single = replace(single, drift=detect_drift(single))
    assert few_recordings(single) == {"robot_00": 2, "robot_01": 2, "robot_02": 1}
    assert "robot_02 has 1 (not tested)" in _report(single, tmp_path)


def test_holm_adjusts_step_down():
    np.testing.assert_allclose(holm(np.array([0.01, 0.04, 0.03, 0.005])), [0.03, 0.06, 0.06, 0.02])
    assert holm(np.array([])).size == 0


def test_recordings_come_from_the_path_or_a_manifest(tmp_path):
    for robot, name in (("arm_b", "2026-02-01.csv"), ("arm_a", "3.csv"), ("arm_a", "12.csv"), ("arm_b", "2026-01-01.npz")):
        (tmp_path / robot).mkdir(exist_ok=True)
        (tmp_path / robot / name).write_text("t\n")
    (tmp_path / "arm_a" / "12.csv.truth.json").write_text("{}")
    found = find_recordings(str(tmp_path / "**" / "*"))
    assert [(r.robot, r.time, r.order) for r in found] == [
        ("arm_a", "3", 0), ("arm_a", "12", 1), ("arm_b", "2026-01-01", 0), ("arm_b", "2026-02-01", 1)
    ]
    manifest = tmp_path / "fleet.csv"
    manifest.write_text(
        "path,robot,time\narm_a/3.csv,x,2026-05-01\narm_a/12.csv,x,2026-04-01\n"
        "arm_b/2026-02-01.csv,y,1\narm_b/2026-01-01.npz,y,0\n"
    )
    found = find_recordings(str(tmp_path / "**" / "*"), manifest)
    assert [(r.robot, os.path.basename(r.path), r.order) for r in found] == [
        ("x", "12.csv", 0), ("x", "3.csv", 1), ("y", "2026-01-01.npz", 0), ("y", "2026-02-01.csv", 1)
    ]
    assert parse_time("2026-03-01T08-30") - parse_time("2026-03-01") == 8.5 * 3600
    assert parse_time("rec_7") == 7.0 and parse_time("latest") is None
    (tmp_path / "arm_a" / "latest.csv").write_text("t\n")
    with pytest.raises(UsageError, match=r"neither an ISO date nor an index; name recordings <robot>/"):
        find_recordings(str(tmp_path / "arm_a" / "*.csv"))


def _cli(args, capsys):
    code = main(["fleet", "--robot", "ur5", *args])
    err = capsys.readouterr().err.strip().splitlines()
    return code, err


def test_an_empty_glob_is_one_sentence_exit_2(tmp_path, capsys):
    code, err = _cli(["--data", str(tmp_path / "none" / "*.csv"), "--out", str(tmp_path / "out")], capsys)
    assert code == 2 and len(err) == 1
    assert err[0].startswith("dynid fleet: error: no recording matches") and "quote it" in err[0]
    assert not (tmp_path / "out").exists()


def test_a_manifest_missing_a_recording_is_one_sentence_exit_2(tmp_path, capsys):
    for name in ("0.csv", "1.csv"):
        (tmp_path / "arm").mkdir(exist_ok=True)
        (tmp_path / "arm" / name).write_text("t\n")
    manifest = tmp_path / "fleet.csv"
    manifest.write_text("path,robot,time\narm/0.csv,arm,0\n")
    code, err = _cli(
        ["--data", str(tmp_path / "arm" / "*.csv"), "--manifest", str(manifest), "--out", str(tmp_path / "out")], capsys
    )
    assert code == 2 and len(err) == 1
    assert "arm/1.csv' is not in the manifest" in err[0] and err[0].endswith("or narrow the pattern.")
    manifest.write_text("path,robot\narm/0.csv,arm\n")
    code, err = _cli(
        ["--data", str(tmp_path / "arm" / "*.csv"), "--manifest", str(manifest), "--out", str(tmp_path / "out")], capsys
    )
    assert code == 2 and len(err) == 1 and "has no column time" in err[0]
    assert not (tmp_path / "out").exists()


def test_an_unknown_scheduler_address_is_one_sentence_exit_2(tmp_path, capsys):
    (tmp_path / "arm").mkdir()
    (tmp_path / "arm" / "0.csv").write_text("t\n")
    code, err = _cli(
        ["--data", str(tmp_path / "arm" / "*.csv"), "--scheduler", "no-port-here", "--out", str(tmp_path / "out")],
        capsys,
    )
    assert code == 2 and len(err) == 1
    assert "no Dask scheduler answered at 'no-port-here'" in err[0] and "leave --scheduler out" in err[0]
    assert not (tmp_path / "out").exists()


def test_a_scheduler_that_does_not_answer_is_refused_after_the_timeout():
    from dynid._cluster import cluster_client

    with pytest.raises(UsageError, match=r"no Dask scheduler answered at 'tcp://127.0.0.1:9' within 1s"):
        with cluster_client("tcp://127.0.0.1:9", timeout="1s"):
            pass


def test_a_missing_scheduler_file_is_refused_at_once(tmp_path):
    """distributed waits for a scheduler file to appear with no time limit; dynid refuses a missing one."""
    from dynid._cluster import cluster_client

    missing = tmp_path / "scheduler.json"
    with pytest.raises(UsageError, match=r"the scheduler file '.*scheduler.json' does not exist"):
        with cluster_client(str(missing), timeout="1s"):
            pass


def test_a_refused_recording_is_reported_and_the_fleet_goes_on(fleet, tmp_path):
    recordings = find_recordings(fleet["pattern"])[:2]
    bad = tmp_path / "robot_09"
    bad.mkdir()
    (bad / "0.csv").write_text("t,q_1\n0,0\n")
    rec = find_recordings(str(bad / "0.csv"))[0]
    result = identify_fleet("ur5", [*recordings, replace(rec, order=0)], serial=True, drift=False, **OPTIONS)
    assert [bool(r["error"]) for r in result.rows] == [False, False, True]
    assert "q_" in result.rows[2]["error"] or "column" in result.rows[2]["error"]
    assert result.drift is None and result.column("fc1")[2] != result.column("fc1")[2]  # NaN: no parameters


def test_the_diagnosis_needs_held_out_data(fleet):
    recordings = find_recordings(fleet["pattern"])[:1]
    with pytest.raises(UsageError, match=r"the diagnosis needs held-out data"):
        identify_fleet("ur5", recordings, serial=True, diagnose=True, holdout=0.0, **OPTIONS)


def test_ros2_bags_go_through_the_same_reader_and_give_the_csv_rows(fleet, tmp_path):
    """A robot's recordings as rosbag2 folders named by their date: found, read and identified as the CSVs."""
    rosbag2 = pytest.importorskip("rosbags.rosbag2", reason="ROS 2 recordings are read with rosbags")
    from rosbags.typesys import Stores, get_typestore

    import dynid
    from dynid.data.files import load_dataset

    store = get_typestore(Stores.LATEST)
    types, kind = store.types, "sensor_msgs/msg/JointState"
    names = list(dynid.load_robot("ur5").joint_names)
    csv_rows = [r for r in fleet["serial"].rows if r["robot"] == "robot_00"]
    for row in csv_rows:
        ds = load_dataset(row["path"], 6)
        folder = tmp_path / "bags" / "robot_00" / row["time"]
        folder.parent.mkdir(parents=True, exist_ok=True)
        with rosbag2.Writer(folder, version=9, storage_plugin=rosbag2.StoragePlugin.MCAP) as writer:
            conn = writer.add_connection("/joint_states", kind, typestore=store)
            for k in range(ds.m):
                ns = 1_700_000_000 * 10**9 + round(float(ds.t[k]) * 1e9)
                msg = types[kind](
                    header=types["std_msgs/msg/Header"](
                        stamp=types["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9), frame_id=""
                    ),
                    name=names, position=ds.q[k], velocity=np.zeros(0), effort=ds.tau[k],
                )
                writer.write(conn, ns, store.serialize_cdr(msg, kind))
    bags = identify_fleet("ur5", str(tmp_path / "bags" / "**" / "*"), serial=True, drift=False, **OPTIONS)
    assert [(r["robot"], r["time"], r["error"]) for r in bags.rows] == [
        ("robot_00", r["time"], "") for r in csv_rows
    ]
    for bag_row, csv_row in zip(bags.rows, csv_rows, strict=True):
        for p in fleet["serial"].parameters:
            np.testing.assert_allclose(bag_row[p["name"]], csv_row[p["name"]], rtol=1e-6, atol=1e-9)


@pytest.mark.slow  # about 21 s of CPU time (four 14 s simulations and four diagnoses)
def test_the_diagnosis_names_an_effect_in_the_verdict_column(tmp_path, capsys):
    """``dynid fleet --diagnose``: two robots, two recordings each; the second robot's last one lags on joint 2.

    The recordings are the smallest that still give the diagnosis its noise floor: 14 s at 200 Hz of a
    0.5 Hz periodic excitation, the last 40 % (2.8 periods) held out, so the floor is the spread across
    periods (two whole periods are needed; a floor from the spectrum would need 2,048 held-out samples).
    The delay (4 control steps, 17 ms at this size) is the diagnosis tests' clearly detectable one.
    """
    from dynid.data.files import save_dataset
    from dynid.sim.cases import case_excitation
    from dynid.sim.simulator import simulate
    from dynid.symbolic.robot import load_robot

    ur5 = load_robot("ur5")
    trajectory = case_excitation(ur5, 14, base_freq=0.5)
    for robot, date, effects, seed in (
        ("robot_00", "2026-01-15", None, 1), ("robot_00", "2026-02-15", None, 2),
        ("robot_01", "2026-01-15", None, 3), ("robot_01", "2026-02-15", "delay@2:4", 4),
    ):
        run = simulate(ur5, trajectory, duration=14.0, rate=200.0, friction="linear", effects=effects, seed=seed,
                       truth_seed=7)
        (tmp_path / robot).mkdir(exist_ok=True)
        save_dataset(run.to_dataset(), tmp_path / robot / f"{date}.csv")
    out = tmp_path / "out"
    code = main(["fleet", "--robot", "ur5", "--data", str(tmp_path / "**" / "*.csv"), "--serial", "--diagnose",
                 "--holdout", "0.4", "--method", "ols", "--friction", "linear", "--gmm", "off", "--out", str(out)])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    with open(out / "fleet.csv", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    assert [(r["robot"], r["time"], r["error"], r["verdict"]) for r in rows] == [
        ("robot_00", "2026-01-15", "", "none"), ("robot_00", "2026-02-15", "", "none"),
        ("robot_01", "2026-01-15", "", "none"), ("robot_01", "2026-02-15", "", "delay"),
    ]
