"""Physically consistent fit, the three-layer pipeline, the model file and 'dynid identify'."""

from __future__ import annotations

import json
import re
import warnings

import numpy as np
import pytest

from dynid.cli import main
from dynid.data.files import save_dataset
from dynid.exceptions import ModelFileError
from dynid.identify.columns import column_set
from dynid.identify.consistent import (
    EPS,
    ConsistentLS,
    consistent_solution,
    is_consistent,
    log_cholesky,
    pseudo_inertia,
    standard_from_pseudo_inertia,
)
from dynid.identify.estimators import IRLS, IdentificationWarning
from dynid.identify.friction import SeedFriction
from dynid.identify.linear_system import build_system
from dynid.identify.model import identify, load_model, save_model
from dynid.sim.simulator import perturb_params
from dynid.sim.synthetic import random_fourier, synthetic_dataset, true_parameters


def test_log_cholesky_round_trip(ur5) -> None:
    for link in ur5.params.reshape(6, 10):
        J = pseudo_inertia(link)
        theta = log_cholesky(J)
        U = np.triu(np.zeros((4, 4)))
        U[np.triu_indices(4)] = [theta[0], *theta[1:4], theta[4], *theta[5:7], theta[7], theta[8], theta[9]]
        U[np.diag_indices(4)] = np.exp(np.diag(U))
        np.testing.assert_allclose(U @ U.T, J, atol=1e-14)
        np.testing.assert_allclose(standard_from_pseudo_inertia(J), link, atol=1e-14)


def test_consistent_fit_returns_a_consistent_estimate_unchanged(ur5) -> None:
    rng = np.random.default_rng(21)
    cols = column_set(ur5)
    x = true_parameters(cols, rng)
    ds = synthetic_dataset(cols, x, random_fourier(ur5, rng, periods=2), rate=50, rng=rng, noise=0.01)
    system = build_system(ur5, ds)
    fit = ConsistentLS(robot=ur5).fit(system)
    unc = IRLS(robot=ur5).fit(system)
    np.testing.assert_allclose(fit.params_, unc.params_, rtol=1e-9, atol=1e-12)
    assert np.all(fit.min_eigenvalues_ > 0)
    np.testing.assert_allclose(cols.P @ np.concatenate([fit.standard_, fit.extras_]), fit.params_, atol=1e-9)


@pytest.mark.parametrize("reference_weight", [0.0, 0.01])
def test_consistent_fit_makes_an_impossible_estimate_physical(ur5, reference_weight) -> None:
    rng = np.random.default_rng(22)
    cols = column_set(ur5)
    params = ur5.params.copy()
    params[10 * 5 + 6] = -0.02  # Iyy6 < 0: no body has that, and Iyy6 is a base parameter alone
    extras = np.concatenate([np.full(6, 0.02), rng.uniform(0.5, 3, 6), rng.uniform(0.2, 2, 6), np.zeros(6)])
    x_bad = cols.P @ np.concatenate([params, extras])
    ds = synthetic_dataset(cols, x_bad, random_fourier(ur5, rng), rate=10, rng=rng, noise=0.3)  # few, noisy
    k = cols.names.index("Iyy6")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no "stopped before its tolerance"
        fit = ConsistentLS(robot=ur5, reference_weight=reference_weight).fit(ds)
    assert fit.solver_["status"] == "converged" and 0 < fit.solver_["iterations"] < 300
    assert fit.unconstrained_.params_[k] < 0  # the unconstrained estimate is inconsistent
    assert np.all(fit.min_eigenvalues_ >= EPS * (1 - 1e-6))  # consistent with the margin
    assert np.all(np.linalg.eigvalsh(pseudo_inertia(fit.standard_.reshape(6, 10))) > 0)
    assert fit.params_[k] >= 0
    kinds = np.array(cols.kinds)
    assert np.all(fit.params_[np.isin(kinds, ["armature", "coulomb", "viscous"])] >= 0)
    assert fit.distance_["mahalanobis"] > 1 and np.mean(fit.distance_["rms_change"]) >= -1e-12
    np.testing.assert_allclose(cols.P @ np.concatenate([fit.standard_, fit.extras_]), fit.params_, atol=1e-9)


def test_consistent_fit_leaves_a_consistent_estimate_alone_even_when_it_must_search(ur5) -> None:
    # standard parameters far from the URDF (50 % perturbation, still physical): the vector nearest
    # the URDF with the same base parameters is not consistent, so the fit searches; it must come
    # back to the estimate itself, to solver tolerance
    rng = np.random.default_rng(10)
    cols = column_set(ur5)
    params = perturb_params(ur5.params, 0.5, rng)
    extras = np.concatenate([np.full(6, 0.02), rng.uniform(0.5, 3, 6), rng.uniform(0.2, 2, 6), np.zeros(6)])
    x = cols.P @ np.concatenate([params, extras])
    R = np.linalg.qr(rng.normal(size=(cols.p, cols.p)))[1] * 100  # some whitened factor
    phi, solver = consistent_solution(ur5, cols, x, R, 1.0)
    assert solver["status"] == "converged" and solver["iterations"] > 0
    assert np.linalg.norm(R @ (cols.P @ phi - x)) < 1e-3  # in standard deviations
    assert is_consistent(phi[:60], tol=EPS * (1 - 1e-6)).all()


@pytest.fixture(scope="module")
def pipeline_data(ur5):
    rng = np.random.default_rng(23)
    cols = column_set(ur5, friction=False)
    x = true_parameters(cols, rng)
    frictions = [SeedFriction().__class__() for _ in range(6)]
    for j, f in enumerate(frictions):
        f.coef_ = np.array([1.0 + 0.2 * j, 0.8, 0.5, 0.2, 0.05, 1.6, 1.3, 0.08])

    def extra(q, dq):  # the paper's friction (nonlinear, with a low-speed region) on every joint
        return np.column_stack([f.predict(dq[:, j]) for j, f in enumerate(frictions)])

    train = synthetic_dataset(
        cols, x, random_fourier(ur5, rng, periods=3), rate=100, rng=rng, noise=0.1, extra=extra
    )
    test = synthetic_dataset(
        cols, x, random_fourier(ur5, rng, periods=1), rate=100, rng=rng, noise=0.1, extra=extra
    )
    return train, test


def heldout_rms(model, ds) -> float:
    return float(np.sqrt(np.mean((model.predict(ds) - model.prepare(ds).tau_reference) ** 2)))


def test_three_layers_beat_ols_on_held_out_data_and_survive_a_file(ur5, pipeline_data, tmp_path) -> None:
    train, test = pipeline_data
    ols = identify(ur5, train, method="ols", friction="linear", gmm="off")
    full = identify(ur5, train, method="gls", friction="seed", gmm="auto")
    noise = 0.1  # N m, the simulated white noise
    excess_ols = heldout_rms(ols, test) ** 2 - noise**2
    excess_full = heldout_rms(full, test) ** 2 - noise**2
    assert excess_full < 0.75 * excess_ols  # the nonlinear friction is what OLS + linear friction misses
    assert full.rms_layers["gmm"][0] <= full.rms_layers["friction"][0] <= full.rms_layers["link"][0]
    json_path, _ = save_model(full, tmp_path / "M.json")
    again = load_model(json_path)
    np.testing.assert_allclose(again.predict(test), full.predict(test), atol=1e-10)
    q, dq, ddq = test.q[:50], test.dq[:50], test.ddq[:50]
    np.testing.assert_allclose(again.predict(q, dq, ddq), full.predict(q, dq, ddq), atol=1e-10)
    doc = json.loads(json_path.read_text())
    for key in ("base_params", "std_percent", "cond", "rms", "preprocessing", "friction", "robot"):
        assert key in doc
    assert doc["robot"]["key"] == ur5.key and doc["friction"]["model"] == "seed"


@pytest.fixture(scope="module")
def ripple_data(ur5):
    """The paper's friction plus a smooth position-dependent torque on every joint (0.3 N m)."""
    rng = np.random.default_rng(24)
    cols = column_set(ur5, friction=False)
    x = true_parameters(cols, rng)
    frictions = [SeedFriction() for _ in range(6)]
    for j, f in enumerate(frictions):
        f.coef_ = np.array([1.0 + 0.2 * j, 0.8, 0.5, 0.2, 0.05, 1.6, 1.3, 0.08])

    def extra(q, dq):
        return np.column_stack([f.predict(dq[:, j]) for j, f in enumerate(frictions)]) + 0.3 * np.sin(
            2 * q + 0.5
        )

    train = synthetic_dataset(
        cols, x, random_fourier(ur5, rng, periods=3), rate=100, rng=rng, noise=0.1, extra=extra
    )
    test = synthetic_dataset(
        cols, x, random_fourier(ur5, rng, periods=1), rate=100, rng=rng, noise=0.1, extra=extra
    )
    return train, test


def test_layers_fitted_together_generalise_where_the_sequence_does_not(ur5, ripple_data) -> None:
    # in sequence, layer 1 soaks up part of the ripple and the nonlinear friction along the training
    # motion; the correction then learns a residual of that motion (held-out excess ~ OLS's)
    train, test = ripple_data
    noise = 0.1
    warnings.simplefilter("ignore", IdentificationWarning)  # the held-out motion leaves q_3's range a little
    joint = identify(ur5, train)
    sequence = identify(ur5, train, rounds=0)
    ols = identify(ur5, train, method="ols", friction="linear", gmm="off")
    excess = {
        label: heldout_rms(m, test) ** 2 - noise**2
        for label, m in (("joint", joint), ("sequence", sequence), ("ols", ols))
    }
    assert excess["joint"] < 0.2 * excess["sequence"] and excess["joint"] < 0.2 * excess["ols"]
    assert joint.gmr is not None and joint.gmr.active_.all() and joint.layers_filtered
    assert joint.info["refinement"]["rounds"] == 2
    # the model file keeps what predicts: same held-out prediction after a round trip
    # (rms_layers are those of the identification data, and predict() reproduces them)
    ref = joint.prepare(train).tau_reference
    np.testing.assert_allclose(
        np.sqrt(np.mean((joint.predict(train) - ref) ** 2, axis=0)), joint.rms_layers["gmm"], rtol=1e-6
    )


def test_bad_model_files_give_one_clear_error(ur5, pipeline_data, tmp_path) -> None:
    from dynid.symbolic import load_robot

    train, _ = pipeline_data
    model = identify(ur5, train, method="ols", friction="linear", gmm="off")
    json_path, npz_path = save_model(model, tmp_path / "M.json")
    with pytest.raises(ModelFileError, match=r"M.json was identified for the robot 'ur5' .*not for 'ur10'"):
        load_model(json_path, robot=load_robot("ur10"))
    npz_path.write_bytes(npz_path.read_bytes()[:-10])
    with pytest.raises(ModelFileError, match=r"M.npz is not the arrays file M.json was written with"):
        load_model(json_path)
    json_path.write_text("{not json")
    with pytest.raises(ModelFileError, match=r"M.json is not a readable dynid model file"):
        load_model(json_path)
    with pytest.raises(ModelFileError, match=r"the folder .* does not exist"):
        save_model(model, tmp_path / "missing" / "M.json")
    assert not (tmp_path / "missing").exists()


def test_a_pair_renamed_together_loads_and_one_renamed_apart_says_so(ur5, pipeline_data, tmp_path) -> None:
    """arm.json and arm.npz, renamed from M.json and M.npz, are the same model (the JSON still names M.npz);
    a JSON renamed without its arrays, or beside another model's, is refused in one sentence saying so."""
    train, test = pipeline_data
    model = identify(ur5, train, method="ols", friction="linear", gmm="off")
    other = identify(ur5, train, method="ols", friction="linear", gmm="off", reference_weight=0.0)
    save_model(model, tmp_path / "M.json")
    (tmp_path / "M.json").rename(tmp_path / "arm.json")
    (tmp_path / "M.npz").rename(tmp_path / "arm.npz")
    again = load_model(tmp_path / "arm.json")
    np.testing.assert_array_equal(again.predict(test), model.predict(test))
    (tmp_path / "arm.npz").unlink()
    with pytest.raises(ModelFileError, match=r"arm.json keeps its arrays in M.npz, which is missing; copy M.npz "
                       r"beside arm.json \(or as arm.npz, if the pair was renamed\)"):  # fmt: skip
        load_model(tmp_path / "arm.json")
    save_model(other, tmp_path / "M.json")  # another model's pair beside it
    with pytest.raises(ModelFileError, match=r"M.npz is not the arrays file arm.json was written with \(checksum "
                       r"differs\): the pair was copied or renamed apart"):  # fmt: skip
        load_model(tmp_path / "arm.json")


def test_identify_command_writes_the_model_and_figures(ur5, pipeline_data, tmp_path, capsys) -> None:
    train, _ = pipeline_data
    data = save_dataset(train, tmp_path / "D.csv")
    out, figs = tmp_path / "M.json", tmp_path / "F.json"
    code = main(
        [
            "identify",
            "--robot",
            "ur5",
            "--data",
            str(data),
            "--method",
            "gls",
            "--friction",
            "linear",
            "--gmm",
            "off",
            "--out",
            str(out),
            "--json",
            str(figs),
        ]
    )
    assert code == 0
    figures = json.loads(figs.read_text())
    assert set(figures) >= {"base_params", "std_percent", "cond", "rms"}
    assert len(figures["rms"]) == 6 and figures["method"] == "gls"
    assert load_model(out).method == "gls"
    code = main(["identify", "--robot", "panda", "--data", str(data), "--out", str(tmp_path / "P.json")])
    assert code == 2
    assert "q has 6 columns; the robot 'panda' has 7 joints" in capsys.readouterr().err
    assert not (tmp_path / "P.json").exists()


@pytest.fixture(scope="module")
def impossible_data(ur5):
    """Few noisy samples of a UR5 whose Iyy6 < 0: its unconstrained estimate has no consistent body."""
    rng = np.random.default_rng(22)
    cols = column_set(ur5)
    params = ur5.params.copy()
    params[10 * 5 + 6] = -0.02  # Iyy6 < 0: no body has that, and Iyy6 is a base parameter alone
    extras = np.concatenate([np.full(6, 0.02), rng.uniform(0.5, 3, 6), rng.uniform(0.2, 2, 6), np.zeros(6)])
    x_bad = cols.P @ np.concatenate([params, extras])
    return synthetic_dataset(cols, x_bad, random_fourier(ur5, rng), rate=10, rng=rng, noise=0.3)


@pytest.mark.parametrize("friction", ["linear", "seed"])  # layer 1 alone; the layers refitted together
def test_default_fit_has_consistent_links_and_names_the_link_at_the_bound(
    ur5, impossible_data, friction, tmp_path, capsys
) -> None:
    k = column_set(ur5).names.index("Iyy6")
    free = identify(ur5, impossible_data, method="irls", friction=friction, gmm="off", physical=False)
    assert free.params[k] < 0 and free.standard_params is None and "consistency" not in free.info
    # the projection alone (no pull toward the description, whose log-det keeps every body off the bound)
    model = identify(ur5, impossible_data, method="irls", friction=friction, gmm="off", reference_weight=0.0)
    c = model.info["consistency"]
    assert model.params[k] >= 0
    phi = model.standard_params
    assert phi.shape == (6, 10)
    assert np.all(np.linalg.eigvalsh(pseudo_inertia(phi)).min(axis=1) >= EPS * (1 - 1e-6))
    # the standard set reproduces the model's base parameters; where an armature is folded into a link's
    # base parameter (joint 1's axis), the rest is that armature, non-negative
    cols = model.columns
    x_from_phi = cols.P[:, :60] @ phi.ravel()
    link = np.array(cols.kinds) == "link"
    folded = np.any(cols.P[:, 60:66] != 0, axis=1)
    np.testing.assert_allclose(x_from_phi[link & ~folded], model.params[link & ~folded], rtol=1e-7, atol=1e-9)
    assert np.all(model.params[link & folded] - x_from_phi[link & folded] >= -1e-9)
    # with 1 period at 10 Hz and 0.3 N m of noise the data push every link against the bound (each
    # multiplier >= 6 squared std); a consistent estimate names none (the test below)
    assert 6 in c["at_bound"] and model.info["bounds"]["links_at_bound"] == c["at_bound"]
    assert c["mahalanobis"] > 1 and max(c["rms_rise"]) > 1.005  # per joint: the weighted sum rises
    # the model file (version 3; 5 with the seed model's speed limit) carries the bodies, as a URDF inertial
    # takes them
    json_path, _ = save_model(model, tmp_path / "M.json")
    doc = json.loads(json_path.read_text())
    assert doc["version"] == (3 if friction == "linear" else 5) and len(doc["links"]) == 6 and doc["links"][5]["at_bound"]
    body = doc["links"][5]
    c6 = np.array(body["com"])
    ixx, ixy, ixz, iyy, iyz, izz = body["inertia_com"]
    Ic = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
    np.testing.assert_allclose(
        Ic + body["mass"] * (c6 @ c6 * np.eye(3) - np.outer(c6, c6)),
        [
            [phi[5, 4], phi[5, 5], phi[5, 7]],
            [phi[5, 5], phi[5, 6], phi[5, 8]],
            [phi[5, 7], phi[5, 8], phi[5, 9]],
        ],
        atol=1e-12,
    )
    again = load_model(json_path, robot=ur5)
    np.testing.assert_allclose(again.standard_params, phi, atol=0)
    # a version-2 file (no bodies) still loads
    del doc["links"], doc["consistency"]
    doc["version"] = 2
    json_path.write_text(json.dumps(doc))
    old = load_model(json_path, robot=ur5)
    assert old.standard_params is None and old.links() is None
    np.testing.assert_allclose(old.params, model.params, atol=0)
    # the command says which link is held at the bound
    data = save_dataset(impossible_data, tmp_path / "D.csv")
    assert (
        main(
            [
                "identify",
                "--robot",
                "ur5",
                "--data",
                str(data),
                "--gmm",
                "off",
                "--reference-weight",
                "0",
                "--out",
                str(tmp_path / "C.json"),
            ]
        )
        == 0
    )
    assert re.search(r"held at the physical-consistency bound on links? [0-9, ]*6 ", capsys.readouterr().out)


def test_default_fit_keeps_an_estimate_that_is_consistent_as_it_is(ur5) -> None:
    rng = np.random.default_rng(21)  # the data of test_consistent_fit_returns_a_consistent_estimate_unchanged
    cols = column_set(ur5)
    x = true_parameters(cols, rng)
    ds = synthetic_dataset(cols, x, random_fourier(ur5, rng, periods=2), rate=50, rng=rng, noise=0.01)
    # without the description's prior (weight 0) a consistent estimate is the answer as it is
    model = identify(ur5, ds, method="irls", friction="linear", gmm="off", reference_weight=0.0)
    free = identify(ur5, ds, method="irls", friction="linear", gmm="off", physical=False)
    assert model.info["consistency"]["at_bound"] == [] and model.info["bounds"]["active"] == []
    assert model.info["consistency"]["mahalanobis"] < 1e-6
    np.testing.assert_allclose(model.params, free.params, rtol=1e-9, atol=1e-12)
    assert np.all(np.linalg.eigvalsh(pseudo_inertia(model.standard_params)).min(axis=1) > 0)
    # with it (the default), the cross-validated pull may move the links only as far as the data allow:
    # the training fit stays within the rule's tolerance of the unconstrained one on every joint
    pulled = identify(ur5, ds, method="irls", friction="linear", gmm="off")
    prior = pulled.info["prior"]
    assert prior["weight"] in prior["grid"] and "cross-validation" in prior["rule"]
    assert np.all(pulled.rms <= 1.05 * free.rms)


def test_a_prediction_far_outside_the_training_torque_says_so_in_one_sentence(ur5, tmp_path) -> None:
    rng = np.random.default_rng(5)
    cols = column_set(ur5)
    x = true_parameters(cols, rng)
    train = synthetic_dataset(cols, x, random_fourier(ur5, rng), rate=50, rng=rng, noise=0.01)
    held = synthetic_dataset(cols, x, random_fourier(ur5, rng), rate=50, rng=rng, noise=0.01)
    model = identify(ur5, train, method="ols", friction="linear", gmm="off")
    lo, hi = np.asarray(model.info["torque_range"]).T
    assert np.all(lo < hi)
    with warnings.catch_warnings():
        warnings.simplefilter("error", IdentificationWarning)
        model.predict(held)  # a motion like the training one: silent
    q, dq, ddq = (np.asarray(held.q), np.asarray(held.dq), np.asarray(held.ddq))
    with pytest.warns(IdentificationWarning, match=r"leaves the training torque's range by far on joint\(s\) .*2"):
        model.predict(q, 30 * dq, 300 * ddq)
    # the range travels with the model file
    json_path, _ = save_model(model, tmp_path / "M.json")
    again = load_model(json_path, robot=ur5)
    assert again.info["torque_range"] == model.info["torque_range"] and "prior" in again.info
    with pytest.warns(IdentificationWarning, match="leaves the training torque's range by far"):
        again.predict(q, 30 * dq, 300 * ddq)


def test_the_range_warning_gives_the_extreme_on_the_side_it_leaves(ur5) -> None:
    """A joint trained on 12.7..18.3 N m that predicts -13.5 reads 'down to -13.5', not 'up to 13.5' (which
    lies inside the range it says was left)."""
    from dataclasses import replace

    rng = np.random.default_rng(6)
    cols = column_set(ur5)
    train = synthetic_dataset(cols, true_parameters(cols, rng), random_fourier(ur5, rng), rate=50, rng=rng)
    model = identify(ur5, train, method="ols", friction="linear", gmm="off")
    q, dq, ddq = (np.asarray(train.q), np.asarray(train.dq), np.asarray(train.ddq))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tau = model.predict(q, dq, ddq)
    ranges = np.asarray(model.info["torque_range"], dtype=float)
    j = 1
    span = np.ptp(tau[:, j])
    for side, (lo, hi), word, extreme in (
        ("above", (tau[:, j].max() + 3 * span, tau[:, j].max() + 4 * span), "down to", tau[:, j].min()),
        ("below", (tau[:, j].min() - 4 * span, tau[:, j].min() - 3 * span), "up to", tau[:, j].max()),
    ):
        r = ranges.copy()
        r[j] = lo, hi
        moved = replace(model, info={**model.info, "torque_range": r.tolist()})
        with pytest.warns(IdentificationWarning) as caught:
            moved.predict(q, dq, ddq)
        text = str(caught[0].message)
        assert f"joint {j + 1}: {word} {extreme:.4g} N m, trained on {lo:.3g}..{hi:.3g}" in text, (side, text)


def test_a_model_identified_from_a_relative_urdf_path_loads_from_another_folder(ur5, tmp_path, monkeypatch):
    """The model file names its description as given, and as found from the model's own folder: a
    command run elsewhere (export, validate) finds the same file."""
    import shutil

    from dynid.symbolic.robot import example_robot_data_dir, load_robot

    (tmp_path / "x").mkdir()
    (tmp_path / "other").mkdir()
    shutil.copy(example_robot_data_dir() / "ur_description" / "urdf" / "ur5_robot.urdf", tmp_path / "x" / "ur5.urdf")
    monkeypatch.chdir(tmp_path)
    robot = load_robot("x/ur5.urdf")
    rng = np.random.default_rng(3)
    cols = column_set(robot)
    data = synthetic_dataset(cols, true_parameters(cols, rng), random_fourier(robot, rng), rate=100, rng=rng)
    model = identify(robot, data, method="ols", friction="linear", gmm="off", physical=False)
    save_model(model, tmp_path / "M.json")
    doc = json.loads((tmp_path / "M.json").read_text())
    assert doc["robot"]["source"] == "x/ur5.urdf" and doc["robot"]["source_from_model"] == "x/ur5.urdf"
    monkeypatch.chdir(tmp_path / "other")
    again = load_model("../M.json")
    np.testing.assert_array_equal(again.params, model.params)
    assert again.robot.key == robot.key
    text = (tmp_path / "x" / "ur5.urdf").read_text()
    edited = text.replace('<mass value="3.7"/>', '<mass value="3.9"/>', 1)
    assert edited != text
    (tmp_path / "x" / "ur5.urdf").write_text(edited)  # the same arm, its shoulder's mass edited
    with pytest.raises(ModelFileError, match=r"identified on the description 'x/ur5.urdf', which has changed since"):
        load_model("../M.json")
    (tmp_path / "x" / "ur5.urdf").unlink()  # gone everywhere: one sentence naming what to give
    with pytest.raises(ModelFileError, match=r"cannot be loaded here .*give the robot it was identified for"):
        load_model("../M.json")


def test_a_model_finds_its_own_description_before_a_namesake_in_the_current_folder(tmp_path, monkeypatch):
    """Identified with --robot robot.urdf (a UR5) in folder A, loaded from folder B whose robot.urdf is
    another arm: the model's own file (found from the model's folder) is taken, not the namesake."""
    import shutil

    from dynid.symbolic.robot import example_robot_data_dir, load_robot

    urdfs = example_robot_data_dir() / "ur_description" / "urdf"
    for folder, arm in (("A", "ur5_robot.urdf"), ("B", "ur10_robot.urdf")):
        (tmp_path / folder).mkdir()
        shutil.copy(urdfs / arm, tmp_path / folder / "robot.urdf")
    monkeypatch.chdir(tmp_path / "A")
    robot = load_robot("robot.urdf")
    rng = np.random.default_rng(4)
    cols = column_set(robot)
    data = synthetic_dataset(cols, true_parameters(cols, rng), random_fourier(robot, rng), rate=100, rng=rng)
    save_model(identify(robot, data, method="ols", friction="linear", gmm="off", physical=False), "M.json")
    monkeypatch.chdir(tmp_path / "B")
    assert load_model("../A/M.json").robot.key == robot.key


def test_a_recording_the_description_cannot_explain_is_said_in_one_sentence(ur5) -> None:
    """Joints 2 and 3 logged in each other's columns, or joint 2's torque with the other sign: the fit
    leaves a large share of the torque (0.38, 0.91) and one warning says what to check; the recording as
    it is (0.008) gets none."""
    from dataclasses import replace

    from dynid.identify.fit_figures import UNEXPLAINED

    rng = np.random.default_rng(8)
    cols = column_set(ur5)
    x = cols.P @ np.concatenate([ur5.params, np.zeros(cols.P.shape[1] - ur5.params.size)])
    data = synthetic_dataset(cols, x, random_fourier(ur5, rng, periods=2, base_freq=0.2), rate=100, rng=rng, noise=0.05)
    fit = dict(method="ols", friction="linear", gmm="off")
    with warnings.catch_warnings(record=True) as own:
        warnings.simplefilter("always")
        identify(ur5, data, **fit)
    assert not [w for w in own if "unexplained" in str(w.message)]
    idx = [0, 2, 1, 3, 4, 5]
    swapped = replace(data, q=data.q[:, idx], tau=data.tau[:, idx], dq=data.dq[:, idx], ddq=data.ddq[:, idx])
    tau = data.tau.copy()
    tau[:, 1] *= -1.0
    for wrong in (swapped, replace(data, tau=tau)):
        with pytest.warns(IdentificationWarning, match=r"leaves \d+ % of the training torque unexplained") as caught:
            model = identify(ur5, wrong, **fit)
        (said,) = [str(w.message) for w in caught if "unexplained" in str(w.message)]
        share = int(said.split("leaves ")[1].split(" %")[0]) / 100
        assert share > UNEXPLAINED and "joints in the recording's order" in said
        measured = np.sqrt(np.sum(np.asarray(model.rms) ** 2) / np.sum(np.var(model.prepare(wrong).tau_reference, axis=0)))
        assert share == pytest.approx(measured, abs=0.006)
