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
flags among the unchanged robots; wall time of the identification on a LocalCluster of ``--workers``
single-thread workers (default 2; warm: each worker and this process have identified one recording first) against the same
function run serially in this process; both tables compared; peak memory (``ru_maxrss``) of each
worker and of this process.

Run:  OMP_NUM_THREADS=1 python benchmarks/fleet_benchmark.py                       # the full fleet
      OMP_NUM_THREADS=1 python benchmarks/fleet_benchmark.py --robots 8 --recordings 4 --duration 12
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import resource  # noqa: E402
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
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


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
    with cluster_client(None, workers=args.workers) as client:
        start = time.perf_counter()
        truth = simulate_fleet(
            "ur5", data, robots=args.robots, recordings=args.recordings, changes=changes,
            duration=args.duration, seed=args.seed, client=client,
        )
        print(f"simulated on the cluster in {time.perf_counter() - start:.1f} s", flush=True)
        recordings = find_recordings(str(data / "**" / "*.csv"))
        client.run(_warm, recordings[0], options)
        cpu0 = client.run(_cpu_seconds)
        load0 = os.getloadavg()[0]
        start = time.perf_counter()
        parallel = identify_fleet("ur5", recordings, client=client, **options)
        t_parallel = time.perf_counter() - start
        cpu_parallel = sum(client.run(_cpu_seconds).values()) - sum(cpu0.values())
        load1 = os.getloadavg()[0]
        memory = worker_peak_memory(client)
    _warm(recordings[0], options)
    cpu0_serial = _cpu_seconds()
    start = time.perf_counter()
    serial = identify_fleet("ur5", recordings, serial=True, **options)
    t_serial = time.perf_counter() - start
    cpu_serial = _cpu_seconds() - cpu0_serial
    load2 = os.getloadavg()[0]
    parallel.write(root / "fleet")

    def strip(rows):
        return [{k: v for k, v in r.items() if k != "elapsed_s"} for r in rows]

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
        f"identification of {len(recordings)} recordings: serial {t_serial:.1f} s, LocalCluster of "
        f"{args.workers} workers {t_parallel:.1f} s: speed-up {t_serial / t_parallel:.2f}x; tables identical: {same}"
    )
    print(
        f"CPU time: serial {cpu_serial:.1f} s in {t_serial:.1f} s wall ({cpu_serial / t_serial:.0%} of a core); "
        f"workers {cpu_parallel:.1f} s in {t_parallel:.1f} s wall ({cpu_parallel / t_parallel / args.workers:.0%} of "
        f"{args.workers} cores); load average {load0:.1f} / {load1:.1f} / {load2:.1f} (before / after the cluster "
        f"run / after the serial run) on {os.cpu_count()} cores"
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
