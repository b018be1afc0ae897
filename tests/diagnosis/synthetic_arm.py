"""A synthetic two-joint arm for the diagnosis stages' tests: known linear columns (inertia, Coulomb,
viscous and gravity per joint), exact states, no filter, no robot.

tests/diagnosis/test_selection.py and test_refinement.py build their training and held-out sides on it.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from dynid.diagnosis.baseline import Side
from dynid.diagnosis.candidates import FeatureSource

__all__ = ["FS", "SIGMA", "X_TRUE", "N", "base_columns", "side", "states"]

FS = 200.0
N = 2
SIGMA = 0.05
X_TRUE = np.array([0.8, 1.5, 0.6, 4.0, 0.4, 0.9, 0.3, 2.0])


def states(t, phase):
    """(q, dq, ddq), each (m, 2): three sines per joint, shifted by ``phase``."""
    w = np.array([[0.5, 0.9], [1.3, 0.7], [2.1, 1.7]])
    a = np.array([[0.6, 0.5], [0.3, 0.4], [0.15, 0.2]])
    arg = w[None] * t[:, None, None] + (np.array([[0.0, 1.0], [0.4, 2.0], [1.1, 0.3]]) + phase)[None]
    return (
        np.sum(a * np.sin(arg), axis=1),
        np.sum(a * w * np.cos(arg), axis=1),
        -np.sum(a * w**2 * np.sin(arg), axis=1),
    )


def base_columns(q, dq, ddq):
    """The arm's base columns (m, 2, 8): ddq, tanh(dq / 0.01), dq, sin q per joint."""
    X = np.zeros((q.shape[0], N, 4 * N))
    for j in range(N):
        X[:, j, 4 * j : 4 * j + 4] = np.stack(
            [ddq[:, j], np.tanh(dq[:, j] / 0.01), dq[:, j], np.sin(q[:, j])], axis=1
        )
    return X


class _Prep(SimpleNamespace):
    def filter(self, A):  # no filter: the columns are exact
        return A


def side(t, q, dq, ddq, y, x) -> Side:
    """A training or held-out side with torque ``y`` and the baseline's parameters ``x``."""
    X = base_columns(q, dq, ddq)
    src = FeatureSource(
        t=t,
        q=q,
        dq=dq,
        ddq=ddq,
        tau_pred=np.einsum("mnk,k->mn", X, x),
        robot=None,
        fs=FS,
        runs=[slice(0, len(t))],
        torque_at=lambda q2, dq2, ddq2: np.einsum("mnk,k->mn", base_columns(q2, dq2, ddq2), x),
    )
    return Side(prep=_Prep(t=t), rows=np.arange(len(t)), y=y, X0=X, moving=np.ones_like(y), src=src)
