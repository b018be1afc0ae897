"""Layer 1 of the identification: OLS, WLS, GLS, IRLS on data made from the regressor itself."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from dynid.data.dataset import Dataset
from dynid.data.preparation import Preprocessing, prepare
from dynid.exceptions import DataError, IdentificationError
from dynid.identify.columns import column_set
from dynid.identify.estimators import GLS, IRLS, OLS, WLS
from dynid.identify.linear_system import build_system
from dynid.sim.synthetic import random_fourier, synthetic_dataset, true_parameters


@pytest.fixture(scope="module")
def setup(ur5):
    rng = np.random.default_rng(11)
    cols = column_set(ur5)
    x = true_parameters(cols, rng)
    traj = random_fourier(ur5, rng, periods=2)
    return ur5, cols, x, traj


def rel_err(est, truth):
    return np.abs(est - truth) / np.maximum(np.abs(truth), 1e-3 * np.abs(truth).max())


@pytest.mark.parametrize("estimator", [OLS, WLS, GLS, IRLS])
def test_noise_free_data_give_the_true_parameters(setup, estimator) -> None:
    robot, cols, x, traj = setup
    ds = synthetic_dataset(cols, x, traj, rate=50, rng=np.random.default_rng(1))
    est = estimator(robot=robot).fit(ds)
    assert est.params_.shape == (cols.p,)
    assert rel_err(est.params_, x).max() < 1e-6
    assert np.all(est.rms_ < 1e-9)


def test_errors_lie_within_the_reported_std_and_shrink_with_the_noise(setup) -> None:
    robot, cols, x, traj = setup
    errors = []
    for sigma in (0.5, 0.05):
        ds = synthetic_dataset(cols, x, traj, rate=50, rng=np.random.default_rng(2), noise=sigma)
        est = OLS(robot=robot).fit(ds)
        z = (est.params_ - x) / est.std_
        assert np.mean(np.abs(z) < 4) >= 0.95
        assert np.allclose(est.rms_, sigma, rtol=0.15)
        errors.append(np.abs(est.params_ - x))
    ratio = np.median(errors[0] / errors[1])
    assert 5 < ratio < 20  # ten times less noise, about ten times smaller errors


@pytest.mark.parametrize("decimate", [1, 5])
def test_reported_std_stay_right_on_filtered_data(setup, decimate) -> None:
    # a 10 Hz filter at 500 Hz correlates the noise over ~27 samples: with independent-sample
    # formulas the errors were ~6 reported std RMS and only ~54 % within 4 std
    robot, cols, x, traj = setup
    sd = np.array([2.0, 1.5, 1.0, 0.5, 0.3, 0.3])
    ds = synthetic_dataset(cols, x, traj, rate=500, rng=np.random.default_rng(12), noise=sd)
    pre = Preprocessing(cutoff=10.0, state_cutoff=None, decimate=decimate)
    est = OLS(robot=robot, preprocessing=pre).fit(ds)
    kappa = prepare(ds, pre).noise_correlation
    assert kappa == pytest.approx(1.09 * 500 / (2 * 10 * decimate), rel=0.05)
    assert np.all(est.correlation_ >= kappa) and np.all(est.correlation_ < 2.5 * kappa)  # an estimate
    z = (est.params_ - x) / est.std_
    assert np.mean(np.abs(z) < 4) >= 0.95
    assert 0.6 < np.sqrt(np.mean(z**2)) < 1.6  # neither too small nor too wide


def test_gls_beats_ols_when_the_joint_noises_are_correlated(setup) -> None:
    robot, cols, x, traj = setup
    sd = np.array([2.0, 1.5, 1.0, 0.5, 0.3, 0.3])
    corr = np.full((6, 6), 0.95) + 0.05 * np.eye(6)
    omega = corr * np.outer(sd, sd)
    ds = synthetic_dataset(cols, x, traj, rate=50, rng=np.random.default_rng(3), noise=omega)
    system = build_system(robot, ds)
    ols, gls = OLS(robot=robot).fit(system), GLS(robot=robot).fit(system)
    scale = gls.std_
    err_ols = np.sum(((ols.params_ - x) / scale) ** 2)
    err_gls = np.sum(((gls.params_ - x) / scale) ** 2)
    assert err_gls < 0.5 * err_ols
    np.testing.assert_allclose(gls.omega_, omega, rtol=0.2)
    irls = IRLS(robot=robot).fit(system)
    assert irls.converged_ and irls.n_iter_ < 20
    assert np.sum(((irls.params_ - x) / scale) ** 2) < 0.5 * err_ols


def test_a_duplicated_armature_column_is_folded_into_its_base_parameter(ur5) -> None:
    cols = column_set(ur5)
    assert "ia1" not in cols.names and "ia3" in cols.names
    k = cols.names.index("Izz1R")
    assert cols.expressions[k].endswith("+ ia1")
    assert any("ia1" in note and "Izz1R" in note for note in cols.notes)


def test_extra_columns_match_the_casadi_friction_and_armature_columns(ur5) -> None:
    from dynid.symbolic.functions import robot_functions

    funcs = robot_functions(ur5)
    cols = column_set(ur5)
    rng = np.random.default_rng(4)
    dq, ddq = rng.normal(size=(5, 6)), rng.normal(size=(5, 6))
    F = funcs.evaluate("friction_columns", dq)  # (5, 6, 18): [fc, fv, fo]
    A = funcs.evaluate("armature_columns", ddq)  # (5, 6, 6)
    full = np.concatenate([A, F], axis=2)  # extras in phi order
    E = cols.extra_columns(dq, ddq)
    for k, e in enumerate(cols.extras):
        np.testing.assert_allclose(E[:, k], full[:, e % 6, e], atol=1e-15)


def test_parallel_filtering_keeps_the_exact_relation(setup) -> None:
    robot, cols, x, traj = setup
    ds = synthetic_dataset(cols, x, traj, rate=200, rng=np.random.default_rng(5))
    pre = Preprocessing(cutoff=5.0, state_cutoff=None, decimate=4)  # exact states: only the parallel filter
    est = OLS(robot=robot, preprocessing=pre).fit(ds)
    assert rel_err(est.params_, x).max() < 1e-6
    pred = est.predict(ds)
    ref = prepare(ds, pre).tau_reference
    assert pred.shape == ref.shape
    np.testing.assert_allclose(pred, ref, atol=1e-9 * np.abs(ref).max())


def test_differentiated_states_predict_the_torque(setup) -> None:
    robot, cols, x, traj = setup
    ds = synthetic_dataset(cols, x, traj, rate=500, rng=np.random.default_rng(6), with_derivatives=False)
    est = OLS(robot=robot, preprocessing=Preprocessing(cutoff=10.0, decimate=5)).fit(ds)
    assert est.preprocessing_["dq"].startswith("central difference")
    tau_rms = np.sqrt(np.mean(ds.tau**2, axis=0))
    assert np.all(est.rms_ < 1e-3 * tau_rms)


def test_too_few_samples_are_refused(setup) -> None:
    robot, cols, x, traj = setup
    ds = synthetic_dataset(cols, x, traj, rate=0.4, rng=np.random.default_rng(7))
    with pytest.raises(IdentificationError, match=r"give \d+ samples \(\d+ equations\).*for 58 parameters"):
        OLS(robot=robot).fit(ds)


def test_a_joint_that_never_moves_is_named_with_the_motion_that_would_excite_it(ur5) -> None:
    rng = np.random.default_rng(8)
    cols = column_set(ur5)
    x = true_parameters(cols, rng)
    traj = random_fourier(ur5, rng, periods=2, still=(6,))
    ds = synthetic_dataset(cols, x, traj, rate=50, rng=rng)
    with pytest.raises(
        IdentificationError, match=r"do not excite the base parameters .*fc6.*joint 6 never moves"
    ):
        OLS(robot=ur5).fit(ds)
    without_friction = OLS(robot=ur5, friction=False)
    with pytest.raises(
        IdentificationError,
        match=r"do not excite the base parameters .*6.*record a motion that moves joint 6",
    ):
        without_friction.fit(ds)


def test_nan_in_the_data_is_refused(setup) -> None:
    robot, cols, x, traj = setup
    ds = synthetic_dataset(cols, x, traj, rate=50, rng=np.random.default_rng(9))
    tau = ds.tau.copy()
    tau[10, 2] = np.nan
    with pytest.raises(DataError, match=r"tau_3 is nan at row 10"):
        dataclasses.replace(ds, tau=tau)
    est = OLS(robot=robot).fit(ds)
    q = ds.q.copy()
    q[3, 0] = np.nan
    with pytest.raises(DataError, match=r"q holds a non-finite value at row 3"):
        est.predict(q, ds.dq, ds.ddq)


def test_an_unfitted_estimator_says_so(ur5) -> None:
    with pytest.raises(IdentificationError, match="not fitted yet"):
        OLS(robot=ur5).predict(np.zeros((2, 6)), np.zeros((2, 6)), np.zeros((2, 6)))


def test_data_of_another_robot_are_refused(ur5) -> None:
    ds = Dataset(np.arange(100) * 0.01, np.zeros((100, 7)), np.zeros((100, 7)))
    with pytest.raises(DataError, match=r"q has 7 columns; the robot has 6 joints"):
        OLS(robot=ur5).fit(ds)


def test_a_shared_system_takes_each_estimators_fit_once(setup, monkeypatch) -> None:
    """Within ``sharing_systems``, a second fit of one estimator and settings on one dataset is the first's
    (equal attributes, copied arrays); other settings or another estimator fit again."""
    from dynid.identify.linear_system import sharing_systems

    robot, cols, x, traj = setup
    ds = synthetic_dataset(cols, x, traj, rate=50, rng=np.random.default_rng(4), noise=0.5)
    calls = []
    original = IRLS._fit_system
    monkeypatch.setattr(IRLS, "_fit_system", lambda self, system: calls.append(self) or original(self, system))
    alone = IRLS(robot=robot).fit(build_system(robot, ds))
    with sharing_systems():
        first = IRLS(robot=robot).fit(build_system(robot, ds))
        second = IRLS(robot=robot).fit(build_system(robot, ds))
        assert len(calls) == 2  # the one outside the block, then the first inside it
        second.params_[0] += 1.0  # the second's arrays are its own
        third = IRLS(robot=robot).fit(build_system(robot, ds))
        other = IRLS(robot=robot, max_iter=3).fit(build_system(robot, ds))
        assert len(calls) == 3  # other settings: fitted
        ols = OLS(robot=robot).fit(build_system(robot, ds))
    np.testing.assert_array_equal(first.params_, alone.params_)
    np.testing.assert_array_equal(third.params_, alone.params_)
    np.testing.assert_array_equal(third.cov_, alone.cov_)
    assert third.n_iter_ == alone.n_iter_ and third.converged_ == alone.converged_
    assert other.n_iter_ == 3 and not np.array_equal(other.params_, alone.params_)
    assert not np.array_equal(ols.params_, alone.params_)


def test_a_shared_fit_says_its_warnings_again_and_a_copy_without_samples_fits_its_own(setup) -> None:
    """The second taker of a shared fit gets the first's warnings (IRLS stopped short); a copy without the
    data matrix, whose residual correlation falls back to the filter's, is fitted for itself."""
    from dynid.exceptions import IdentificationWarning
    from dynid.identify.linear_system import sharing_systems

    robot, cols, x, traj = setup
    ds = synthetic_dataset(cols, x, traj, rate=50, rng=np.random.default_rng(5), noise=0.5)
    with sharing_systems():
        for _ in range(2):
            with pytest.warns(IdentificationWarning, match="IRLS did not converge in 2 iterations"):
                IRLS(robot=robot, max_iter=2).fit(build_system(robot, ds))
        full = OLS(robot=robot).fit(build_system(robot, ds))
        bare = OLS(robot=robot).fit(build_system(robot, ds, keep_samples=False))
    alone = OLS(robot=robot).fit(build_system(robot, ds, keep_samples=False))
    np.testing.assert_array_equal(bare.correlation_, alone.correlation_)
    np.testing.assert_array_equal(bare.cov_, alone.cov_)
    assert not np.array_equal(full.correlation_, bare.correlation_)  # the two really differ
