"""The simulator's sensors: torque noise, encoder and current quantisation, and the sensor effects.

The measured torque is the drive torque read through the sensor effects of the truth (in the order
:data:`SENSOR_ORDER`: drive_gain, delay, offset), plus white and AR(1) coloured noise, then quantised
to the current sensor's step (:func:`measured_torque`).  :class:`NoiseModel` holds the settings
(``noise=`` of :func:`dynid.sim.simulator.simulate`, ``--noise key=value,...``); its table of keys is
in :mod:`dynid.sim.simulator`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from dynid.exceptions import UsageError
from dynid.sim.truth import Truth

__all__ = ["SENSOR_ORDER", "NoiseModel", "measured_torque", "torque_noise"]

SENSOR_ORDER = ("drive_gain", "delay", "offset")
"""The order in which the sensor effects act on the measured torque, whatever the order given."""


@dataclass(frozen=True)
class NoiseModel:
    """Sensor model: torque noise (white and AR(1)), encoder and current quantisation.

    Parameters
    ----------
    torque : float
        White torque noise std, fraction of each joint's torque scale.
    coloured : float
        Stationary std of the AR(1) torque noise, fraction of each joint's torque scale.
    colour : float
        AR(1) coefficient per control tick, ``0 <= colour < 1``.
    encoder_bits : int
        The logged angles have ``2**encoder_bits`` counts per joint revolution; 0 logs exact angles.
    current_lsb : float
        Quantisation step of the torque reading, fraction of each joint's torque scale; 0 for none.
    """

    torque: float = 0.01
    coloured: float = 0.005
    colour: float = 0.9
    encoder_bits: int = 18
    current_lsb: float = 0.001

    control_bits: int = 24

    KEYS = ("torque", "coloured", "colour", "encoder_bits", "current_lsb", "control_bits")

    def __post_init__(self) -> None:
        for key in ("torque", "coloured", "current_lsb"):
            value = getattr(self, key)
            if not (math.isfinite(value) and value >= 0):
                raise UsageError(
                    f"the noise setting {key} is {value}; give a fraction >= 0 of the torque scale."
                )
        if not (math.isfinite(self.colour) and 0 <= self.colour < 1):
            raise UsageError(
                f"the noise setting colour is {self.colour}; give an AR(1) coefficient in [0, 1)."
            )
        for key in ("encoder_bits", "control_bits"):
            value = getattr(self, key)
            if not (math.isfinite(value) and int(value) == value and 0 <= value <= 40):
                raise UsageError(
                    f"the noise setting {key} is {value}; give a whole number of bits in 0..40 (0 for exact angles)."
                )
            object.__setattr__(self, key, int(value))

    @classmethod
    def off(cls) -> NoiseModel:
        """No noise and no quantisation: the measured values are the exact ones."""
        return cls(torque=0.0, coloured=0.0, colour=0.0, encoder_bits=0, current_lsb=0.0, control_bits=0)

    @classmethod
    def parse(cls, spec: str | Mapping[str, float] | NoiseModel | None) -> NoiseModel:
        """Read ``key=value,...`` (keys in :attr:`KEYS`), ``off``/``none``, a mapping, or None (defaults).

        Keys not given keep their default; ``off,torque=0.01`` starts from no noise instead.
        """
        if isinstance(spec, NoiseModel):
            return spec
        if spec is None:
            return cls()
        if isinstance(spec, Mapping):
            items = list(spec.items())
            base = cls()
        else:
            parts = [p.strip() for p in str(spec).split(",") if p.strip()]
            base = cls()
            if parts and parts[0].lower() in ("off", "none"):
                base = cls.off()
                parts = parts[1:]
            items = []
            for part in parts:
                if "=" not in part:
                    raise UsageError(
                        f"the noise setting '{part}' is not key=value; write e.g. --noise torque=0.02,colour=0.8 "
                        f"(keys: {', '.join(cls.KEYS)}) or --noise off."
                    )
                key, _, value = part.partition("=")
                items.append((key.strip().lower().replace("color", "colour"), value.strip()))
        values = {k: getattr(base, k) for k in cls.KEYS}
        for key, value in items:
            if key not in cls.KEYS:
                raise UsageError(f"unknown noise setting '{key}'; the known ones are {', '.join(cls.KEYS)}.")
            try:
                values[key] = float(value)
            except (TypeError, ValueError):
                raise UsageError(
                    f"the noise setting {key} is '{value}', not a number; give e.g. {key}=0.01."
                ) from None
        return cls(**values)

    def to_dict(self) -> dict:
        return {k: getattr(self, k) for k in self.KEYS}


def torque_noise(noise: NoiseModel, scale: np.ndarray, ticks: int, rng: np.random.Generator) -> np.ndarray:
    """White + AR(1) torque noise, shape (ticks, n) (N m)."""
    from scipy.signal import lfilter

    n = scale.size
    white = rng.normal(size=(ticks, n)) * (noise.torque * scale)
    if noise.coloured == 0:
        return white
    rho = noise.colour
    drive = rng.normal(size=(ticks, n))
    first = rng.normal(size=n)  # stationary start
    coloured = lfilter([math.sqrt(1 - rho * rho)], [1.0, -rho], drive, axis=0, zi=(rho * first)[None, :])[0]
    return white + coloured * (noise.coloured * scale)


def measured_torque(
    truth: Truth, noise: NoiseModel, t: np.ndarray, tau_drive: np.ndarray, seed: int
) -> np.ndarray:
    """The torque the current sensors read, (m, n) (N m), for drive torques ``tau_drive`` at times ``t``.

    Parameters
    ----------
    truth : Truth
        Its sensor effects act in the order :data:`SENSOR_ORDER`; its torque scales size the noise.
    noise : NoiseModel
    t : ndarray, shape (m,)
        Control ticks (s).
    tau_drive : ndarray, shape (m, n)
        Torque the drives apply (N m).
    seed : int
        Seed of the noise (the generator ``np.random.default_rng([seed, 1])``).
    """
    tau_meas = tau_drive
    by_name = {e.name: e for e in truth.effects}
    for name in SENSOR_ORDER:
        if name in by_name:
            tau_meas = by_name[name].measure(t, tau_meas)
    scales = truth.scales
    rng = np.random.default_rng([seed, 1])
    tau_meas = tau_meas + torque_noise(noise, scales.torque, t.size, rng)
    if noise.current_lsb > 0:
        lsb = noise.current_lsb * scales.torque
        tau_meas = np.round(tau_meas / lsb) * lsb
    return tau_meas
