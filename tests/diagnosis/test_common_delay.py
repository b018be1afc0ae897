"""One delay on every joint reads as one finding: the common-delay candidate (``delay@all``).

The torques of many arms are stamped late against the angles by the same few milliseconds on every joint.
Screened joint by joint, that one cause was accepted on three joints (the cap of ``max_effects``) and left
the others at 4-10 times the floor.  The catalogue holds a delay common to all joints, one parameter for
the arm, beside the per-joint ones.
"""

from __future__ import annotations

import numpy as np
import pytest

from dynid.diagnosis.candidates import enumerate_candidates, excitation_hint
from dynid.exceptions import UsageError
from dynid.identify.effect_terms import (
    Candidate,
    FeatureSource,
    candidate_columns,
    common_term,
    parse_effect_terms,
)

TRUE_DELAY = 0.005  # s: delay:1.25 in the simulator's units (4 ms each)


def _source(robot, rng) -> FeatureSource:
    m, n = 400, robot.n
    t = np.arange(m) / 500.0
    tau = np.cumsum(rng.standard_normal((m, n)), axis=0)
    zeros = np.zeros((m, n))
    return FeatureSource(t=t, q=zeros, dq=zeros, ddq=zeros, tau_pred=tau, robot=robot, fs=500.0, runs=[slice(0, m)])


def test_the_common_delay_is_one_column_over_every_joint(ur5):
    src = _source(ur5, np.random.default_rng(3))
    common = common_term("delay", ur5.n)
    assert common.key == "delay@all"
    assert common.scored == tuple(range(ur5.n))
    for hyper in ({}, {"exact": 1.0, "d": 0.004}):
        C = candidate_columns(src, Candidate("delay", None, tuple(range(ur5.n)), hyper))
        assert C.shape == (src.m, ur5.n, 1)
        for j in range(ur5.n):
            per_joint = candidate_columns(src, Candidate("delay", j, (j,), hyper))
            np.testing.assert_allclose(C[:, j, 0], per_joint[:, j, 0], rtol=0, atol=1e-12)


def test_the_common_delay_is_written_and_read_as_delay_at_all(ur5):
    terms = parse_effect_terms("delay@all:d=0.004,delay@3", ur5.n)
    assert [t.key for t in terms] == ["delay@all", "delay@3"]
    assert terms[0].joint is None and terms[0].hyper["d"] == pytest.approx(0.004)
    with pytest.raises(UsageError, match="no form common to all joints"):
        parse_effect_terms("stribeck@all", ur5.n)
    with pytest.raises(UsageError, match="no form common to all joints"):
        common_term("drive_gain", ur5.n)


def test_the_catalogue_screens_one_common_delay_beside_the_per_joint_ones(ur5):
    src = _source(ur5, np.random.default_rng(4))
    groups = enumerate_candidates(src, ("delay",))
    keys = [g[0].key for g in groups]
    assert keys == [f"delay@{j + 1}" for j in range(ur5.n)] + ["delay@all"]
    assert "every joint" in excitation_hint(groups[-1][0])


@pytest.mark.slow
def test_a_delay_on_every_joint_is_one_common_delay_verdict(ur5):
    from dynid.diagnosis.cases import run_case

    case = run_case(ur5, [f"delay:{TRUE_DELAY / 0.004:g}"], level=3.0, seed=1)
    d = case["diagnosis"]
    assert d.verdict == ["delay"]
    [accepted] = d.accepted
    assert accepted.candidate.key == "delay@all"
    assert accepted.refit["effective"]["d"] == pytest.approx(TRUE_DELAY, abs=0.001)
    # one finding closes the gap on every joint, not on the three the cap of max_effects allowed
    ratio = d.decomposition["mse_after"] / d.decomposition["noise"]
    assert np.all(ratio < 1.5), ratio
