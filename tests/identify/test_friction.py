"""Layer 2: friction models recover their coefficients from simulated friction data."""

from __future__ import annotations

import numpy as np
import pytest

from dynid.exceptions import DataError, UsageError
from dynid.identify.friction import (
    FrictionLayer,
    LinearFriction,
    SeedFriction,
    SigmoidFriction,
    StribeckFriction,
    friction_model,
)


def velocities(rng: np.random.Generator, m: int = 20_000) -> np.ndarray:
    """Joint speeds sweeping both directions and lingering near zero (rad/s)."""
    t = np.linspace(0.0, 40.0, m)
    return 1.5 * np.sin(2 * np.pi * 0.25 * t) * np.abs(np.sin(2 * np.pi * 0.05 * t)) + 0.02 * rng.normal(
        size=m
    )


def with_coef(model, coef):
    model.coef_ = np.asarray(coef, dtype=float)
    return model


def test_seed_model_recovers_its_coefficients_and_threshold(rng) -> None:
    dq = velocities(rng)
    truth = with_coef(SeedFriction(), [1.0, 0.8, 0.5, 0.2, 0.05, 1.6, 1.3, 0.08])
    F = truth.predict(dq) + 0.02 * rng.normal(size=dq.size)
    fit = SeedFriction().fit(dq, F)
    np.testing.assert_allclose(fit.coef_[:2], truth.coef_[:2], rtol=0.03)  # Coulomb per direction
    np.testing.assert_allclose(fit.coef_[5:7], truth.coef_[5:7], rtol=0.03)  # static levels
    np.testing.assert_allclose(fit.coef_[7], truth.coef_[7], rtol=0.05)  # threshold lambda
    np.testing.assert_allclose(fit.coef_[2], truth.coef_[2], rtol=0.1)
    assert fit.rms_ < 0.021
    # continuous at +-lambda
    lam = fit.coef_[7]
    for side in (1, -1):
        below, above = fit.predict(np.array([side * lam * (1 - 1e-9), side * lam * (1 + 1e-9)]))
        assert abs(below - above) < 1e-6


def test_stribeck_sigmoid_and_linear_models_recover_their_coefficients(rng) -> None:
    dq = velocities(rng)
    noise = 0.02 * rng.normal(size=dq.size)
    cases = [
        (StribeckFriction, [1.0, 1.5, 0.4, 0.1, 0.05], 0.05),
        (SigmoidFriction, [5.0, 8.0, 0.1], 0.02),
        (LinearFriction, [0.7, 0.3, -0.2], 0.02),
    ]
    for klass, coef, rtol in cases:
        F = with_coef(klass(), coef).predict(dq) + noise
        np.testing.assert_allclose(klass().fit(dq, F).coef_, coef, rtol=rtol, atol=2e-3)


def test_linear_friction_keeps_coulomb_and_viscous_non_negative(rng) -> None:
    dq = velocities(rng)
    F = -0.5 * np.sign(dq) + 0.1 + 0.01 * rng.normal(size=dq.size)  # "negative friction": unphysical
    fit = LinearFriction().fit(dq, F)
    assert fit.coef_[0] >= 0 and fit.coef_[1] >= 0


def test_layer_round_trips_through_its_dict(rng) -> None:
    dq = np.column_stack([velocities(rng, 4000), velocities(rng, 4000)])
    F = 0.8 * np.sign(dq) + 0.3 * dq
    layer = FrictionLayer(model="stribeck").fit(dq, F)
    again = FrictionLayer.from_dict(layer.to_dict())
    np.testing.assert_allclose(again.predict(dq), layer.predict(dq), rtol=0, atol=1e-12)
    assert layer.rms_.shape == (2,)


def test_bad_friction_input_is_refused(rng) -> None:
    dq = velocities(rng, 100)
    with pytest.raises(DataError, match="one friction torque"):
        SeedFriction().fit(dq, np.zeros(99))
    with pytest.raises(DataError, match="needs at least 20 samples"):
        SeedFriction().fit(dq[:5], dq[:5])
    with pytest.raises(UsageError, match="unknown friction model 'coulomb'"):
        friction_model("coulomb")
    with pytest.raises(DataError, match=r"joint 2: .*needs the joint to move"):
        FrictionLayer(model="seed").fit(np.column_stack([dq, np.zeros(100)]), np.zeros((100, 2)))


def test_seed_model_fitted_through_the_torque_filter_finds_the_threshold(rng) -> None:
    # at 1 kHz with a 20 Hz filter the Coulomb step of every reversal is smeared over ~25 ms: fitted
    # unfiltered against the filtered torque, the static levels come out 11-13 % low (the threshold 3-10
    # times too small while a joint at rest still had a direction) and the filtered torque 25 times worse
    from dynid.data.dataset import Dataset
    from dynid.data.preparation import Preprocessing, prepare

    t = np.arange(40_000) * 1e-3
    q = 0.6 * np.sin(2 * np.pi * 0.2 * t) * np.sin(2 * np.pi * 0.05 * t)
    ds = Dataset(t, q[:, None], np.zeros((len(t), 1)))
    prep = prepare(ds, Preprocessing(cutoff=20.0))
    truth = with_coef(SeedFriction(), [1.0, 0.8, 0.5, 0.2, 0.05, 1.6, 1.3, 0.08])
    F = prep.filter(truth.predict(prep.dq) + 0.05 * rng.normal(size=prep.dq.shape))[prep.rows]
    plain = FrictionLayer(model="seed").fit(prep.dq[prep.rows], F)
    filtered = FrictionLayer(model="seed").fit(prep.dq, F, prepared=prep)
    lam = filtered.models_[0].coef_[7]
    assert lam == pytest.approx(0.08, rel=0.15)
    np.testing.assert_allclose(filtered.models_[0].coef_[5:7], [1.6, 1.3], rtol=0.03)
    assert np.all(plain.models_[0].coef_[5:7] < 0.92 * np.array([1.6, 1.3]))  # the unfiltered fit's bias
    pred = prep.filter(filtered.predict(prep.dq))[prep.rows]
    expect = prep.filter(truth.predict(prep.dq))[prep.rows]
    err = np.sqrt(np.mean((pred - expect) ** 2))
    assert err < 0.02
    assert np.sqrt(np.mean((prep.filter(plain.predict(prep.dq))[prep.rows] - expect) ** 2)) > 10 * err
    # the fit's own filtered columns are the filtered basis, to the bit, handed out once
    again = [prep.filter(B)[prep.rows] for B in filtered.basis(prep.dq)]
    first = filtered.filtered_basis(prep)
    assert first is not None and all(np.array_equal(a, b) for a, b in zip(first, again, strict=True))
    assert not hasattr(filtered, "_filtered_basis")
    assert all(np.array_equal(a, b) for a, b in zip(filtered.filtered_basis(prep), again, strict=True))


def test_linear_part_round_trips_through_basis_and_set_linear(rng) -> None:
    dq = velocities(rng, 3000)
    for klass, coef in (
        (SeedFriction, [1.0, 0.8, 0.5, 0.2, 0.05, 1.6, 1.3, 0.08]),
        (LinearFriction, [0.7, 0.3, -0.2]),
    ):
        mdl = with_coef(klass(), coef)
        np.testing.assert_allclose(mdl.basis(dq) @ mdl.linear_coef(), mdl.predict(dq), atol=1e-12)
        mdl.set_linear(-np.ones(len(mdl.linear_coef())))  # below the bounds: kept at them
        assert np.all(mdl.linear_coef() >= mdl.linear_bounds)


def test_seed_model_holds_an_implausible_static_level_at_the_coulomb_level(rng) -> None:
    """Coulomb + viscous friction whose reversals carry a timing error (a short burst of torque on one
    side of each zero crossing, as a differentiated angle gives): free, the fit puts a static level of
    many Coulomb levels on the few samples below a tiny threshold; held, the static level is the Coulomb
    level and the model predicts a motion with slow reversals as the truth does."""
    dq = velocities(rng)
    kc, kv = 1.0, 0.5
    burst = np.where((np.abs(dq) < 0.004) & (dq < 0), -6.0, 0.0)  # the reversals' timing error
    F = kc * np.sign(dq) + kv * dq + burst + 0.02 * rng.normal(size=dq.size)
    free = SeedFriction()
    free.static_ratio = np.inf
    free.fit(dq, F)
    assert free.coef_[6] > 3 * free.coef_[1]  # the burst taken for stiction
    fit = SeedFriction().fit(dq, F)
    assert fit.tied_ == (False, True)
    assert fit.coef_[6] == fit.coef_[1] and fit.coef_[5] <= 3 * fit.coef_[0]
    fast = np.abs(dq) > 0.1  # away from the reversals the fit is Coulomb + viscous
    assert np.sqrt(np.mean((fit.predict(dq[fast]) - kc * np.sign(dq[fast]) - kv * dq[fast]) ** 2)) < 0.1 * kc
    assert len(fit.basis(dq[:5]).T) == len(fit.linear_coef()) == 6  # one Coulomb column on the held side
    slow = np.linspace(-0.05, 0.05, 201)  # a motion that lingers near zero speed
    truth = kc * np.sign(slow) + kv * slow
    assert np.max(np.abs(fit.predict(slow) - truth)) < 1.1 * kc  # free: several Coulomb levels off
    assert np.max(np.abs(free.predict(slow) - truth)) > 3 * kc
    before = fit.coef_.copy()
    fit.set_linear(fit.linear_coef() * 1.5)  # a joint refit keeps the two levels together
    assert fit.coef_[6] == fit.coef_[1] == 1.5 * before[1]
    again = FrictionLayer.from_dict(FrictionLayer(model="seed").fit(dq[:, None], F[:, None]).to_dict())
    assert again.models_[0].tied_ == (False, True)  # read back from a file, still held
    # equal levels that were not held (a joint that never moves backwards: both 0) stay apart
    untied = with_coef(SeedFriction(), [1.0, 0.0, 0.5, 0.0, 0.0, 1.4, 0.0, 0.05])
    back = FrictionLayer.from_dict({"model": "seed", "joints": [untied.to_dict()["coef"]]}).models_[0]
    assert back.tied_ == (False, False) and len(back.linear_coef()) == 7
    old_file = {k: v for k, v in untied.to_dict()["coef"].items() if not k.endswith("_held")}
    assert FrictionLayer.from_dict({"model": "seed", "joints": [old_file]}).models_[0].tied_ == (False, False)


def test_the_shared_seed_model_recovers_one_static_level_and_keeps_it_one(rng) -> None:
    """seed_shared: Coulomb per direction, one static level; recovered from friction data, filtered or
    not; the joint refit, the file and the C export's columns keep the two levels one. A seed truth with
    different static levels is fitted at a level between them (it cannot take both)."""
    from dynid.identify.friction_models import SharedSeedFriction

    dq = velocities(rng)
    truth = with_coef(SeedFriction(), [1.0, 0.8, 0.5, 0.2, 0.05, 1.5, 1.5, 0.08])
    F = truth.predict(dq) + 0.02 * rng.normal(size=dq.size)
    fit = SharedSeedFriction().fit(dq, F)
    assert fit.shared_ and fit.tied_ == (False, False) and fit.coef_[5] == fit.coef_[6]
    np.testing.assert_allclose(fit.coef_[:2], truth.coef_[:2], rtol=0.03)
    np.testing.assert_allclose(fit.coef_[5], 1.5, rtol=0.03)
    np.testing.assert_allclose(fit.coef_[7], 0.08, rtol=0.05)
    assert len(fit.linear_coef()) == len(fit.basis(dq[:5]).T) == 6
    np.testing.assert_allclose(fit.basis(dq) @ fit.linear_coef(), fit.predict(dq), atol=1e-12)
    np.testing.assert_allclose(fit.predict(dq), truth.predict(dq), atol=0.05)
    fit.set_linear(fit.linear_coef() * 1.5)  # a joint refit keeps one level
    assert fit.coef_[5] == fit.coef_[6]
    again = FrictionLayer.from_dict(FrictionLayer(model="seed_shared").fit(dq[:, None], F[:, None]).to_dict())
    back = again.models_[0]
    assert isinstance(back, SharedSeedFriction) and back.shared_ and len(back.linear_coef()) == 6
    symbols = [f"c{k}" for k in range(7)]  # the C export adds the columns as it merges them
    assert back.merged(symbols) == ["c0", "c1", "c2", "c3", "c4", "c5c6"]
    # different static levels: one level between them, the seed model takes both
    two = with_coef(SeedFriction(), [1.0, 0.8, 0.5, 0.2, 0.05, 1.9, 1.1, 0.08])
    F2 = two.predict(dq) + 0.02 * rng.normal(size=dq.size)
    shared = SharedSeedFriction().fit(dq, F2)
    assert 1.1 < shared.coef_[5] == shared.coef_[6] < 1.9
    np.testing.assert_allclose(SeedFriction().fit(dq, F2).coef_[5:7], [1.9, 1.1], rtol=0.05)


def test_a_shared_static_level_past_its_cap_is_held_at_the_coulomb_levels(rng) -> None:
    """The burst of a reversal's timing error (Coulomb and viscous friction, no stiction): the shared level
    takes it past the cap, and the static levels are held at their Coulomb levels, as the seed model's are;
    the model predicts a slow motion as the truth does, where the free level is several Coulomb levels off."""
    from dynid.identify.friction_models import SharedSeedFriction

    dq = velocities(rng)
    burst = np.where((np.abs(dq) < 0.004) & (dq < 0), -6.0, 0.0)
    F = 1.0 * np.sign(dq) + 0.5 * dq + burst + 0.02 * rng.normal(size=dq.size)
    free = SharedSeedFriction()
    free.static_ratio = np.inf
    free.fit(dq, F)
    assert free.shared_ and free.coef_[5] > 3 * free.coef_[0]
    fit = SharedSeedFriction().fit(dq, F)
    assert not fit.shared_ and fit.tied_ == (True, True) and np.array_equal(fit.coef_[5:7], fit.coef_[:2])
    assert len(fit.linear_coef()) == len(fit.basis(dq[:5]).T) == 5
    np.testing.assert_allclose(fit.basis(dq) @ fit.linear_coef(), fit.predict(dq), atol=1e-12)
    slow = np.linspace(-0.05, 0.05, 201)
    truth = np.sign(slow) + 0.5 * slow
    assert np.max(np.abs(fit.predict(slow) - truth)) < 1.1 and np.max(np.abs(free.predict(slow) - truth)) > 3
    back = FrictionLayer.from_dict(FrictionLayer(model="seed_shared").fit(dq[:, None], F[:, None]).to_dict())
    assert not back.models_[0].shared_ and back.models_[0].tied_ == (True, True)


def test_after_a_split_no_static_level_is_left_past_its_cap(rng) -> None:
    """A shared level past the cap on one side only: that side is held, and the other side's own level,
    refitted, is held too if it passes its cap (a burst of timing error on the side of a small Coulomb
    level: the seed model holds it there, and so must seed_shared)."""
    from dynid.identify.friction_models import SharedSeedFriction

    dq = velocities(rng)
    burst = np.where((np.abs(dq) < 0.004) & (dq > 0), 3.0, 0.0)
    F = np.where(dq > 0, 1.0, -0.2) + 0.5 * dq + burst + 0.02 * rng.normal(size=dq.size)
    for model in (SeedFriction(), SharedSeedFriction()):
        fit = model.fit(dq, F)
        c = fit.coef_
        assert c[5] <= fit.static_ratio * c[0] + 1e-12 and c[6] <= fit.static_ratio * c[1] + 1e-12, (model, c)
        np.testing.assert_allclose(fit.basis(dq) @ fit.linear_coef(), fit.predict(dq), atol=1e-12)


def test_the_threshold_search_stops_where_its_cost_is_flat_and_not_before_a_sharp_minimum() -> None:
    """A measured cost is flat near its minimum: the golden section stops at a 0.5 % bracket. A
    noise-free cost has a sharp minimum: it is searched its 20 steps and lands on it."""
    from dynid.identify.friction_fitting import shape_search

    best = 0.0137
    candidates = np.geomspace(1e-3, 1.0, 30)
    for floor, most, rtol in ((1.0, 2 + 10, 5e-3), (0.0, 2 + 20, 1e-5)):
        calls = []

        def cost(c, floor=floor, calls=calls):
            calls.append(c)
            return floor + 1e-3 * np.log(c / best) ** 2

        found, sse = shape_search(cost, candidates)
        assert len(sse) == 30 and len(calls) - 30 <= most
        assert abs(np.log(found / best)) < rtol
        if floor:
            assert len(calls) - 30 < 2 + 20  # stopped before the 20 steps


@pytest.mark.parametrize("model", ["linear", "seed", "seed_shared", "stribeck"])
def test_a_joint_at_rest_has_no_friction_direction(rng, model) -> None:
    """Below 1e-3 rad/s a joint's speed is a creep or the noise's, not a direction: the direction-dependent
    levels are off there (a stuck joint's flickering speed must not flip its static level), and on at
    2e-3 rad/s."""
    dq = velocities(rng, 4000)
    F = 0.8 * np.sign(dq) + 0.5 * np.sign(dq) * np.exp(-((dq / 0.05) ** 2)) + 0.3 * dq + 0.05 * rng.normal(size=dq.size)
    layer = FrictionLayer(model=model).fit(dq[:, None], F[:, None])
    at_zero = layer.predict(np.zeros((1, 1)))[0, 0]
    creep = layer.predict(np.array([[-9e-4], [-1e-5], [1e-5], [9e-4]]))[:, 0]
    np.testing.assert_allclose(creep, at_zero, atol=1e-3)  # the viscous part of 9e-4 rad/s at most
    moving = layer.predict(np.array([[-2e-3], [2e-3]]))[:, 0] - at_zero
    assert moving[0] < -0.5 and moving[1] > 0.5, moving


@pytest.mark.parametrize("model", ["seed", "seed_shared"])
def test_the_seed_models_viscous_polynomial_is_not_extrapolated(rng, model) -> None:
    """Fitted over |dq| <= 2 rad/s, the square and cube go on beyond the fastest training speed as their
    secants: continuous there, straight beyond, and the speed limit survives the model file."""
    dq = rng.uniform(-2.0, 2.0, 6000)
    F = 0.5 * np.sign(dq) + 0.1 * dq + 0.08 * dq * np.abs(dq) + 0.02 * dq**3 + 0.01 * rng.normal(size=dq.size)
    layer = FrictionLayer(model=model).fit(dq[:, None], F[:, None])
    mdl = layer.models_[0]
    vmax = mdl.vmax_
    assert vmax == pytest.approx(np.abs(dq).max())
    c = mdl.to_dict()["coef"]
    assert c["kv2"] > 0.05 and c["kv3"] > 0.01  # the polynomial was fitted
    inside = layer.predict(np.array([[vmax * (1 - 1e-9)], [-vmax * (1 - 1e-9)]]))[:, 0]
    edge = layer.predict(np.array([[vmax * (1 + 1e-9)], [-vmax * (1 + 1e-9)]]))[:, 0]
    np.testing.assert_allclose(edge, inside, atol=1e-6)  # continuous at vmax
    v = vmax * np.array([1.5, 2.0, 3.0])
    far = layer.predict(v[:, None])[:, 0]
    slope = c["kv1"] + c["kv2"] * vmax + c["kv3"] * vmax**2
    np.testing.assert_allclose(np.diff(far) / np.diff(v), slope, rtol=1e-9)  # a straight line beyond it
    cubic = c["kc_pos"] + c["kv1"] * v[-1] + c["kv2"] * v[-1] ** 2 + c["kv3"] * v[-1] ** 3
    assert far[-1] < 0.6 * cubic  # where the polynomial would have gone
    again = FrictionLayer.from_dict(layer.to_dict())
    assert again.models_[0].vmax_ == vmax
    np.testing.assert_array_equal(again.predict(v[:, None]), layer.predict(v[:, None]))
    old = layer.to_dict()
    del old["joints"][0]["vmax"]  # a file written before the limit: the polynomial, as it was
    np.testing.assert_allclose(FrictionLayer.from_dict(old).predict(v[-1:, None])[0, 0], cubic, rtol=1e-9)


def test_a_model_file_with_the_speed_limit_or_the_rest_gate_is_version_5(tmp_path, ur5) -> None:
    """A version-4 reader would ignore a seed model's vmax (and extrapolate its polynomial) and a mixture's
    rest gate: such files are written as version 5, which it refuses; a model with neither stays lower."""
    import json

    from dynid.identify.columns import column_set
    from dynid.identify.model import identify, save_model
    from dynid.sim.synthetic import random_fourier, synthetic_dataset, true_parameters

    rng = np.random.default_rng(2)
    cols = column_set(ur5)
    data = synthetic_dataset(cols, true_parameters(cols, rng), random_fourier(ur5, rng), rate=100, rng=rng)
    for friction, gmm, version in (("seed", "off", 5), ("linear", 3, 5), ("linear", "off", 3)):
        model = identify(ur5, data, method="ols", friction=friction, gmm=gmm, reference_weight=0.0)
        save_model(model, tmp_path / "M.json")
        assert json.loads((tmp_path / "M.json").read_text())["version"] == version, (friction, gmm)
