"""Gap diagnosis on field-like recordings: the lab benchmark's confusion figures where the held-out run is aperiodic.

The lab benchmark (``diagnosis_benchmark.py``) holds out three periods of a periodic excitation, so the
noise floor is measured across periods.  Here every case is recorded as a robot in the field records it
(:mod:`dynid.diagnosis.field_cases`):

* training: three periods (15 s) of a random periodic excitation, as ``dynid simulate`` records by default;
* held-out: 20 s of minimum-jerk moves between random waypoints, with rests (no period repeats);
* torque noise: white + AR(1) with a 100 ms time constant, the coloured std as large as the white one;
* angles quantised to 18 bits per revolution; the datasets hold ``t, q, tau`` only (no ``dq``, ``ddq``);
* robots: the UR5 (6 joints) and the Panda (7 joints, fingers locked).

Why 18 bits: the arms the field cases stand for log finer angles than that (UR e-series joint encoders are
18-20 bit absolute on the output side; the Panda reads about 2^19-2^20 counts per revolution), so 18 bits
is the coarse end of what a user's recording holds.  At 14 bits (``2^14`` counts, 0.38 mrad) the
accelerations differentiated from the angles leave 1-10 noise variances of model error on every joint
with nothing injected, which no catalogue effect explains and which hides effects of 1x-3x the noise; the
diagnosis counts that share as noise (:func:`dynid.diagnosis.baseline.state_estimation_variance`), but an
effect below it cannot be seen.  That setting stays as a stress group of its own (``--stress-bits 14``,
the default): per robot and seed, the quick subset below (stribeck, cogging and delay at 3x, two
effect-free cases, the unknown effect at 3x), printed apart from the main figures.

Cases per robot and seed: each of the 14 catalogue effects alone at 1x and 3x the noise (its RMS torque
contribution on its joint, noise-free, on the training excitation, over the std of the field noise), on a
joint drawn per seed as in the lab benchmark; effect-free cases (the false-alarm rate); and the lab
benchmark's effect outside the catalogue (coupled_friction, at 1x and 3x, left out of the catalogue).

Each (robot, seed) also runs its effect-free twin: the same seed, so the same motions and noise, with
nothing injected.  What an effect adds to the refit's held-out excess is the case's minus the twin's.

Printed, per robot and together: the confusion matrix; the share right where the effect adds >= 1x the
diagnosis' noise floor to the refit's held-out excess on its joints (the case minus its twin; and the same
over the true filtered noise); the share right where the refit's excess on the effect's joints, background
included, is >= 1x (the lab benchmark's measure: on an aperiodic held-out run it counts the refit's own
parameter error, so effects that add nothing visible are counted as visible); false alarms (the
effect-free cases and the twins) with the one-sided 95 % upper bound, unknown effects called "unexplained",
how many "unexplained" verdicts rest on evidence that no floor enters alone: the two runs' disagreement
on a joint's parameters (:mod:`dynid.diagnosis.consistency`) or the training refit's misfit across the
training periods (:mod:`dynid.diagnosis.lack_of_fit`), the share of provisional verdicts, the noise-floor
method per case (periods / training periods / spectrum), how often the floor covers the true noise
(the simulator's injected torque noise put through the diagnosis' filter and trim), and how often the
floor's 95 % interval (:meth:`dynid.validation.metrics.NoiseFloor.std_interval`) covers the std of the
noise process (:func:`dynid.diagnosis.field_cases.process_noise_std`: what a floor measured on another
run of the robot estimates).  The issue's targets
are printed beside the figures; nothing is tuned to them and nothing is asserted.

Run::

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python benchmarks/field_diagnosis_benchmark.py [--quick]
        [--seeds 2] [--robots ur5,panda] [--only stribeck,cogging] [--none 4] [--train-periods 3] [--n-jobs 2]
        [--json out.json]

``--train-periods N`` records the training run over N periods instead of three (the effects keep the
level calibrated on three): a floor measured across more periods is more precise, and the excess test,
which allows for the floor's own error, more sensitive.

``--quick``: one seed, three effects (stribeck, cogging, delay) at 3x, two effect-free cases and the
unknown effect at 3x per robot (12 cases, about 5 CPU-minutes: a UR5 case takes about 20 s of CPU, a
Panda case about 30 s; the wall time is what the machine's load makes of it), plus the 14-bit stress
group (``--stress-bits 0`` leaves it out).  ``--encoder-bits B`` records the main cases' angles at B bits.
Seeds start at 1 (effect-free cases 101 and up); the diagnosis' thresholds were set on seeds 1000 and up.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from collections import Counter, defaultdict
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("DYNID_NUM_THREADS", "1")

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from diagnosis_benchmark import ABSORBED, SHAKE_ARM, UNKNOWN, _joint, _lower95, _upper95, undecided_lines

LEVELS = (1.0, 3.0)
QUICK_EFFECTS = ("stribeck", "cogging", "delay")
TARGETS = {"right": 0.85, "false_alarm": 0.03, "unknown": 0.80, "provisional": 0.20}
METHODS = ("periods", "training periods", "spectrum")


def build_cases(
    robots: list[str],
    seeds: list[int],
    none_per_seed: int,
    *,
    effects=None,
    levels=LEVELS,
    unknown_levels=LEVELS,
) -> list[dict]:
    """The field cases: every (robot, seed) gets each effect at each level, effect-free and unknown cases."""
    from dynid.sim.effects import EFFECT_NAMES
    from dynid.symbolic import load_robot

    effects = EFFECT_NAMES if effects is None else effects
    cases = []
    for name in robots:
        n = load_robot(name).n
        for seed in seeds:
            for effect in effects:
                j = _joint(effect, seed, n)
                spec = f"{effect}@{j}" if j else effect
                for level in levels:
                    cases.append(
                        {"robot": name, "kind": "single", "effect": effect, "injected": [spec], "level": level,
                         "seed": seed}
                    )  # fmt: skip
            if effects:  # the single cases' effect-free twin: the same seed, so the same motion and noise
                cases.append(
                    {"robot": name, "kind": "twin", "effect": "none", "injected": [], "level": 0.0, "seed": seed}
                )  # fmt: skip
            for k in range(none_per_seed):
                free = 100 + 20 * k + seed
                cases.append(
                    {
                        "robot": name,
                        "kind": "none",
                        "effect": "none",
                        "injected": [],
                        "level": 0.0,
                        "seed": free,
                    }
                )
            for level in unknown_levels:
                cases.append(
                    {"robot": name, "kind": "unknown", "effect": UNKNOWN, "injected": [UNKNOWN], "level": level,
                     "seed": seed}
                )  # fmt: skip
    free = [c["seed"] for c in cases if c["kind"] == "none"]
    if free and max(free) >= 1000:
        raise SystemExit(f"effect-free seeds reach {max(free)}, the tuning seeds (1000+); give fewer --none")
    return cases


def run_one(case: dict) -> dict:
    from dynid.diagnosis.field_cases import field_noise, run_field_case
    from dynid.sim.effects import EFFECT_NAMES
    from dynid.sim.sensors import NoiseModel
    from dynid.symbolic import load_robot

    robot = load_robot(case["robot"])
    noise = field_noise()
    noise = NoiseModel(**{**noise.to_dict(), "encoder_bits": case.get("encoder_bits", noise.encoder_bits)})
    catalogue = [e for e in EFFECT_NAMES if not (case["kind"] == "unknown" and e == UNKNOWN)]
    started, cpu = time.perf_counter(), time.process_time()
    try:
        out = run_field_case(
            robot,
            case["injected"],
            level=case["level"],
            seed=case["seed"],
            catalogue=catalogue,
            noise=noise,
            train_periods=case.get("train_periods", 3),
        )
    except Exception as err:  # a failed case is reported, not hidden
        return {**case, "error": f"{type(err).__name__}: {err}", "correct": False, "label": "error"}
    d = out.pop("diagnosis")
    joints = [int(s.split("@")[1]) - 1 for s in case["injected"] if "@" in s]
    if not joints or any(s.split("@")[0] in SHAKE_ARM for s in case["injected"]):
        joints = list(range(robot.n))
    true_var = np.square(out["true_noise"])
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
        "excess": out["excess"],
        "excess_joint": [out["excess"][j] for j in joints],
        "excess_true_joint": [out["mse_refit"][j] / true_var[j] for j in joints],
        "excess_true": (np.asarray(out["mse_refit"]) / true_var).tolist(),
        "joints": joints,
        "provisional": out["provisional"],
        "floor_method": out["floor_method"],
        "floor": out["floor"],
        "true_noise": out["true_noise"],
        "floor_over_true": out["floor_over_true"],
        "floor_interval": out["floor_interval"],
        "process_noise": out["process_noise"],
        "top": [r.candidate.key for r in d.ranking[:3]],
        "undecided": [r.candidate.key for r in d.undecided],
        "consistency_lead": [j + 1 for j, hit in enumerate(d.consistency["lead_joint"]) if hit],
        "misfit_lead": [j + 1 for j, hit in enumerate((d.lack_of_fit or {}).get("lead_joint", [])) if hit],
        "lack_of_fit": None
        if d.lack_of_fit is None
        else {k: d.lack_of_fit[k] for k in ("misfit", "state_estimation", "p_raw", "periods")},
        "consistency": {k: d.consistency[k] for k in ("cost", "p_raw")},
        "excess_significant": bool(d.excess["significant"]),
        "remainder_confirms": (
            bool(np.any(d.remainder["predictable_joint"])) if d.remainder is not None else None
        ),
        "seconds": time.perf_counter() - started,
        "cpu_seconds": time.process_time() - cpu,
    }


def _visible(r: dict, key: str = "excess_joint") -> float:
    """The refit's held-out excess on the effect's joints, background included (the lab benchmark's
    measure): on an aperiodic held-out run the refit's own parameter error shows there too (up to 16
    noise variances on an effect-free UR5's shoulder), whether or not the effect adds anything."""
    return max(r.get(key) or [1.0]) - 1.0


def _added(r: dict, twins: dict, key: str = "excess") -> float | None:
    """What the effect adds to the refit's held-out excess on its joints, in noise variances: the case's
    excess minus its effect-free twin's (the same seed: the same motions and noise), the largest over
    the effect's joints.  None without a twin."""
    twin = twins.get(_twin_key(r))
    if twin is None or twin.get("error") or r.get("error") or "joints" not in r:
        return None
    return max(r[key][j] - twin[key][j] for j in r["joints"])


def _twin_key(r: dict) -> tuple:
    return (r["robot"], r["seed"], r.get("group", "main"), r.get("encoder_bits"))


def _pct(k: int, n: int) -> str:
    return f"{k}/{n} = {100 * k / n:.0f} %" if n else "0/0"


def _confusion(results: list[dict]) -> list[str]:
    from dynid.sim.effects import EFFECT_NAMES

    cols = [*EFFECT_NAMES, "parametric", "none", "unexplained", "error"]
    short = {c: c[:6] for c in cols}
    short.update({"nonlinear_viscous": "nlvisc", "coupled_friction": "coupled", "load_friction": "loadfr",
                  "unexplained": "unexpl", "parametric": "param", "drive_gain": "dgain", "base_tilt": "tilt",
                  "elasticity": "elast", "temperature": "temp", "armature": "armat", "stribeck": "strib"})  # fmt: skip
    rows = defaultdict(Counter)
    for r in results:
        key = r["effect"] if r["kind"] != "unknown" else f"{r['effect']} (unknown)"
        rows[key][r["label"]] += 1
    lines = ["Confusion matrix (rows: injected, all levels; columns: first diagnosed effect, or the",
             "parameter-change finding, none, unexplained):",
             f"{'injected':<26}" + "".join(f"{short[c]:>7}" for c in cols)]  # fmt: skip
    for key in [*EFFECT_NAMES, f"{UNKNOWN} (unknown)", "none"]:
        if key in rows:
            lines.append(f"{key:<26}" + "".join(f"{rows[key].get(c, 0) or '.':>7}" for c in cols))
    return lines


def _figures(results: list[dict]) -> tuple[list[str], dict]:
    """The confusion figures of one group of cases: printed lines and a summary dict."""
    lines = _confusion(results)
    fig: dict = {"cases": len(results)}
    singles = [r for r in results if r["kind"] == "single"]
    for level in LEVELS:
        sel = [r for r in singles if r["level"] == level]
        lines.append(
            f"  calibrated contribution {level:g}x noise: right {_pct(sum(r['correct'] for r in sel), len(sel))}"
        )
    twins = {_twin_key(r): r for r in results if r["kind"] == "twin"}
    added = {id(r): _added(r, twins) for r in singles}
    if any(a is not None for a in added.values()):
        seen = [r for r in singles if r.get("error") or (added[id(r)] is not None and added[id(r)] >= 1.0)]
        ok = sum(r["correct"] for r in seen)
        fig["right_added"] = ok / len(seen) if seen else None
        lines.append(
            "Right where the effect adds >= 1x the diagnosis' noise floor to the refit's held-out excess on its "
            f"joints (the case minus its effect-free twin): {_pct(ok, len(seen))}  (target >= "
            f"{100 * TARGETS['right']:.0f} %)"
        )
        seen_t = [r for r in singles if r.get("error") or (_added(r, twins, "excess_true") or 0.0) >= 1.0]
        lines.append(
            "  the same over the true (injected, filtered) noise: "
            f"{_pct(sum(r['correct'] for r in seen_t), len(seen_t))}"
        )
        for r in seen:
            if not r["correct"]:
                lines.append(
                    f"    miss: {r['robot']} {r['injected'][0]} {r['level']:g}x seed {r['seed']} (adds "
                    f"{added[id(r)]:.2f}x): {'/'.join(r.get('verdict', ['error']))} "
                    f"({r.get('parametric', r.get('error'))})"
                )
        lines.append(
            f"  adds < 1x (not counted): {sum(a is not None and a < 1.0 for a in added.values())} cases, of "
            f"which named or found anyway {sum(r['correct'] for r in singles if (added[id(r)] or 0.0) < 1.0)}"
        )
    vis = [r for r in singles if r.get("error") or _visible(r) >= 1.0]
    ok = sum(r["correct"] for r in vis)
    fig["right_visible"] = ok / len(vis) if vis else None
    lines.append(
        "Right where the refit's held-out excess on the effect's joints, background included, is >= 1x the "
        f"diagnosis' noise floor: {_pct(ok, len(vis))}  (the lab benchmark's measure)"
    )
    vis_t = [r for r in singles if r.get("error") or _visible(r, "excess_true_joint") >= 1.0]
    ok_t = sum(r["correct"] for r in vis_t)
    fig["right_visible_true"] = ok_t / len(vis_t) if vis_t else None
    lines.append(
        f"  the same with the excess over the true (injected, filtered) noise: {_pct(ok_t, len(vis_t))}"
    )
    for r in vis:
        if not r["correct"]:
            lines.append(
                f"    miss: {r['robot']} {r['injected'][0]} {r['level']:g}x seed {r['seed']} (excess "
                f"{_visible(r):.2f}x, over true noise {_visible(r, 'excess_true_joint'):.2f}x): "
                f"{'/'.join(r.get('verdict', ['error']))} ({r.get('parametric', r.get('error'))})"
            )
    hidden = [r for r in singles if not r.get("error") and _visible(r) < 1.0]
    lines.append(
        f"Visible excess < 1x (not counted above): {len(hidden)} cases, of which named or found anyway "
        f"{sum(r['correct'] for r in hidden)} ({sum(r['effect'] in ABSORBED for r in hidden)} are effects "
        "re-identification absorbs)"
    )
    none = [r for r in results if r["kind"] in ("none", "twin")]
    fa = sum(not r["correct"] for r in none)
    fig["false_alarm"] = fa / len(none) if none else None
    fig["false_alarm_upper95"] = _upper95(fa, len(none)) if none else None
    lines.append(
        f"False alarms with nothing injected ({sum(r['kind'] == 'twin' for r in none)} of them the twins): "
        f"{fa}/{len(none)} = {100 * fa / max(len(none), 1):.1f} %, one-sided "
        f"95 % upper bound {100 * _upper95(fa, len(none)) if none else 100:.1f} %  (target <= "
        f"{100 * TARGETS['false_alarm']:.0f} %)"
    )
    for r in none:
        if not r["correct"]:
            ex = np.round(r.get("excess", []), 1).tolist()
            lines.append(
                f"    {r['robot']} seed {r['seed']}: {r.get('verdict', r.get('error'))} parametric "
                f"{r.get('parametric')}; excess per joint {ex}"
            )
    lines.extend(undecided_lines(results))
    unk = [r for r in results if r["kind"] == "unknown"]
    ok = sum(r["correct"] for r in unk)
    fig["unknown_unexplained"] = ok / len(unk) if unk else None
    fig["unknown_unexplained_lower95"] = _lower95(ok, len(unk)) if unk else None
    lines.append(
        f"Unknown effect ({UNKNOWN} not in the catalogue) called unexplained: {_pct(ok, len(unk))}, one-sided 95 % "
        f"lower bound {100 * _lower95(ok, len(unk)) if unk else 0:.0f} %  (target >= "
        f"{100 * TARGETS['unknown']:.0f} %)"
        + "".join(
            f"; at {lv:g}x {sum(r['correct'] for r in unk if r['level'] == lv)}/"
            f"{sum(r['level'] == lv for r in unk)}"
            for lv in sorted({r["level"] for r in unk})
        )
    )
    for r in unk:
        if not r["correct"]:
            lines.append(
                f"    {r['robot']} {r['level']:g}x seed {r['seed']}: {r.get('verdict', r.get('error'))}"
                + (
                    f", consistency lead on joint {r['consistency_lead']}"
                    if r.get("consistency_lead")
                    else ""
                )
                + (f", training misfit lead on joint {r['misfit_lead']}" if r.get("misfit_lead") else "")
            )
    lines.append(_lead_line(results))
    unexplained = [r for r in results if not r.get("error") and r.get("verdict") == ["unexplained"]]
    if unexplained:
        parts = []
        for kind, label in (("unknown", "unknown effects"), ("none", "effect-free"), ("twin", "twins")):
            rs = [r for r in unexplained if r["kind"] == kind]
            parts.append(f"{label} {sum(bool(r.get('remainder_confirms')) for r in rs)}/{len(rs)}")
        rs = [r for r in unexplained if r["kind"] == "single"]
        parts.append(f"single effects {sum(bool(r.get('remainder_confirms')) for r in rs)}/{len(rs)}")
        lines.append(
            "'Unexplained' verdicts that the check without the floor confirms (a state model predicts the "
            "residual on held-out folds it did not see): " + ", ".join(parts)
        )
    done = [r for r in results if not r.get("error")]
    prov = sum(r["provisional"] for r in done)
    fig["provisional"] = prov / len(done) if done else None
    lines.append(
        f"Provisional verdicts: {_pct(prov, len(done))}  (target < {100 * TARGETS['provisional']:.0f} %)"
    )
    methods = Counter(r["floor_method"] for r in done)
    fig["floor_methods"] = dict(methods)
    lines.append("Noise-floor method: " + ", ".join(f"{m} {methods.get(m, 0)}" for m in METHODS))
    ratio = np.concatenate([r["floor_over_true"] for r in done]) if done else np.zeros(0)
    if ratio.size:
        cover = float(np.mean(ratio >= 1.0))
        fig["floor_covers"] = cover
        fig["floor_over_true_quantiles"] = np.quantile(ratio, [0.1, 0.5, 0.9]).tolist()
        lines.append(
            f"Floor over the true noise std (per case and joint, {ratio.size}): covers it (>= 1) {100 * cover:.0f} %, "
            f"within 0.8 {100 * np.mean(ratio >= 0.8):.0f} %; ratio 10/50/90 % quantiles "
            + "/".join(f"{v:.2f}" for v in fig["floor_over_true_quantiles"])
        )
        for m in METHODS:
            sel = [r for r in done if r["floor_method"] == m]
            if sel and len(methods) > 1:
                rr = np.concatenate([r["floor_over_true"] for r in sel])
                lines.append(
                    f"  {m}: covers {100 * np.mean(rr >= 1.0):.0f} %, median ratio {np.median(rr):.2f}"
                )
    spans = [r for r in done if r.get("floor_interval") and r.get("process_noise")]
    if spans:
        lo = np.concatenate([r["floor_interval"][0] for r in spans])
        hi = np.concatenate([r["floor_interval"][1] for r in spans])
        proc = np.concatenate([r["process_noise"] for r in spans])
        known = np.isfinite(lo) & np.isfinite(hi)
        if known.any():
            inside = (lo[known] <= proc[known]) & (proc[known] <= hi[known])
            fig["floor_interval_covers"] = float(np.mean(inside))
            half = np.median((hi[known] - lo[known]) / 2 / (0.5 * (hi[known] + lo[known])))
            lines.append(
                f"Floor's 95 % interval covers the noise process' std (per case and joint, {int(known.sum())}): "
                f"{100 * np.mean(inside):.1f} % (nominal 95 %); median half-width {100 * half:.0f} % of the std"
            )
    clos = [r["closure"] for r in results if r["correct"] and r.get("closure") is not None]
    if clos:
        lines.append(f"Closure of the right diagnoses: median {np.median(clos):.2f} over {len(clos)} cases")
    for r in results:
        if r.get("error"):
            lines.append(f"ERROR {r['robot']} {r['injected']} {r['level']}x seed {r['seed']}: {r['error']}")
    return lines, fig


def _lead_line(results: list[dict]) -> str:
    """How many "unexplained" verdicts rest on evidence that no floor enters alone (the excess over the floor
    not significant): the runs' disagreement (:mod:`dynid.diagnosis.consistency`), the training run's
    misfit across its periods (:mod:`dynid.diagnosis.lack_of_fit`), and how often each is found at all."""
    parts = []
    for kind, label in (("none", "effect-free"), ("twin", "twins"), ("unknown", "unknown effect")):
        rs = [r for r in results if r["kind"] == kind and not r.get("error")]
        if rs:
            alone = [
                r
                for r in rs
                if r.get("verdict") == ["unexplained"]
                and not r.get("excess_significant")
                and (r.get("consistency_lead") or r.get("misfit_lead"))
            ]
            parts.append(
                f"{label} {len(alone)}/{len(rs)} (disagreement found in "
                f"{sum(bool(r.get('consistency_lead')) for r in rs)}, training misfit in "
                f"{sum(bool(r.get('misfit_lead')) for r in rs)}, both in "
                f"{sum(bool(r.get('consistency_lead')) and bool(r.get('misfit_lead')) for r in rs)})"
            )
    return (
        "Unexplained on evidence without the floor alone (no significant excess; the runs' disagreement or "
        "the training misfit across its periods): " + (", ".join(parts) or "no case")
    )


def report(results: list[dict]) -> tuple[str, dict]:
    """The printed report (all robots, then each) and the figures as a dict."""
    primary = [r for r in results if r.get("group", "main") == "main"]
    stress = [r for r in results if r.get("group") == "stress"]
    robots = sorted({r["robot"] for r in primary}, key=[r["robot"] for r in primary].index)
    lines, figures = [], {}
    bits = sorted({r.get("encoder_bits") for r in primary} - {None})
    tag = f", {'/'.join(map(str, bits))}-bit angles" if bits else ""
    groups = [(f"all robots{tag}", primary)] if len(robots) > 1 else []
    groups += [(f"{name}{tag}", [r for r in primary if r["robot"] == name]) for name in robots]
    if stress:
        sbits = "/".join(str(b) for b in sorted({r.get("encoder_bits") for r in stress}))
        groups.append((f"stress: {sbits}-bit angles, all robots (quick subset)", stress))
    for title, rs in groups:
        lines.append(f"=== {title} ({len(rs)} cases) ===")
        text, fig = _figures(rs)
        lines.extend(text)
        lines.append("")
        figures[title] = fig
    secs = sum(r.get("seconds", 0.0) for r in results)
    cpu = sum(r.get("cpu_seconds", 0.0) for r in results)
    lines.append(
        f"{len(results)} cases, {cpu / 60:.1f} CPU-minutes ({secs / 60:.1f} worker-minutes of wall time)"
    )
    return "\n".join(lines), figures


def main() -> None:
    from dynid.sim.effects import EFFECT_NAMES

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=2, help="seeds per robot (benchmark seeds start at 1)")
    parser.add_argument(
        "--first-seed", type=int, default=1, help="first seed (the method was tuned on 1000+)"
    )
    parser.add_argument("--robots", default="ur5,panda", help="comma-separated built-in robots")
    parser.add_argument("--none", type=int, default=8, help="effect-free cases per robot and seed")
    parser.add_argument(
        "--only",
        default=None,
        help="comma-separated effects to run (default all); none: the effect-free cases, unknown: the "
        f"effect outside the catalogue ({UNKNOWN} left out of it)",
    )
    parser.add_argument(
        "--quick", action="store_true", help="1 seed, 3 effects at 3x, 2 effect-free, unknown at 3x"
    )
    parser.add_argument(
        "--encoder-bits", type=int, default=18, help="resolution of the logged angles (bits/rev)"
    )
    parser.add_argument(
        "--stress-bits",
        type=int,
        default=14,
        help="resolution of the stress group's angles (bits/rev; 0: no stress group)",
    )
    parser.add_argument(
        "--train-periods",
        type=int,
        default=3,
        help="periods of the training run (default 3, what dynid simulate records by default)",
    )
    parser.add_argument("--n-jobs", type=int, default=2)
    parser.add_argument("--json", default=None, help="write every case's result and the figures to this file")
    args = parser.parse_args()
    robots = [r.strip() for r in args.robots.split(",") if r.strip()]
    if args.quick:
        seeds = [args.first_seed]
        cases = build_cases(robots, seeds, 2, effects=QUICK_EFFECTS, levels=(3.0,), unknown_levels=(3.0,))
    else:
        seeds = list(range(args.first_seed, args.first_seed + args.seeds))
        cases = build_cases(robots, seeds, args.none)
    for c in cases:
        c["encoder_bits"] = args.encoder_bits
        c["group"] = "main"
        c["train_periods"] = args.train_periods
    if args.stress_bits:
        stress = build_cases(
            robots, seeds[:1], 2, effects=QUICK_EFFECTS, levels=(3.0,), unknown_levels=(3.0,)
        )
        cases += [
            {**c, "encoder_bits": args.stress_bits, "group": "stress", "train_periods": args.train_periods}
            for c in stress
        ]
    if args.only:
        keep = set(args.only.split(","))
        unknown = keep - set(EFFECT_NAMES) - {"none", "unknown"}
        if unknown:
            raise SystemExit(
                f"--only names {', '.join(sorted(unknown))}, not catalogue effects, none or unknown"
            )
        cases = [
            c
            for c in cases
            if (c["effect"] in keep and c["kind"] != "unknown")
            or (c["kind"] == "unknown" and ({"unknown", UNKNOWN} & keep))
            or (c["kind"] == "twin" and keep - {"none", "unknown"})
        ]
    from joblib import Parallel, delayed

    started = time.perf_counter()
    results = Parallel(n_jobs=args.n_jobs, verbose=0)(delayed(run_one)(c) for c in cases)
    text, figures = report(results)
    print(text)
    print(f"wall time {(time.perf_counter() - started) / 60:.1f} min on {args.n_jobs} workers")
    if args.json:
        from dynid._io import write_text

        write_text(args.json, json.dumps({"figures": figures, "cases": results}, indent=1, default=float))


if __name__ == "__main__":
    main()
