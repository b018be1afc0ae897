"""Speed, memory and accuracy of the three-layer identification (prints figures; not a test).

60 s at 1 kHz on the UR5 (60,000 samples, 360,000 stacked rows): torque from the regressor itself
plus the paper's nonlinear friction, a smooth unmodelled torque (0.3 sin(2 q_j + 0.5) N m on every
joint) and white noise (0.2 N m); joint angles with encoder-like noise, velocities and accelerations
left to preprocessing (20 Hz Butterworth, central differences, parallel filtering).  Held out: 20 s
of another random trajectory (seed 2024 here; the methods were developed on other seeds).

The baseline is the paper's (METHOD.md sections 1-2): OLS on the linear model ``tau = [H_b H_f] delta``
with linear friction, here Coulomb, viscous and an offset per joint identified with the base
parameters (the paper's ``kc sign(dq) + kv dq`` plus the offset every dynid linear model carries).

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
    from dynid.data.preparation import Preprocessing
    from dynid.data.preprocess import lowpass
    from dynid.identify.columns import column_set
    from dynid.identify.consistent import ConsistentLS
    from dynid.identify.estimators import IRLS, OLS
    from dynid.identify.friction import FrictionLayer, SeedFriction
    from dynid.identify.gmr import GMRCorrection
    from dynid.identify.linear_system import build_system
    from dynid.identify.model import identify
    from dynid.sim.synthetic import random_fourier, synthetic_dataset, true_parameters
    from dynid.symbolic import load_robot
    from dynid.validation.metrics import noise_floor

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

    def recording(periods: int):
        """A run of a new random trajectory, with the torque and noise above (angles only)."""
        return synthetic_dataset(
            cols,
            x,
            random_fourier(robot, rng, periods=periods),
            rate=rate,
            rng=rng,
            noise=noise,
            extra=extra,
            state_noise=1e-5,
            with_derivatives=False,
        )

    train = recording(6).select_rows(np.arange(60_000))
    test = recording(2)
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
        "consistent (barrier Newton)", lambda: ConsistentLS(robot=robot, preprocessing=pre).fit(system), res
    )
    print(
        f"  consistent: {cons.solver_['status']} in {cons.solver_['iterations']} Newton steps, "
        f"{cons.solver_['time_s']:.2f} s; min pseudo-inertia eigenvalue {cons.min_eigenvalues_.min():.3g}, "
        f"{cons.distance_['mahalanobis']:.4g} std from the unconstrained estimate"
    )
    est = IRLS(robot=robot, preprocessing=pre).fit(system)
    rows = system.prepared.rows
    F_est = system.tau() - system.predict(est.params_, mask=system.columns.link_mask)
    dq_k, q_k = system.prepared.dq[rows], system.prepared.q[rows]
    prep_t = system.prepared
    layer = measured(
        "friction (seed, 6 joints, filtered)",
        lambda: FrictionLayer(model="seed").fit(prep_t.dq, F_est, prepared=prep_t),
        res,
    )
    resid = F_est - prep_t.filter(layer.predict(prep_t.dq))[rows]
    measured(
        "GMM (auto, position)", lambda: GMRCorrection(mode="position").fit(np.hstack([q_k, dq_k]), resid), res
    )
    system.release()
    full = measured(
        "all three layers: identify()",
        lambda: identify(robot, train, method="irls", friction="seed", gmm="auto", preprocessing=pre),
        res,
    )
    sequence = measured(
        "the same in sequence (rounds=0)",
        lambda: identify(
            robot, train, method="irls", friction="seed", gmm="auto", preprocessing=pre, rounds=0
        ),
        res,
    )
    consistent = identify(robot, train, method="consistent", friction="seed", gmm="auto", preprocessing=pre)
    rss1 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"process peak RSS {rss1:.0f} MiB (ru_maxrss; {rss1 - rss0:+.0f} MiB over the data set-up)")

    # the paper's baseline: unconstrained least squares (no bounds, no consistency projection)
    ols = identify(
        robot, train, method="ols", friction="linear", gmm="off", preprocessing=pre, physical=False
    )

    def heldout(model) -> np.ndarray:
        ref = model.prepare(test).tau_reference
        return np.sqrt(np.mean((model.predict(test) - ref) ** 2, axis=0))

    r_full, r_ols, r_seq, r_cons = heldout(full), heldout(ols), heldout(sequence), heldout(consistent)
    prep = full.prepare(test)
    floor_noise = lowpass(
        np.random.default_rng(1).normal(size=(len(prep.t), robot.n)) * noise, fs=rate, cutoff=20.0
    )
    floor = np.sqrt(np.mean(floor_noise[prep.rows] ** 2, axis=0))
    # measured, not assumed: the white level of the raw held-out torque above 125 Hz, through the filter
    # (white noise of std s leaves it with std s / sqrt(kappa), kappa = 1 / sum h^2 of the filter)
    raw_floor = noise_floor(prep.t, prep.tau)
    floor_measured = raw_floor.std / np.sqrt(prep.noise_correlation)
    print("baseline: OLS on tau = [H_b H_f] delta, linear friction (Coulomb, viscous, offset) with the links")
    print(f"held-out RMS per joint (N m), OLS + linear friction:        {np.round(r_ols, 3)}")
    print(f"held-out RMS per joint (N m), three layers in sequence:     {np.round(r_seq, 3)}")
    print(f"held-out RMS per joint (N m), three layers fitted together: {np.round(r_full, 3)}")
    print(f"held-out RMS per joint (N m), the same, consistent links:   {np.round(r_cons, 3)}")
    print(f"noise floor (the 0.2 N m noise through the 20 Hz filter):   {np.round(floor, 3)}")
    print(
        f"noise floor measured (raw spectrum above 125 Hz, through the filter): {np.round(floor_measured, 3)}"
    )
    print(
        f"ratio to OLS (mean over joints): in sequence {r_seq.mean() / r_ols.mean():.3f}, fitted together "
        f"{r_full.mean() / r_ols.mean():.3f}, consistent {r_cons.mean() / r_ols.mean():.3f}  (paper: 0.64)"
    )
    print(
        f"full / noise floor (mean over joints): {r_full.mean() / floor.mean():.2f} "
        f"(measured floor: {r_full.mean() / floor_measured.mean():.2f})"
    )
    print(
        f"GMM active on joints: {np.flatnonzero(full.gmr.active_) + 1 if full.gmr is not None else []}, "
        f"sizes {full.gmr.n_components_ if full.gmr is not None else []}"
    )


if __name__ == "__main__":
    main()
