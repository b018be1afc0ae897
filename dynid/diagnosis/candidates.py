"""The catalogue of candidate effects of the gap diagnosis: their feature columns.

Each effect of the catalogue (DESIGN.md; the simulator's :mod:`dynid.sim.effects` injects the
same names) is a :class:`Candidate`: a rule that turns the states of a dataset into extra regressor
columns, one or a few per joint, that are refitted *together with* the base parameters (so what
re-identification absorbs is never credited to the effect).  Columns are computed at full rate, from
the same states as the base regressor, and then low-passed with the torque's filter (parallel
filtering, DIAGNOSIS.md section 3).

========================  ===================================================  ===================
effect                    columns on joint j (``s = sign``)                    hyper-parameter
========================  ===================================================  ===================
offset                    1                                                    -
armature                  ddq_j                                                -
stribeck                  s(dq_j) exp(-(|dq_j| / vs)^2)                        vs
load_friction             s(dq_j) |tau_j|,  s(dq_j) |tau_j| s(dq_j tau_j)      -
temperature               h(t) s(dq_j),  h(t) dq_j;  h = 1 - exp(-t / T)       T
cogging                   sin(k N q_j), cos(k N q_j), k = 1, 2                 N (gear ratio)
elasticity                M(q)[:, j] d^2 tau_j / dt^2 (all joints; first      -
                          order of q_j = theta_j - tau_j / K)
backlash                  M(q)[:, j] d^2 b_j / dt^2, M(q)[:, j] d^2 tau_j /    eps
                          dt^2 (all joints), b_j; b_j = tanh(tau_j / eps)
delay                     d tau_j / dt (first order of tau(t - d))             -
drive_gain                tau_j                                                -
base_tilt                 d g(q) / d alpha about two horizontal axes (all j)   -
coupled_friction          s(w), w on joints a and b, w = dq_a +- dq_b          pair and sign
nonlinear_viscous         dq_j |dq_j|,  dq_j^3                                 -
payload                   (absorbed by the base parameters: parametric test)   -
========================  ===================================================  ===================

``tau`` is the identified model's predicted torque (the "first fit"); for backlash its links' share,
which the transmission carries (the motor's armature and friction act before the gear).
Elasticity, backlash and delay are not linear in their parameters: the screen uses the first-order
columns above, the refit (:mod:`dynid.diagnosis.refinement`) fits their physical parameters (for
backlash a dead zone whose sides change once the torque has reversed beyond a threshold, a crossing
time later).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dynid.sim.effects import EFFECT_NAMES  # the catalogue: one list for simulate, identify, diagnose

__all__ = [
    "CANDIDATES",
    "EFFECT_NAMES",
    "PARAMETRIC_EFFECTS",
    "Candidate",
    "FeatureSource",
    "candidate_columns",
    "describe_hyper",
    "enumerate_candidates",
    "excitation_hint",
]

PARAMETRIC_EFFECTS = ("drive_gain", "payload", "offset")
"""Effects that re-identification can absorb, tested on the change of the base parameters."""

_SIGN_EPS = 1e-3  # rad/s: velocities below this count as zero in sign(dq) (quantised encoders)


@dataclass(frozen=True, eq=False)
class FeatureSource:
    """Full-rate signals of one dataset from which candidate columns are built.

    Complete when made; ``cache`` only memoises what its methods compute from these signals (the mass
    matrix, the gravity tilt columns).

    Parameters
    ----------
    t : ndarray, shape (M,)
        Time (s) from the start of the recording.
    q, dq, ddq : ndarray, shape (M, n)
        States the regressor is evaluated at (rad, rad/s, rad/s^2).
    tau_pred : ndarray, shape (M, n)
        The identified model's torque at those states (N m), unfiltered.
    robot : RobotModel
        The robot.
    fs : float
        Sampling rate (Hz).
    runs : list of slice
        Runs (signals are differentiated within a run only).
    torque_at : callable, optional
        ``f(q, dq, ddq) -> (M, n)``: the model's torque at other states (what the exact transmission
        columns shift); ``tau_pred`` at the recorded states.
    tau_link, link_torque_at : optional
        The same for the links' share of the torque, which the transmission carries (without the
        model's armature and friction, which act on the motor side); the full torque when not given.
    """

    t: NDArray[np.float64]
    q: NDArray[np.float64]
    dq: NDArray[np.float64]
    ddq: NDArray[np.float64]
    tau_pred: NDArray[np.float64]
    robot: Any
    fs: float
    runs: list[slice]
    torque_at: (
        Callable[[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]], NDArray[np.float64]] | None
    ) = None
    cache: dict[str, Any] = field(default_factory=dict)
    tau_link: NDArray[np.float64] | None = None
    link_torque_at: (
        Callable[[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]], NDArray[np.float64]] | None
    ) = None

    def transmitted(self, j: int) -> NDArray[np.float64]:
        """Torque (M,) that joint j's transmission carries to the link (N m): what deflects a spring or
        closes a dead zone.  The motor's friction and inertia act before the gear, not through it."""
        return (self.tau_pred if self.tau_link is None else self.tau_link)[:, j]

    @property
    def n(self) -> int:
        """Number of joints."""
        return int(self.q.shape[1])

    @property
    def m(self) -> int:
        """Number of samples."""
        return int(self.q.shape[0])

    def derivative(self, x: NDArray[np.float64], order: int = 1) -> NDArray[np.float64]:
        """Central-difference derivative along time, run by run: shape of ``x``, unit per s^order."""
        out = np.array(x, dtype=float, copy=True)
        dt = 1.0 / self.fs
        for _ in range(order):
            res = np.empty_like(out)
            for run in self.runs:
                seg = out[run]
                res[run] = np.gradient(seg, dt, axis=0) if len(seg) > 1 else 0.0
            out = res
        return out

    def sign(self, v: NDArray[np.float64]) -> NDArray[np.float64]:
        """``sign(v)`` with |v| < 1e-3 counted as zero."""
        return np.where(np.abs(v) < _SIGN_EPS, 0.0, np.sign(v))

    def mass_column(self, j: int) -> NDArray[np.float64]:
        """Column j of the mass matrix M(q) at every sample, (M, n) (kg m^2)."""
        key = "mass"
        if key not in self.cache:
            import pinocchio as pin

            model = self.robot.pin_model
            data = model.createData()
            self.cache[key] = np.array([pin.crba(model, data, qi) for qi in self.q])
        M = self.cache[key]
        return 0.5 * (M[:, :, j] + M[:, j, :])

    def gravity_tilt(self) -> NDArray[np.float64]:
        """``d g(q) / d alpha`` for gravity tilted about two horizontal axes: (M, n, 2) (N m/rad)."""
        if "tilt" in self.cache:
            return self.cache["tilt"]
        import pinocchio as pin

        model = self.robot.pin_model.copy()
        data = model.createData()
        g0 = np.array(model.gravity.linear, dtype=float)
        up = g0 / max(np.linalg.norm(g0), 1e-12)
        a1 = np.cross(up, [1.0, 0.0, 0.0])
        if np.linalg.norm(a1) < 1e-6:
            a1 = np.cross(up, [0.0, 1.0, 0.0])
        a1 /= np.linalg.norm(a1)
        a2 = np.cross(up, a1)
        out = np.empty((self.m, self.n, 2))
        for k, axis in enumerate((a1, a2)):
            # Small rotation: g' = g + alpha (axis x g); derivative exact since g(q) is linear in g.
            model.gravity.linear = np.cross(axis, g0)
            for i in range(self.m):
                out[i, :, k] = pin.computeGeneralizedGravity(model, data, self.q[i])
        self.cache["tilt"] = out
        return out


@dataclass(frozen=True)
class Candidate:
    """One candidate effect: its columns and what it needs.

    Attributes
    ----------
    effect : str
        Catalogue name.
    joint : int or None
        Joint (0-based) it acts on, None for an effect of the whole arm.
    joints : tuple of int
        Joints (0-based) whose torque it changes.
    hyper : dict
        Hyper-parameter values (tuned on the training data).
    label : str
        Human label ("stribeck on joint 3").
    """

    effect: str
    joint: int | None
    joints: tuple[int, ...]
    hyper: dict[str, float] = field(default_factory=dict)
    label: str = ""

    @property
    def scored(self) -> tuple[int, ...]:
        """Joints (0-based) on which it is scored: a flexible transmission shakes the whole arm."""
        if self.effect in ("elasticity", "backlash") and self.joint is not None:
            return ()  # all joints
        return self.joints

    @property
    def key(self) -> str:
        """Effect and joint(s), e.g. ``stribeck@3`` or ``coupled_friction@5+6``."""
        if self.joint is None and len(self.joints) == 0:
            return self.effect
        if self.joint is not None:
            return f"{self.effect}@{self.joint + 1}"
        return f"{self.effect}@" + "+".join(str(j + 1) for j in self.joints)


def _on_joint(src: FeatureSource, j: int, cols: Sequence[NDArray[np.float64]]) -> NDArray[np.float64]:
    out = np.zeros((src.m, src.n, len(cols)))
    for k, c in enumerate(cols):
        out[:, j, k] = c
    return out


def _warm(t: NDArray[np.float64], T: float) -> NDArray[np.float64]:
    return 1.0 - np.exp(-np.maximum(t, 0.0) / T)


Builder = Callable[[FeatureSource, Candidate], NDArray[np.float64]]


def _offset(src, c):
    return _on_joint(src, c.joint, [np.ones(src.m)])


def _armature(src, c):
    return _on_joint(src, c.joint, [src.ddq[:, c.joint]])


def _stribeck(src, c):
    v = src.dq[:, c.joint]
    vs = c.hyper["vs"]
    return _on_joint(src, c.joint, [src.sign(v) * np.exp(-((np.abs(v) / vs) ** 2))])


def _load_friction(src, c):
    j = c.joint
    s = src.sign(src.dq[:, j])
    a = np.abs(src.tau_pred[:, j])
    drive = np.sign(src.dq[:, j] * src.tau_pred[:, j])
    return _on_joint(src, j, [s * a, s * a * drive])


def _temperature(src, c):
    j = c.joint
    h = _warm(src.t, c.hyper["T"])
    return _on_joint(src, j, [h * src.sign(src.dq[:, j]), h * src.dq[:, j]])


def _cogging(src, c):
    j = c.joint
    N = c.hyper["N"]
    x = src.q[:, j]
    return _on_joint(src, j, [f(k * N * x) for k in (1, 2) for f in (np.sin, np.cos)])


def _shifted(src: FeatureSource, j: int, delta: NDArray[np.float64], *, links: bool = False) -> NDArray[np.float64]:
    """Change of the first-fit torque (M, n, 1) when the link angle of joint j lags the encoder by delta;
    with ``links`` of the links' share only (the motor's friction and inertia stay at the encoder's states)."""
    at, base = src.torque_at, src.tau_pred
    if links and src.link_torque_at is not None and src.tau_link is not None:
        at, base = src.link_torque_at, src.tau_link
    if at is None:
        raise ValueError("the exact transmission columns need FeatureSource.torque_at")
    q, dq, ddq = src.q.copy(), src.dq.copy(), src.ddq.copy()
    q[:, j] -= delta
    dq[:, j] -= src.derivative(delta, 1)
    ddq[:, j] -= src.derivative(delta, 2)
    return (at(q, dq, ddq) - base)[:, :, None]


def _spring_deflection(src: FeatureSource, j: int, tau, w: float, z: float) -> NDArray[np.float64]:
    """Deflection (M,) of a spring of natural frequency w (rad/s), damping ratio z, loaded by tau (N m)."""
    from scipy.signal import cont2discrete, lfilter

    m = float(np.median(src.mass_column(j)[:, j]))
    K = m * w * w
    b, a, _ = cont2discrete(([w * w], [1.0, 2 * z * w, w * w]), 1.0 / src.fs, method="bilinear")
    out = np.empty_like(tau)
    for run in src.runs:
        seg = tau[run] / K
        out[run] = lfilter(b[0], a, seg - seg[0]) + seg[0]
    return out


def _elasticity(src, c):
    j = c.joint
    # The model's whole torque loads the spring here: its links' share alone (physically the load)
    # lost a flexible shoulder (UR5 joint 2, resonance 10 Hz: 0.64 of its gap closed, then none).
    tau = src.tau_pred[:, j]
    # The motor inertia of a flexible joint acts on the encoder side like an armature: its column
    # goes with the spring's when the model has no armature of its own.
    motor = [src.ddq[:, j]] if c.hyper.get("motor") else []
    if "exact" in c.hyper:
        # Refit: the link is a mass on a spring driven from the encoder side, q_j = theta_j - delta with
        # m delta'' + d delta' + K delta = tau_j (natural frequency w, damping ratio z, m = M_jj).
        delta = _spring_deflection(src, j, tau, c.hyper["w"], c.hyper["z"])
        out = _shifted(src, j, delta)
        return np.concatenate([out, _on_joint(src, j, motor)], axis=2) if motor else out
    # First order of q_j = theta_j - c tau_j: the whole arm feels -M(q)[:, j] c d2tau_j/dt2.
    out = src.mass_column(j)[:, :, None] * src.derivative(tau, 2)[:, None, None]
    return np.concatenate([out, _on_joint(src, j, motor)], axis=2) if motor else out


def _relay(x: NDArray[np.float64], h: float) -> NDArray[np.float64]:
    """+-1 by the side x last crossed: above h, below -h (a relay with hysteresis 2 h)."""
    s = np.where(x > h, 1.0, np.where(x < -h, -1.0, 0.0))
    idx = np.where(s != 0, np.arange(s.size), 0)
    idx = np.maximum.accumulate(idx)
    out = s[idx]
    first = np.flatnonzero(s)
    out[: first[0] if first.size else s.size] = s[first[0]] if first.size else 0.0
    return out


def _backlash(src, c):
    j = c.joint
    tau = src.transmitted(j)
    motor = [src.ddq[:, j]] if c.hyper.get("motor") else []
    if "exact" in c.hyper:
        # Refit: the teeth change sides once the transmitted torque has reversed beyond h (the impacts
        # and the link's own swing make it hover about zero), d seconds later (the time the motor takes
        # to cross the gap); the link lags the encoder by a on the side last pushed.
        b = _relay(tau, c.hyper["h"] * max(float(np.std(tau)), 1e-12))
        if c.hyper.get("d", 0.0):
            b = np.interp(src.t - c.hyper["d"], src.t, b)
        out = _shifted(src, j, c.hyper["a"] * b, links=True)
        return np.concatenate([out, _on_joint(src, j, motor)], axis=2) if motor else out
    b = np.tanh(tau / c.hyper["eps"])
    # The link lags by a tanh(tau / eps) + c tau (dead zone and the teeth's stiffness): to first order the
    # whole arm feels -M(q)[:, j] times their second derivatives; the offset b shifts gravity on joint j.
    Mj = src.mass_column(j)[:, :, None]
    out = np.concatenate(
        [Mj * src.derivative(b, 2)[:, None, None], Mj * src.derivative(tau, 2)[:, None, None]], axis=2
    )
    return np.concatenate([out, _on_joint(src, j, [b, *motor])], axis=2)


def _delay(src, c):
    j = c.joint
    tau = src.tau_pred[:, j]
    if "exact" in c.hyper:  # refit: tau(t - d) - tau(t)
        return _on_joint(src, j, [np.interp(src.t - c.hyper["d"], src.t, tau) - tau])
    return _on_joint(src, j, [src.derivative(tau, 1)])


def _drive_gain(src, c):
    j = c.joint
    return _on_joint(src, j, [src.tau_pred[:, j]])


def _base_tilt(src, c):
    return src.gravity_tilt()


def _coupled(src, c):
    a, b = c.joints
    w = src.dq[:, a] + c.hyper["sign"] * src.dq[:, b]
    s = src.sign(w)
    out = np.zeros((src.m, src.n, 2))
    out[:, a, 0] = s
    out[:, a, 1] = w
    # The coupled motor's friction reaches joint b through the same coupling sign.
    out[:, b, 0] = c.hyper["sign"] * s
    out[:, b, 1] = c.hyper["sign"] * w
    return out


def _nonlinear_viscous(src, c):
    v = src.dq[:, c.joint]
    return _on_joint(src, c.joint, [v * np.abs(v), v**3])


_BUILDERS: dict[str, Builder] = {
    "offset": _offset,
    "armature": _armature,
    "stribeck": _stribeck,
    "load_friction": _load_friction,
    "temperature": _temperature,
    "cogging": _cogging,
    "elasticity": _elasticity,
    "backlash": _backlash,
    "delay": _delay,
    "drive_gain": _drive_gain,
    "base_tilt": _base_tilt,
    "coupled_friction": _coupled,
    "nonlinear_viscous": _nonlinear_viscous,
}


def candidate_columns(src: FeatureSource, cand: Candidate) -> NDArray[np.float64]:
    """Full-rate columns of a candidate: (M, n, k), zero on the joints it does not act on.

    Parameters
    ----------
    src : FeatureSource
        Signals of one dataset.
    cand : Candidate
        The candidate with its hyper-parameters.
    """
    return _BUILDERS[cand.effect](src, cand)


@dataclass(frozen=True)
class _Spec:
    per_joint: bool
    grid: Callable[[FeatureSource, int], list[dict[str, float]]] | None
    excites: str


def _stribeck_grid(src: FeatureSource, j: int) -> list[dict[str, float]]:
    vmax = max(float(np.max(np.abs(src.dq[:, j]))), 1e-6)
    return [{"vs": f * vmax} for f in (0.01, 0.02, 0.04, 0.08, 0.16)]


def _temperature_grid(src: FeatureSource, j: int) -> list[dict[str, float]]:
    span = max(float(src.t[-1]), 1.0)
    return [{"T": f * span} for f in (0.25, 1.0, 4.0)]


def _backlash_grid(src: FeatureSource, j: int) -> list[dict[str, float]]:
    s = max(float(np.std(src.transmitted(j))), 1e-9)
    return [{"eps": f * s} for f in (0.02, 0.05, 0.15)]


def _cogging_grid(src: FeatureSource, j: int) -> list[dict[str, float]]:
    return [{"N": float(N)} for N in (50, 80, 100, 120, 160, 200)]


CANDIDATES: dict[str, _Spec] = {
    "offset": _Spec(True, None, "both directions of motion at every speed (a constant does not change sign)"),
    "armature": _Spec(True, None, "large accelerations of joint {j}"),
    "stribeck": _Spec(True, _stribeck_grid, "slow motion and many velocity reversals of joint {j}"),
    "load_friction": _Spec(True, None, "large loads on joint {j}, both driving and back-driven"),
    "temperature": _Spec(
        True, _temperature_grid, "a longer run (minutes) so that friction drift and motion part"
    ),
    "cogging": _Spec(
        True, _cogging_grid, "slow constant-speed sweeps of joint {j} over several gear periods"
    ),
    "elasticity": _Spec(True, None, "fast torque changes on joint {j} (harmonics near its resonance)"),
    "backlash": _Spec(True, _backlash_grid, "torque reversals of joint {j} at low speed"),
    "delay": _Spec(True, None, "faster excitation of joint {j} (a delay grows with frequency)"),
    "drive_gain": _Spec(True, None, "large torques on joint {j} at several speeds"),
    "payload": _Spec(False, None, "several tool orientations under gravity"),
    "base_tilt": _Spec(False, None, "full turns of joint 1 in several arm configurations"),
    "coupled_friction": _Spec(False, None, "wrist joints moving in equal and opposite directions"),
    "nonlinear_viscous": _Spec(True, None, "high speeds of joint {j}"),
}


def excitation_hint(cand: Candidate) -> str:
    """Words for the motion that excites a candidate."""
    j = cand.joint + 1 if cand.joint is not None else (cand.joints[0] + 1 if cand.joints else 1)
    return CANDIDATES[cand.effect].excites.format(j=j)


def enumerate_candidates(
    src: FeatureSource, effects: Sequence[str], *, skip: Sequence[str] = (), motor_inertia: bool = False
) -> list[list[Candidate]]:
    """Every candidate of the catalogue on every joint, each as its list of hyper-parameter variants.

    Parameters
    ----------
    src : FeatureSource
        Training signals (the grids of hyper-parameters are scaled from them).
    effects : sequence of str
        Effects to consider.
    skip : sequence of str
        Effects that the model already holds (their columns would duplicate the model's).
    motor_inertia : bool
        Give elasticity and backlash a motor-inertia column ``ddq_j`` (when the model has no armature).

    Returns
    -------
    list of list of Candidate
        One inner list per (effect, joint): the variants to tune among.
    """
    n = src.n
    out: list[list[Candidate]] = []
    for name in effects:
        if name in skip or name == "payload":
            continue
        spec = CANDIDATES[name]
        if spec.per_joint:
            for j in range(n):
                grid = spec.grid(src, j) if spec.grid else [{}]
                if name in ("elasticity", "backlash") and motor_inertia:
                    grid = [{**g, "motor": 1.0} for g in grid]
                label = f"{name} on joint {j + 1}"
                out.append([Candidate(name, j, (j,), g, label) for g in grid])
        elif name == "base_tilt":
            out.append([Candidate(name, None, tuple(range(n)), {}, "base tilt (gravity direction)")])
        elif name == "coupled_friction" and n >= 2:
            wrist = list(range(max(0, n - 3), n))
            for ia, a in enumerate(wrist):
                for b in wrist[ia + 1 :]:
                    out.append(
                        [
                            Candidate(
                                name,
                                None,
                                (a, b),
                                {"sign": sgn},
                                f"coupled friction of joints {a + 1} and {b + 1}",
                            )
                            for sgn in (1.0, -1.0)
                        ]
                    )
    return out


def describe_hyper(cand: Candidate) -> str:
    """Hyper-parameters in words (``vs = 0.05 rad/s``)."""
    units = {"vs": "rad/s", "T": "s", "N": "", "eps": "N m", "sign": ""}
    parts = []
    for k, v in cand.hyper.items():
        if k in ("motor", "exact"):
            continue
        if k == "sign":
            parts.append("w = dq_a + dq_b" if v > 0 else "w = dq_a - dq_b")
        else:
            parts.append(f"{k} = {v:.3g}{(' ' + units[k]) if units.get(k) else ''}")
    return ", ".join(parts)


def nominal_gear_period(N: float) -> float:
    """Angle (rad) of one gear period for a ratio N."""
    return 2 * math.pi / N
