"""The settings of the gap diagnosis: one frozen record that every stage reads.

>>> settings = DiagnosisSettings(max_effects=2, max_samples=6000)
>>> diagnose(model, train, heldout, max_effects=2, max_samples=6000)   # the same settings, as keywords
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from dynid.diagnosis.candidates import effect_names
from dynid.exceptions import UsageError

__all__ = ["DiagnosisSettings"]


def _positive(value: object) -> bool:
    """Whether ``value`` is a positive, finite number (not a string or a bool)."""
    if isinstance(value, str | bytes | bool):
        return False
    try:
        number = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return False
    return number > 0 and math.isfinite(number)


@dataclass(frozen=True)
class DiagnosisSettings:
    """How :func:`dynid.diagnosis.core.diagnose` tests and selects the candidate effects.

    Attributes
    ----------
    effects : tuple of str
        The catalogue of candidate effects; None (the default): all of it, registered effects included
        (:func:`dynid.sim.effects.effect_names`, read when the settings are made).
    alpha : float
        Family-wise error rate of the candidate tests (Holm).
    max_effects : int
        At most this many effects are accepted (forward selection).
    min_gain : float
        Smallest relevant reduction of the held-out loss, in noise variances per sample.
    min_closure : float
        An accepted candidate must close at least this fraction of the gap on its joint(s); when the
        excess is significant and none does, the verdict is ``["unexplained"]``.
    excess_tol : float
        The baseline's excess counts only when its ratio to the noise floor exceeds ``1 + excess_tol``
        (state estimation leaves a small excess even on an effect-free robot), where the floor's own
        precision is unknown (a spectral lower bound): the tolerance then also absorbs the floor's error.
    measured_excess_tol : float
        The same where the floor states its precision (a floor measured across periods,
        :attr:`dynid.validation.metrics.NoiseFloor.rel_se`): the excess test then integrates the floor's
        error itself, and the tolerance only allows for the model's small misfit.
    period : float or None
        Period (s) of the held-out excitation; detected from the angles when None.
    max_samples : int
        Rows used per dataset (the filtered data are thinned evenly beyond it).
    block_seconds : float
        Block length (s) of the Diebold-Mariano block means, the covariance and the bootstrap.
    refit : bool
        Refit accepted effects by nonlinear least squares (elasticity, backlash, delay) and refine the
        continuous hyper-parameters of the others.
    confound_deg : float
        Principal angle (degrees) below which two candidates count as not separable.
    stick_fraction : float
        Samples of a joint slower than this fraction of its top speed are left out of the fits and
        losses (sticking and presliding make Coulomb friction ill-defined there; the gap map still
        shows them in its stiction bin).
    screen_top : int
        The candidates that the training data alone rank first (by the Wald test of their columns on
        the training residual) form a second family of this size, tested at half of ``alpha`` beside
        the family of all candidates (:func:`dynid.diagnosis.stats.screened_holm`); 0: one family.

    Raises
    ------
    UsageError
        Unknown effect names, a period that is not a positive number of seconds.
    """

    effects: tuple[str, ...] | None = None
    alpha: float = 0.05
    max_effects: int = 3
    min_gain: float = 0.15
    min_closure: float = 0.5
    excess_tol: float = 1.0
    measured_excess_tol: float = 0.5
    period: float | None = None
    max_samples: int = 12000
    block_seconds: float = 0.1
    refit: bool = True
    confound_deg: float = 15.0
    stick_fraction: float = 0.02
    screen_top: int = 5

    def __post_init__(self) -> None:
        catalogue = effect_names()
        object.__setattr__(self, "effects", catalogue if self.effects is None else tuple(self.effects))
        unknown = [e for e in self.effects if e not in catalogue]
        if unknown:
            raise UsageError(
                f"unknown effect {', '.join(repr(u) for u in unknown)}; the catalogue is "
                f"{', '.join(catalogue)}: use those names."
            )
        if self.period is not None and not _positive(self.period):
            raise UsageError(
                f"period is {self.period}; give the period of the held-out motion in seconds (> 0), or None to "
                "detect it."
            )
        if int(self.screen_top) != self.screen_top or self.screen_top < 0:
            raise UsageError(
                f"screen_top is {self.screen_top}; give a whole number of candidates, at least 0 (default 5)."
            )
        object.__setattr__(self, "screen_top", int(self.screen_top))
