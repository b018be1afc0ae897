"""Base parameters: the identity Y_b beta == Y pi, the rank, the maps, the gravity split."""

from __future__ import annotations

import re

import numpy as np
import pytest

from dynid.exceptions import ShapeError
from dynid.symbolic import base_parameters, load_robot, robot_functions
from tests.conftest import DATA


@pytest.fixture(scope="module", params=["ur5", "panda", str(DATA / "rpr.urdf"), str(DATA / "rrpr_mdh.toml")])
def robot_and_base(request):
    robot = load_robot(request.param)
    funcs = robot_functions(robot)
    return robot, funcs, base_parameters(funcs)


def _states(robot, rng, m):
    return (
        rng.uniform(robot.q_min, robot.q_max, size=(m, robot.n)),
        rng.normal(size=(m, robot.n)),
        rng.normal(size=(m, robot.n)),
    )


def test_base_regressor_reproduces_the_torque(robot_and_base, rng):
    robot, funcs, base = robot_and_base
    q, dq, ddq = _states(robot, rng, 30)
    beta = base.to_base(robot.params)
    Y = funcs.regressor_numeric(q, dq, ddq)
    Yb = base.evaluate(q, dq, ddq)
    np.testing.assert_allclose(Yb @ beta, Y @ robot.params, rtol=1e-10, atol=1e-10)
    # ... for any standard parameters, not just the model's.
    pi = rng.normal(size=10 * robot.n)
    np.testing.assert_allclose(Yb @ base.to_base(pi), Y @ pi, rtol=1e-9, atol=1e-9)


def test_stacked_base_regressor_has_full_rank(robot_and_base, rng):
    robot, _, base = robot_and_base
    q, dq, ddq = _states(robot, rng, 100)
    W = base.evaluate(q, dq, ddq).reshape(-1, base.n_base)
    assert np.linalg.matrix_rank(W) == base.n_base
    assert base.n_base + len(base.dependent) == 10 * robot.n


def test_known_numbers_of_base_parameters():
    counts = {
        name: base_parameters(robot_functions(load_robot(name))).n_base for name in ("ur5", "ur10", "panda")
    }
    assert counts == {"ur5": 36, "ur10": 36, "panda": 43}


def test_standard_from_base_lands_on_the_same_base(robot_and_base, rng):
    robot, _, base = robot_and_base
    beta = base.to_base(robot.params) * (1 + 0.1 * rng.normal(size=base.n_base))
    for reference in (None, robot.params):
        pi = base.to_standard(beta, reference=reference)
        np.testing.assert_allclose(base.to_base(pi), beta, rtol=1e-9, atol=1e-12)
    # The model's own base parameters map back to the model's standard parameters.
    np.testing.assert_allclose(
        base.to_standard(base.to_base(robot.params), robot.params), robot.params, atol=1e-12
    )
    # Identifiable standard parameters are fixed by beta alone.
    pi0 = base.to_standard(beta)
    np.testing.assert_allclose(
        pi0[base.identifiable], base.to_standard(beta, robot.params)[base.identifiable], atol=1e-12
    )


def test_names_and_expressions_are_readable():
    base = base_parameters(robot_functions(load_robot("ur5")))
    assert len(base.names) == len(base.expressions) == 36
    assert len(set(base.names)) == 36
    # Joint 2 is the shoulder; 0.425 m is the upper-arm length of the UR5.
    expr = dict(zip(base.names, base.expressions, strict=True))
    assert expr["mz2R"] == "mz2 + 0.425*m3 + 0.425*m4 + 0.425*m5 + 0.425*m6"
    assert expr["Izz1R"].startswith("Izz1 + ")
    assert expr["mx2"] == "mx2"
    # a coefficient of 1 to the digits shown (1 - 4e-8 on an arm whose angles were rounded) reads as 1
    from dataclasses import replace

    nearly = replace(base, K=np.where(np.abs(np.abs(base.K) - 1) < 1e-12, base.K * (1 - 4e-8), base.K))
    assert nearly.expressions == base.expressions
    assert not any(re.search(r"(?<![\d.])1\*", e) for e in nearly.expressions)


def test_gravity_related_columns(robot_and_base, rng):
    robot, _, base = robot_and_base
    q = rng.uniform(robot.q_min, robot.q_max, size=(50, robot.n))
    still = base.evaluate(q, np.zeros_like(q), np.zeros_like(q)).reshape(-1, base.n_base)
    moving = np.linalg.norm(still, axis=0) > 1e-9
    np.testing.assert_array_equal(base.gravity_related, moving)
    assert 0 < base.gravity_related.sum() < base.n_base
    # Inertia-only parameters never feel gravity.
    names = np.array(base.names)
    assert not any(base.gravity_related[np.char.startswith(names, "I")])


def test_wrong_sizes_are_refused():
    base = base_parameters(robot_functions(load_robot("ur5")))
    with pytest.raises(ShapeError, match=r"the standard parameters have 50 values; the robot 'ur5' has 60"):
        base.to_base(np.zeros(50))
    with pytest.raises(ShapeError, match=r"beta has shape \(35,\); the robot 'ur5' has 36 base parameters"):
        base.to_standard(np.zeros(35))


def test_the_split_does_not_depend_on_joint_limits():
    """A model identified on a slowed robot must match the same robot loaded again."""
    from dynid.symbolic.base import _MEMO

    _MEMO.clear()
    slow = load_robot("ur5").with_limits(q_min=-0.5, q_max=0.5, dq_max=0.3, ddq_max=1.0)
    first = base_parameters(robot_functions(slow))
    _MEMO.clear()
    again = base_parameters(robot_functions(load_robot("ur5")))
    np.testing.assert_array_equal(first.independent, again.independent)
    np.testing.assert_allclose(first.K, again.K, atol=1e-12)
