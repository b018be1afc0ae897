"""Speed, memory and accuracy of the three-layer identification (prints figures; not a test).

60 s at 1 kHz on the UR5 (60,000 samples, 360,000 stacked rows): torque from the regressor itself
plus the paper's nonlinear friction, a smooth unmodelled torque and white noise; joint angles with
encoder-like noise, velocities and accelerations left to preprocessing (20 Hz Butterworth, central
differences, parallel filtering).

Memory: ``tracemalloc`` peaks (numpy buffers and Python objects; not the compiled regressor's own
small work arrays) per step, and the process's ``ru_maxrss`` at the end.

Run:  OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python benchmarks/identification_benchmark.py
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import resource  # noqa: E402
import time  # noqa: E402
import tracemalloc  # noqa: E402
import warnings  # noqa: E402

import numpy as np  # noqa: E402


def measured(label: str, func, results: dict):
    tracemalloc.start()
    start = time.perf_counter()
    out = func()
    elapsed = time.perf_counter() - start
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    results[label] = (elapsed, peak / 2**20)
    print(f"{label:<34} {elapsed:7.2f} s   peak {peak / 2**20:8.1f} MiB (tracemalloc)", flush=True)
    return out


def main() -> None:
    from dynid.identify._synthetic import random_fourier, synthetic_dataset, true_parameters
    from dynid.identify.consistent import ConsistentLS
    from dynid.identify.estimators import IRLS, OLS
    from dynid.identify.friction import FrictionLayer, SeedFriction
    from dynid.identify.gmr import GMRCorrection
    from dynid.identify.linear_system import Preprocessing, build_system, column_set
    from dynid.identify.model import identify
    from dynid.identify.preprocess import lowpass
    from dynid.symbolic import load_robot

    warnings.simplefilter("ignore")
    robot = load_robot("ur5")
    rng = np.random.default_rng(2024)
    cols = column_set(robot, friction=False)
    x = true_parameters(cols, rng)
    frictions = []
    for j in range(robot.n):
        f = SeedFriction()
        f.coef_ = np.array([1.0 + 0.2 * j, 0.8 + 0.1 * j, 0.5, 0.2, 0.05, 1.6, 1.3, 0.08])
        frictions.append(f)

    def extra(q, dq):
        fr = np.column_stack([f.predict(dq[:, j]) for j, f in enumerate(frictions)])
        return fr + 0.3 * np.sin(2 * q + 0.5)  # friction + a smooth unmodelled, position-dependent torque

    noise = 0.2  # N m
    rate = 1000.0
    train = synthetic_dataset(
        cols,
        x,
        random_fourier(robot, rng, periods=6),
        rate=rate,
        rng=rng,
        noise=noise,
        extra=extra,
        state_noise=1e-5,
        with_derivatives=False,
    )
    train = train.select_rows(np.arange(60_000))
    test = synthetic_dataset(
        cols,
        x,
        random_fourier(robot, rng, periods=2),
        rate=rate,
        rng=rng,
        noise=noise,
        extra=extra,
        state_noise=1e-5,
        with_derivatives=False,
    )
    pre = Preprocessing(cutoff=20.0)
    print(f"data: {train.m} samples x {train.n} joints = {train.m * train.n} stacked rows at {rate:g} Hz")
    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    res: dict = {}
    system = measured(
        "build system (regressor, filter, QR)", lambda: build_system(robot, train, preprocessing=pre), res
    )
    measured("OLS", lambda: OLS(robot=robot, preprocessing=pre).fit(system), res)
    measured("IRLS", lambda: IRLS(robot=robot, preprocessing=pre).fit(system), res)
    cons = measured(
        "consistent (IPOPT)", lambda: ConsistentLS(robot=robot, preprocessing=pre).fit(system), res
    )
    print(f"  consistent: {cons.solver_['status']}, min eigenvalue {cons.min_eigenvalues_.min():.3g}")
    est = IRLS(robot=robot, preprocessing=pre).fit(system)
    rows = system.prepared.rows
    F_est = system.tau() - system.predict(est.params_, mask=system.columns.link_mask)
    dq_k, q_k = system.prepared.dq[rows], system.prepared.q[rows]
    layer = measured("friction (seed, 6 joints)", lambda: FrictionLayer(model="seed").fit(dq_k, F_est), res)
    resid = F_est - layer.predict(dq_k)
    measured("GMM (auto, own)", lambda: GMRCorrection().fit(np.hstack([q_k, dq_k]), resid), res)
    system.release()
    full = measured(
        "all three layers: identify()",
        lambda: identify(robot, train, method="irls", friction="seed", gmm="auto", preprocessing=pre),
        res,
    )
    rss1 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"process peak RSS {rss1:.0f} MiB (ru_maxrss; {rss1 - rss0:+.0f} MiB over the data set-up)")

    ols = identify(robot, train, method="ols", friction="linear", gmm="off", preprocessing=pre)

    def heldout(model) -> np.ndarray:
        ref = model.prepare(test).tau_reference
        return np.sqrt(np.mean((model.predict(test) - ref) ** 2, axis=0))

    r_full, r_ols = heldout(full), heldout(ols)
    prep = full.prepare(test)
    floor_noise = lowpass(
        np.random.default_rng(1).normal(size=(len(prep.t), robot.n)) * noise, fs=rate, cutoff=20.0
    )
    floor = np.sqrt(np.mean(floor_noise[prep.rows] ** 2, axis=0))
    print(f"held-out RMS per joint (N m), OLS + linear friction: {np.round(r_ols, 3)}")
    print(f"held-out RMS per joint (N m), full three layers:    {np.round(r_full, 3)}")
    print(f"noise floor (the 0.2 N m noise through the 20 Hz filter): {np.round(floor, 3)}")
    print(f"ratio full / OLS (mean over joints): {r_full.mean() / r_ols.mean():.3f}  (paper: 0.64)")
    print(f"full / noise floor (mean over joints): {r_full.mean() / floor.mean():.2f}")
    print(f"GMM active on joints: {np.flatnonzero(full.gmr.active_) + 1 if full.gmr is not None else []}")


if __name__ == "__main__":
    main()
