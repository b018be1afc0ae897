"""dynid._rest: the direction of motion a friction model sees."""

from __future__ import annotations

import casadi as ca
import numpy as np

from dynid._rest import AT_REST, direction
from dynid.symbolic.functions import friction_columns_function


def test_a_speed_below_the_rest_limit_has_no_direction() -> None:
    v = np.array([-1.0, -AT_REST, -0.999 * AT_REST, -1e-6, 0.0, 1e-6, 0.999 * AT_REST, AT_REST, 2.0])
    np.testing.assert_array_equal(direction(v), [-1, -1, 0, 0, 0, 0, 0, 1, 1])
    assert direction([[0.5, -1e-4]]).shape == (1, 2)


def test_the_symbolic_coulomb_columns_follow_the_same_rule() -> None:
    v = np.array([-0.5, -5e-4, 5e-4, 3e-3])
    F = np.asarray(friction_columns_function(4)(ca.DM(v)))
    np.testing.assert_array_equal(np.diag(F[:, :4]), direction(v))
    np.testing.assert_array_equal(np.diag(F[:, 4:8]), v)
