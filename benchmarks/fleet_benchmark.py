"""A simulated fleet of UR5s identified on a Dask LocalCluster: drift found, false flags, speed-up (prints figures).

The fleet (:mod:`dynid.fleet.simulated`): ``--robots`` UR5s (default 40), each with its standard
parameters perturbed by 5 % (physically consistent) and its friction (the paper's nonlinear model)
scaled per joint within +-10 %: manufacturing tolerance.  Each robot has ``--recordings`` recordings
(default 6) of ``--duration`` s (default 30) at 200 Hz, one a month, all of the same random feasible
Fourier excitation (3 harmonics at 0.1 Hz), each with its own sensor noise.  Four robots change
partway: every friction coefficient of one joint +50 % (wear) on three of them, a 1 kg tool on the last
link on the fourth.

Every recording is identified as ``dynid fleet`` does (:func:`dynid.fleet.identify_fleet`: IRLS, the
last 20 % held out), here with linear friction in layer 1 and no mixture correction (``--friction``,
``--gmm``): the drift tests read the layer-1 parameters and their covariance, and the default mixture
costs about 10 s a recording.  The drift tests (:mod:`dynid.fleet.drift`) then name the flagged robots.

Printed: the flagged robots with their parameters and recording of change against the truth; false
flags among the unchanged robots; wall and CPU time of the identification on a LocalCluster of
``--workers`` single-thread workers (default 2) against the same function run serially in this process
(``dynid fleet --serial``), ``--repeat`` times each in alternating order, with the load average before
each run (the machine may be shared: CPU time per recording is the figure its load does not change);
both are warm (the cluster's start, printed, and one identification per process are outside the timed
runs); both tables compared; peak memory (``ru_maxrss``) of each worker and of this process.
``--dask-trim`` gives the workers Dask's default ``MALLOC_TRIM_THRESHOLD_=65536``, which
:mod:`dynid._cluster` leaves out (it cost the workers about 45 % more CPU time per recording).

Measured (2026-11-24, 2 vCPUs shared with other work at a load average of 8-19; ``--robots 16``: 96
recordings; each row one invocation, its runs in order)::

                                                 workers' CPU / serial CPU   wall speed-up
    Dask's MALLOC_TRIM_THRESHOLD_ (--dask-trim)  1.46, 1.40                 1.75x, 1.64x
    no trim threshold                            1.24, 1.28, 1.33           1.60x, 0.90x, 0.67x
    no trim threshold, quiet workers (default)   1.09, 1.05                 0.86x, 0.71x

The CPU time per recording in this process was 0.52-0.60 s throughout.  The wall speed-ups follow the
machine's load, not the code: the share of the 2 cores a run got (0.18-0.67 cores) varied more than
the runs differ, and Linux schedules a session's processes as one group (autogroup, on here), so two
workers need not get more of a busy machine than one serial process.  The last row's CPU times allow
1.8-1.9x on two otherwise idle cores, before what the cores share (cache, memory).

Then measured on the same machine with nothing else running (load 1.1-1.6, ``--robots 16 --repeat 2``,
default settings): wall 26.8 and 27.7 s on the cluster against 52.5 and 51.2 s serial, a speed-up of
1.96x and 1.85x (median 1.90x), the workers' CPU over the serial run's 0.93 and 1.02; the tables were
identical, 4 of 4 changed robots found with the right parameter and recording, no false flag among the
12 others; 247 MiB peak per worker.

Later, other processes paused, ``--robots 16 --reuse --repeat 1``: 20.9 s on the cluster against 37.6 s
serial (1.80x; the same run before local workers got ``DYNID_NUM_THREADS=1``: 21.3 against 38.1 s,
1.79x).  Each identification took 0.40 s of CPU, against 0.55 s in the runs above; these settings fit
no mixture, and what made them cheaper was not measured here.

Run:  OMP_NUM_THREADS=1 python benchmarks/fleet_benchmark.py                       # the full fleet
      OMP_NUM_THREADS=1 python benchmarks/fleet_benchmark.py --robots 16 --out /tmp/fleet16 --repeat 3
      OMP_NUM_THREADS=1 python benchmarks/fleet_benchmark.py --robots 16 --out /tmp/fleet16 --reuse --dask-trim
      OMP_NUM_THREADS=1 python benchmarks/fleet_benchmark.py --robots 8 --recordings 4 --duration 12
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import resource  # noqa: E402
import statistics  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402


def changed_robots(robots: int, recordings: int):
    """Robot index -> Change: three friction wears and one tool, spread over the fleet and its recordings."""
    from dynid.fleet.simulated import Change

    if robots < 4 or recordings < 3:
        raise SystemExit("the benchmark needs at least 4 robots and 3 recordings")
    picks = sorted({round(robots * f) for f in (0.12, 0.37, 0.62, 0.87)})
    ats = [max(1, min(recordings - 1, round(recordings * f))) for f in (0.5, 0.34, 0.67, 0.5)]
    kinds = [
        Change("friction", at=ats[0], joint=2),
        Change("friction", at=ats[1], joint=3),
        Change("friction", at=ats[2], joint=5),
        Change("tool", at=ats[3], mass=1.0),
    ]
    return dict(zip(picks, kinds, strict=True))


def _warm(recording, options) -> bool:
    """One identification, so that the process has loaded the robot's functions and their caches (2-3 s once)."""
    from dynid.fleet.core import FleetSettings, identify_recording

    identify_recording("ur5", recording, FleetSettings(**options))
    return True


def _cpu_seconds() -> float:
    """CPU time (s) of the process that runs it: here and, by ``client.run``, on each worker (a function of
    this script travels to the workers by value; one of ``benchmarks/_timing.py`` would need that module
    importable there)."""
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def _run(rep, kind, wall, cpu, result, load, **extra) -> dict:
    """One timed run's figures: wall and CPU time (s), mean CPU time per recording, load average before it."""
    per = result.column("cpu_s")
    return {"rep": rep, "kind": kind, "wall": wall, "cpu": cpu, "cpu_per_rec": float(per.mean()), "load": load, **extra}


def _right(test, change) -> bool:
    """Whether a flagged test names the change: the changed joint's friction, or a link parameter for a tool."""
    if change["kind"] == "friction":
        return test.kind in ("coulomb", "viscous") and test.parameter.endswith(str(change["joint"]))
    return test.kind == "link"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--robots", type=int, default=40)
    parser.add_argument("--recordings", type=int, default=6)
    parser.add_argument("--duration", type=float, default=30.0, help="seconds per recording")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--friction", default="linear")
    parser.add_argument("--gmm", default="off")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--repeat", type=int, default=2, help="timed runs of each (default 2), alternating order")
    parser.add_argument(
        "--dask-trim", action="store_true",
        help="give the workers Dask's default MALLOC_TRIM_THRESHOLD_=65536 (what made them slower; for comparison)",
    )
    parser.add_argument("--reuse", action="store_true", help="reuse the recordings of an earlier run in --out")
    parser.add_argument("--out", help="folder for the recordings and the fleet's output (default: a temporary one)")
    args = parser.parse_args()

    from dynid._cluster import cluster_client, worker_peak_memory
    from dynid.fleet import identify_fleet
    from dynid.fleet.recordings import find_recordings
    from dynid.fleet.simulated import simulate_fleet

    tmp = None if args.out else tempfile.TemporaryDirectory(prefix="dynid-fleet-")
    root = Path(args.out or tmp.name)
    data = root / "recordings"
    changes = changed_robots(args.robots, args.recordings)
    gmm = args.gmm if args.gmm in ("off", "auto") else int(args.gmm)
    options = {"friction": args.friction, "gmm": gmm}
    print(
        f"fleet: {args.robots} UR5s x {args.recordings} recordings of {args.duration:g} s at 200 Hz; "
        f"identification: irls, friction {args.friction}, gmm {args.gmm}, last 20 % held out",
        flush=True,
    )
    truth_file = data / "truth.json"
    if args.reuse and truth_file.is_file():
        truth = json.loads(truth_file.read_text(encoding="utf-8"))
        print(f"recordings of an earlier run reused: {data}", flush=True)
    else:
        with cluster_client(None, workers=args.workers) as client:
            start = time.perf_counter()
            truth = simulate_fleet(
                "ur5", data, robots=args.robots, recordings=args.recordings, changes=changes,
                duration=args.duration, seed=args.seed, client=client,
            )
        print(f"simulated on the cluster in {time.perf_counter() - start:.1f} s", flush=True)
    recordings = find_recordings(str(data / "**" / "*.csv"))
    if args.dask_trim:  # a trim threshold in the caller's environment reaches the workers (Dask's default)
        os.environ["MALLOC_TRIM_THRESHOLD_"] = "65536"
    runs = []
    serial_warm = False
    for rep in range(args.repeat):
        # alternate which comes first, so that neither always runs after the other's load
        for kind in ("cluster", "serial") if rep % 2 == 0 else ("serial", "cluster"):
            if kind == "serial":
                if not serial_warm:
                    _warm(recordings[0], options)
                    serial_warm = True
                load0, cpu0 = os.getloadavg()[0], _cpu_seconds()
                start = time.perf_counter()
                serial = identify_fleet("ur5", recordings, serial=True, **options)
                wall = time.perf_counter() - start
                runs.append(_run(rep, kind, wall, _cpu_seconds() - cpu0, serial, load0))
                continue
            start = time.perf_counter()
            with cluster_client(None, workers=args.workers) as client:
                client.run(_warm, recordings[0], options)
                startup = time.perf_counter() - start
                cpu0 = client.run(_cpu_seconds)
                load0 = os.getloadavg()[0]
                start = time.perf_counter()
                parallel = identify_fleet("ur5", recordings, client=client, **options)
                wall = time.perf_counter() - start
                cpu = sum(client.run(_cpu_seconds).values()) - sum(cpu0.values())
                memory = worker_peak_memory(client)
            runs.append(_run(rep, kind, wall, cpu, parallel, load0, startup=startup))
    parallel.write(root / "fleet")

    def strip(rows):
        return [{k: v for k, v in r.items() if k not in ("elapsed_s", "cpu_s")} for r in rows]

    same = strip(parallel.rows) == strip(serial.rows)
    drift = parallel.drift
    flagged = drift.flagged_robots
    print()
    print(drift.summary())
    print()
    print(f"{'robot':<10} {'truth':<34} {'flagged (top 3)':<44} {'change found':<14} result")
    hits = 0
    for name, entry in truth["robots"].items():
        change = entry["change"]
        tests = flagged.get(name, [])
        if change is None and not tests:
            continue
        want = (
            "-" if change is None else
            f"friction j{change['joint']} x{change['factor']:g} at rec {change['at']}" if change["kind"] == "friction"
            else f"{change['mass']:g} kg tool at rec {change['at']}"
        )
        got = ", ".join(f"{t.parameter}({t.shift_sigma:+.0f}sd)" for t in tests[:3]) or "not flagged"
        at = "-" if not tests else str(tests[0].change_order)
        ok = change is not None and bool(tests) and _right(tests[0], change) and tests[0].change_order == change["at"]
        hits += ok
        print(f"{name:<10} {want:<34} {got:<44} {at:<14} {'right' if ok else 'WRONG'}")
    unchanged = [n for n, e in truth["robots"].items() if e["change"] is None]
    false = [n for n in unchanged if n in flagged]
    print()
    print(f"changed robots found with the right parameter and recording: {hits} of {len(changes)}")
    print(f"false flags among the {len(unchanged)} unchanged robots: {len(false)}{' (' + ', '.join(false) + ')' if false else ''}")
    outliers = drift.fleet_outliers
    print(f"robots that differ from the fleet: {', '.join(outliers) or 'none'}")
    print()
    print(
        f"identification of {len(recordings)} recordings (warm: the cluster's start and one identification "
        f"per process are outside the timed runs); tables identical: {same}"
    )
    print(
        f"{'run':<4} {'where':<8} {'wall s':>7} {'CPU s':>7} {'CPU/rec s':>10} {'cores':>6} {'load':>5} "
        f"{'start s':>8}  (CPU: the process(es) over the run; CPU/rec: mean cpu_s column)"
    )
    for r in runs:
        print(
            f"{r['rep']:<4} {r['kind']:<8} {r['wall']:>7.1f} {r['cpu']:>7.1f} {r['cpu_per_rec']:>10.3f} "
            f"{r['cpu'] / r['wall']:>6.2f} {r['load']:>5.1f} {r.get('startup', float('nan')):>8.1f}"
        )
    pairs = [
        (next(r for r in runs if r["rep"] == k and r["kind"] == "serial"),
         next(r for r in runs if r["rep"] == k and r["kind"] == "cluster"))
        for k in range(args.repeat)
    ]
    speedups = [s["wall"] / c["wall"] for s, c in pairs]
    cpu_ratio = [c["cpu"] / s["cpu"] for s, c in pairs]
    print(
        f"speed-up on {args.workers} workers over serial (wall): "
        + ", ".join(f"{x:.2f}x" for x in speedups)
        + f"; median {statistics.median(speedups):.2f}x (target 1.7x); the workers' CPU time over the serial "
        f"run's: {', '.join(f'{x:.2f}' for x in cpu_ratio)}; {os.cpu_count()} cores, load average over 1 min "
        "given per run (other work on the machine lowers both runs' share of it)"
    )
    # Linux schedules a session's processes as one group (autogroup): on a busy machine the workers
    # together get about the share one serial process gets, so the wall times measure the load.
    print(
        f"speed-up the CPU times allow on {args.workers} otherwise idle cores ({args.workers} x serial CPU / "
        "workers' CPU, an estimate, not a measurement): "
        + ", ".join(f"{args.workers / x:.2f}x" for x in cpu_ratio)
    )
    print(
        "peak memory per worker (MiB): " + ", ".join(f"{v:.0f}" for v in memory.values())
        + f"; this process {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MiB"
    )
    print(f"fleet table and report: {root / 'fleet'}" + (" (temporary, removed)" if tmp else ""))
    if tmp is not None:
        tmp.cleanup()


if __name__ == "__main__":
    main()
