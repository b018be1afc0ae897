"""The parameter-change test (dynid.diagnosis.parameter_change) names changes that can happen.

An armature is never negative (identify keeps it at zero or above), so a refit whose ddq column goes
below zero (a delay or a gain takes it; issue 37 item 6: -0.00027 kg m^2 for a delay, -0.024 kg m^2 on a
Panda whose nominal armature is about 0) must not be reported as an armature change below minus the
nominal armature.  The data are synthetic: the UR5's regressor with linear friction and a torque of
-0.2 ddq_3 (what a delay or a lagging sensor leaves in the ddq column), nominal armature zero.
"""

from __future__ import annotations

import numpy as np
import pytest

from dynid.data.preparation import Preprocessing
from dynid.diagnosis import baseline as bl
from dynid.diagnosis import stats as st
from dynid.diagnosis.parameter_change import parameter_change_test
from dynid.diagnosis.settings import DiagnosisSettings
from dynid.identify.columns import column_set
from dynid.sim.synthetic import random_fourier, synthetic_dataset

NOISE = 0.05  # N m


def test_a_one_parameter_hypothesis_is_held_at_its_lower_bound(rng):
    A = rng.normal(size=(12, 1))
    delta = -3.0 * A[:, 0] + 0.01 * rng.normal(size=12)
    free = st.structured_change_test(delta, 1e-4 * np.eye(12), {"arm": A}, n_obs=1000)
    bounded = st.structured_change_test(delta, 1e-4 * np.eye(12), {"arm": A}, n_obs=1000, lower={"arm": -1.0})
    (f_free,) = [f for f in free if f.name == "arm"]
    (f_bound,) = [f for f in bounded if f.name == "arm"]
    assert f_free.theta[0] == pytest.approx(-3.0, abs=0.05) and not f_free.at_bound
    assert f_bound.theta[0] == -1.0 and f_bound.at_bound
    assert f_bound.chi2 > f_free.chi2


@pytest.fixture(scope="module")
def negative_ddq(ur5):
    cols = column_set(ur5, friction=True, armature=True)
    n = ur5.n
    armature = np.zeros(n)
    armature[2] = -0.2  # kg m^2: not a rotor, what a delay leaves in the ddq column
    coulomb = np.array([2.0, 2.5, 1.5, 0.8, 0.6, 0.5])
    viscous = np.array([1.2, 1.5, 0.8, 0.4, 0.3, 0.2])
    x = cols.P @ np.concatenate([ur5.params, armature, coulomb, viscous, np.zeros(n)])
    rng = np.random.default_rng(37)
    train = synthetic_dataset(
        cols, x, random_fourier(ur5, rng, periods=2, base_freq=0.2), rate=200, rng=rng, noise=NOISE
    )
    structure = bl.ModelStructure(
        robot=ur5, columns=cols, preprocessing=Preprocessing().resolve(train), friction_shape=None
    )
    tr = bl.sample(structure, train, DiagnosisSettings())
    base = bl.refit_baseline(tr)
    return cols, tr, base


def test_an_armature_change_never_goes_below_zero_armature(ur5, negative_ddq):
    cols, tr, base = negative_ddq
    k3 = next(
        k
        for k, (kd, j) in enumerate(zip(cols.kinds, cols.joints, strict=True))
        if kd == "armature" and j == 3
    )
    assert base.x[k3] < -0.1  # the unconstrained refit's ddq_3 coefficient is negative
    sigma = np.full(ur5.n, NOISE)
    par = parameter_change_test(tr.prep.ddq[tr.rows], cols, base.fit, base.x, ur5, 20, 0.05, sigma)
    nominal = np.asarray(ur5.armature)
    for row in par["armatures"]:
        change = row.get("change", row["value"] - row["nominal"])
        assert change >= -nominal[row["joint"] - 1] - 1e-15, row
    (row3,) = [r for r in par["armatures"] if r["joint"] == 3]
    assert row3["value"] < 0 and row3["at_bound"]
    # at its bound the change is zero: no armature finding, and no negative armature in the words
    assert par["finding"] != "armature", par["text"]
    for h in par["hypotheses"]:
        if h["name"].startswith("armature@"):
            j = int(h["name"].split("@")[1])
            assert h["theta"][0] >= -nominal[j - 1] - 1e-15, h
