"""The registries of friction models and layer-1 estimators: name -> class, light to import.

The command line's ``--friction`` and ``--method`` choices (``dynid identify``, ``dynid fleet``), the
checks of :class:`~dynid.identify.model.ThreeLayerModel` and the simulator export
(:mod:`dynid.simmodel.parameters`) read these two tables.  Their built-in entries name a class by its
module, imported only when the class is looked up, so that reading the names (``dynid --help``)
imports neither SciPy nor CasADi.

>>> FRICTION_MODELS.names()        # ('none', 'linear', 'seed', 'seed_shared', 'stribeck', 'sigmoid')
>>> FRICTION_MODELS["seed"]        # SeedFriction (imports dynid.identify.friction_models)

A built-in model is one line of a table below beside its class; a model of one's own is registered by
its class, checked against its base: :func:`dynid.identify.friction.register_friction_model`
(:class:`~dynid.identify.friction.FrictionModel`) and :func:`dynid.identify.estimators.register_estimator`
(:class:`~dynid.identify.estimators.LinkEstimator`).
"""

from __future__ import annotations

import importlib
from collections.abc import Iterator, Mapping

from dynid.exceptions import UsageError

__all__ = ["CONSTRAINED_METHODS", "ESTIMATORS", "FRICTION_MODELS", "Registry", "method_names"]


class Registry(Mapping[str, type]):
    """A name -> class table whose built-in classes are imported on first look-up.

    Parameters
    ----------
    kind : str
        What the entries are, for messages (``"friction model"``).
    builtin : mapping of str to str
        Name -> ``"module:Class"`` of the built-in entries, in the order the choices are shown.
    """

    def __init__(self, kind: str, builtin: Mapping[str, str]) -> None:
        self.kind = kind
        self._entries: dict[str, type | str] = dict(builtin)

    def __repr__(self) -> str:
        return f"Registry({self.kind!r}, names={self.names()!r})"

    def __getitem__(self, name: str) -> type:
        entry = self._entries[name]
        if isinstance(entry, str):
            module, _, attr = entry.partition(":")
            entry = getattr(importlib.import_module(module), attr)
            self._entries[name] = entry
        return entry

    def __contains__(self, name: object) -> bool:
        return name in self._entries

    def __iter__(self) -> Iterator[str]:
        return iter(self._entries)

    def __len__(self) -> int:
        return len(self._entries)

    def names(self) -> tuple[str, ...]:
        """The registered names, built-in first, without importing any class."""
        return tuple(self._entries)

    def add(self, name: str, cls: type, *, replace: bool = False) -> None:
        """Register ``cls`` under ``name`` (the ``register_*`` functions check the class first).

        Parameters
        ----------
        name : str
            Its name (a command-line choice).
        cls : type
            The class.
        replace : bool
            Replace a class registered under the same name; else a taken name is refused.
        """
        if name in self._entries and not replace and self[name] is not cls:
            raise UsageError(
                f"the {self.kind} name {name!r} is taken by {self[name].__name__}; give the class another "
                "name, or pass replace=True to replace it"
            )
        self._entries[name] = cls

    def remove(self, name: str) -> None:
        """Forget a registered name (a test's clean-up).

        Parameters
        ----------
        name : str
            A registered name.
        """
        if name not in self._entries:
            raise UsageError(f"no {self.kind} is registered as {name!r}; the names are {', '.join(self)}")
        del self._entries[name]


FRICTION_MODELS = Registry(
    "friction model",
    {
        "none": "dynid.identify.friction_models:NoFriction",
        "linear": "dynid.identify.friction_models:LinearFriction",
        "seed": "dynid.identify.friction_models:SeedFriction",
        "seed_shared": "dynid.identify.friction_models:SharedSeedFriction",
        "stribeck": "dynid.identify.friction_models:StribeckFriction",
        "sigmoid": "dynid.identify.friction_models:SigmoidFriction",
    },
)
"""Single-joint friction models by name (subclasses of :class:`dynid.identify.friction.FrictionModel`): the
``--friction`` choices of ``dynid identify`` and ``dynid fleet`` besides ``auto``."""

ESTIMATORS = Registry(
    "estimator",
    {
        "ols": "dynid.identify.estimators:OLS",
        "wls": "dynid.identify.estimators:WLS",
        "gls": "dynid.identify.estimators:GLS",
        "irls": "dynid.identify.estimators:IRLS",
    },
)
"""Layer-1 estimators by method name (subclasses of :class:`dynid.identify.estimators.LinkEstimator`, each a
weighting of the linear system)."""

CONSTRAINED_METHODS = ("consistent",)
"""Layer-1 methods that are not a weighting: chosen by name in :meth:`ThreeLayerModel.fit
<dynid.identify.model.ThreeLayerModel.fit>` (``consistent``: :class:`dynid.identify.consistent.ConsistentLS`)."""


def method_names() -> tuple[str, ...]:
    """The layer-1 methods: every registered estimator, then :data:`CONSTRAINED_METHODS`."""
    return (*ESTIMATORS, *CONSTRAINED_METHODS)
