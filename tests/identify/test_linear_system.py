"""The column set, the compressed linear system and its weighted solutions, the preprocessing settings."""

from __future__ import annotations

import dataclasses
from collections import Counter

import numpy as np
import pinocchio as pin
import pytest
import scipy.linalg

from dynid.data.dataset import Dataset
from dynid.data.preparation import AUTO_CUTOFF_HZ, Preprocessing, prepare
from dynid.exceptions import DataError, DynidError, IdentificationError, NotFittedError, UsageError
from dynid.identify.columns import column_set, linear_torque
from dynid.identify.estimators import OLS
from dynid.identify.friction import FrictionLayer, SeedFriction
from dynid.identify.gmr import GMRCorrection
from dynid.identify.linear_system import LinearSystem, WeightedSolution, build_system
from dynid.sim.synthetic import random_fourier, synthetic_dataset, true_parameters


# ---------------------------------------------------------------------------- the column set
def test_the_column_set_names_and_counts_the_parameters(ur5) -> None:
    cols = column_set(ur5)
    assert (cols.n, cols.n_base, cols.p) == (6, 36, 58)
    kinds = Counter(cols.kinds)
    # the armature of joints 1 and 2 acts exactly like a base parameter and is folded into it
    assert kinds == {"link": 36, "armature": 4, "coulomb": 6, "viscous": 6, "offset": 6}
    assert cols.names[36:] == (
        *(f"ia{j}" for j in range(3, 7)),
        *(f"fc{j}" for j in range(1, 7)),
        *(f"fv{j}" for j in range(1, 7)),
        *(f"fo{j}" for j in range(1, 7)),
    )
    assert len(cols.notes) == 2
    assert "(ia1) duplicates the column of Izz1R" in cols.notes[0]
    assert "(ia2) duplicates the column of Iyy2R" in cols.notes[1]
    assert "ia1" in cols.expressions[cols.names.index("Izz1R")]
    assert cols.P.shape == (58, 14 * 6) and cols.pattern.shape == (6, 58)
    assert len(cols.names) == len(cols.kinds) == len(cols.expressions) == len(cols.joints) == 58
    np.testing.assert_array_equal(cols.joints[36:], [3, 4, 5, 6] + list(range(1, 7)) * 3)
    # the two masks split the parameters: rigid body (links, armature) and linear friction
    assert not np.any(cols.link_mask & cols.friction_mask)
    assert np.all(cols.link_mask | cols.friction_mask)
    assert int(cols.friction_mask.sum()) == 18


def test_a_column_set_without_extras_holds_the_base_parameters_only(ur5) -> None:
    cols = column_set(ur5, friction=False, armature=False)
    assert cols.p == cols.n_base == 36
    assert cols.notes == () and len(cols.extras) == 0
    assert set(cols.kinds) == {"link"}
    assert not cols.enabled_extras.any()
    assert Counter(column_set(ur5, friction=False).kinds) == {"link": 36, "armature": 4}


def _physical(ur5, rng):
    """Standard parameters of the URDF plus random armature and linear friction: phi (14 n,)."""
    n = ur5.n
    extras = [
        rng.uniform(0.01, 0.05, n),
        rng.uniform(0.5, 3, n),
        rng.uniform(0.2, 2, n),
        rng.uniform(-0.5, 0.5, n),
    ]
    return np.concatenate([ur5.params, *extras])


def _reference_torque(ur5, phi, q, dq, ddq):
    """Pinocchio's inverse dynamics with the standard parameters, plus armature and friction by hand."""
    n = ur5.n
    model, data = ur5.pin_model, ur5.pin_model.createData()
    rigid = np.array([pin.rnea(model, data, q[k], dq[k], ddq[k]) for k in range(len(q))])
    rigid -= ur5.armature * ddq  # Pinocchio adds the model's own rotor inertia; phi holds ours
    ia, fc, fv, fo = (phi[10 * n + k * n : 10 * n + (k + 1) * n] for k in range(4))
    at_rest = np.abs(dq) < 1e-3  # rad/s: a joint slower than this has no direction for its Coulomb friction
    return rigid + ia * ddq + fc * np.where(at_rest, 0.0, np.sign(dq)) + fv * dq + fo


# ---------------------------------------------------------------------------- the linear system
@pytest.fixture(scope="module")
def exact_data(ur5):
    """Noise-free data with exact derivatives (no filter, nothing trimmed) and the true parameters."""
    rng = np.random.default_rng(31)
    cols = column_set(ur5)
    phi = _physical(ur5, rng)
    x = cols.P @ phi
    ds = synthetic_dataset(cols, x, random_fourier(ur5, rng), rate=40, rng=rng)
    return cols, phi, x, ds


def test_the_linear_model_is_inverse_dynamics_with_armature_and_friction(ur5, exact_data) -> None:
    cols, phi, x, ds = exact_data
    expected = _reference_torque(ur5, phi, ds.q, ds.dq, ds.ddq)
    scale = np.abs(expected).max()
    np.testing.assert_allclose(
        linear_torque(cols, x, ds.q, ds.dq, ds.ddq), expected, rtol=1e-10, atol=1e-10 * scale
    )
    system = build_system(ur5, ds)
    assert system.m == len(ds.t) and system.p == 58  # no filter, no trimming: every sample
    np.testing.assert_allclose(system.predict(x), expected, rtol=1e-10, atol=1e-10 * scale)
    np.testing.assert_allclose(system.tau(), ds.tau, rtol=1e-12, atol=1e-12 * scale)
    # the compressed factor holds the residual of any parameters: here none at the truth ...
    assert np.all(system.rms(x) < 1e-9 * scale)
    # ... and E^T E of a wrong vector as the per-sample residual gives it
    x_wrong = x * (1 + 0.1 * np.random.default_rng(1).standard_normal(len(x)))
    E = system.tau() - system.predict(x_wrong)
    np.testing.assert_allclose(
        system.residual_matrix(x_wrong), E.T @ E, rtol=1e-9, atol=1e-9 * np.abs(E.T @ E).max()
    )
    # the rigid-body part alone: friction columns masked out
    no_friction = phi.copy()
    no_friction[11 * 6 :] = 0.0
    np.testing.assert_allclose(
        system.predict(x, mask=cols.link_mask),
        _reference_torque(ur5, no_friction, ds.q, ds.dq, ds.ddq),
        rtol=1e-10,
        atol=1e-10 * scale,
    )


def test_ordinary_least_squares_on_exact_data_returns_the_truth(ur5, exact_data) -> None:
    _, _, x, ds = exact_data
    sol = build_system(ur5, ds).solve(np.eye(6))
    assert isinstance(sol, WeightedSolution)
    np.testing.assert_allclose(sol.x, x, rtol=1e-7, atol=1e-9 * np.abs(x).max())
    assert sol.rss < 1e-16 * float(np.sum(ds.tau**2))
    with pytest.raises(dataclasses.FrozenInstanceError, match="cannot assign to field 'x'"):
        sol.x = x  # type: ignore[misc]


def _dense(ur5, cols, ds):
    """The stacked regressor (m n, p) column by column through linear_torque: the plain reference."""
    m, n, p = len(ds.t), ur5.n, cols.p
    W = np.empty((m * n, p))
    for k in range(p):
        e = np.zeros(p)
        e[k] = 1.0
        W[:, k] = linear_torque(cols, e, ds.q, ds.dq, ds.ddq).reshape(m * n)
    return W


def test_a_weighted_solution_is_the_whitened_least_squares(ur5) -> None:
    rng = np.random.default_rng(32)
    cols = column_set(ur5)
    x_true = cols.P @ _physical(ur5, rng)
    A = rng.normal(size=(6, 6))
    omega = 0.01 * (A @ A.T + 0.5 * np.eye(6))  # correlated joint noise
    ds = synthetic_dataset(cols, x_true, random_fourier(ur5, rng), rate=40, rng=rng, noise=omega)
    system = build_system(ur5, ds)
    L_inv = scipy.linalg.solve_triangular(np.linalg.cholesky(omega), np.eye(6), lower=True)
    sol = system.solve(L_inv)
    # reference: whiten every sample of the dense stacked system, plain least squares
    m, n = len(ds.t), 6
    W = _dense(ur5, cols, ds).reshape(m, n, cols.p)
    Ww = np.einsum("ij,mjp->mip", L_inv, W).reshape(m * n, cols.p)
    yw = (ds.tau @ L_inv.T).reshape(m * n)
    x_ref, rss_ref, *_ = np.linalg.lstsq(Ww, yw, rcond=None)
    np.testing.assert_allclose(sol.R.T @ sol.R, Ww.T @ Ww, rtol=1e-9, atol=1e-9 * np.abs(Ww.T @ Ww).max())
    np.testing.assert_allclose(sol.x, x_ref, rtol=1e-7, atol=1e-8 * np.abs(x_ref).max())
    np.testing.assert_allclose(sol.rss, float(rss_ref[0]), rtol=1e-8)
    np.testing.assert_array_equal(sol.whitener, L_inv)
    # the weighting matters: unweighted least squares gives another estimate and a larger whitened residual
    ols = system.solve(np.eye(6))
    assert np.max(np.abs(ols.x - sol.x)) > 1e-3 * np.abs(sol.x).max()
    assert float(np.sum((Ww @ ols.x - yw) ** 2)) > sol.rss
    # the estimators read their solution from the same record
    fit = OLS(robot=ur5).fit(system)
    np.testing.assert_allclose(fit.params_, ols.x, rtol=1e-12, atol=0)
    np.testing.assert_array_equal(fit.solution_.R, ols.R)


def test_a_released_system_keeps_its_factor_and_refuses_per_sample_values(ur5, exact_data) -> None:
    _, _, x, ds = exact_data
    system = build_system(ur5, ds, keep_samples=False)
    assert isinstance(system, LinearSystem) and system.Z is None
    assert np.all(system.rms(x) < 1e-9 * np.abs(ds.tau).max())
    with pytest.raises(IdentificationError, match="the data matrix of this system was released"):
        system.predict(x)


# ---------------------------------------------------------------------------- preprocessing settings
def _dataset(ur5, rate: float, *, derivatives: bool) -> Dataset:
    rng = np.random.default_rng(33)
    cols = column_set(ur5, friction=False, armature=False)
    x = cols.P @ np.concatenate([ur5.params, np.zeros(4 * ur5.n)])
    traj = random_fourier(ur5, rng, base_freq=0.5)
    return synthetic_dataset(cols, x, traj, rate=rate, rng=rng, with_derivatives=derivatives)


def test_preprocessing_defaults(ur5) -> None:
    default = Preprocessing()
    assert (default.cutoff, default.state_cutoff, default.order) == ("auto", "auto", 5)
    assert (default.decimate, default.trim, default.parallel) == (1, None, True)
    # measured derivatives: no filter, nothing trimmed
    measured = default.resolve(_dataset(ur5, 1000.0, derivatives=True))
    assert measured == {
        "cutoff_hz": None,
        "state_cutoff_hz": None,
        "order": 5,
        "decimate": 1,
        "trim_s": 0.0,
        "parallel": True,
    }
    # angles only: the cut-off from the data (noise-free angles carry signal far up: the largest,
    # a fifth of the sampling rate), on torque and states, 5 / cutoff trimmed at both ends
    only_q = _dataset(ur5, 1000.0, derivatives=False)
    settings = default.resolve(only_q)
    cutoff = settings["cutoff_hz"]
    assert AUTO_CUTOFF_HZ <= cutoff <= 200.0 and settings["state_cutoff_hz"] == cutoff
    assert settings["trim_s"] == pytest.approx(5.0 / cutoff, rel=1e-12)
    # at most a fifth of the sampling rate
    assert default.resolve(_dataset(ur5, 50.0, derivatives=False))["cutoff_hz"] == pytest.approx(10.0)
    # the resolved settings describe the preprocessing again
    assert Preprocessing.from_settings(settings).resolve(only_q) == settings
    prepared = prepare(only_q)
    assert prepared.settings["cutoff_hz"] == cutoff and prepared.parallel_filter
    assert prepared.settings["cutoff_rule"].startswith("from the data: q carries signal up to")
    trimmed = int(np.ceil(5.0 / cutoff * 1000 - 1e-9))
    np.testing.assert_array_equal(prepared.rows, np.arange(trimmed, len(only_q.t) - trimmed))
    assert prepared.reference == "filtered and trimmed"


def test_preprocessing_rejects_a_cut_off_above_nyquist(ur5) -> None:
    ds = _dataset(ur5, 1000.0, derivatives=False)
    with pytest.raises(DataError, match=r"cutoff is 600.*Nyquist frequency 500 Hz"):
        Preprocessing(cutoff=600.0).resolve(ds)
    with pytest.raises(DataError, match="decimate is 0; give a positive integer"):
        Preprocessing(decimate=0).resolve(ds)


# ---------------------------------------------------------------------------- one not-fitted error
def test_every_unfitted_estimator_raises_the_one_not_fitted_error(ur5) -> None:
    zeros = np.zeros((3, 6))
    for call in (
        lambda: OLS(robot=ur5).predict(zeros, zeros, zeros),
        lambda: GMRCorrection().predict(np.zeros((3, 12))),
        lambda: FrictionLayer().predict(zeros),
        lambda: SeedFriction().predict(np.zeros(3)),
    ):
        with pytest.raises(NotFittedError, match="is not fitted yet; call fit") as info:
            call()
        assert isinstance(info.value, DynidError)  # the command line's catch
    assert issubclass(NotFittedError, IdentificationError) and issubclass(NotFittedError, UsageError)


@pytest.mark.parametrize("shape", [(5000, 9), (40, 60), (3, 2), (0, 4)])
def test_r_factor_is_scipys_triangular_factor_to_the_bit(shape) -> None:
    from dynid.identify._qr import fortran_stack, r_factor

    rng = np.random.default_rng(shape[0])
    A = rng.standard_normal(shape)
    ref = scipy.linalg.qr(A, mode="r", check_finite=False)[0][: min(shape)]
    assert np.array_equal(r_factor(A), ref)
    assert np.array_equal(r_factor(fortran_stack(A[:, :1], A[:, 1:]), overwrite=True), ref)


@pytest.mark.parametrize("shape", [(5000, 9), (40, 40), (3, 5)])
def test_q_factor_is_scipys_economic_q_to_the_bit(shape) -> None:
    from dynid.identify._qr import q_factor

    A = np.random.default_rng(shape[1]).standard_normal(shape)
    ref = scipy.linalg.qr(A, mode="economic", check_finite=False)[0]
    assert np.array_equal(q_factor(np.asfortranarray(A)), ref)


def test_shared_systems_are_built_once_and_change_no_result(ur5, monkeypatch):
    """Inside ``sharing_systems`` every fit of one dataset takes the one system built for it, and a fit
    after another one (sharing its derived arrays) is the same, bit for bit, as a fit on its own."""
    from dynid.identify import linear_system
    from dynid.identify.model import ThreeLayerModel

    rng = np.random.default_rng(5)
    cols = column_set(ur5)
    run = synthetic_dataset(
        cols, true_parameters(cols, rng), random_fourier(ur5, rng, periods=1), rate=100, rng=rng, noise=0.05
    )
    alone = ThreeLayerModel(robot=ur5, method="irls", friction="seed", gmm=2).fit(run).model_
    builds = Counter()
    real = linear_system._build

    def counted(robot, data, *args):
        builds[id(data)] += 1
        return real(robot, data, *args)

    monkeypatch.setattr(linear_system, "_build", counted)
    with linear_system.sharing_systems():
        ThreeLayerModel(robot=ur5, method="ols", friction="seed", gmm="off").fit(run)
        shared = ThreeLayerModel(robot=ur5, method="irls", friction="seed", gmm=2).fit(run).model_
        again = build_system(ur5, run, keep_samples=False)
    assert builds == {id(run): 1}
    assert again.Z is None and again.shared
    np.testing.assert_array_equal(shared.params, alone.params)
    np.testing.assert_array_equal(shared.cov, alone.cov)
    np.testing.assert_array_equal(shared.rms, alone.rms)
    np.testing.assert_array_equal(shared.predict(run), alone.predict(run))
    build_system(ur5, run)  # outside the block: built again
    assert builds[id(run)] == 2


# ---------------------------------------------------------------------------- long recordings
@pytest.fixture(scope="module")
def filtered_run(ur5):
    """20 s at 1 kHz, angles only, noisy torque: the filter, the differentiation and the trim all act."""
    rng = np.random.default_rng(41)
    cols = column_set(ur5)
    x = true_parameters(cols, rng)
    ds = synthetic_dataset(
        cols, x, random_fourier(ur5, rng, base_freq=0.1, periods=2), rate=1000, rng=rng, noise=0.2,
        with_derivatives=False,
    )  # fmt: skip
    return cols, x, ds


def test_a_long_recording_is_filtered_a_block_at_a_time_with_the_same_result(ur5, filtered_run, monkeypatch):
    """Past FULL_RATE_BYTES the data matrix is filled and filtered in blocks widened by the filter's
    margin and only the kept rows are held: the same system as the whole-recording pass, to rounding."""
    from dynid.identify import linear_system

    _, _, ds = filtered_run
    whole = build_system(ur5, ds)
    monkeypatch.setattr(linear_system, "FULL_RATE_BYTES", 1 << 20)  # 1 MB: blocks of about 3,000 samples
    blocks = build_system(ur5, ds)
    assert blocks.Z.shape == whole.Z.shape == (whole.m, len(whole.z_joint))
    scale = np.abs(whole.Z).max(axis=0)
    assert np.max(np.abs(blocks.Z - whole.Z) / scale) < 1e-9
    # the ends of the recording and every block boundary inside it agree, not only the bulk
    assert np.max(np.abs(blocks.Z[:50] - whole.Z[:50]) / scale) < 1e-9
    np.testing.assert_allclose(
        OLS(robot=ur5).fit(blocks).params_, OLS(robot=ur5).fit(whole).params_, rtol=1e-7, atol=1e-9
    )


def test_a_recording_beyond_the_memory_budget_is_identified_on_one_sample_in_D(ur5, filtered_run, monkeypatch):
    """Over KEPT_BYTES the kept rows are thinned (states and filter at full rate), said in the model's notes
    and recorded as its decimation; the estimate moves by a fraction of its standard deviation, and the
    standard deviations grow as the information kept shrinks."""
    from dynid.identify import linear_system
    from dynid.identify.model import identify

    cols, _, ds = filtered_run
    options = {"method": "ols", "friction": "linear", "gmm": "off", "physical": False}
    pre = Preprocessing(cutoff=20.0)
    full = identify(ur5, ds, preprocessing=pre, **options)
    assert full.preprocessing["decimate"] == 1 and "decimate_rule" not in full.preprocessing
    c = int(cols.pattern.sum()) + ur5.n
    budget = full.info["n_samples"] * c * 8 // 4 + 1  # a quarter of what the kept rows take
    monkeypatch.setattr(linear_system, "KEPT_BYTES", budget)
    thin = identify(ur5, ds, preprocessing=pre, **options)
    D = thin.preprocessing["decimate"]
    assert D == 4 and abs(thin.info["n_samples"] * D - full.info["n_samples"]) <= 2 * D
    assert f"one sample in {D}" in thin.info["notes"][0] and "--decimate" in thin.info["notes"][0]
    std = np.sqrt(np.diag(full.cov))
    assert np.max(np.abs(thin.params - full.params) / std) < 1.0
    assert np.median(np.sqrt(np.diag(thin.cov)) / std) == pytest.approx(1.0, abs=0.25)
    # the decimation is the model's: a held-out recording is scored on the same grid
    assert thin.prepare(ds).m == thin.info["n_samples"]
    # thin=False (the command line's --decimate 1) keeps every sample whatever the budget
    kept = identify(ur5, ds, preprocessing=dataclasses.replace(pre, thin=False), **options)
    assert kept.preprocessing["decimate"] == 1 and kept.info["n_samples"] == full.info["n_samples"]
    np.testing.assert_array_equal(kept.params, full.params)


def test_thinning_never_takes_the_decimated_rate_below_the_filters_band(ur5, filtered_run) -> None:
    from dynid.identify.linear_system import thinned_for_memory

    _, _, ds = filtered_run
    prep = prepare(ds, Preprocessing(cutoff=40.0))
    same = thinned_for_memory(prep, 100, budget=prep.m * 100 * 8)
    assert same is prep
    thin = thinned_for_memory(prep, 100, budget=1000)  # would need D in the thousands
    assert thin.settings["decimate"] == 10  # 1 kHz / 10 = 100 Hz = 2.5 x the 40 Hz cut-off
    assert "2.5 times the 40 Hz cut-off" in thin.settings["decimate_rule"]
    assert np.all(np.diff(thin.rows) >= 10)


def test_unfiltered_data_beyond_the_budget_evaluate_the_kept_rows_only(ur5, exact_data, monkeypatch):
    """Measured derivatives, no filter: the thinned system is the one built on every D-th sample."""
    from dynid.identify import linear_system

    _, _, _, ds = exact_data
    whole = build_system(ur5, ds)
    monkeypatch.setattr(linear_system, "KEPT_BYTES", whole.Z.nbytes // 3 + 1)
    thin = build_system(ur5, ds)
    D = thin.prepared.settings["decimate"]
    assert D == 3 and thin.prepared.settings["cutoff_hz"] is None
    np.testing.assert_array_equal(thin.Z, whole.Z[::D][: thin.m])
    np.testing.assert_allclose(OLS(robot=ur5).fit(thin).params_, OLS(robot=ur5).fit(whole).params_, rtol=1e-8, atol=1e-8)
