"""The nonlinear refinement of candidates (dynid.diagnosis.refinement) on the synthetic arm of
``test_selection``: a torque delayed by a known time, a Stribeck friction of a known speed.

``fitted_delay`` reads the refit's delay, else the first-order column's; ``refine`` recovers the delay and
the Stribeck speed from a start off the truth (better than the first-order estimate for a long delay);
``refine_leaders`` refits only the leading nonlinear candidates and keeps the list's order.
"""

from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from dynid.diagnosis.baseline import refit_baseline
from dynid.diagnosis.candidates import Candidate
from dynid.diagnosis.fitting import losses, mse, predict
from dynid.diagnosis.refinement import _LEADERS, KEPT, fitted_delay, refine, refine_leaders
from dynid.diagnosis.result import RankedCandidate
from dynid.diagnosis.screening import Context, Current, score
from tests.diagnosis.synthetic_arm import FS, SIGMA, X_TRUE, N
from tests.diagnosis.synthetic_arm import base_columns as _base_columns
from tests.diagnosis.synthetic_arm import side as _side
from tests.diagnosis.synthetic_arm import states as _states


def _context(effect, *, seed=1, seconds=20.0):
    """(ctx, current): training and held-out runs whose torque is ``effect(t, phase)`` (m, n) plus noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(round(seconds * FS)) / FS
    runs = []
    for k in range(2):
        q, dq, ddq = _states(t, 1.7 * k)
        runs.append((t, q, dq, ddq, effect(t, 1.7 * k) + SIGMA * rng.normal(size=(t.size, N))))
    (t, q, dq, ddq, y), ho_run = runs
    base = refit_baseline(SimpleNamespace(y=y, X0=_base_columns(q, dq, ddq), moving=np.ones_like(y)))
    tr, ho = _side(t, q, dq, ddq, y, base.x), _side(*ho_run, base.x)
    sigma = np.full(N, SIGMA)
    ctx = Context(tr=tr, ho=ho, sigma=sigma, block=20, mask=ho.moving, min_delay=1 / FS)
    r = ho.y - predict(ho.X0, base.x, None, None)
    empty = np.zeros((t.size, N, 0))
    current = Current(base.fit, empty, empty, r, losses(r, sigma, ho.moving), mse(r, ho.moving))
    return ctx, current


def _torque(t, phase):
    return np.einsum("mnk,k->mn", _base_columns(*_states(t, phase)), X_TRUE)


def _delayed(d, j=0):
    """The torque of joint j measured ``d`` seconds late: tau_j(t - d)."""

    def effect(t, phase):
        y = _torque(t, phase)
        y[:, j] = _torque(t - d, phase)[:, j]
        return y

    return effect


def _with_stribeck(vs, size=0.3, j=1):
    def effect(t, phase):
        dq = _states(t, phase)[1][:, j]
        y = _torque(t, phase)
        y[:, j] += size * np.sign(dq) * np.exp(-((np.abs(dq) / vs) ** 2))
        return y

    return effect


DELAY = Candidate("delay", 0, (0,), {}, "delay on joint 1")


@pytest.mark.parametrize("d", [0.01, -0.006])
def test_fitted_delay_reads_the_first_order_column(d):
    """Without a refit, the delay is minus the coefficient of d tau / dt: of either sign, to a few %."""
    ctx, current = _context(_delayed(d))
    C = ctx.tr.columns(DELAY)
    rc = RankedCandidate(DELAY, gain=1.0, closure=1.0, p_value=0.0)
    assert fitted_delay(ctx, current.fit, rc, C) == pytest.approx(d, rel=0.08)


def test_fitted_delay_reads_the_refit_when_there_is_one():
    ctx, current = _context(_delayed(0.01))
    C = ctx.tr.columns(DELAY)
    rc = RankedCandidate(DELAY, gain=1.0, closure=1.0, p_value=0.0, refit={"effective": {"d": 0.0123}})
    assert fitted_delay(ctx, current.fit, rc, C) == 0.0123


def test_refine_recovers_a_long_delay_that_the_first_order_column_underestimates():
    d = 0.02
    ctx, current = _context(_delayed(d))
    C = ctx.tr.columns(DELAY)
    first = fitted_delay(ctx, current.fit, RankedCandidate(DELAY, 1.0, 1.0, 0.0), C)
    best, C_tr, C_ho, info = refine(ctx, current.fit, DELAY, C)
    assert best.effect == "delay" and best.hyper["exact"] == 1.0
    assert info["units"] == "d in s" and info["method"].startswith("nonlinear least squares")
    # the physical delay is the column's delay times its coefficient
    assert info["effective"]["d"] == pytest.approx(info["parameters"]["d"] * info["coefficient"])
    assert info["effective"]["d"] == pytest.approx(d, rel=0.05)
    assert abs(info["effective"]["d"] - d) < 0.5 * abs(first - d)  # the first order is 20 % short
    assert (
        fitted_delay(ctx, current.fit, replace(RankedCandidate(DELAY, 1.0, 1.0, 0.0), refit=info), C)
        == (info["effective"]["d"])
    )
    # the columns returned are the refined candidate's, on both sides
    np.testing.assert_array_equal(C_tr, ctx.tr.columns(best))
    np.testing.assert_array_equal(C_ho, ctx.ho.columns(best))
    # and fit the training data better than the first-order column
    assert np.sum(current.fit.varpro_residual(C_tr) ** 2) < np.sum(current.fit.varpro_residual(C) ** 2)


def test_refine_moves_a_stribeck_speed_to_the_truth():
    ctx, current = _context(_with_stribeck(0.1))
    start = Candidate("stribeck", 1, (1,), {"vs": 0.2}, "stribeck on joint 2")
    best, _, _, info = refine(ctx, current.fit, start, ctx.tr.columns(start))
    assert best.hyper["vs"] == pytest.approx(0.1, rel=0.03)
    assert info["parameters"]["vs"] == best.hyper["vs"]
    assert "exact" not in best.hyper  # a linear column: no coefficient folded in


def test_a_linear_candidate_is_not_refined():
    ctx, current = _context(_with_stribeck(0.1))
    offset = Candidate("offset", 1, (1,), {}, "offset on joint 2")
    C = ctx.tr.columns(offset)
    best, C_tr, C_ho, info = refine(ctx, current.fit, offset, C)
    assert best is offset and C_tr is C and info["method"].startswith("linear least squares")
    np.testing.assert_array_equal(C_ho, ctx.ho.columns(offset))


def test_refine_leaders_refits_only_the_leading_nonlinear_candidates_in_place():
    ctx, current = _context(_delayed(0.02))
    cands = [
        Candidate("offset", 0, (0,), {}, "offset on joint 1"),
        DELAY,
        Candidate("stribeck", 1, (1,), {"vs": 0.2}, "stribeck on joint 2"),
    ]
    scored = [score(ctx, current, c, ctx.tr.columns(c), ctx.ho.columns(c)) for c in cands]
    out = refine_leaders(ctx, current, scored)
    assert [s.ranked.candidate.key for s in out] == ["offset@1", "delay@1", "stribeck@2"]
    assert out[0] is scored[0] and out[2] is scored[2]  # not nonlinear: untouched
    refit = out[1].ranked
    assert refit.refit["method"].startswith("nonlinear least squares") and "kept" not in refit.refit
    assert refit.candidate.hyper["exact"] == 1.0 and refit.gain > scored[1].ranked.gain
    # at most _LEADERS are refitted, those with the largest gain
    copies = [replace(scored[1], ranked=replace(scored[1].ranked, gain=g)) for g in range(_LEADERS + 1)]
    out = refine_leaders(ctx, current, copies)
    assert out[0] is copies[0]
    assert all(s is not c and "method" in s.ranked.refit for s, c in zip(out[1:], copies[1:], strict=True))


def test_a_refit_that_gains_nothing_keeps_the_screen_columns():
    """No delay in the data: the exact column gains no more than d tau / dt; the screen's are kept, said so."""
    ctx, current = _context(_delayed(0.0))
    s = score(ctx, current, DELAY, ctx.tr.columns(DELAY), ctx.ho.columns(DELAY))
    (out,) = refine_leaders(ctx, current, [s])
    assert out.ranked.refit["kept"] == KEPT
    assert out.C_tr is s.C_tr and out.ranked.candidate is DELAY
