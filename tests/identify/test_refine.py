"""The joint refit of link parameters, friction and mixture experts (dynid.identify.refine)."""

from __future__ import annotations

import os

import numpy as np
import pytest

from dynid.identify.columns import column_set
from dynid.identify.estimators import OLS
from dynid.identify.friction import StribeckFriction
from dynid.identify.linear_system import build_system
from dynid.identify.refine import refine
from dynid.sim.synthetic import random_fourier, synthetic_dataset, true_parameters

NOISES = (0.1, 0.01)  # N m, white torque noise


def _linear_case(ur5, noise: float):
    """Link parameters, armature and linear friction as the truth; the same motion and noise pattern."""
    rng = np.random.default_rng(41)
    cols = column_set(ur5)
    x = true_parameters(cols, rng)
    ds = synthetic_dataset(cols, x, random_fourier(ur5, rng, periods=2), rate=100, rng=rng, noise=noise)
    system = build_system(ur5, ds)
    start = OLS(robot=ur5).fit(system)
    out = refine(system, start.params_, start.omega_, friction="linear", gmm="off", weighting="none")
    return x, start, out


STRIBECK = np.column_stack(
    [1.0 + 0.2 * np.arange(6), 1.8 + 0.2 * np.arange(6), np.full(6, 0.5), np.full(6, 0.1), np.full(6, 0.05)]
)
"""True Stribeck coefficients per joint: fc, fs (N m), fv (N m s/rad), fo (N m), vs (rad/s)."""


def _stribeck_case(ur5, noise: float):
    """Link parameters and armature plus a Stribeck friction that layer 1's linear friction cannot express."""
    rng = np.random.default_rng(42)
    cols = column_set(ur5)
    n = ur5.n
    x = cols.P @ np.concatenate([ur5.params, rng.uniform(0.01, 0.05, n), np.zeros(3 * n)])
    models = [StribeckFriction() for _ in range(n)]
    for model, coef in zip(models, STRIBECK, strict=True):
        model.coef_ = coef

    def friction(q, dq):
        return np.column_stack([model.predict(dq[:, j]) for j, model in enumerate(models)])

    traj = random_fourier(ur5, rng, periods=2)
    ds = synthetic_dataset(cols, x, traj, rate=100, rng=rng, noise=noise, extra=friction)
    system = build_system(ur5, ds)
    start = OLS(robot=ur5).fit(system)
    out = refine(system, start.params_, start.omega_, friction="stribeck", gmm="off", weighting="none")
    return x, start, out, cols.link_mask


def test_the_joint_refit_of_a_linear_model_recovers_it_within_its_deviations(ur5) -> None:
    x, start, out = _linear_case(ur5, NOISES[0])
    assert (
        out.mask.all() and out.friction is None and out.gmr is None
    )  # linear friction: refined with the links
    std = np.sqrt(np.diag(out.cov))
    z = (out.params - x) / std
    assert np.abs(z).max() < 4.5
    assert 0.5 < np.sqrt(np.mean(z**2)) < 1.6  # the reported deviations are the errors' size
    # nothing to eliminate and all joints weighed alike: the joint least squares is OLS
    np.testing.assert_allclose(out.params, start.params_, rtol=1e-8, atol=1e-10 * np.abs(x).max())
    np.testing.assert_allclose(np.sqrt(np.mean(out.residual**2, axis=0)), start.rms_, rtol=1e-8)


def test_the_joint_refit_error_shrinks_with_the_noise(ur5) -> None:
    errors = []
    for noise in NOISES:
        x, _, out = _linear_case(ur5, noise)
        errors.append(np.linalg.norm(out.params - x))
    assert errors[1] < 0.15 * errors[0]  # a tenth of the noise: about a tenth of the error


@pytest.fixture(scope="module")
def stribeck_fits(ur5):
    return {noise: _stribeck_case(ur5, noise) for noise in NOISES}


def test_the_joint_refit_recovers_links_and_a_nonlinear_friction(stribeck_fits) -> None:
    errors, baseline = [], []
    for noise in NOISES:
        x, start, out, links = stribeck_fits[noise]
        errors.append(np.linalg.norm(out.params[links] - x[links]))
        baseline.append(np.linalg.norm(start.params_[links] - x[links]))
        assert out.info["rounds"] == 2
        assert out.friction is not None and len(out.friction.models_) == 6
        layers = out.rms_layers
        assert all(f < 0.2 * k for f, k in zip(layers["friction"], layers["link"], strict=True))
        rms = np.sqrt(np.mean(out.residual**2, axis=0))
        assert np.all(rms < 1.6 * noise) and np.all(rms > 0.9 * noise)  # down to the noise
    # layer 1's linear friction leaks the Stribeck hump into the link parameters; the joint refit does not
    assert errors[0] < 0.35 * baseline[0] and errors[1] < 0.15 * baseline[1]
    assert errors[1] < 0.5 * errors[0]  # and its error shrinks with the noise
    _, _, out, _ = stribeck_fits[NOISES[1]]
    fitted = np.array([model.coef_ for model in out.friction.models_])
    np.testing.assert_allclose(fitted[:, :3], STRIBECK[:, :3], rtol=0.05)  # fc, fs, fv within 5 %


@pytest.mark.parametrize(
    ("value", "expected"),
    [
        ("1", 1),
        (" 1 ", 1),
        ("", None),
        ("none", None),
        ("0", None),
        ("-1", None),
        ("1.5", None),
        ("\u00b2", None),
    ],
)
def test_dynid_num_threads_is_read_alike_by_the_per_joint_work_and_the_compiled_regressors(value, expected):
    import subprocess
    import sys

    from dynid._threads import core_count

    code = (
        "from dynid._threads import JOINT_THREADS; from dynid.symbolic._export.loader import _env_threads; "
        "print(JOINT_THREADS, _env_threads())"
    )
    env = {**os.environ, "DYNID_NUM_THREADS": value}
    out = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
    ).stdout
    joint, loader = out.split()
    assert int(joint) == (min(2, core_count()) if expected is None else expected)
    assert loader == str(expected)
