"""The one not-fitted check of the estimators, friction models and corrections of dynid.

It follows scikit-learn's rule (``fit`` sets attributes whose names end in ``_``; an object without
them is not fitted) and raises :class:`dynid.exceptions.NotFittedError`.  scikit-learn's own
``check_is_fitted`` is not called: it needs ``__sklearn_tags__`` (objects derived from its
``BaseEstimator``) and imports scikit-learn, 1.4 s at start-up on paths that never use it.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Any

from dynid.exceptions import NotFittedError

__all__ = ["check_is_fitted"]


def check_is_fitted(
    estimator: Any,
    attributes: str | Iterable[str] = "params_",
    *,
    call: str = "fit(...)",
    all_or_any: Callable[[Iterable[object]], bool] = all,
) -> None:
    """Raise a :class:`NotFittedError` if ``estimator`` has not been fitted.

    Parameters
    ----------
    estimator : object
        An estimator, friction model or correction of dynid.
    attributes : str or iterable of str
        Fitted attributes (names ending in ``_``) that ``fit`` sets.
    call : str
        How to fit it, for the message (e.g. ``"fit(dq, F)"``).
    all_or_any : {all, any}
        Whether all or any of ``attributes`` must be present.

    Raises
    ------
    NotFittedError
        The attributes are missing.
    """
    names = [attributes] if isinstance(attributes, str) else list(attributes)
    if not all_or_any(hasattr(estimator, name) for name in names):
        raise NotFittedError(
            f"this {type(estimator).__name__} is not fitted yet; call {call} before using it"
        )
