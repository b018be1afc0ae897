"""The truth's joint friction (``--friction``) and the default sizes of friction it shares with the effects.

:class:`TruthFriction` is the friction of the simulator's truth robot (the formulas and sizes are in
:mod:`dynid.sim.effects`); :func:`smooth_sign` is the ``tanh(dq / eps)`` that stands for ``sign(dq)``
there and in the friction-like effects of :mod:`dynid.sim.effect_classes`, which size themselves with
the same fractions of the robot's scales (:data:`COULOMB`, :data:`VISCOUS`, ...).  Split out of
:mod:`dynid.sim.effects`, which re-exports its names.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from dynid.exceptions import UsageError
from dynid.sim.scales import RobotScales

__all__ = [
    "COULOMB",
    "FRICTION_KINDS",
    "SEED_ASYMMETRY",
    "SEED_KS",
    "SEED_KV2",
    "SEED_KV3",
    "SEED_LAMBDA",
    "SMOOTHING",
    "STRIBECK_BUMP",
    "STRIBECK_SPEED",
    "VISCOUS",
    "TruthFriction",
    "smooth_sign",
]

FRICTION_KINDS = ("none", "linear", "seed", "stribeck")
"""Friction models of the truth (``--friction``)."""

SMOOTHING = 1e-3
"""Default velocity (rad/s) of the ``tanh(dq / eps)`` that stands for ``sign(dq)``."""

# Default sizes, fractions of the torque scale s_j unless stated.
COULOMB = 0.05
VISCOUS = 0.03  # at the reference speed v_j
SEED_ASYMMETRY = 0.1  # kc+ = (1 + a) Fc, kc- = (1 - a) Fc
SEED_KV2, SEED_KV3 = 0.01, 0.005
SEED_LAMBDA = 0.03  # of dq_max
SEED_KS = 0.5  # of Fc
STRIBECK_BUMP = 0.5  # Fs - Fc, of Fc
STRIBECK_SPEED = 0.02  # of dq_max


def smooth_sign(dx: np.ndarray, eps: float) -> tuple[np.ndarray, np.ndarray]:
    """``tanh(dx / eps)`` and its derivative with respect to dx: the smoothed ``sign`` of the truth's
    friction and of the friction-like effects."""
    s = np.tanh(dx / eps)
    return s, (1.0 - s * s) / eps


# ---------------------------------------------------------------------------- truth friction
@dataclass(frozen=True, eq=False)
class TruthFriction:
    """Joint friction of the truth model (see :mod:`dynid.sim.effects` for the formulas).

    Parameters
    ----------
    kind : {"none", "linear", "seed", "stribeck"}
        Which model.
    kc_pos, kc_neg : ndarray, shape (n,)
        Coulomb friction (N m, both positive) when moving in the positive / negative direction.
    kv1, kv2, kv3 : ndarray, shape (n,)
        Viscous terms ``kv1 dq + kv2 dq|dq| + kv3 dq^3`` (N m s/rad, N m s^2/rad^2, N m s^3/rad^3).
    ks : ndarray, shape (n,)
        Extra friction at zero speed (N m): the low-speed region of ``seed``, ``Fs - Fc`` of ``stribeck``.
    vs : ndarray, shape (n,)
        ``lambda`` of ``seed`` or the Stribeck speed of ``stribeck`` (rad/s).
    eps : float
        Smoothing speed of ``sign`` (rad/s).
    """

    kind: str
    kc_pos: np.ndarray
    kc_neg: np.ndarray
    kv1: np.ndarray
    kv2: np.ndarray
    kv3: np.ndarray
    ks: np.ndarray
    vs: np.ndarray
    eps: float = SMOOTHING

    def __post_init__(self) -> None:
        if self.kind not in FRICTION_KINDS:
            raise UsageError(
                f"the friction model '{self.kind}' is unknown; choose one of {', '.join(FRICTION_KINDS)}."
            )
        if not (self.eps > 0 and math.isfinite(self.eps)):
            raise UsageError(
                f"the friction smoothing speed eps is {self.eps}; give a positive speed in rad/s."
            )
        for name in ("kc_pos", "kc_neg", "kv1", "kv2", "kv3", "ks", "vs"):
            value = np.array(getattr(self, name), dtype=float)
            value.setflags(write=False)
            object.__setattr__(self, name, value)

    @classmethod
    def default(
        cls, kind: str, scales: RobotScales, dq_max: np.ndarray, *, eps: float = SMOOTHING
    ) -> TruthFriction:
        """The default friction of each kind, sized by the robot's scales (:mod:`dynid.sim.effects`).

        Parameters
        ----------
        kind : {"none", "linear", "seed", "stribeck"}
        scales : RobotScales
        dq_max : ndarray, shape (n,)
            Joint speed limits (rad/s).
        eps : float
            Smoothing speed of ``sign`` (rad/s).
        """
        if kind not in FRICTION_KINDS:
            raise UsageError(
                f"the friction model '{kind}' is unknown; choose one of {', '.join(FRICTION_KINDS)}."
            )
        s, v = scales.torque, scales.speed
        zero = np.zeros_like(s)
        fc, fv = COULOMB * s, VISCOUS * s / v
        dq_max = np.asarray(dq_max, dtype=float)
        if kind == "none":
            return cls(kind, zero, zero, zero, zero, zero, zero, zero, eps)
        if kind == "linear":
            return cls(kind, fc, fc, fv, zero, zero, zero, zero, eps)
        if kind == "seed":
            return cls(
                kind,
                (1 + SEED_ASYMMETRY) * fc,
                (1 - SEED_ASYMMETRY) * fc,
                fv,
                SEED_KV2 * s / v**2,
                SEED_KV3 * s / v**3,
                SEED_KS * fc,
                SEED_LAMBDA * dq_max,
                eps,
            )
        return cls(kind, fc, fc, fv, zero, zero, STRIBECK_BUMP * fc, STRIBECK_SPEED * dq_max, eps)

    @property
    def active(self) -> bool:
        return self.kind != "none"

    def torque(self, dq: np.ndarray, factor: np.ndarray | float = 1.0) -> tuple[np.ndarray, np.ndarray]:
        """Friction torque and its derivative with respect to the speed.

        Parameters
        ----------
        dq : ndarray, shape (n,) or (m, n)
            Joint speeds (rad/s).
        factor : float or ndarray, shape (n,)
            Scale of every coefficient (the temperature effect), 1 by default.

        Returns
        -------
        f, df : ndarray, same shape as dq
            Torque (N m, along the motion) and ``d f / d dq`` (N m s/rad).
        """
        s, ds = smooth_sign(dq, self.eps)
        pos = s >= 0
        kc = np.where(pos, self.kc_pos, self.kc_neg)
        a = np.abs(dq)
        f = kc * s + self.kv1 * dq
        df = kc * ds + self.kv1
        if self.kind == "seed":
            # Magnitude g(|dq|): kc + kv(|dq|) above lambda; below, the line from kc + ks (at 0) to
            # kc + kv(lambda) (at lambda).  f = s g, with s the smooth sign.
            lam = self.vs
            kv_lam = self.kv1 * lam + self.kv2 * lam**2 + self.kv3 * lam**3
            inside = a < lam
            r = a / lam
            g = np.where(
                inside,
                kc + (1.0 - r) * self.ks + r * kv_lam,
                kc + self.kv1 * a + self.kv2 * a * a + self.kv3 * a**3,
            )
            dg = np.where(
                inside, (kv_lam - self.ks) / lam, self.kv1 + 2 * self.kv2 * a + 3 * self.kv3 * a * a
            )
            f = s * g
            df = ds * g + np.abs(s) * dg
        elif self.kind == "stribeck":
            e = np.exp(-((dq / self.vs) ** 2))
            f = f + self.ks * s * e
            df = df + self.ks * e * (ds - 2 * s * dq / self.vs**2)
        return f * factor, df * factor

    def to_dict(self) -> dict:
        out: dict[str, Any] = {"kind": self.kind, "eps": self.eps}
        names = {
            "linear": {"kc_pos": "Fc", "kv1": "Fv"},
            "seed": {
                "kc_pos": "kc_pos",
                "kc_neg": "kc_neg",
                "kv1": "kv1",
                "kv2": "kv2",
                "kv3": "kv3",
                "ks": "ks",
                "vs": "lambda",
            },
            "stribeck": {"kc_pos": "Fc", "ks": "Fs_minus_Fc", "vs": "vs", "kv1": "Fv"},
        }.get(self.kind, {})
        for attr, label in names.items():
            out[label] = getattr(self, attr).tolist()
        if self.kind == "seed":
            out["ks_pos"] = (self.kc_pos + self.ks).tolist()  # static levels, as SeedFriction names them
            out["ks_neg"] = (self.kc_neg + self.ks).tolist()
        out["units"] = "N m, rad/s (kv1 N m s/rad, kv2 N m s^2/rad^2, kv3 N m s^3/rad^3)"
        return out
