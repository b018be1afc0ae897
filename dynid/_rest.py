"""The direction of motion a friction model sees, with a joint at rest told apart from a slow one.

A friction model's direction-dependent terms (Coulomb levels, static levels) switch on the sign of the
joint's speed.  Below a speed that no recording resolves, that sign is the noise's or a creep's, not the
motion's: a joint held still by its stiction reads speeds of 1e-5-1e-4 rad/s of either sign, and a model
that switched there would predict its full static level, flipping, while the joint stands.  On a simulated
xArm 7 whose held-out motion holds joint 3 still at 8 % of its samples (Stribeck friction), the seed model
predicted +-1.9 N m there and the joint's held-out RMS was 1.57 times that of OLS with linear friction;
with a speed below :data:`AT_REST` counted as rest, 1.1 times.  The TX40's held-out recording stands
still for 39 % of its samples: the defaults' held-out RMS fell by 10-44 % on five joints (joint 6: 1 % higher).

Every built-in friction model, the layer-1 Coulomb columns, the effect terms and the C export use
:func:`direction`, so a model predicts the same in Python and in C.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["AT_REST", "direction"]

AT_REST = 1e-3
"""rad/s (0.06 deg/s): a joint slower than this is at rest for friction (its direction is 0).

A 1 rad/s excitation spends a few tenths of a percent of its samples below it, at its reversals; a 16-bit
encoder read at 1 kHz steps by 0.1 rad/s, and an 18-bit one by 0.024, so no recording resolves a speed this
small from one sample to the next."""


def direction(v: ArrayLike) -> NDArray[np.float64]:
    """``sign(v)``, with ``|v| < AT_REST`` counted as 0 (at rest)."""
    v = np.asarray(v, dtype=np.float64)
    return np.where(np.abs(v) < AT_REST, 0.0, np.sign(v))
