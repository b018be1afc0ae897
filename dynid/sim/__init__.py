"""dynid.sim: the simulated arm, the ONE catalogue of unmodelled effects, and synthetic cases.

:mod:`dynid.sim.simulator` runs a truth robot under closed-loop tracking with sensor noise and
unmodelled effects (its parts: :mod:`~dynid.sim.truth`, :mod:`~dynid.sim.tracking`,
:mod:`~dynid.sim.sensors`, :mod:`~dynid.sim.results`); :mod:`dynid.sim.effects` is the effect
catalogue (:data:`~dynid.sim.effects.EFFECT_NAMES`; the classes in :mod:`~dynid.sim.effect_classes`, and
:func:`~dynid.sim.effects.register_effect` for one's own) that ``simulate --effects``, ``identify --effects``
and ``diagnose`` all read; :mod:`dynid.sim.synthetic` makes data whose truth is known exactly and holds
the ONE random excitation (:func:`~dynid.sim.synthetic.random_fourier`); :mod:`dynid.sim.cases`
sizes the effects of the diagnosis' withheld-effect cases.  Submodules are imported on first use.
"""

from __future__ import annotations

from dynid._lazy import lazy_exports

_EXPORTS = {
    "EFFECTS": "effects",
    "EFFECT_NAMES": "effects",
    "effect_names": "effects",
    "parse_effects": "effects",
    "register_effect": "effects",
    "unregister_effect": "effects",
    "NoiseModel": "simulator",
    "SimulationResult": "simulator",
    "build_truth": "simulator",
    "simulate": "simulator",
    "write_simulation": "simulator",
    "random_fourier": "synthetic",
}

__all__, __getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
