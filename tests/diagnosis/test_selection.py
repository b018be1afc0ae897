"""The forward selection of effects (dynid.diagnosis.selection) on a synthetic two-joint arm.

The data are linear in known columns (inertia, Coulomb, viscous and gravity per joint), with effects added
from the catalogue's own column builders and white noise of a known level, so that what the selection must
accept is known: one injected effect is accepted on its joint and closes its gap, an effect-free run accepts
nothing, ``max_effects`` caps the rounds.  Its helpers are tested on hand-made scored candidates:
``_acceptable`` (significance, closure, a delay shorter than a sample), ``_choose`` (the training footing's
figures, the simpler candidate) and ``_shown_accepted``.  No robot and no simulation: the file runs in a
second.
"""

from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from dynid.diagnosis.baseline import HeldOutBaseline, refit_baseline
from dynid.diagnosis.candidates import Candidate, enumerate_candidates
from dynid.diagnosis.fitting import losses, mse, predict
from dynid.diagnosis.result import RankedCandidate
from dynid.diagnosis.screening import TRAINING, Context, Scored
from dynid.diagnosis.selection import _acceptable, _choose, _shown_accepted, select
from dynid.diagnosis.settings import DiagnosisSettings
from tests.diagnosis.synthetic_arm import FS, SIGMA, X_TRUE, N
from tests.diagnosis.synthetic_arm import base_columns as _base_columns
from tests.diagnosis.synthetic_arm import side as _side
from tests.diagnosis.synthetic_arm import states as _states

EFFECTS = ("offset", "stribeck", "nonlinear_viscous", "delay")


def _stribeck(j, size, vs):
    def effect(q, dq):
        out = np.zeros_like(dq)
        out[:, j] = size * np.sign(dq[:, j]) * np.exp(-((np.abs(dq[:, j]) / vs) ** 2))
        return out

    return effect


def _offset(j, size):
    def effect(q, dq):
        out = np.zeros_like(dq)
        out[:, j] = size
        return out

    return effect


def _hum(j, size):
    """A torque that no column of the baseline or the catalogue holds: a sine in the sample index."""

    def effect(q, dq):
        out = np.zeros_like(dq)
        out[:, j] = size * np.sin(2 * np.pi * 3.1 / FS * np.arange(dq.shape[0]))
        return out

    return effect


def _problem(*effects, seed=3, seconds=20.0):
    """(ctx, base, held, groups): training and held-out runs of the arm with ``effects`` added."""
    rng = np.random.default_rng(seed)
    t = np.arange(round(seconds * FS)) / FS
    runs = []
    for k in range(2):
        q, dq, ddq = _states(t, 1.7 * k)
        y = np.einsum("mnk,k->mn", _base_columns(q, dq, ddq), X_TRUE) + SIGMA * rng.normal(size=(t.size, N))
        for effect in effects:
            y = y + effect(q, dq)
        runs.append((t, q, dq, ddq, y))
    (t, q, dq, ddq, y), ho_run = runs
    base = refit_baseline(SimpleNamespace(y=y, X0=_base_columns(q, dq, ddq), moving=np.ones_like(y)))
    tr, ho = _side(t, q, dq, ddq, y, base.x), _side(*ho_run, base.x)
    sigma = np.full(N, SIGMA)
    r = ho.y - predict(ho.X0, base.x, None, None)
    held = HeldOutBaseline(r, losses(r, sigma, ho.moving), mse(r, ho.moving), mse(r, ho.moving))
    ctx = Context(tr=tr, ho=ho, sigma=sigma, block=20, mask=ho.moving, min_delay=1 / FS)
    return ctx, base, held, enumerate_candidates(tr.src, EFFECTS)


def _select(problem, significant=(True, True), **settings):
    ctx, base, held, groups = problem
    return select(ctx, base, held, groups, DiagnosisSettings(**settings), np.array(significant))


# ---------------------------------------------------------------------------- select
def test_one_injected_effect_is_accepted_on_its_joint_and_closes_its_gap():
    problem = _problem(_stribeck(1, 0.3, 0.1))
    held = problem[2]
    assert held.mse[1] / SIGMA**2 > 2.0  # the gap the effect makes (the other joint is at the floor)
    sel = _select(problem)
    assert [a.candidate.key for a in sel.accepted] == ["stribeck@2"]
    (acc,) = sel.accepted
    assert acc.accepted and acc.significant and acc.p_holm < 0.05 and acc.closure > 0.9
    # refined to the injected Stribeck speed (the tuned grid's nearest is 0.8 of it or 1.6 times)
    assert acc.candidate.hyper["vs"] == pytest.approx(0.1, rel=0.05)
    # the model with it is back at the noise floor on its joint; the held-out residual is the new model's
    assert sel.mse[1] / SIGMA**2 == pytest.approx(1.0, abs=0.1)
    assert sel.residual is not held.residual
    np.testing.assert_allclose(sel.mse, mse(sel.residual, problem[0].mask))
    # round 0's ranking holds every candidate once, best first, the accepted one marked
    assert len(sel.ranking) == len(problem[3])
    assert sel.ranking[0].candidate.key == "stribeck@2" and sel.ranking[0].accepted
    assert [r.candidate.key for r in sel.ranking if r.accepted] == ["stribeck@2"]
    gains = [r.gain for r in sel.ranking]
    assert gains == sorted(gains, reverse=True)


def test_an_effect_free_run_accepts_nothing_and_keeps_the_baseline():
    problem = _problem()
    sel = _select(problem)
    assert sel.accepted == []
    assert not any(r.significant for r in sel.ranking)
    # the baseline's own held-out figures, unchanged
    held = problem[2]
    assert sel.residual is held.residual and sel.loss is held.loss
    np.testing.assert_array_equal(sel.mse, held.mse)


def test_max_effects_caps_the_accepted_effects():
    """Two effects: the one that mends the arm most first, the next in the second round; a cap of one
    accepts only the first, a cap of zero only ranks."""
    problem = _problem(_stribeck(1, 0.3, 0.1), _offset(0, 0.1))
    both = _select(problem, max_effects=3)
    assert [a.candidate.key for a in both.accepted] == ["offset@1", "stribeck@2"]
    assert [a.round for a in both.accepted] == [0, 1]
    np.testing.assert_allclose(both.mse / SIGMA**2, 1.0, atol=0.1)
    one = _select(problem, max_effects=1)
    assert [a.candidate.key for a in one.accepted] == ["offset@1"]
    assert one.mse[1] == pytest.approx(problem[2].mse[1], rel=0.01)  # joint 2's gap left
    none = _select(problem, max_effects=0)
    assert none.accepted == [] and len(none.ranking) == len(problem[3])
    assert {r.candidate.key for r in none.ranking if r.significant} >= {"offset@1", "stribeck@2"}


def test_a_candidate_must_close_half_the_gap_where_its_joint_shows_no_significant_excess():
    """min_closure 0.2: an offset that closes about 0.4 of joint 1's gap (the rest is a hum no column
    holds) is accepted when that joint's excess is significant, not when it is not."""
    problem = _problem(_offset(0, 0.04), _hum(0, 0.08), seed=5)
    ctx, base, held, groups = problem
    groups = [g for g in groups if g[0].effect == "offset"]
    settings = {"min_closure": 0.2, "max_effects": 1}
    on = select(ctx, base, held, groups, DiagnosisSettings(**settings), np.array([True, False]))
    (acc,) = on.accepted
    assert acc.candidate.key == "offset@1" and 0.3 <= acc.closure < 0.47
    off = select(ctx, base, held, groups, DiagnosisSettings(**settings), np.array([False, False]))
    assert off.accepted == []


# ---------------------------------------------------------------------------- helpers
def _scored(
    effect, joint, *, closure=0.9, significant=True, n_columns=1, gain_all=1.0, loss=None, refit=None
):
    cand = Candidate(effect, joint, (joint,), {}, f"{effect} on joint {joint + 1}")
    loss = np.zeros((400, N)) if loss is None else loss
    rc = RankedCandidate(
        candidate=cand,
        gain=1.0,
        closure=closure,
        p_value=1e-6,
        p_holm=1e-5 if significant else 0.5,
        significant=significant,
        n_columns=n_columns,
        gain_all=gain_all,
        loss=loss,
        refit=refit or {},
    )
    C = np.zeros((400, N, n_columns))
    return Scored(ranked=rc, C_tr=C, C_ho=C, losses={TRAINING: loss})


def _ctx(min_delay=0.005):
    return SimpleNamespace(tr=SimpleNamespace(y=np.zeros((400, N))), min_delay=min_delay, block=20)


def test_acceptable_keeps_the_significant_candidates_that_close_enough():
    settings = DiagnosisSettings(min_closure=0.3)
    current = SimpleNamespace(fit=None)
    good = _scored("offset", 0, closure=0.9)
    weak = _scored("offset", 1, closure=0.2)  # below min_closure
    insignificant = _scored("armature", 0, closure=0.95, significant=False)
    partial = _scored("stribeck", 1, closure=0.4)  # above min_closure, below one half
    scored = [good, weak, insignificant, partial]
    ok, notes = _acceptable(_ctx(), current, scored, settings, np.array([True, True]))
    assert ok == [good, partial] and notes == []
    # where the joint shows no significant excess, half the gap must close
    ok, _ = _acceptable(_ctx(), current, scored, settings, np.array([True, False]))
    assert ok == [good]


def test_a_delay_shorter_than_a_sample_is_noted_not_accepted():
    settings = DiagnosisSettings()
    short = _scored("delay", 0, refit={"effective": {"d": 0.002}})
    long = _scored("delay", 1, refit={"effective": {"d": -0.008}})  # a lead counts by its size
    ok, notes = _acceptable(_ctx(0.005), SimpleNamespace(fit=None), [short, long], settings, np.ones(N, bool))
    assert ok == [long]
    (note,) = notes
    assert note.startswith("delay on joint 1: a timing mismatch of 2 ms, shorter than one sample (5 ms)")


def test_choose_compares_the_candidates_on_the_training_footing():
    """The cross-fitted footing decided the first candidate with the larger gain over the arm; on the
    training footing the second mends more, and it is chosen."""
    a = _scored("offset", 0, gain_all=5.0, refit={"footing": {TRAINING: {"gain_all": 1.0}}})
    b = _scored("stribeck", 1, gain_all=2.0, refit={"footing": {TRAINING: {"gain_all": 2.0}}})
    assert _choose(_ctx(), [a, b], DiagnosisSettings()) is b
    # recorded on no footing: a candidate's own figure
    c = _scored("offset", 0, gain_all=3.0)
    assert _choose(_ctx(), [b, c], DiagnosisSettings()) is c


def test_choose_prefers_a_simpler_candidate_the_best_does_not_beat_significantly(rng):
    m = 400
    noise = rng.chisquare(1, size=(m, N))
    rich = _scored("nonlinear_viscous", 0, n_columns=2, gain_all=1.05, loss=noise)
    # the simpler one: the same loss with a little noise of its own, a slightly smaller gain
    close = noise + 0.02 * rng.normal(size=(m, N))
    simple = _scored("stribeck", 0, n_columns=1, gain_all=1.0, loss=close)
    assert _choose(_ctx(), [rich, simple], DiagnosisSettings()) is simple
    # a simpler candidate that the best beats by far is not taken
    worse = _scored("stribeck", 0, n_columns=1, gain_all=1.0, loss=noise + 1.0)
    assert _choose(_ctx(), [rich, worse], DiagnosisSettings()) is rich
    # a simpler candidate on another joint is no alternative
    other = _scored("stribeck", 1, n_columns=1, gain_all=1.0, loss=close)
    assert _choose(_ctx(), [rich, other], DiagnosisSettings()) is rich


def test_the_ranking_shows_the_accepted_candidate():
    chosen = _scored("offset", 0).ranked
    other = _scored("stribeck", 1).ranked
    same_key = replace(_scored("offset", 0).ranked, gain=0.5)
    accepted = replace(chosen, accepted=True, refit={"kept": "screen columns"})
    shown = _shown_accepted([chosen, other, same_key], chosen, accepted, replaced=False)
    assert shown[0] is accepted  # as chosen, with its refit note
    assert shown[1] is other and not other.accepted
    assert shown[2].accepted and shown[2].gain == 0.5
    # replaced by a refit: the entry keeps its round-0 figures and is marked
    refit = replace(chosen, gain=3.0, accepted=True)
    shown = _shown_accepted([chosen, other], chosen, refit, replaced=True)
    assert shown[0] is not refit and shown[0].accepted and shown[0].gain == chosen.gain
