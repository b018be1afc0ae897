"""Speed where a user waits: the first-run build, one excitation design, the default identification.

Prints three figures on this machine, each against a named baseline, with wall and CPU time and the
load of the machine (``os.getloadavg``) before and after each part:

``build``
    The symbolic generator built from an empty cache (a temporary ``DYNID_CACHE_DIR``), as the first
    ``dynid demo`` builds it: two translation units compiled in parallel at -O0, Pinocchio's
    algorithms instantiated for the joint types dynid uses only.  Baseline: the issue's quoted 221 s
    (previous recipe, one translation unit at -O1 with Pinocchio's 25 joint types, idle 2-core
    machine); ``--build-baseline`` also rebuilds the previous recipe in this script (its source from
    git history, ``git show 9121d39:dynid/symbolic/_generator/generator.cpp``; about 3.5 minutes of
    CPU) and checks that both generators write byte-identical Functions for the UR5.
``excite``
    One UR5 design with the paper's criterion (``dynid excite --robot ur5 --criterion seed``: seed 0,
    100 random baseline trajectories, 2 parallel tries): wall time, CPU time of the process and its
    workers, and the cond ratio (cond / best random cond).  Baseline: the issue's quoted 93 s wall
    (80 s without the random baseline), 156 s of CPU, cond ratio 0.34.  ``--excite-seeds 0,1,2``
    repeats the design on other seeds (the ratio over seeds); ``--screen-iter 0`` runs the previous
    search (every try solved to the end, with the present linear algebra) in this script.
``identify``
    ``identify(robot, data)`` with default flags on the whole TX40 recording (45,000 rows, needs
    ``../shared/data``), against OLS with linear friction in the same process; FIGAROH 0.2.4's 9.0 s on
    the same recording is quoted from the issue.
``cli``
    The commands as a user runs them on FIGAROH's TX40 split, each a whole process (imports, reading
    the CSV, the HTML report): ``dynid identify`` with defaults and with OLS + linear friction, and
    ``dynid validate --report`` of each model on the held-out rows; wall time, CPU time and peak memory
    of each (``os.wait4``), the median over ``--repeat`` rounds run one after the other.  With
    ``--figaroh-example DIR`` (a copy of figaroh-examples' ``examples/staubli_tx40`` folder, laid out as
    that repository lays it out) and ``--figaroh-python PY`` (a Python with figaroh installed), FIGAROH's
    own example runs in the same rounds, as it ships (its HTML report, its verification, its archive).

Run::

    OMP_NUM_THREADS=1 python benchmarks/speed_benchmark.py [--part build excite identify cli] [--repeat N]
        [--build-baseline] [--stages] [--figaroh-example DIR --figaroh-python PY]

The machine may be shared: every time is printed with the CPU time beside it and the load averages.

Measured on a shared 2-core machine (load 3-10, so the CPU times are the comparable figures):

- build: 85-88 s of CPU (146 s wall at load 6, 229 s at load 10); the previous recipe rebuilt here
  198-210 s of CPU (215 s wall at load 3-5, 586 s at load 10); byte-identical UR5 Functions.  On
  2 idle cores the two units take about 45 s (each about 43 s of CPU).
- excite: 32 s of CPU (151 s wall at load 16-17), ratio 0.349, 44 tries screened at 40 IPOPT
  iterations and 2 finished; seeds 1 and 2: 14 and 17 s of CPU, ratio 0.335 and 0.326.  Before
  (every try solved to the end, IPOPT's Sherman-Morrison limited-memory update): 154-155 s of CPU,
  158 s wall at load 4, ratio 0.353 (seeds 1 and 2: 0.325 and 0.346).  On 2 idle cores the 32 s of CPU are about
  16 s of wall time.
- identify: default 9.3-9.6 s of CPU (13.8-17.9 s wall at load 6) against 12.2-12.6 s before on the
  same code otherwise (identical parameters to the bit); OLS 0.7 s.
- identify, after the friction search, link step and refinement changes of commits 5a050b7-6157cf8
  (identical parameters to the bit), alternated with the code before them at load 12-18: default
  7.5-9.6 s of CPU against 10.3-12.2 s (20-45 s wall at that load; the wall time of an idle 2-core
  machine was not measured).  ``--stages`` at load 12, after (before): friction searches 1.30 s
  (2.72), link steps 0.83 (1.28), nuisance steps 0.20 (0.31), the rest of the refinements 0.76
  (1.30); unchanged: the mixtures 3.2 s (EM 1.54, designs 0.53, the mixture fitted on the physical
  layers' residual 1.14: 43 % of the CPU time), consistent projection 0.42, build 0.51, IRLS 0.19.

With nothing else running (load 0.7-1.2), at fa58a13: ``dynid excite --robot ur5 --criterion seed``
(with its 100-trajectory random baseline) 21.4 s wall, cond ratio 0.35; the default identification of
the TX40 recording 8.66 s wall / 10.0 s of CPU (OLS 0.64 s), against FIGAROH's quoted 9.0 s.

At the start of the next change (7accfff, load 0.4): the default identification 7.05 s wall / 8.35 s of
CPU.  After the mixtures' EM and gates were stacked over their components (``fit_gaussian_mixture``: the
same parameters as scikit-learn's to rounding, five times faster on these small fits; 2.7 s of EM cut to
about 0.5 s, 0.9 s of gates to about 0.3 s, and about 0.4 s of OpenMP-limit calls gone), with every
other process of the machine paused, one run of each part: build 38.2 s wall (69.9 s of CPU in the two
compilers); the design 13.6 s wall, 25.3 s of CPU, ratio 0.349 (44 tries, kept #29, as before); the
default identification **3.83 s wall / 5.02 s of CPU** (OLS 0.51 s; five more runs of the same code:
3.80-4.21 s, mean 3.99 s), link and friction parameters identical to before, the mixtures to 1e-12.
``dynid identify`` on the same recording as a CSV, from the shell: 5.6-5.9 s wall, of which about 1.5 s
are imports (scipy.signal alone 1.1 s) and 0.3 s reading the 11 MB file.  Fitting the physical layers
alone in a second thread beside the joint fit was tried and dropped: 3.80 s mean over five runs against
3.99 s one after the other, for 0.5 s more CPU.

The default now chooses its pipeline by cross-validation (four candidates on two halves, then the chosen
one on the whole).  Its fits share one system per dataset (8 builds of the TX40 split become 3, results
identical to the bit), and the candidates are scored on the recording decimated to ten times its
cut-off (``dynid.identify.pipeline.RATE_FACTOR``).  At the start of that work (eb9674c, load 0.5-1.0):
default identification of the whole recording 15.7 s of CPU (OLS 0.66 s); after it (load 8): 5.7 s of
CPU (OLS 0.67 s).  Fitting the chosen pipeline at the coarse rate too was tried and dropped: the TX40
split's default fell from 7.2 to 3.8 s of CPU, but joint 4's held-out RMS rose from 1.08 to 1.29 N m.

``--part cli --repeat 2 --figaroh-example ...`` at 1afe5ed (load 0.5-0.7; FIGAROH 1.0.2's example as its
repository lays it out, run as it ships: it processes the whole recording decimated by 10, writes its
report, archive and a 21 MB verdict, and exits 1 because its verification finds no held-out data
configured), medians of 2 rounds:

=====================================================  ======  ======  ========
command                                                wall s  CPU s   peak MiB
=====================================================  ======  ======  ========
dynid identify (defaults)                                5.91    6.72       367
dynid validate (defaults' model, HTML report)            3.30    3.29       244
dynid identify --method ols --friction linear --gmm off  2.28    2.32       306
dynid validate (OLS model, HTML report)                  3.31    3.30       250
FIGAROH's TX40 example                                   8.96    8.89      1193
=====================================================  ======  ======  ========

identify + validate: defaults 10.0 s of CPU (1.13 times FIGAROH's example), OLS 5.6 s (0.63 times); peak
memory 0.31 times.  Of validate's 3.3 s, 1.5 s are the command without ``--report`` (0.8 s of it imports)
and 1.8 s the HTML report's figures and matplotlib.

After every command stopped importing scipy.signal (its filter, spectra and design in
``dynid.data.dsp``, the section loop compiled once into the cache) and the mixtures' k-means start
stopped importing scikit-learn (``dynid.identify.mixture.kmeans_labels``, scikit-learn's labels from
the same seed), at 7708ed8, load 1.2-1.6, medians of 3 rounds (parameters identical to the bit):

=====================================================  ======  ======  ========
command                                                wall s  CPU s   peak MiB
=====================================================  ======  ======  ========
dynid identify (defaults)                                4.76    5.34       303
dynid validate (defaults' model, HTML report)            2.78    2.77       217
dynid identify --method ols --friction linear --gmm off  1.82    1.85       244
dynid validate (OLS model, HTML report)                  2.89    2.88       217
FIGAROH's TX40 example                                  10.46    9.97      1188
=====================================================  ======  ======  ========

identify + validate: defaults 0.81 times FIGAROH's CPU time, OLS 0.47 times; identification alone
0.54 and 0.19 times; peak memory 0.25 times.  After scipy.optimize left the paths that do not use it
(load 1.2-1.6, medians of 3): defaults identify 6.74 s, validate 2.76 s; OLS identify 1.96 s, validate
2.66 s; FIGAROH 10.21 s: 0.93x and 0.45x for identify + validate.  The defaults' CPU time varies by about
20 % between runs of the same code on this shared machine (5.2-6.3 s in three alternated runs of each of
7708ed8 and the commit after it, means 6.36 and 6.37 s); the ratios are the comparable figures.

After the per-joint steps stopped running in two threads (they held each other's interpreter lock:
0.7-1.1 s more CPU, no wall time saved), the threshold searches stopped at a 0.5 % bracket, the
consistent fit's log-det terms moved to the links' standard parameters and a shared system's layer-1
fit was taken once per estimator (parameters identical on the three real arms, but for the threshold
searches' rounding), in-process default identifications alternated with the code before them (a2ad3e7),
two rounds, CPU s: TX40 split 3.4-4.4 (5.1-6.0 before), Panda 4.1-4.3 (6.4-6.7), LWR4+ 5.7-6.3
(8.1-9.3).  ``--part cli --repeat 3`` (load 0.4-1.3; the children run from cached bytecode, as an
installed package does): defaults identify 4.75-5.25 s of CPU, validate 2.4-3.2 s; OLS identify
1.73-1.86 s; FIGAROH 10.5-10.9 s.  The identification alone: defaults 0.45-0.48x FIGAROH's CPU time
(the target is 1/3), OLS 0.16-0.17x; identify + validate 0.68-0.78x and 0.46x; defaults 2.75-2.81 times
OLS from the shell.  With scipy.special left to the sigmoid friction (18442d9, load 0.7-1.2): defaults
identify 4.27 s of CPU, validate 2.39 s; OLS identify 1.50 s, validate 2.39 s; FIGAROH 9.90 s: the
identification alone 0.43x and 0.15x, identify + validate 0.67x and 0.39x.

On a faster machine and a fresh install (2026-11-28), with figaroh-examples' TX40 example as its repository
now lays it out (the unified config: the older example's legacy config is refused by FIGAROH 1.0.2; this one
runs to the end and exits 0, with the repository's ``models/`` beside ``examples/`` and its URDF a symlink
into it), two runs of ``--part cli --repeat 3`` (load 0.6-1.0): defaults identify 2.71-2.74 s of CPU, OLS
0.92-0.95 s, FIGAROH 4.85-5.31 s: the identification alone 0.52-0.56x and 0.18-0.19x (targets 1/3 and
1/5), peak memory 0.23x.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import filecmp  # noqa: E402
import shutil  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from _timing import children_cpu, load, run_measured, self_cpu, workers_cpu  # noqa: E402

ISSUE_BUILD_S = 221.0
ISSUE_EXCITE_S = (80.0, 93.0, 156.0, 0.34)  # wall without / with baseline, CPU, cond ratio
FIGAROH_TX40_S = 9.0
OLD_GENERATOR = "9121d39:dynid/symbolic/_generator/generator.cpp"


def part_build(repeat: int, baseline: bool) -> None:
    from dynid.symbolic import build

    print(
        f"\n== build of the symbolic generator from an empty cache ({build.build_jobs()} parallel compilers)"
    )
    for k in range(repeat):
        with tempfile.TemporaryDirectory() as cache:
            os.environ["DYNID_CACHE_DIR"] = cache
            print(f"  [{load()}]")
            c0, t0 = children_cpu(), time.perf_counter()
            exe = build.generator_path(progress=None)
            wall, cpu = time.perf_counter() - t0, children_cpu() - c0
            print(f"  run {k + 1}: {wall:.1f} s wall, {cpu:.1f} s CPU (compilers)  [{load()}]")
            if baseline and k == 0:
                _build_baseline(exe)
        os.environ.pop("DYNID_CACHE_DIR", None)
    print(f"  baseline: the issue's quoted {ISSUE_BUILD_S:.0f} s (previous recipe, idle 2-core machine)")


def _build_baseline(new_exe: Path) -> None:
    """Build the previous recipe (one unit, -O1, every joint type) and compare the UR5's Functions."""
    from dynid.symbolic import build, load_robot

    repo = Path(__file__).resolve().parents[1]
    try:
        source = subprocess.run(
            ["git", "-C", str(repo), "show", OLD_GENERATOR], capture_output=True, text=True, check=True
        ).stdout
    except (OSError, subprocess.CalledProcessError):
        print("  previous recipe: its source is not in this checkout's git history; skipped")
        return
    prefix, casadi_dir = build._prefixes()
    lib_dirs = [prefix / "lib", casadi_dir]
    with tempfile.TemporaryDirectory() as work:
        src = Path(work) / "generator.cpp"
        src.write_text(source)
        exe = Path(work) / "old-generator"
        cmd = [
            build.find_compiler("c++"),
            "-std=c++17",
            "-O1",
            "-w",
            *(f"-D{d}" for d in build._DEFINES),
            f"-I{prefix / 'include'}",
            f"-I{casadi_dir / 'include'}",
            f"-I{casadi_dir / 'include' / 'eigen3'}",
            str(src),
            "-o",
            str(exe),
            *(f"-L{d}" for d in lib_dirs),
            "-lpinocchio_default",
            "-lcasadi",
            *(f"-Wl,-rpath,{d}" for d in lib_dirs),
        ]
        c0, t0 = children_cpu(), time.perf_counter()
        subprocess.run(cmd, check=True)
        wall, cpu = time.perf_counter() - t0, children_cpu() - c0
        print(f"  previous recipe, built here: {wall:.1f} s wall, {cpu:.1f} s CPU  [{load()}]")
        spec = Path(work) / "ur5.spec"
        spec.write_text(load_robot("ur5").spec)
        same = True
        for label, program in (("old", exe), ("new", new_exe)):
            out = Path(work) / label
            out.mkdir()
            t0 = time.perf_counter()
            subprocess.run([str(program), str(spec), str(out)], check=True)
            print(f"  {label} generator: UR5 functions in {time.perf_counter() - t0:.2f} s")
        names = sorted(p.name for p in (Path(work) / "old").glob("*.casadi"))
        for name in names:
            same &= filecmp.cmp(Path(work) / "old" / name, Path(work) / "new" / name, shallow=False)
        print(f"  UR5 Functions of both generators byte-identical: {same} ({len(names)} files)")


def part_excite(repeat: int, seeds: list[int] | None = None, screen_iter: int = 40) -> None:
    from dynid.optim.excitation import ExcitationProblem, design_excitation
    from dynid.symbolic import load_robot

    print(
        "\n== one UR5 excitation design, criterion seed (dynid excite defaults: 2 parallel tries, "
        f"screening {screen_iter or 'off'})"
    )
    robot = load_robot("ur5")
    for k, seed in enumerate([0] * repeat if not seeds else seeds):
        problem = ExcitationProblem(robot=robot, criterion="seed")
        print(f"  [{load()}]")
        # joblib's workers outlive a design (and may serve the next one): count their CPU time as a
        # difference too
        c0, t0 = self_cpu() + children_cpu() + workers_cpu(), time.perf_counter()
        result = design_excitation(problem, seed=seed, n_jobs=2, screen_iter=screen_iter or None)
        wall = time.perf_counter() - t0
        cpu = self_cpu() + children_cpu() + workers_cpu() - c0
        stage = result.stages[0]
        print(
            f"  run {k + 1} (seed {seed}): {wall:.1f} s wall, {cpu:.1f} s CPU (process and workers), "
            f"cond {result.cond:.4g}, "
            f"random baseline {result.baseline_cond:.4g}, ratio {result.cond / result.baseline_cond:.3f}; "
            f"{stage.tries} tries, kept #{stage.kept + 1}  [{load()}]"
        )
    wall0, wall1, cpu0, ratio0 = ISSUE_EXCITE_S
    print(
        f"  baseline: the issue's quoted {wall1:.0f} s wall with the random baseline ({wall0:.0f} s without), "
        f"{cpu0:.0f} s CPU, ratio {ratio0:.2f} (previous settings, idle 2-core machine)"
    )


# where the default identification spends its CPU time (--stages): (label, module, owner, attribute);
# stages nest (the refinements hold the friction fits, the mixtures, the link steps, ...); each is
# called from one thread at a time, so the process's CPU time during its calls is its own (with what
# its calls run in threads)
STAGES = (
    ("build_system (states, regressor, filter, QR)", "dynid.identify.three_layer", None, "build_system"),
    ("  its blocked QR of Z", "dynid.identify.linear_system", None, "_qr_rows"),
    ("layer 1 (IRLS)", "dynid.identify.estimators", "IRLS", "fit"),
    ("refine (two calls: with mixtures, physical alone)", "dynid.identify.three_layer", None, "refine"),
    ("  friction fits (shape searches)", "dynid.identify.friction", "FrictionLayer", "fit"),
    ("  mixture EM (fit_mixtures)", "dynid.identify.gmr", "GMRCorrection", "fit_mixtures"),
    ("  mixture designs (gates at full rate)", "dynid.identify.gmr", "GMRCorrection", "design"),
    ("  link steps", "dynid.identify.refine", None, "_link_step"),
    ("  nuisance steps", "dynid.identify.refine", None, "_nuisance_step"),
    ("  consistent projection", "dynid.identify.refine", None, "_consistent_step"),
    ("mixture fitted on the physical layers' residual", "dynid.identify.gmr", "GMRCorrection", "fit"),
)


def _stage_timers() -> tuple[dict[str, list[float]], list]:
    """Wrap each stage's function to add up its calls and CPU time (all threads of the process)."""
    import functools
    import importlib

    totals: dict[str, list[float]] = {label: [0, 0.0] for label, *_ in STAGES}
    undo = []
    for label, module, owner, attr in STAGES:
        target = importlib.import_module(module)
        if owner is not None:
            target = getattr(target, owner)
        func = getattr(target, attr)

        def timed(*args, _func=func, _label=label, **kwargs):
            c0 = time.process_time()
            try:
                return _func(*args, **kwargs)
            finally:
                totals[_label][0] += 1
                totals[_label][1] += time.process_time() - c0

        setattr(target, attr, functools.wraps(func)(timed))
        undo.append((target, attr, func))
    return totals, undo


def _tx40():
    """The TX40 recording and its URDF, or None (said) where the shared recordings are not."""
    from dynid.data.adapters import load_recording, recording_model_path

    warnings.simplefilter("ignore")
    try:
        return load_recording("tx40"), str(recording_model_path("tx40"))
    except Exception as exc:  # the shared recordings are not everywhere
        print(f"  skipped: {exc}")
        return None


def part_identify(repeat: int, stages: bool = False) -> None:
    from dynid.identify.model import identify
    from dynid.symbolic import load_robot

    print("\n== default identification of the TX40 recording (45,000 rows) against OLS")
    found = _tx40()
    if found is None:
        return
    data, urdf = found
    robot = load_robot(urdf)
    identify(robot, data.select_rows(np.arange(2000)), method="ols", friction="linear", gmm="off")  # warm-up
    for k in range(repeat):
        print(f"  [{load()}]")
        figures = []
        for label, options in (
            ("default", {}),
            ("ols", {"method": "ols", "friction": "linear", "gmm": "off", "physical": False}),
        ):
            c0, t0 = self_cpu(), time.perf_counter()
            identify(robot, data, **options)
            figures.append(f"{label} {time.perf_counter() - t0:.2f} s wall / {self_cpu() - c0:.2f} s CPU")
        print(f"  run {k + 1}: " + ", ".join(figures) + f"  [{load()}]")
    print(f"  reference: FIGAROH 0.2.4 {FIGAROH_TX40_S:.1f} s on the same recording (quoted from the issue)")
    if stages:
        totals, undo = _stage_timers()
        c0 = time.process_time()
        identify(robot, data)
        cpu = time.process_time() - c0
        for target, attr, func in undo:
            setattr(target, attr, func)
        print(
            f"  CPU time by stage of one default identification ({cpu:.2f} s CPU in all; stages nest)  [{load()}]"
        )
        for label, (calls, seconds) in totals.items():
            print(f"    {label:<52s} {int(calls):4d} calls {seconds:6.2f} s")


TX40_SPLIT = (
    24750,
    29250,
)  # FIGAROH's split of the TX40 recording: rows [0, 24750) train, [29250, 45000) held out


def part_cli(repeat: int, figaroh_example: str | None, figaroh_python: str) -> None:
    """The commands as a user runs them on FIGAROH's TX40 split, whole processes, beside FIGAROH's own
    TX40 example when a copy of it is given (``--figaroh-example``)."""
    from dynid.data.files import save_dataset

    print("\n== the TX40 split from the shell: whole processes (imports and file reading included)")
    found = _tx40()
    if found is None:
        return
    data, urdf = found
    train_end, held_start = TX40_SPLIT
    with tempfile.TemporaryDirectory() as tmp:
        train, held = Path(tmp, "train.csv"), Path(tmp, "heldout.csv")
        save_dataset(data.select_rows(np.arange(train_end)), train)
        save_dataset(data.select_rows(np.arange(held_start, data.m)), held)

        def dynid(*args: str) -> list[str]:
            return [sys.executable, "-m", "dynid", *args, "--quiet"]

        if os.environ.pop("PYTHONDONTWRITEBYTECODE", None):
            # an installed package runs from cached bytecode (pip compiles it, as it compiled FIGAROH's);
            # with the variable set, every dynid command would compile its 80 modules again (0.15 s)
            print("  PYTHONDONTWRITEBYTECODE is unset for these runs: modules run from cached bytecode")

        ols = ("--method", "ols", "--friction", "linear", "--gmm", "off")
        runs = {
            "dynid identify (defaults)": dynid(
                "identify", "--robot", urdf, "--data", str(train), "--out", "d.json"
            ),
            "dynid validate (defaults' model, HTML report)": dynid(
                "validate", "--model", "d.json", "--data", str(held), "--report", "d.html"
            ),
            "dynid identify --method ols --friction linear --gmm off": dynid(
                "identify", "--robot", urdf, "--data", str(train), "--out", "o.json", *ols
            ),
            "dynid validate (OLS model, HTML report)": dynid(
                "validate", "--model", "o.json", "--data", str(held), "--report", "o.html"
            ),
        }
        figaroh = None
        if figaroh_example:
            script = Path(figaroh_example, "identification.py")
            if script.is_file():
                figaroh = [figaroh_python, str(script)]
                runs["FIGAROH's TX40 example (identification.py, its report and checks)"] = figaroh
            else:
                print(f"  FIGAROH: no identification.py in {figaroh_example}; its run is skipped")
        else:
            print(
                "  FIGAROH: not run (give --figaroh-example DIR, a checkout of figaroh-examples' Staubli TX40 "
                "example, and --figaroh-python for the Python that has figaroh installed)"
            )
        sums: dict[str, list[dict]] = {label: [] for label in runs}
        for k in range(repeat):  # the commands interleaved round by round, so a load change hits them alike
            for label, argv in runs.items():
                cwd = figaroh_example if argv is figaroh else tmp
                result = run_measured(argv, cwd=cwd)
                sums[label].append(result)
                if result["code"] != 0:
                    print(f"  {label}: exit {result['code']}: {' / '.join(result['tail'])}")
            print(f"  round {k + 1} done  [{load()}]")
        print(f"  {'':64s} {'wall s':>8s} {'CPU s':>8s} {'peak MiB':>9s}   (the median of {repeat} rounds)")
        med = {}
        for label, results in sums.items():
            med[label] = {
                key: float(np.median([r[key] for r in results])) for key in ("wall", "cpu", "rss_mib")
            }
            m = med[label]
            print(f"  {label:64s} {m['wall']:8.2f} {m['cpu']:8.2f} {m['rss_mib']:9.0f}")
        keys = list(runs)
        default_cpu = med[keys[0]]["cpu"] + med[keys[1]]["cpu"]
        ols_cpu = med[keys[2]]["cpu"] + med[keys[3]]["cpu"]
        print(f"  identify + validate: defaults {default_cpu:.2f} s CPU, OLS {ols_cpu:.2f} s CPU (ratio "
              f"{default_cpu / ols_cpu:.2f}); identify alone: defaults {med[keys[0]]['cpu']:.2f}, OLS "
              f"{med[keys[2]]['cpu']:.2f} (ratio {med[keys[0]]['cpu'] / med[keys[2]]['cpu']:.2f})")  # fmt: skip
        if figaroh is not None:
            peer = med[keys[-1]]
            print(
                f"  against FIGAROH's example ({peer['cpu']:.2f} s CPU, {peer['rss_mib']:.0f} MiB): defaults "
                f"{default_cpu / peer['cpu']:.2f}x its CPU time, OLS {ols_cpu / peer['cpu']:.2f}x; peak memory "
                f"{max(med[keys[0]]['rss_mib'], med[keys[1]]['rss_mib']) / peer['rss_mib']:.2f}x; identify alone: "
                f"defaults {med[keys[0]]['cpu'] / peer['cpu']:.2f}x, OLS {med[keys[2]]['cpu'] / peer['cpu']:.2f}x"
            )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument(
        "--part",
        nargs="+",
        choices=("build", "excite", "identify", "cli"),
        default=["build", "excite", "identify", "cli"],
    )
    parser.add_argument(
        "--figaroh-example",
        help="folder of FIGAROH's Staubli TX40 example (identification.py) to run beside dynid",
    )
    parser.add_argument(
        "--figaroh-python",
        default=sys.executable,
        help="the Python that has figaroh installed (default this one)",
    )
    parser.add_argument("--repeat", type=int, default=1, help="runs of each part (default 1)")
    parser.add_argument(
        "--build-baseline", action="store_true", help="also build the previous recipe here (minutes of CPU)"
    )
    parser.add_argument(
        "--stages", action="store_true", help="also the CPU time of each stage of one default identification"
    )
    parser.add_argument(
        "--excite-seeds", help="seeds of the excitation designs, e.g. 0,1,2 (default: 0, --repeat times)"
    )
    parser.add_argument(
        "--screen-iter",
        type=int,
        default=40,
        help="screening iterations of the design (0: every try to the end)",
    )
    args = parser.parse_args()
    print(
        f"{os.cpu_count()} cores, {load()}, python {sys.version.split()[0]}, compiler {shutil.which('c++')}"
    )
    if "build" in args.part:
        part_build(args.repeat, args.build_baseline)
    if "excite" in args.part:
        seeds = None if not args.excite_seeds else [int(v) for v in args.excite_seeds.split(",")]
        part_excite(args.repeat, seeds, args.screen_iter)
    if "identify" in args.part:
        part_identify(args.repeat, args.stages)
    if "cli" in args.part:
        part_cli(max(args.repeat, 1), args.figaroh_example, args.figaroh_python)


if __name__ == "__main__":
    main()
