"""The column builders of the effect catalogue: the signals they read, the candidate, one builder per effect.

:class:`FeatureSource` holds a dataset's full-rate signals (and memoises the mass matrix and the gravity
tilt), :class:`Candidate` one effect on its joints with its hyper-parameters, :data:`BUILDERS` the
function that turns a candidate into its columns (:func:`candidate_columns`; the exact transmission
columns shift the model's torque, :func:`relay` is the backlash's dead zone) and :data:`EFFECT_GRIDS`
the hyper-parameter grids scaled from the data (the ``*_grid`` functions).  Identify's side (parsing
``--effects``, the model file's terms, tuning) is :mod:`dynid.identify.effect_terms`, which gives these
names too; the diagnosis screens the same columns as candidates (:mod:`dynid.diagnosis.candidates`).
An effect kept outside dynid adds its builder with :func:`register_builder`, which
:func:`dynid.sim.effects.register_effect` calls beside the effect's simulation class.

Each effect of the catalogue (:mod:`dynid.sim.effect_classes`) is one or a few columns per joint,
linear in their coefficients, refitted *together with* the base parameters (so what re-identification
absorbs is never credited to the effect):

========================  ===================================================  ===================
effect                    columns on joint j (``s = sign``)                    hyper-parameter
========================  ===================================================  ===================
offset                    1                                                    -
armature                  ddq_j                                                -
stribeck                  s(dq_j) exp(-(|dq_j| / vs)^2)                        vs
load_friction             s(dq_j) |tau_j|                                      -
temperature               h(t) s(dq_j),  h(t) dq_j;  h = 1 - exp(-t / T)       T
cogging                   sin(k N q_j), cos(k N q_j), k = 1, 2                 N (gear ratio)
elasticity                M(q)[:, j] d^2 tau_j / dt^2 (all joints; first      -
                          order of q_j = theta_j - tau_j / K)
backlash                  M(q)[:, j] d^2 b_j / dt^2, M(q)[:, j] d^2 tau_j /    eps
                          dt^2 (all joints), b_j; b_j = tanh(tau_j / eps)
delay                     d tau_j / dt (first order of tau(t - d))             -
drive_gain                tau_j                                                -
base_tilt                 d g(q) / d alpha about two horizontal axes (all j)   -
coupled_friction          s(w), w on joints a and b, w = m dq_a +- dq_b        pair, sign, mix m
                          (m = 1: a coupled motor's speed; m = 0: joint b's     (default 1)
                          output stage, driven by that motor)
nonlinear_viscous         dq_j |dq_j|,  dq_j^3                                 -
payload                   (absorbed by the base parameters: parametric test)   -
========================  ===================================================  ===================

A delay also has a form common to all joints (``delay@all``, :func:`common_term`): the delay column on
every joint with one coefficient, so that one lag of the torques against the angles is one candidate.
``tau`` is the identified model's predicted torque (the "first fit"); for backlash its links' share,
which the transmission carries (the motor's armature and friction act before the gear).
No two candidates on a joint span the same columns: a load friction that differs between driving and
back-driven motion has no column of its own for the difference, ``s(dq_j) |tau_j| s(dq_j tau_j)`` being
``tau_j`` itself, the drive gain's column (the simulator's load friction, 0.05 driving and 0.025
back-driven, is a load friction of 0.0375 and a drive gain of 0.0125 on its joint).  Candidates whose
columns contain a simpler one's by design (the motor-inertia column of elasticity and backlash is the
armature's; backlash holds the teeth's stiffness, elasticity's column) are told apart by the
simpler-candidate test (:func:`dynid.diagnosis.screening.parsimonious`).
Elasticity, backlash and delay are not linear in their parameters: the screen uses the first-order
columns above, the refit (:mod:`dynid.diagnosis.refinement`) fits their physical parameters (for
backlash a dead zone whose sides change once the torque has reversed beyond a threshold, a crossing
time later).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dynid._rest import direction
from dynid.exceptions import UsageError

__all__ = [
    "BUILDERS",
    "COMMON_EFFECTS",
    "EFFECT_GRIDS",
    "Builder",
    "Candidate",
    "FeatureSource",
    "Grid",
    "backlash_grid",
    "candidate_columns",
    "cogging_grid",
    "common_term",
    "register_builder",
    "relay",
    "stribeck_grid",
    "temperature_grid",
    "tilt_axes",
    "unregister_builder",
]


COMMON_EFFECTS = ("delay",)
"""Per-joint effects that also have a form common to all joints, one parameter for the arm
(:func:`common_term`; written ``NAME@all``)."""


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
        """``sign(v)`` with a joint at rest counted as zero (:func:`dynid._rest.direction`)."""
        return direction(v)

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
        out = np.empty((self.m, self.n, 2))
        for k, axis in enumerate(tilt_axes(g0)):
            # Small rotation: g' = g + alpha (axis x g); derivative exact since g(q) is linear in g.
            model.gravity.linear = np.cross(axis, g0)
            for i in range(self.m):
                out[i, :, k] = pin.computeGeneralizedGravity(model, data, self.q[i])
        self.cache["tilt"] = out
        return out


def tilt_axes(gravity: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The two horizontal axes (unit vectors in the base frame) of the base tilt's columns ``ax``, ``ay``."""
    g0 = np.asarray(gravity, dtype=float)
    up = g0 / max(np.linalg.norm(g0), 1e-12)
    a1 = np.cross(up, [1.0, 0.0, 0.0])
    if np.linalg.norm(a1) < 1e-6:
        a1 = np.cross(up, [0.0, 1.0, 0.0])
    a1 /= np.linalg.norm(a1)
    return a1, np.cross(up, a1)


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
        """Effect and joint(s), e.g. ``stribeck@3``, ``coupled_friction@5+6`` or ``delay@all`` (one delay
        common to every joint, :data:`COMMON_EFFECTS`)."""
        if self.joint is None and len(self.joints) == 0:
            return self.effect
        if self.joint is None and self.effect in COMMON_EFFECTS:
            return f"{self.effect}@all"
        if self.joint is not None:
            return f"{self.effect}@{self.joint + 1}"
        key = f"{self.effect}@" + "+".join(str(j + 1) for j in self.joints)
        mix = float(self.hyper.get("mix", 1.0)) + 0.0  # (-0 is 0)
        text = repr(mix).removesuffix(".0")  # to the bit: two mixes are one key only when equal
        return key if mix == 1.0 else f"{key}:mix={text}"  # the output stage's friction beside the motor's


def _on_joint(src: FeatureSource, j: int, cols: Sequence[NDArray[np.float64]]) -> NDArray[np.float64]:
    out = np.zeros((src.m, src.n, len(cols)))
    for k, c in enumerate(cols):
        out[:, j, k] = c
    return out


def _warm(t: NDArray[np.float64], T: float) -> NDArray[np.float64]:
    return 1.0 - np.exp(-np.maximum(t, 0.0) / T)


Builder = Callable[[FeatureSource, Candidate], NDArray[np.float64]]
"""A column builder: ``(src, cand) -> (M, n, k)`` columns, zero on the joints the candidate does not act on."""

Grid = Callable[[FeatureSource, int], list[dict[str, float]]]
"""A hyper-parameter grid: ``(src, j) -> [hyper, ...]``, the variants to tune a candidate on joint j among."""


def _offset(src, c):
    return _on_joint(src, c.joint, [np.ones(src.m)])


def _armature(src, c):
    return _on_joint(src, c.joint, [src.ddq[:, c.joint]])


def _stribeck(src, c):
    v = src.dq[:, c.joint]
    vs = c.hyper["vs"]
    return _on_joint(src, c.joint, [src.sign(v) * np.exp(-((np.abs(v) / vs) ** 2))])


def _load_friction(src, c):
    # Coulomb friction growing with the load, mu |tau| sign(dq): one column.  Its driving / back-driven
    # asymmetry is no column of its own: sign(dq) |tau| sign(dq tau) is tau itself wherever the joint
    # moves, the drive_gain column, so an asymmetric load friction (mu_d driving, mu_b back-driven) is
    # (mu_d + mu_b) / 2 here and a drive gain (mu_d - mu_b) / 2 beside it.  Model files written with the
    # two columns load with ``asymmetric`` set (:func:`effect_from_dict`).
    j = c.joint
    s = src.sign(src.dq[:, j])
    a = np.abs(src.tau_pred[:, j])
    if c.hyper.get("asymmetric"):
        drive = np.sign(src.dq[:, j] * src.tau_pred[:, j])
        return _on_joint(src, j, [s * a, s * a * drive])
    return _on_joint(src, j, [s * a])


def _temperature(src, c):
    j = c.joint
    h = _warm(src.t, c.hyper["T"])
    return _on_joint(src, j, [h * src.sign(src.dq[:, j]), h * src.dq[:, j]])


def _cogging(src, c):
    j = c.joint
    N = c.hyper["N"]
    x = src.q[:, j]
    return _on_joint(src, j, [f(k * N * x) for k in (1, 2) for f in (np.sin, np.cos)])


def _shifted(
    src: FeatureSource, j: int, delta: NDArray[np.float64], *, links: bool = False
) -> NDArray[np.float64]:
    """Change of the first-fit torque (M, n, 1) when the link angle of joint j lags the encoder by delta;
    with ``links`` of the links' share only (the motor's friction and inertia stay at the encoder's states)."""
    if links and src.link_torque_at is not None and src.tau_link is not None:
        Jq, Jv, Ja = _link_sensitivity(src, j)
        d1, d2 = src.derivative(delta, 1), src.derivative(delta, 2)
        return -(Jq * delta[:, None] + Jv * d1[:, None] + Ja * d2[:, None])[:, :, None]
    at, base = src.torque_at, src.tau_pred
    if at is None:
        raise ValueError("the exact transmission columns need FeatureSource.torque_at")
    q, dq, ddq = src.q.copy(), src.dq.copy(), src.ddq.copy()
    q[:, j] -= delta
    dq[:, j] -= src.derivative(delta, 1)
    ddq[:, j] -= src.derivative(delta, 2)
    return (at(q, dq, ddq) - base)[:, :, None]


def _link_sensitivity(src: FeatureSource, j: int):
    """Derivatives (M, n) of the links' torque with respect to joint j's angle, speed and acceleration.

    The links' torque is smooth in the angles, quadratic in the speeds and linear in the accelerations, and
    a transmission's deflection is a fraction of a milliradian: to first order, which is all a column with
    a free coefficient stands for, the torque change is linear in the deflection and its derivatives.
    Central differences (exact for the speeds'), memoised per joint: five evaluations of the links' torque
    instead of one per column built (the backlash refit builds about a hundred).
    """
    key = f"link_sensitivity_{j}"
    if key not in src.cache:
        at, q, dq, ddq = src.link_torque_at, src.q, src.dq, src.ddq

        def moved(x, h):
            x = x.copy()
            x[:, j] += h
            return x

        hq, hv = 1e-5, 1e-2
        Jq = (at(moved(q, hq), dq, ddq) - at(moved(q, -hq), dq, ddq)) / (2 * hq)
        Jv = (at(q, moved(dq, hv), ddq) - at(q, moved(dq, -hv), ddq)) / (2 * hv)
        Ja = at(q, dq, moved(ddq, 1.0)) - src.tau_link
        src.cache[key] = (Jq, Jv, Ja)
    return src.cache[key]


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


def relay(x: NDArray[np.float64], h: float) -> NDArray[np.float64]:
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
        # to cross the gap); the link lags the encoder by a on the side last pushed.  With ``w``, the
        # teeth's stiffness too (the screen's c tau, with its dynamics): a spring of natural frequency w,
        # damping ratio z, loaded by the transmitted torque, in a column of its own.
        b = relay(tau, c.hyper["h"] * max(float(np.std(tau)), 1e-12))
        if c.hyper.get("d", 0.0):
            b = np.interp(src.t - c.hyper["d"], src.t, b)
        out = _shifted(src, j, c.hyper["a"] * b, links=True)
        if "w" in c.hyper:
            spring = _spring_deflection(src, j, tau, c.hyper["w"], c.hyper["z"])
            out = np.concatenate([out, _shifted(src, j, spring, links=True)], axis=2)
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
    if c.joint is None:  # one delay common to the joints (one column, one coefficient)
        out = np.zeros((src.m, src.n, 1))
        for j in c.joints:
            out[:, j, 0] = _delay(src, Candidate(c.effect, j, (j,), c.hyper))[:, j, 0]
        return out
    j = c.joint
    tau = src.tau_pred[:, j]
    if "exact" in c.hyper:  # refit: tau(t - d) - tau(t)
        return _on_joint(src, j, [np.interp(src.t - c.hyper["d"], src.t, tau) - tau])
    return _on_joint(src, j, [src.derivative(tau, 1)])


def common_term(name: str, n: int, hyper: dict[str, float] | None = None) -> Candidate:
    """The form of a per-joint effect common to all ``n`` joints: one parameter shared by every joint
    (:data:`COMMON_EFFECTS`; ``delay@all`` in an effect list).

    One cause on every joint (the torques' timestamps against the angles') then reads as one finding with
    one parameter, not as a per-joint effect on each joint.  A common drive gain has no such form: it
    scales every base parameter alike, which re-identification absorbs (the parameter-change test sees it).
    """
    if name not in COMMON_EFFECTS:
        raise UsageError(
            f"the effect '{name}' has no form common to all joints; those that do: {', '.join(COMMON_EFFECTS)}"
        )
    return Candidate(name, None, tuple(range(n)), dict(hyper or {}), f"{name} common to all joints")


def _drive_gain(src, c):
    j = c.joint
    return _on_joint(src, j, [src.tau_pred[:, j]])


def _base_tilt(src, c):
    return src.gravity_tilt()


def _coupled(src, c):
    a, b = c.joints
    # mix 1: the coupled motor's own speed; 0: joint b's output stage, which the same motor drives
    w = c.hyper.get("mix", 1.0) * src.dq[:, a] + c.hyper["sign"] * src.dq[:, b]
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


BUILDERS: dict[str, Builder] = {
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
    return BUILDERS[cand.effect](src, cand)


def stribeck_grid(src: FeatureSource, j: int) -> list[dict[str, float]]:
    vmax = max(float(np.max(np.abs(src.dq[:, j]))), 1e-6)
    return [{"vs": f * vmax} for f in (0.01, 0.02, 0.04, 0.08, 0.16)]


def temperature_grid(src: FeatureSource, j: int) -> list[dict[str, float]]:
    span = max(float(src.t[-1]), 1.0)
    return [{"T": f * span} for f in (0.25, 1.0, 4.0)]


def backlash_grid(src: FeatureSource, j: int) -> list[dict[str, float]]:
    s = max(float(np.std(src.transmitted(j))), 1e-9)
    return [{"eps": f * s} for f in (0.02, 0.05, 0.15)]


def cogging_grid(src: FeatureSource, j: int) -> list[dict[str, float]]:
    return [{"N": float(N)} for N in (50, 80, 100, 120, 160, 200)]


EFFECT_GRIDS: dict[str, Grid] = {
    "stribeck": stribeck_grid,
    "temperature": temperature_grid,
    "backlash": backlash_grid,
    "cogging": cogging_grid,
}
"""Hyper-parameter grids (scaled from the training data) of the effects that have one."""

_BUILTIN = frozenset(BUILDERS)


def register_builder(name: str, builder: Builder, *, grid: Grid | None = None, replace: bool = False) -> None:
    """Add the column builder (and the hyper-parameter grid, if any) of an effect kept outside dynid.

    :func:`dynid.sim.effects.register_effect` calls it with the effect's simulation class; on its own it
    makes ``identify --effects NAME`` (and the diagnosis' columns) know the effect.

    Parameters
    ----------
    name : str
        The effect's catalogue name.
    builder : callable
        ``(FeatureSource, Candidate) -> (M, n, k)`` columns (:data:`Builder`).
    grid : callable, optional
        ``(FeatureSource, j) -> [hyper, ...]``: the hyper-parameter variants to tune among (:data:`Grid`).
    replace : bool
        Replace a builder registered before under this name (a built-in one is never replaced).

    Raises
    ------
    UsageError
        A builder or grid that is not callable, a built-in name, or a name taken without ``replace``.
    """
    if not callable(builder):
        raise UsageError(
            f"the effect '{name}' has no column builder ({builder!r} is not callable); give a function "
            "(FeatureSource, Candidate) -> (M, n, k) columns."
        )
    if grid is not None and not callable(grid):
        raise UsageError(
            f"the hyper-parameter grid of the effect '{name}' is {grid!r}, not a function; give "
            "(FeatureSource, joint) -> list of dicts, or None."
        )
    if name in _BUILTIN:
        raise UsageError(
            f"the effect name '{name}' is a built-in effect's; give your effect a name of its own."
        )
    if name in BUILDERS and not replace and BUILDERS[name] is not builder:
        raise UsageError(
            f"the effect name '{name}' has a column builder already; choose another name or pass replace=True."
        )
    BUILDERS[name] = builder
    if grid is None:
        EFFECT_GRIDS.pop(name, None)
    else:
        EFFECT_GRIDS[name] = grid


def unregister_builder(name: str) -> None:
    """Forget the builder (and grid) registered under ``name``; built-in builders stay.  Nothing to forget: no change."""
    if name in _BUILTIN:
        raise UsageError(f"the effect '{name}' is built in; only registered effects can be forgotten.")
    BUILDERS.pop(name, None)
    EFFECT_GRIDS.pop(name, None)
