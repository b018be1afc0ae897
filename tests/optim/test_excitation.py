"""Excitation design (dynid.optim.excitation), the ruckig approach (dynid.optim.approach), ``dynid excite``.

Small problems (UR5, 3 harmonics, 30 grid points, few tries) keep the file well under a minute on 2 cores.
"""

from __future__ import annotations

import json
import os

os.environ.setdefault("OMP_NUM_THREADS", "1")  # loky workers inherit these
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np
import pytest

from dynid.cli import main
from dynid.exceptions import RobotModelError, UsageError
from dynid.optim.approach import default_home, executable_trajectory, point_to_point
from dynid.optim.criteria import SmoothCriterion, soft_log_cond2
from dynid.optim.excitation import CartesianLimits, ExcitationError, ExcitationProblem, design_excitation
from dynid.optim.problem import excitation_functions
from dynid.optim.trajectory import load_trajectory
from dynid.symbolic import load_robot

SMALL = {"harmonics": 3, "grid": 30}
SEARCH = {"patience": 2, "max_tries": 3, "baseline": 20}


@pytest.fixture(scope="module")
def ur5():
    return load_robot("ur5")


@pytest.fixture(scope="module")
def problem(ur5):
    return ExcitationProblem(robot=ur5, criterion="seed", **SMALL)


@pytest.fixture(scope="module")
def stacked(problem):
    """Two trajectories, the second designed over the first's rows; tries in two processes."""
    return design_excitation(problem, trajectories=2, seed=3, n_jobs=2, **SEARCH)


# ---------------------------------------------------------------------------- the design
def test_every_limit_holds_on_the_fine_grid(problem, stacked):
    robot = problem.robot
    t = problem.times(fine=True)
    assert t.size == 10 * problem.grid + 1
    for traj in stacked.trajectories:
        q, dq, ddq = traj.evaluate(t)
        assert np.all(q >= robot.q_min) and np.all(q <= robot.q_max)
        assert np.all(np.abs(dq) <= robot.dq_max)
        assert np.all(np.abs(ddq) <= robot.ddq_max)
        assert problem.is_feasible(traj)
    assert stacked.feasible


def test_boundary_conditions_hold(stacked):
    for traj in stacked.trajectories:
        q, dq, ddq = traj.evaluate([0.0, traj.period])
        np.testing.assert_allclose(dq, 0.0, atol=1e-9)
        np.testing.assert_allclose(ddq, 0.0, atol=1e-9)
        np.testing.assert_allclose(q[0], q[1], atol=1e-9)


def test_optimised_beats_its_start_and_the_baseline_with_full_rank(problem, stacked):
    first = stacked.stages[0]
    assert first.cond < 0.7 * first.start_cond
    assert first.objective < first.start_objective
    H = problem.regressor(stacked.trajectories[0])
    assert np.linalg.matrix_rank(H) == excitation_functions(problem).n_base
    np.testing.assert_allclose(np.linalg.cond(H), first.cond, rtol=1e-10)
    assert stacked.cond < stacked.baseline_cond


def test_stacked_design_beats_the_first_trajectory_alone(problem, stacked):
    alone = np.linalg.cond(problem.regressor(stacked.trajectories[0]))
    both = np.linalg.cond(np.vstack([problem.regressor(t) for t in stacked.trajectories]))
    np.testing.assert_allclose(both, stacked.cond, rtol=1e-10)
    assert both < alone


def test_same_seed_same_result_whatever_n_jobs(problem, stacked):
    again = design_excitation(problem, trajectories=1, seed=3, n_jobs=1, **SEARCH)
    first = stacked.trajectories[0]
    for name in ("a", "b", "c"):
        np.testing.assert_array_equal(getattr(again.trajectories[0], name), getattr(first, name))
    assert again.stages[0].cond == stacked.stages[0].cond


def test_every_try_solved_to_the_end_without_screening(problem, stacked):
    """screen_iter=None: the search ranks finished tries (the previous method); the design holds the same checks."""
    full = design_excitation(problem, seed=3, n_jobs=1, screen_iter=None, **SEARCH)
    first = full.stages[0]
    assert full.feasible and problem.is_feasible(full.trajectories[0])
    assert first.cond < 0.7 * first.start_cond
    assert full.cond < full.baseline_cond
    # screening finishes only the best screened tries: here the same try, to the same criterion within 2 %
    assert first.kept == stacked.stages[0].kept
    np.testing.assert_allclose(first.objective, stacked.stages[0].objective, rtol=0.02)
    # what each record counts: screened tries that met the limits, and those finished after screening
    assert first.polished == 0
    screened = stacked.stages[0]
    assert 1 <= screened.polished <= screened.feasible_tries <= screened.tries


def test_cli_negative_screen_iter_is_refused(tmp_path, capsys):
    code = main(["excite", "--robot", "ur5", "--screen-iter", "-1", "--out", str(tmp_path / "T.json")])
    assert code == 2
    assert "--screen-iter is -1; give 1 or more iterations, or 0" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_cartesian_floor_holds(ur5):
    problem = ExcitationProblem(robot=ur5, criterion="cond", cartesian=CartesianLimits(z_min=-0.3), **SMALL)
    result = design_excitation(problem, seed=0, n_jobs=2, patience=1, max_tries=2, baseline=5)
    q = result.trajectories[0].evaluate(problem.times(fine=True))[0]
    z = excitation_functions(problem).tool_positions(q)[:, 2]
    assert z.min() >= -0.3
    assert result.stages[0].cond < result.stages[0].start_cond


# ---------------------------------------------------------------------------- the smooth criterion
@pytest.mark.parametrize("criterion", ["seed", "cond", "logdet"])
def test_smooth_criterion_gradient_matches_finite_differences(criterion):
    rng = np.random.default_rng(1)
    H = rng.standard_normal((40, 6)) * np.array([1.0, 3.0, 0.2, 1.0, 5.0, 0.5])
    A = H.T @ H
    gravity = np.array([True, True, False, False, False, False])
    fn = SmoothCriterion(criterion, gravity, 16.0)
    w, s = np.array([1.0, 0.3, 0.7]), np.full(6, 0.5)
    _, dA, _, _ = fn(A, w, s)
    E = rng.standard_normal((6, 6))
    E = E + E.T
    h = 1e-6
    numeric = (fn(A + h * E, w, s)[0] - fn(A - h * E, w, s)[0]) / (2 * h)
    np.testing.assert_allclose(np.sum(dA * E), numeric, rtol=1e-5)


def test_smooth_log_cond_bounds_the_exact_one():
    rng = np.random.default_rng(2)
    H = rng.standard_normal((50, 8)) @ np.diag(np.logspace(0, 2, 8))
    exact = 2 * np.log(np.linalg.cond(H))
    for p in (4.0, 16.0, 64.0):
        value, _ = soft_log_cond2(H.T @ H, p)
        assert exact <= value + 1e-12 <= exact + 2 * np.log(8) / p + 1e-12
    value, _ = soft_log_cond2(H.T @ H, np.inf)
    np.testing.assert_allclose(value, exact, rtol=1e-10)


# ---------------------------------------------------------------------------- approach and retreat
def test_approach_starts_at_home_ends_at_rest_within_limits(problem, stacked):
    robot = problem.robot
    home = default_home(robot) + 0.3
    rate = 100.0
    run = executable_trajectory(robot, stacked.trajectories, rate=rate, home=home)
    segments = run.meta["segments"]
    assert [s["kind"] for s in segments] == ["approach", "excitation", "transfer", "excitation", "retreat"]
    np.testing.assert_allclose(run.q[0], home, atol=1e-12)
    np.testing.assert_allclose(run.dq[0], 0.0, atol=1e-12)
    np.testing.assert_allclose(run.q[-1], home, atol=1e-9)
    np.testing.assert_allclose(run.dq[-1], 0.0, atol=1e-9)
    # The approach ends on a sample, at rest, where the first excitation starts.
    end = segments[1]["start"]
    k = round(end * rate)
    np.testing.assert_allclose(run.t[k], end, atol=1e-12)
    q0 = stacked.trajectories[0].evaluate([0.0])[0][0]
    np.testing.assert_allclose(run.q[k], q0, atol=1e-9)
    np.testing.assert_allclose(run.dq[k], 0.0, atol=1e-9)
    np.testing.assert_allclose(np.diff(run.t), 1 / rate, atol=1e-9)
    assert np.all(run.q >= robot.q_min - 1e-12) and np.all(run.q <= robot.q_max + 1e-12)
    assert np.all(np.abs(run.dq) <= robot.dq_max + 1e-9)
    assert np.all(np.abs(run.ddq) <= robot.ddq_max + 1e-9)


def test_rests_hold_home_and_excitation_repeats(problem, stacked):
    robot = problem.robot
    home = default_home(robot)
    rate, rest, periods = 100.0, 1.5, 3
    run = executable_trajectory(robot, stacked.trajectories[:1], rate=rate, home=home, periods=periods, rest=rest)
    segments = run.meta["segments"]
    assert [s["kind"] for s in segments] == ["rest", "approach", "excitation", "retreat", "rest"]
    assert segments[0]["duration"] == rest and segments[-1]["duration"] == rest
    exc = stacked.trajectories[0]
    assert segments[2]["duration"] == pytest.approx(periods / exc.base_freq, rel=1e-12)
    still = (run.t <= rest + 1e-9) | (run.t >= segments[-1]["start"] - 1e-9)
    assert still.sum() >= 2 * rest * rate
    np.testing.assert_allclose(run.q[still], np.broadcast_to(home, run.q[still].shape), atol=1e-9)
    np.testing.assert_allclose(run.dq[still], 0.0, atol=1e-9)
    # The excitation is periodic in the CSV: one period apart, the samples agree.
    start = round(segments[2]["start"] * rate)
    lag = round(rate / exc.base_freq)
    np.testing.assert_allclose(run.q[start : start + lag], run.q[start + lag : start + 2 * lag], atol=1e-9)
    with pytest.raises(UsageError, match=r"the rest is -1.0 s; give a duration of at least 0 s"):
        executable_trajectory(robot, stacked.trajectories[:1], rate=rate, home=home, rest=-1.0)


def test_point_to_point_respects_its_limits(ur5):
    seg = point_to_point(ur5, default_home(ur5), default_home(ur5) + 1.0, rate=200.0, speed_fraction=0.5)
    t = np.linspace(0, seg.duration, 400)
    q, dq, ddq = seg.evaluate(t)
    assert np.all(np.abs(dq) <= 0.5 * ur5.dq_max + 1e-9)
    assert np.all(np.abs(ddq) <= 0.5 * ur5.ddq_max + 1e-9)
    np.testing.assert_allclose(q[-1], default_home(ur5) + 1.0, atol=1e-9)
    np.testing.assert_allclose(seg.duration * 200.0, round(seg.duration * 200.0), atol=1e-9)


# ---------------------------------------------------------------------------- command line
def test_cli_writes_trajectory_csv_and_figures(tmp_path, capsys):
    out, csv, figs = tmp_path / "T.json", tmp_path / "T.csv", tmp_path / "F.json"
    code = main(
        ["excite", "--robot", "ur5", "--harmonics", "3", "--grid", "30", "--criterion", "cond", "--patience", "1",
         "--max-tries", "2", "--baseline", "10", "--n-jobs", "1", "--out", str(out), "--csv", str(csv),
         "--rate", "50", "--json", str(figs)]
    )  # fmt: skip
    assert code == 0
    figures = json.loads(figs.read_text())
    for key in ("cond", "objective", "criterion", "baseline_cond", "feasible"):
        assert key in figures
    assert figures["criterion"] == "cond" and figures["feasible"] is True
    traj = load_trajectory(out)
    assert traj.harmonics == 3 and traj.meta["criterion"] == "cond"
    sampled = load_trajectory(csv)
    assert sampled.n == 6 and sampled.t[1] == pytest.approx(1 / 50)
    # By default the CSV repeats the excitation three times between rests of 2 s at home.
    kinds = [s["kind"] for s in figures["csv"]["segments"]]
    assert kinds == ["rest", "approach", "excitation", "retreat", "rest"]
    assert figures["csv"]["segments"][2]["duration"] == pytest.approx(3 / traj.base_freq)
    assert figures["csv"]["segments"][0]["duration"] == 2.0
    assert "cond" in capsys.readouterr().out


# ---------------------------------------------------------------------------- bad input
def test_zero_velocity_limit_is_refused(ur5):
    with pytest.raises(RobotModelError, match=r"dq_max of joint 1 .* is 0; limits must be positive"):
        ur5.with_limits(dq_max=0.0)


def test_cli_zero_velocity_limit_writes_nothing(tmp_path, capsys):
    out = tmp_path / "T.json"
    code = main(["excite", "--robot", "ur5", "--dq-max", "0", "--out", str(out), "--csv", str(tmp_path / "T.csv")])
    assert code == 2
    assert "dq_max of joint 1" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_home_outside_limits_is_refused(ur5, problem, stacked):
    home = default_home(ur5)
    home[2] = 4.0  # joint 3 of the UR5 stops at pi
    with pytest.raises(UsageError, match="home pose puts joint 3 at 4, outside its limits"):
        executable_trajectory(ur5, stacked.trajectories, rate=100.0, home=home)


def test_cli_home_outside_limits_writes_nothing(tmp_path, capsys):
    code = main(
        ["excite", "--robot", "ur5", "--harmonics", "3", "--out", str(tmp_path / "T.json"), "--csv",
         str(tmp_path / "T.csv"), "--home", "0,0,4,0,0,0"]
    )  # fmt: skip
    assert code == 2
    assert "outside its limits" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_zero_harmonics_is_refused(ur5):
    with pytest.raises(UsageError, match="harmonics is 0; give a whole number of at least 2"):
        ExcitationProblem(robot=ur5, harmonics=0)


def test_one_harmonic_cannot_excite(ur5):
    problem = ExcitationProblem(robot=ur5, harmonics=1, grid=30)
    with pytest.raises(ExcitationError, match=r"reaches rank 5 of 36: .*at least 2 harmonics"):
        design_excitation(problem, n_jobs=1, **SEARCH)


def test_too_few_grid_points_cannot_excite(ur5):
    problem = ExcitationProblem(robot=ur5, harmonics=3, grid=5)
    with pytest.raises(ExcitationError, match=r"30 rows for 36 base parameters.*at least 6 grid points"):
        design_excitation(problem, n_jobs=1, **SEARCH)


def test_unreachable_floor_is_infeasible(ur5, tmp_path, capsys):
    problem = ExcitationProblem(robot=ur5, cartesian=CartesianLimits(z_min=2.0), **SMALL)
    with pytest.raises(ExcitationError, match="keeps the tool inside the Cartesian limits"):
        design_excitation(problem, n_jobs=1, patience=1, max_tries=1, baseline=2)
    code = main(
        ["excite", "--robot", "ur5", "--harmonics", "3", "--grid", "30", "--z-min", "2", "--baseline", "2",
         "--out", str(tmp_path / "T.json"), "--json", str(tmp_path / "F.json")]
    )  # fmt: skip
    assert code == 2
    assert "Cartesian limits" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_unknown_criterion_is_refused(ur5):
    with pytest.raises(UsageError, match="criterion is 'aopt'; choose one of seed, cond, logdet"):
        ExcitationProblem(robot=ur5, criterion="aopt")


# ---------------------------------------------------------------------------- interrupts
def _children(pid: int) -> list[int]:
    """Process ids whose parent is ``pid`` (Linux /proc; empty elsewhere)."""
    from pathlib import Path

    out = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            out.append(int(stat.parent.name))
    return out


def _cmdline(pid: int) -> bytes:
    from pathlib import Path

    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ")
    except OSError:
        return b""


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    from pathlib import Path

    try:  # a zombie has ended
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


@pytest.mark.parametrize(
    ("n_jobs", "signame"),
    [("1", "SIGTERM"), ("2", "SIGTERM"), ("2", "SIGINT")],
    ids=["in-process-sigterm", "workers-sigterm", "workers-ctrl-c"],
)
def test_a_signal_during_the_design_ends_it_at_once_with_one_line(tmp_path, n_jobs, signame):
    """IPOPT runs the tries: the signal stops it within seconds, exit 130, one line, no file, no worker left.

    CasADi swallows a KeyboardInterrupt raised while IPOPT runs; before the fix the design went on to the
    end and wrote its files (exit 0).  Ctrl-C reaches the whole process group (the workers too).
    """
    import signal
    import subprocess
    import sys
    import time

    out = tmp_path / "T.json"
    argv = [
        sys.executable, "-m", "dynid.cli", "excite", "--robot", "ur5", "--criterion", "seed", "--n-jobs", n_jobs,
        "--baseline", "5", "--patience", "60", "--out", str(out), "--csv", str(tmp_path / "T.csv"), "--json",
        str(tmp_path / "F.json"),
    ]  # fmt: skip
    proc = subprocess.Popen(
        argv,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,  # a process group of its own: Ctrl-C reaches it and its workers only
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL) and None,  # a background shell ignores it
    )
    try:
        assert "seed criterion" in proc.stdout.readline()  # printed just before the design starts
        # The 5-trajectory baseline takes under a second; with up to 60 tries the search runs for minutes:
        # at 4 s IPOPT is at work (in this process with n_jobs 1, in the workers otherwise).
        time.sleep(4.0)
        workers = _children(proc.pid)
        assert proc.poll() is None, "the design ended before the signal"
        # joblib's resource tracker shares the command's stderr: it must not add its own lines to the one line
        if n_jobs != "1":
            trackers = [p for p in workers if b"resource_tracker" in _cmdline(p)]
            assert trackers, "no resource tracker among the workers"
            assert all(b"-Wignore::UserWarning:joblib.externals.loky" in _cmdline(p) for p in trackers)
        t0 = time.monotonic()
        if signame == "SIGINT":
            os.killpg(proc.pid, signal.SIGINT)
        else:
            proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=60)
        elapsed = time.monotonic() - t0
    finally:
        if proc.poll() is None:  # the whole group: workers holding the pipes would keep communicate() waiting
            os.killpg(proc.pid, signal.SIGKILL)
            proc.communicate()
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "KeyboardInterrupt" not in err, err
    lines = err.strip().splitlines()
    name = "" if signame == "SIGINT" else f" by {signame}"
    # the one line of the interrupt, after the progress lines of the design (nothing else)
    assert lines[-1] == f"dynid excite: interrupted{name}; no file was left half written", err
    assert all(ln.startswith("dynid excite: designing") for ln in lines[:-1]), err
    assert elapsed < 10.0
    assert list(tmp_path.iterdir()) == []
    deadline = time.monotonic() + 10.0
    while any(_alive(pid) for pid in workers) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not [pid for pid in workers if _alive(pid)], "a worker outlived the command"


# ---------------------------------------------------------------------------- on a Dask cluster
@pytest.mark.slow
def test_cli_scheduler_runs_the_tries_on_a_dask_cluster_with_the_serial_design(problem, tmp_path, capsys):
    """--scheduler: the tries go to a real LocalCluster (2 worker processes) through joblib's dask backend,
    and the design is the one of the serial search (the rest of a batch is discarded whatever its size)."""
    distributed = pytest.importorskip("distributed", reason="--scheduler needs dask.distributed")
    serial = design_excitation(problem, seed=5, n_jobs=1, **SEARCH)
    out = tmp_path / "T.json"
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0", silence_logs=40
    ) as cluster:
        code = main(
            ["excite", "--robot", "ur5", "--harmonics", "3", "--grid", "30", "--criterion", "seed", "--seed", "5",
             "--patience", "2", "--max-tries", "3", "--baseline", "20", "--scheduler", cluster.scheduler_address,
             "--out", str(out)]
        )  # fmt: skip
        assert cluster.scheduler.transition_counter > 0  # the scheduler ran the tries
    assert code == 0
    assert "tries on the Dask cluster" in capsys.readouterr().out
    again = load_trajectory(out)
    for name in ("a", "b", "c"):
        np.testing.assert_array_equal(getattr(again, name), getattr(serial.trajectories[0], name))
    assert again.meta["cond_stack"] == serial.stages[0].cond


def test_cli_scheduler_and_backend_are_refused_together(tmp_path, capsys):
    code = main(["excite", "--robot", "ur5", "--scheduler", "tcp://127.0.0.1:1", "--backend", "loky", "--out",
                 str(tmp_path / "T.json")])  # fmt: skip
    assert code == 2
    assert "--scheduler and --backend loky exclude each other" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []
