"""The consistent projection is the closest consistent set, checked against known true parameters."""

from __future__ import annotations

import numpy as np
import pytest

from dynid.identify.columns import column_set
from dynid.identify.consistent import (
    ConsistentLS,
    consistent_solution,
    pseudo_inertia,
    standard_from_pseudo_inertia,
)
from dynid.sim.synthetic import random_fourier, synthetic_dataset


def _thin_wrist(ur5, rng):
    """True parameters whose wrist bodies sit 2e-4 kg m^2 inside the consistency bound, and noisy data of them."""
    cols = column_set(ur5)
    params = ur5.params.copy()
    for link in (3, 4, 5):
        w, V = np.linalg.eigh(pseudo_inertia(params[10 * link : 10 * link + 10]))
        w[0] = 2e-4
        params[10 * link : 10 * link + 10] = standard_from_pseudo_inertia((V * w) @ V.T)
    extras = np.concatenate([np.full(6, 0.02), rng.uniform(0.5, 3, 6), rng.uniform(0.2, 2, 6), np.zeros(6)])
    x_true = cols.P @ np.concatenate([params, extras])
    ds = synthetic_dataset(cols, x_true, random_fourier(ur5, rng), rate=10, rng=rng, noise=0.3)
    return cols, x_true, ds


@pytest.mark.parametrize("seed", [0, 3])
def test_projection_moves_an_inconsistent_estimate_toward_the_true_parameters(ur5, seed) -> None:
    # The consistent set is convex and holds the true parameters, so the projection of the estimate onto it,
    # in the estimate's own metric H = R^T R, obeys the projection inequality
    #     ||x_c - x_true||_H^2 <= ||x_hat - x_true||_H^2 - ||x_c - x_hat||_H^2.
    # It fails for a point that is consistent but not the closest one: measured here, the identity metric
    # misses it by 8-36 squared units, the barrier stopped after 20 Newton steps by 0.6-1.0; the optimum
    # keeps 0.16-0.51 to spare.
    rng = np.random.default_rng(seed)
    cols, x_true, ds = _thin_wrist(ur5, rng)
    fit = ConsistentLS(robot=ur5).fit(ds)
    assert fit.solver_["status"] == "converged" and fit.solver_["at_bound"]  # the estimate was inconsistent
    R, x_hat, x_c = fit.unconstrained_.R_, fit.unconstrained_.params_, fit.params_

    def d2(a, b):
        return float(np.sum((R @ (a - b)) ** 2))

    assert d2(x_hat, x_c) > 0.1  # the projection moved it
    assert d2(x_c, x_true) <= d2(x_hat, x_true) - d2(x_c, x_hat) + 1e-3
    # in the metric of the identity instead (every parameter alike), the consistent point found is
    # farther: the inequality above fails for it, so the check tells the metric apart
    phi, _ = consistent_solution(ur5, cols, x_hat, np.eye(cols.p), 1.0)
    x_eye = cols.P @ phi
    assert d2(x_eye, x_true) > d2(x_hat, x_true) - d2(x_eye, x_hat) + 1e-3
    # every body is consistent with the margin, and the bounded extras are >= 0
    assert np.all(fit.min_eigenvalues_ >= 1e-6 * (1 - 1e-6))
    kinds = np.array(cols.kinds)
    assert np.all(x_c[np.isin(kinds, ["armature", "coulomb", "viscous"])] >= -1e-12)
