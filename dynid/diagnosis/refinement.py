"""Nonlinear refinement of the candidates whose parameters the screen's columns only approximate.

Elasticity, backlash and delay are not linear in their parameters: the screen scores their first-order
columns, which recover only part of what they cause.  :func:`refine` fits their physical parameters by
least squares on the training data (variable projection: the baseline and the column's coefficient are
solved for at every step), and the continuous hyper-parameters of the others (Stribeck velocity,
cogging's gear ratio, the warm-up time constant); backlash by a grid over the reversal threshold and
crossing time of a relay on the links' torque.  :func:`refine_leaders` refines the leading not-LIP
candidates before the choice, so that they are compared with the others on their refit;
:func:`fitted_delay` is the delay a scored delay candidate stands for.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from numpy.typing import NDArray
from scipy import optimize

from dynid.diagnosis.candidates import Candidate
from dynid.diagnosis.fitting import WeightedFit
from dynid.diagnosis.result import RankedCandidate
from dynid.diagnosis.screening import Context, Current, Scored, on_training, score

__all__ = ["KEPT", "fitted_delay", "refine", "refine_leaders"]

KEPT = "screen columns (the refit did not lower the held-out loss)"
"""Why a refit candidate keeps its screen columns."""

_NONLINEAR = ("elasticity", "backlash", "delay")
_LEADERS = 4


def fitted_delay(ctx: Context, fit: WeightedFit, rc: RankedCandidate, C_tr: NDArray[np.float64]) -> float:
    """The delay (s) of a scored delay candidate ``rc`` with training columns ``C_tr``: its refit's, else
    the first-order estimate.

    A delay shorter than one sample of the recording is not told apart from the state estimation's own
    errors: central differences and the zero-order hold of a sampled drive already shift torque against
    states by about half a sample (effect-free simulated UR5s gave 'delays' of 0.3-0.7 ms at 1 kHz,
    closing 55-60 % of a gap below the significance level).
    """
    d = (rc.refit.get("effective") or {}).get("d")
    return _first_order_delay(ctx, fit, rc.candidate, C_tr) if d is None else float(d)


def refine_leaders(ctx: Context, current: Current, scored: list[Scored]) -> list[Scored]:
    """Refit the leading not-LIP candidates (elasticity, backlash, delay) before the choice.

    Their first-order columns recover only part of what they cause, so they are compared with the
    others on their nonlinear refit (on training data; held-out data only score it, on the footings of
    :func:`~dynid.diagnosis.screening.score`).  The list keeps its order; the refit is kept when it
    gains more on the training footing (the one candidates are compared on,
    :func:`~dynid.diagnosis.screening.on_training`).
    """
    order = sorted(range(len(scored)), key=lambda i: -scored[i].ranked.gain)
    leaders = [i for i in order if scored[i].ranked.candidate.effect in _NONLINEAR][:_LEADERS]
    out = list(scored)
    for i in leaders:
        out[i] = _refined_leader(ctx, current, scored[i])
    return out


def _refined_leader(ctx: Context, current: Current, s: Scored) -> Scored:
    """A leader scored on its refit when that gains more on the training footing, else on the screen's
    columns; either way with the refit's account in ``refit``."""
    rc = s.ranked
    cand, C_tr2, C_ho2, info = refine(ctx, current.fit, rc.candidate, s.C_tr)
    s2 = score(ctx, current, cand, C_tr2, C_ho2)
    if on_training(s2.ranked, "gain") > on_training(rc, "gain"):
        return replace(s2, ranked=replace(s2.ranked, refit={**s2.ranked.refit, **info}))
    return replace(s, ranked=replace(rc, refit={**rc.refit, **info, "kept": KEPT}))


def refine(ctx: Context, fit: WeightedFit, cand: Candidate, C_tr):
    """Refit an accepted candidate's nonlinear parameters by least squares on the training data."""
    e = cand.effect
    specs: dict[str, tuple[list[str], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]] = {}
    if e == "delay":
        specs["delay"] = (
            ["d"],
            np.array([_first_order_delay(ctx, fit, cand, C_tr)]),
            np.array([-0.05]),
            np.array([0.05]),
        )
    elif e == "elasticity":
        # Start from the first-order compliance c = 1 / (m w^2) when it is positive, else 15 Hz.
        c0 = _first_order_compliance(ctx, fit, cand, C_tr)
        m = float(np.median(ctx.tr.src.mass_column(cand.joint)[:, cand.joint]))
        w0 = math.sqrt(1.0 / (m * c0)) if c0 > 0 else 2 * math.pi * 15.0
        w0 = float(np.clip(w0, 2 * math.pi * 3.0, 2 * math.pi * 100.0))
        specs[e] = (
            ["w", "z"],
            np.array([w0, 0.1]),
            np.array([2 * math.pi * 2.0, 0.005]),
            np.array([2 * math.pi * 150.0, 1.0]),
        )
    elif e == "backlash":
        return _refine_backlash(ctx, fit, cand)
    elif e == "stribeck":
        v = cand.hyper["vs"]
        specs[e] = (["vs"], np.array([v]), np.array([v / 8]), np.array([v * 8]))
    elif e == "cogging":
        N = cand.hyper["N"]
        specs[e] = (["N"], np.array([N]), np.array([N - 1.0]), np.array([N + 1.0]))
    elif e == "temperature":
        T = cand.hyper["T"]
        specs[e] = (["T"], np.array([T]), np.array([T / 10]), np.array([T * 10]))
    if e not in specs:
        return cand, C_tr, ctx.ho.columns(cand), {"method": "linear least squares (no nonlinear parameter)"}
    names, x0, lo, hi = specs[e]
    if e == "elasticity":
        # The resonance makes the loss multimodal in w: start from the best of a coarse grid.
        grid = [2 * math.pi * f for f in (4.0, 7.0, 12.0, 20.0, 35.0, 60.0)] + [float(x0[0])]

        def rss(w: float) -> float:
            C = ctx.tr.columns(replace(cand, hyper={**cand.hyper, "w": w, "z": 0.1, "exact": 1.0}))
            return float(np.sum(fit.varpro_residual(C) ** 2))

        x0 = np.array([min(grid, key=rss), 0.1])
    x0 = np.clip(x0, lo + 1e-12 * np.abs(lo), hi - 1e-12 * np.abs(hi))
    scale = np.maximum(np.abs(x0), (hi - lo) * 1e-3)

    def make(theta) -> Candidate:
        hyper = dict(cand.hyper)
        hyper.update({k: float(v) for k, v in zip(names, theta, strict=True)})
        if e in ("elasticity", "backlash", "delay"):
            hyper["exact"] = 1.0
        return replace(cand, hyper=hyper)

    def resid(z):
        theta = z * scale
        return fit.varpro_residual(ctx.tr.columns(make(theta)))

    try:
        sol = optimize.least_squares(
            resid, x0 / scale, bounds=(lo / scale, hi / scale), x_scale=1.0, diff_step=1e-3, max_nfev=40
        )
        theta = sol.x * scale
        info = {
            "method": "nonlinear least squares (scipy.optimize.least_squares, variable projection)",
            "parameters": {k: float(v) for k, v in zip(names, theta, strict=True)},
            "evaluations": int(sol.nfev),
        }
    except (ValueError, np.linalg.LinAlgError) as err:  # pragma: no cover - defensive
        return cand, C_tr, ctx.ho.columns(cand), {"method": f"refit failed ({err}); screen columns kept"}
    best = make(theta)
    C_best = ctx.tr.columns(best)
    if e in ("elasticity", "backlash", "delay"):
        # The column's coefficient is free: (theta, beta) and (-theta, -beta) fit alike to first order,
        # so the physical value is theta times the coefficient.
        _, beta, _ = fit.solve(C_best)
        coef = float(beta[0]) if beta.size else 1.0
        info["coefficient"] = coef
        info["effective"] = {k: float(v) * coef for k, v in zip(names, theta, strict=True) if k != "eps"}
        if e == "elasticity":
            w = float(theta[0])
            m = float(np.median(ctx.tr.src.mass_column(cand.joint)[:, cand.joint]))
            info["effective"] = {"w": w, "z": float(theta[1])}
            info["frequency_hz"] = w / (2 * math.pi)
            info["at_bound"] = bool(w >= 0.99 * hi[0] or w <= 1.01 * lo[0])
            info["stiffness"] = m * w * w
            info["units"] = "w in rad/s, stiffness in N m/rad (with the median M_jj)"
        else:
            info["units"] = "d in s"
    return best, C_best, ctx.ho.columns(best), info


_BACKLASH_H = (0.0, 0.04, 0.08, 0.12, 0.16, 0.24)  # reversal thresholds, in torque standard deviations
_BACKLASH_D = (0.0, 0.004, 0.008, 0.012, 0.016, 0.02, 0.025, 0.03, 0.04)  # crossing times (s)
_SPRING_W = tuple(2 * math.pi * f for f in (7.0, 12.0, 20.0, 35.0, 60.0))  # the teeth's spring (rad/s)
_SPRING_Z = (0.05, 0.3, 1.0)  # its damping ratio


def _refine_backlash(ctx: Context, fit: WeightedFit, cand: Candidate):
    """Refit a dead zone in a stiff transmission: the teeth change sides when the transmitted torque has
    reversed beyond a threshold, a crossing time later, and deflect like a spring while they touch.

    The spring first (its natural frequency and damping ratio by a coarse grid, then least squares, with
    the sides changing at every reversal), then the dead zone's threshold and crossing time with the
    spring held (grid, then the time by a bounded scalar search); the half gap and the stiffness are the
    columns' coefficients.  All on the training data, by variable projection.

    A smooth dead zone (``tanh(tau / eps)``) misses the timing: the impacts and the link's swing make the
    transmitted torque hover about zero, and the motor takes a few milliseconds to cross the gap (a
    simulated 0.26 mrad gap on a UR5 wrist: 0.40 of the gap closed smoothly, 0.82 with the relay).  The
    teeth's stiffness matters as much where the gap is narrow: a 0.32 mrad gap in a 23 kN m/rad
    transmission on a UR5's base joint deflects up to 0.5 mrad, most of it in the spring, and the relay
    alone closed 0.41 of that gap (the screen's columns), a spring alone 0.49, the two 0.56.
    """
    a = 1e-4  # rad: the relay column's scale; its coefficient gives the half gap
    base = {**cand.hyper, "a": a, "exact": 1.0}

    def rss(hyper: dict) -> float:
        return float(np.sum(fit.varpro_residual(ctx.tr.columns(replace(cand, hyper=hyper))) ** 2))

    springs = {
        (w, z): rss({**base, "h": 0.0, "d": 0.0, "w": w, "z": z}) for w in _SPRING_W for z in _SPRING_Z
    }
    w0, z0 = min(springs, key=springs.get)
    sol = optimize.least_squares(
        lambda x: fit.varpro_residual(
            ctx.tr.columns(replace(cand, hyper={**base, "h": 0.0, "d": 0.0, "w": x[0] * w0, "z": x[1]}))
        ),
        np.array([1.0, z0]),
        bounds=([0.5, 0.005], [2.0, 1.0]),
        diff_step=1e-3,
        max_nfev=20,
    )
    spring = {"w": float(sol.x[0] * w0), "z": float(sol.x[1])}
    evaluations = len(springs) + int(sol.nfev)

    def make(h: float, d: float) -> Candidate:
        return replace(cand, hyper={**base, "h": h, "d": d, **spring})

    grid = {(h, d): rss(make(h, d).hyper) for h in _BACKLASH_H for d in _BACKLASH_D}
    h, d = min(grid, key=grid.get)
    step = 0.005
    sol = optimize.minimize_scalar(
        lambda x: rss(make(h, x).hyper),
        bounds=(max(0.0, d - step), d + step),
        method="bounded",
        options={"xatol": 5e-4},
    )
    if sol.fun < grid[(h, d)]:
        d = float(sol.x)
    best = make(h, d)
    C_best = ctx.tr.columns(best)
    _, beta, _ = fit.solve(C_best)
    coef = float(beta[0]) if beta.size else 1.0
    s = max(float(np.std(ctx.tr.src.transmitted(cand.joint))), 1e-12)
    m = float(np.median(ctx.tr.src.mass_column(cand.joint)[:, cand.joint]))
    info = {
        "method": "spring by a grid and least squares, then a grid over the reversal threshold and crossing "
        "time and a bounded search of the time, on the training data (variable projection)",
        "parameters": {"h": h * s, "d": d, "a": a, **spring},
        "evaluations": evaluations + len(grid) + int(sol.nfev),
        "coefficient": coef,
        "effective": {"a": abs(a * coef), "h": h * s, "d": d, **spring},
        "frequency_hz": spring["w"] / (2 * math.pi),
        "stiffness": m * spring["w"] ** 2,
        "units": "a (half the gap) in rad, h in N m, d in s, stiffness in N m/rad (with the median M_jj), "
        "w in rad/s",
    }
    return best, C_best, ctx.ho.columns(best), info


def _first_order_delay(ctx, fit, cand, C_tr) -> float:
    _, beta, _ = fit.solve(C_tr)
    # tau(t - d) - tau(t) ~ -d dtau/dt: the coefficient of dtau/dt is -d.
    return float(np.clip(-beta[0], -0.04, 0.04)) if beta.size else 0.0


def _first_order_compliance(ctx, fit, cand, C_tr) -> float:
    _, beta, _ = fit.solve(C_tr)
    # tau(q - c tau_j e_j) ~ tau - M[:, j] c d2tau_j/dt2: the coefficient of the screen column is -c.
    return float(-beta[0]) if beta.size else 0.0
