"""The helpers the diagnosis and the fleet share instead of keeping twins.

* one Holm correction (:func:`dynid.diagnosis.stats.holm`), which the fleet's drift tests import;
* one bootstrap loop (:func:`dynid.diagnosis.stats.bootstrap_null`) behind the parameter-consistency and
  the lack-of-fit tests;
* one simulation of a case's two runs (:func:`dynid.diagnosis.cases.simulate_runs`) behind the lab and
  the field cases;
* the selection's named records (:class:`dynid.diagnosis.screening.Scored`): the simpler-candidate test
  reads a candidate's training-footing losses by name.
"""

from __future__ import annotations

import numpy as np
import pytest

from dynid.diagnosis import stats as st
from dynid.diagnosis.result import RankedCandidate
from dynid.diagnosis.screening import CROSS, TRAINING, Scored, parsimonious
from dynid.identify.effect_terms import Candidate


def _step_down(p: np.ndarray) -> np.ndarray:
    """Holm written the other way round (the fleet's former copy): a running maximum of ``(m - i) p_(i)``
    over the sorted p-values, capped at 1 afterwards."""
    m = p.size
    if m == 0:
        return p.copy()
    order = np.argsort(p, kind="stable")
    out = np.empty(m)
    out[order] = np.minimum(np.maximum.accumulate((m - np.arange(m)) * p[order]), 1.0)
    return out


def test_the_fleet_adjusts_with_the_diagnosis_holm(rng):
    from dynid.fleet import drift

    assert drift.holm is st.holm
    for k in [0, 1, 2, 3, 7, 40, 300]:
        for _ in range(20):
            p = rng.uniform(0.0, 1.0, k) ** rng.uniform(0.2, 5.0)
            if k:
                p[rng.integers(0, k, max(1, k // 3))] = np.round(p[0], 1)  # ties
                p[rng.integers(0, k, 1)] = 0.0
                p[rng.integers(0, k, 1)] = 1.0
            np.testing.assert_array_equal(st.holm(p), _step_down(p))  # to the last bit
    np.testing.assert_array_equal(st.holm([0.01, 0.04, 0.03, 0.5]), [0.04, 0.09, 0.09, 0.5])


@pytest.mark.parametrize(("draws", "chunk", "calls"), [(60, 25, [25, 25, 10]), (7, 25, [7]), (50, 25, [25, 25])])
def test_the_bootstrap_null_is_drawn_a_chunk_at_a_time_in_order(draws, chunk, calls):
    made = []
    rng = np.random.default_rng(5)

    def statistic(d: int) -> np.ndarray:
        made.append(d)
        return rng.standard_normal((d, 3)).T  # one column per draw

    null = st.bootstrap_null(statistic, draws, chunk=chunk)
    assert made == calls
    assert null.shape == (3, draws)
    np.testing.assert_array_equal(null, np.random.default_rng(5).standard_normal((draws, 3)).T)


def test_both_runs_of_a_case_carry_the_same_effects(ur5):
    from dynid.diagnosis.cases import simulate_runs, truth_labels
    from dynid.sim.cases import case_excitation

    runs = simulate_runs(
        ur5,
        ["stribeck@3:0.05", "delay:0.004"],
        case_excitation(ur5, 2, base_freq=0.5),
        case_excitation(ur5, 3, base_freq=0.5),
        level=1.0,
        seed=1,
        calibration_seconds=2.0,
        train_seconds=2.0,
        heldout_seconds=2.0,
        friction="linear",
        armature=True,
    )
    assert runs.specs == ["stribeck@3:0.05", "delay:0.004"]
    assert runs.values == [0.05, 0.004]
    assert np.isnan(runs.achieved).all()  # values given: nothing calibrated
    assert (runs.train.seed, runs.heldout.seed) == (1, 100_001)
    assert [e.to_dict() for e in runs.heldout.truth.effects] == [e.to_dict() for e in runs.train.truth.effects]
    assert runs.train.t[-1] == pytest.approx(2.0, abs=0.01) and runs.heldout.t[-1] == pytest.approx(2.0, abs=0.01)
    assert truth_labels(runs.specs, ("delay",)) == [("unknown:stribeck", 3), ("delay", None)]


def _scored(n_columns: int, training: np.ndarray, decided: np.ndarray, C: np.ndarray) -> Scored:
    cand = Candidate("armature" if n_columns == 1 else "elasticity", 2, (2,), label=f"{n_columns} columns")
    ranked = RankedCandidate(candidate=cand, gain=1.0, closure=0.9, p_value=1e-6, loss=decided, n_columns=n_columns)
    return Scored(ranked=ranked, C_tr=C, C_ho=C, losses={TRAINING: training, CROSS: decided})


def test_the_simpler_candidate_test_compares_the_training_footings(rng):
    m, n = 2000, 4
    big = rng.standard_normal((m, n, 2))
    small = big[:, :, :1]  # nested in the richer candidate's columns
    even = rng.chisquare(1, (m, n))
    better = 0.5 * rng.chisquare(1, (m, n))
    # Decided on the cross-fitted footing, the richer one looks far better; on the training footing, the
    # one candidates are compared on, the two are alike: the simpler one is kept.
    rich = _scored(2, training=even, decided=better, C=big)
    simple = _scored(1, training=even.copy(), decided=even, C=small)
    assert parsimonious([rich, simple], 0.05, 50, 0.1) is simple
    # Better on the training footing too: the richer one stays.
    rich = _scored(2, training=better, decided=better, C=big)
    assert parsimonious([rich, simple], 0.05, 50, 0.1) is rich
