"""The description's prior (dynid.identify.prior): bodies the data cannot see stay as described."""

from __future__ import annotations

import numpy as np
import pytest

from dynid.identify.columns import column_set
from dynid.identify.consistent import described_bodies, pseudo_inertia
from dynid.identify.linear_system import build_system
from dynid.identify.model import identify
from dynid.identify.prior import GRID, TOLERANCE, choose_prior, link_report, prior_precision
from dynid.sim.synthetic import random_fourier, synthetic_dataset, true_parameters


@pytest.fixture(scope="module")
def run(ur5):
    """A UR5 whose true bodies differ from its URDF's (random standard parameters), 10 s at 100 Hz."""
    rng = np.random.default_rng(17)
    cols = column_set(ur5)
    x = true_parameters(cols, rng)
    return synthetic_dataset(cols, x, random_fourier(ur5, rng), rate=100, rng=rng, noise=0.05)


def test_the_quadratic_form_is_the_divergence_near_the_description(ur5, rng):
    phi_ref, Lam = prior_precision(ur5, column_set(ur5))
    d = 1e-4 * rng.normal(size=10) * np.abs(ur5.params[:10])
    J, Jr = pseudo_inertia(ur5.params[:10] + d), pseudo_inertia(ur5.params[:10])
    M = np.linalg.solve(Jr, J)
    exact = np.trace(M) - np.linalg.slogdet(M)[1] - 4
    np.testing.assert_allclose(d @ Lam[:10, :10] @ d, exact, rtol=1e-3)
    assert np.allclose(phi_ref[:10], ur5.params[:10])


def test_a_link_the_data_cannot_see_keeps_its_description(ur5, run):
    """Link 1 turns about the vertical axis only: its mass never reaches a joint torque."""
    model = identify(ur5, run, method="ols", friction="linear", gmm="off")
    phi = model.standard_params
    np.testing.assert_allclose(phi[0, 0], ur5.params[0], rtol=1e-6)
    links = model.links()
    assert links[0]["decided_by"] == "description" and links[0]["mass_ratio"] == pytest.approx(1.0, rel=1e-6)
    # where the data do see the bodies, they move them: some link is decided by the data or by both
    assert any(body["decided_by"] in ("data", "both") for body in links)


def test_a_link_held_at_the_bound_is_not_said_to_be_the_descriptions(ur5, run):
    """A link the data hardly see that sits at the consistency bound was moved by the bound: 'bound', not
    'description' (which would read as unchanged)."""
    from dataclasses import replace

    model = identify(ur5, run, method="ols", friction="linear", gmm="off")
    assert model.links()[0]["decided_by"] == "description"
    info = {**model.info, "consistency": {**model.info["consistency"], "at_bound": [1]}}
    links = replace(model, info=info).links()
    assert links[0]["decided_by"] == "bound" and links[0]["at_bound"]
    assert [b["decided_by"] for b in links[1:]] == [b["decided_by"] for b in model.links()[1:]]


def test_described_bodies_change_no_identified_parameter(ur5, run):
    model = identify(ur5, run, method="ols", friction="linear", gmm="off", reference_weight=0.0)
    cols = model.columns
    n = cols.n
    phi = np.concatenate([model.standard_params.ravel(), np.zeros(4 * n)])
    # a body far from the description with the same identified parameters: along the null space
    link = np.array(cols.kinds) == "link"
    _, _, Vt = np.linalg.svd(cols.P[link][:, : 10 * n])
    null = Vt[np.sum(np.linalg.svd(cols.P[link][:, : 10 * n], compute_uv=False) > 1e-10) :].T
    moved, info = described_bodies(ur5, cols, phi, eps=1e-9)
    np.testing.assert_allclose(cols.P[link] @ moved, cols.P[link] @ phi, rtol=1e-9, atol=1e-12)
    assert info["directions"] >= null.shape[1] > 0
    assert info["divergence"]["end"] <= info["divergence"]["start"] + 1e-9


def test_the_strength_is_the_strongest_within_the_tolerance_of_the_best(ur5, run):
    system = build_system(ur5, run, friction=True, armature=True)
    choice = choose_prior(ur5, system)
    cv = choice.cv_rms
    score = np.mean(cv / cv.min(axis=0), axis=1)
    pick = GRID.index(choice.weight)
    assert score[pick] <= (1 + TOLERANCE) * score.min() + 1e-12
    assert all(score[k] > (1 + TOLERANCE) * score.min() for k in range(pick + 1, len(GRID)))
    assert choice.kappa >= 1 and choice.data_share.shape == (6,)
    assert np.all((choice.data_share >= 0) & (choice.data_share <= 1))


def test_link_report_measures_the_move(ur5):
    phi = ur5.params.reshape(6, 10).copy()
    phi[2] *= 2.0  # link 3 twice as heavy, same shape: the centre of mass stays
    report = link_report(ur5, phi)
    assert report[2]["mass_ratio"] == pytest.approx(2.0) and report[2]["com_shift"] == pytest.approx(0.0, abs=1e-12)
    assert report[2]["divergence"] == pytest.approx(4 * (2 - np.log(2) - 1))
    assert report[0]["divergence"] == pytest.approx(0.0, abs=1e-9) and report[0]["decided_by"] is None
    # who decided: the data's share of the uncertainty removed, and for a small share whether the body stayed
    share = np.array([0.0, 0.95, 0.05, 0.5, 0.05, 0.05])
    phi[4] *= 1.2  # 4 (1.2 - ln 1.2 - 1) = 0.071: stayed near the description
    phi[5] *= 1.3  # 0.150: moved, by the few combinations the data see
    decided = [r["decided_by"] for r in link_report(ur5, phi, share)]
    assert decided == ["description", "data", "shared", "both", "description", "shared"]


def test_noise_free_data_choose_a_prior_and_fit_to_rounding(tmp_path):
    """A simulation without noise fits the link parameters to rounding: the prior's cross-validation,
    whose data term is in squared standard deviations, floors the residual instead of dividing by 0
    (a LinAlgError from the consistent fit on such data, for an arm whose joints turn a full turn)."""
    import warnings

    from dynid.identify.columns import column_set
    from dynid.identify.model import identify
    from dynid.sim.synthetic import random_fourier, synthetic_dataset, true_parameters
    from dynid.symbolic.robot import example_robot_data_dir, load_robot

    text = (example_robot_data_dir() / "ur_description" / "urdf" / "ur5_robot.urdf").read_text()
    (tmp_path / "ur5c.urdf").write_text(text.replace('type="revolute"', 'type="continuous"'))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        robot = load_robot(tmp_path / "ur5c.urdf")
        rng = np.random.default_rng(0)
        cols = column_set(robot)
        data = synthetic_dataset(
            cols, true_parameters(cols, rng), random_fourier(robot, rng), rate=100, rng=rng, noise=0.0
        )
        model = identify(robot, data, method="ols", friction="linear", gmm="off")
    scale = np.sqrt(np.mean(data.tau**2, axis=0))
    assert np.all(np.isfinite(model.params)) and np.all(model.rms <= 1e-6 * scale)
