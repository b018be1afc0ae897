"""Gap diagnosis on withheld effects: confusion matrix, false-alarm rate, closure (DIAGNOSIS.md section 4).

A simulated UR5 (closed-loop tracking at 1 kHz, 2^18-count encoders, states filtered and
differentiated, white + AR(1) coloured torque noise; :mod:`dynid.sim.simulator`) runs a random
periodic excitation for training and another for held-out data (20 s each, 5 s period).  Cases:

* each of the 14 catalogue effects alone, its VALUE calibrated so that its RMS torque contribution
  (noise-free, on its joint) is 0.3x, 1x and 3x the noise standard deviation, on a joint drawn per seed;
* two effects at once (3x each, on different joints);
* nothing injected (the false-alarm rate);
* an effect the diagnosis is not told about: coupled_friction injected, left out of its catalogue.

Each case identifies a model without the effects (OLS, linear friction with offsets, armature; no
GMM), diagnoses it (:func:`dynid.diagnosis.core.diagnose`) and classifies the verdict
(:func:`dynid.diagnosis.cases.classify`).  Printed: the confusion matrix (injected x diagnosed,
with parametric / none / unexplained columns), accuracy per level, false-alarm rate, share of unknown
effects called "unexplained", median closure.  The method's thresholds were set on other seeds
(1000 and up) than the benchmark's (1 and up; effect-free cases 101 and up).

Run::

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python benchmarks/diagnosis_benchmark.py [--seeds 3] [--quick]
        [--n-jobs 2] [--scheduler local|tcp://HOST:8786] [--json results.json]

``--quick`` uses 2 seeds and 10 effect-free cases per seed (about 25 minutes on 2 free cores; the
full run, 3 seeds and 17 effect-free cases per seed, about 40).  Not a test: nothing is asserted.
``--scheduler`` runs the same cases on Dask through joblib's ``dask`` backend (``local``: a LocalCluster of
``--n-jobs`` workers; an address: a running scheduler, whose workers need dynid installed); each case is
seeded on its own, so the figures are the same wherever it runs.

"Right where the visible excess is >= 1x" selects the single-effect cases by the excess the effect
leaves on its joints after re-identification (the baseline refit's held-out MSE over the measured
noise floor, minus one), whatever calibrated size produced it: the calibration measures the raw
torque contribution, of which the low-pass filter and the refit can hide most (a 10-20 Hz
transmission vibration, a gain error the base parameters absorb).
"""

from __future__ import annotations

import argparse
import json
import os
import time
from collections import Counter, defaultdict

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("DYNID_NUM_THREADS", "1")

import numpy as np

LEVELS = (0.3, 1.0, 3.0)
PAIRS = (("stribeck", "delay"), ("cogging", "load_friction"), ("nonlinear_viscous", "base_tilt"))
WHOLE_ARM = ("payload", "base_tilt", "coupled_friction")
UNKNOWN = "coupled_friction"
SHAKE_ARM = ("elasticity", "backlash")  # a flexible transmission shows on every joint
ABSORBED = ("payload", "drive_gain", "offset", "armature", "base_tilt")  # re-identification can absorb them


def _visible(r: dict) -> float:
    """The effect's excess over the noise floor on its joints, in noise variances: the baseline refit's
    held-out MSE ratio minus 1 (measured before any candidate is scored).  For whole-arm effects and
    flexible transmissions the largest over all joints, background included."""
    return max(r.get("excess_joint") or [1.0]) - 1.0


def _upper95(k: int, n: int) -> float:
    """One-sided 95 % upper confidence bound of a rate seen k times in n (Clopper-Pearson)."""
    from scipy.stats import beta

    return 1.0 if k >= n else float(beta.ppf(0.95, k + 1, n - k))


def _lower95(k: int, n: int) -> float:
    """One-sided 95 % lower confidence bound of a rate seen k times in n (Clopper-Pearson)."""
    from scipy.stats import beta

    return 0.0 if k <= 0 else float(beta.ppf(0.05, k, n - k + 1))


def _joint(effect: str, seed: int, n: int, avoid: int | None = None) -> int | None:
    """A joint (1-based) drawn per seed; joint 1's armature is not identifiable apart from Izz1."""
    if effect in WHOLE_ARM:
        return None
    rng = np.random.default_rng([seed, sum(map(ord, effect))])
    choices = [j for j in range(1, n + 1) if j != avoid and not (effect == "armature" and j == 1)]
    return int(rng.choice(choices))


def build_cases(seeds: list[int], none_per_seed: int, n: int = 6) -> list[dict]:
    from dynid.sim.effects import EFFECT_NAMES

    cases = []
    for seed in seeds:
        for effect in EFFECT_NAMES:
            j = _joint(effect, seed, n)
            spec = f"{effect}@{j}" if j else effect
            for level in LEVELS:
                cases.append(
                    {"kind": "single", "effect": effect, "injected": [spec], "level": level, "seed": seed}
                )
        for a, b in PAIRS:
            ja = _joint(a, seed, n)
            jb = _joint(b, seed, n, avoid=ja)
            specs = [f"{a}@{ja}" if ja else a, f"{b}@{jb}" if jb else b]
            cases.append(
                {"kind": "pair", "effect": f"{a}+{b}", "injected": specs, "level": 3.0, "seed": seed}
            )
        for k in range(none_per_seed):
            free = 100 + 20 * k + seed  # below the tuning seeds (1000+); checked distinct below
            cases.append({"kind": "none", "effect": "none", "injected": [], "level": 0.0, "seed": free})
        for level in (1.0, 3.0):
            cases.append(
                {"kind": "unknown", "effect": UNKNOWN, "injected": [UNKNOWN], "level": level, "seed": seed}
            )
    free = [c["seed"] for c in cases if c["kind"] == "none"]
    if len(set(free)) != len(free) or (free and max(free) >= 1000):
        raise SystemExit(
            f"effect-free seeds {min(free)}..{max(free)} repeat or reach the tuning seeds (1000+)"
        )
    return cases


def run_one(case: dict) -> dict:
    from dynid.diagnosis.cases import run_case
    from dynid.sim.effects import EFFECT_NAMES
    from dynid.symbolic import load_robot

    robot = load_robot("ur5")
    catalogue = [e for e in EFFECT_NAMES if not (case["kind"] == "unknown" and e == UNKNOWN)]
    started = time.perf_counter()
    try:
        out = run_case(robot, case["injected"], level=case["level"], seed=case["seed"], catalogue=catalogue)
    except Exception as err:  # a failed case is reported, not hidden
        return {**case, "error": f"{type(err).__name__}: {err}", "correct": False, "label": "error"}
    d = out.pop("diagnosis")
    joints = [int(s.split("@")[1]) - 1 for s in case["injected"] if "@" in s]
    if not joints or any(s.split("@")[0] in SHAKE_ARM for s in case["injected"]):
        joints = list(range(len(out["excess"])))  # whole-arm effects and flexible transmissions
    return {
        **case,
        "values": out["values"],
        "achieved_level": out["achieved_level"],
        "verdict": out["verdict"],
        "label": out["label"],
        "parametric": out["parametric"],
        "correct": out["correct"],
        "closure": out["closure"],
        "found": out["found"],
        "excess_joint": [out["excess"][j] for j in joints],
        "excess": out["excess"],
        "top": [r.candidate.key for r in d.ranking[:3]],
        "undecided": [r.candidate.key for r in d.undecided],
        "seconds": time.perf_counter() - started,
    }


def _same_effect(key: str, injected: str) -> bool:
    """A candidate's key (``stribeck@2``) names the injected effect (``stribeck@2``, or ``base_tilt``)."""
    return key == injected or ("@" not in injected and key.split("@")[0] == injected)


def undecided_lines(results: list[dict]) -> list[str]:
    """How the undecided candidates (a lead the held-out run cannot decide, with the recording that would)
    fare: on effect-free cases they are false leads; on missed single effects, the first one is right or not."""
    none = [r for r in results if r["kind"] in ("none", "twin") and "undecided" in r]
    leads = [r for r in none if r["undecided"]]
    lines = [
        f"Effect-free cases with an undecided lead (a recording suggested for nothing): {len(leads)}/{len(none)}"
        f" = {100 * len(leads) / max(len(none), 1):.0f} %, one-sided 95 % upper bound "
        f"{100 * _upper95(len(leads), len(none)):.0f} %"
    ]
    lines.extend(f"    seed {r['seed']}: {', '.join(r['undecided'])}" for r in leads)
    missed = [
        r
        for r in results
        if r["kind"] == "single"
        and not r["correct"]
        and "undecided" in r
        and r["verdict"] in (["none"], ["unexplained"])
    ]
    right = [r for r in missed if r["undecided"] and _same_effect(r["undecided"][0], r["injected"][0])]
    lines.append(
        f"Single effects called none or unexplained whose first undecided lead is the injected effect: "
        f"{len(right)}/{len(missed)} (the recording printed would test the right effect)"
    )
    return lines


def report(results: list[dict]) -> str:
    from dynid.sim.effects import EFFECT_NAMES

    lines = []
    cols = [*EFFECT_NAMES, "parametric", "none", "unexplained", "error"]
    short = {e: e[:6] for e in cols}
    short.update(
        {
            "nonlinear_viscous": "nlvisc",
            "coupled_friction": "coupled",
            "load_friction": "loadfr",
            "unexplained": "unexpl",
            "parametric": "param",
            "drive_gain": "dgain",
            "base_tilt": "tilt",
            "elasticity": "elast",
            "temperature": "temp",
            "armature": "armat",
            "stribeck": "strib",
        }
    )
    rows = defaultdict(Counter)
    for r in results:
        if r["kind"] == "pair":
            continue
        key = r["effect"] if r["kind"] != "unknown" else f"{r['effect']} (unknown)"
        rows[key][r["label"]] += 1
    width = 7
    lines.append("Confusion matrix (rows: injected, all levels; columns: first diagnosed effect, or the")
    lines.append("parameter-change finding, none, unexplained):")
    lines.append(f"{'injected':<26}" + "".join(f"{short[c]:>{width}}" for c in cols))
    order = [*EFFECT_NAMES, f"{UNKNOWN} (unknown)", "none"]
    for key in order:
        if key not in rows:
            continue
        lines.append(f"{key:<26}" + "".join(f"{rows[key].get(c, 0) or '.':>{width}}" for c in cols))
    lines.append("")
    singles = [r for r in results if r["kind"] == "single"]
    lines.append("Right diagnosis of single effects (effect and joint, or the parameter-change finding):")
    for level in LEVELS:
        sel = [r for r in singles if r["level"] == level]
        ok = sum(r["correct"] for r in sel)
        lines.append(
            f"  calibrated RMS contribution {level:>3g}x noise: {ok}/{len(sel)} = {100 * ok / max(len(sel), 1):.0f} %"
        )
    big = [r for r in singles if r["level"] >= 1.0]
    ok = sum(r["correct"] for r in big)
    lines.append(f"  at >= 1x noise: {ok}/{len(big)} = {100 * ok / max(len(big), 1):.0f} %  (target >= 90 %)")
    # A case that raised counts as a miss (its excess is unknown).
    vis = [r for r in singles if r.get("error") or _visible(r) >= 1.0]
    ok = sum(r["correct"] for r in vis)
    lines.append(
        f"Right where the effect's visible excess on its joints is >= 1x the noise floor (the issue's criterion; "
        f"all levels): {ok}/{len(vis)} = {100 * ok / max(len(vis), 1):.0f} %  (target >= 90 %)"
    )
    for r in vis:
        if not r["correct"]:
            lines.append(
                f"    miss: {r['injected'][0]} level {r['level']:g} seed {r['seed']} (excess {_visible(r):.2f}x): "
                f"{'/'.join(r['verdict'])} ({r['parametric']})"
            )
    hidden = [r for r in big if not r.get("error") and _visible(r) < 1.0]
    hid_abs = [r for r in hidden if r["effect"] in ABSORBED]
    lines.append(
        f"Calibrated >= 1x but visible excess < 1x: {len(hidden)} cases; of these, effects re-identification "
        f"absorbs ({', '.join(ABSORBED)}) named or found by the parameter-change test: "
        f"{sum(r['correct'] for r in hid_abs)}/{len(hid_abs)}; others named: "
        f"{sum(r['correct'] for r in hidden if r not in hid_abs)}/{len(hidden) - len(hid_abs)}"
    )
    per_effect = defaultdict(list)
    for r in big:
        per_effect[r["effect"]].append(r)
    lines.append("  per effect at >= 1x (right / cases; verdicts of the misses):")
    for e in EFFECT_NAMES:
        rs = per_effect.get(e, [])
        miss = [
            f"{r['injected'][0]}:{r['level']:g}->{'/'.join(r['verdict'])}({r['parametric']})"
            for r in rs
            if not r["correct"]
        ]
        lines.append(f"    {e:<18} {sum(r['correct'] for r in rs)}/{len(rs)}  {'; '.join(miss)}")
    pairs = [r for r in results if r["kind"] == "pair"]
    ok = sum(r["correct"] for r in pairs)
    lines.append(f"Two effects at once (both named): {ok}/{len(pairs)}")
    for r in pairs:
        lines.append(
            f"    {' + '.join(r['injected'])} (seed {r['seed']}): {r['verdict']} {'right' if r['correct'] else 'wrong'}"
        )
    none = [r for r in results if r["kind"] == "none"]
    fa = sum(not r["correct"] for r in none)
    lines.append(
        f"False alarms with nothing injected: {fa}/{len(none)} = {100 * fa / max(len(none), 1):.1f} %  (target "
        f"<= 2 %; one-sided 95 % upper bound {100 * _upper95(fa, len(none)):.1f} %: bounding it below 2 % "
        "takes 149 clean cases)"
    )
    for r in none:
        if not r["correct"]:
            lines.append(f"    seed {r['seed']}: {r['verdict']} parametric {r['parametric']}")
    lines.extend(undecided_lines(results))
    unk = [r for r in results if r["kind"] == "unknown"]
    ok = sum(r["correct"] for r in unk)
    lines.append(
        f"Unknown effect ({UNKNOWN} not in the catalogue) called unexplained: {ok}/{len(unk)} = "
        f"{100 * ok / max(len(unk), 1):.0f} %  (target >= 80 %)"
    )
    for r in unk:
        if not r["correct"]:
            lines.append(f"    level {r['level']:g} seed {r['seed']}: {r['verdict']}")
    clos = [r["closure"] for r in results if r["correct"] and r.get("closure") is not None]
    if clos:
        lines.append(
            f"Closure of the right diagnoses (held-out, on the effect's joints): median {np.median(clos):.2f}, "
            f"quartiles {np.quantile(clos, 0.25):.2f}-{np.quantile(clos, 0.75):.2f} over {len(clos)} cases"
        )
    errors = [r for r in results if r.get("error")]
    for r in errors:
        lines.append(f"ERROR {r['injected']} level {r['level']} seed {r['seed']}: {r['error']}")
    secs = sum(r.get("seconds", 0.0) for r in results)
    lines.append(f"{len(results)} cases, {secs / 60:.1f} CPU-minutes")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=3, help="seeds per case (benchmark seeds start at 1)")
    parser.add_argument(
        "--first-seed", type=int, default=1, help="first seed (the method was tuned on 1000+)"
    )
    parser.add_argument("--none", type=int, default=17, help="effect-free cases per seed")
    parser.add_argument("--quick", action="store_true", help="2 seeds, 10 effect-free cases per seed")
    parser.add_argument(
        "--n-jobs", type=int, default=2, help="processes (joblib's own), or local Dask workers"
    )
    parser.add_argument(
        "--scheduler",
        default=None,
        metavar="ADDRESS",
        help="run the cases on Dask through joblib's dask backend: a running scheduler's address "
        "(tcp://HOST:8786), or 'local' for a LocalCluster of --n-jobs single-thread workers",
    )
    parser.add_argument("--only", default=None, help="comma-separated effects to run (default all)")
    parser.add_argument("--json", default=None, help="write every case's result to this file")
    args = parser.parse_args()
    seeds = list(range(args.first_seed, args.first_seed + (2 if args.quick else args.seeds)))
    cases = build_cases(seeds, 10 if args.quick else args.none)
    if args.only:
        keep = set(args.only.split(","))
        cases = [c for c in cases if c["effect"] in keep or any(p in keep for p in c["effect"].split("+"))]
    from joblib import Parallel, delayed

    started = time.perf_counter()
    if args.scheduler is None:
        results = Parallel(n_jobs=args.n_jobs, verbose=0)(delayed(run_one)(c) for c in cases)
        where = f"{args.n_jobs} workers"
    else:
        from joblib import parallel_config

        from dynid._cluster import cluster_client

        address = None if args.scheduler == "local" else args.scheduler
        with cluster_client(address, workers=args.n_jobs) as client, parallel_config(backend="dask"):
            results = Parallel(verbose=0)(delayed(run_one)(c) for c in cases)
            where = f"Dask ({args.scheduler}, {len(client.scheduler_info()['workers'])} workers)"
    print(report(results))
    print(f"wall time {(time.perf_counter() - started) / 60:.1f} min on {where}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(results, f, indent=1, default=float)


if __name__ == "__main__":
    main()
