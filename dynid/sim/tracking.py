"""Closed-loop tracking: the PD + feedforward controller and the integrator of the truth robot.

Per control tick the controller reads the (quantised) drive-side angle, computes
``tau_m = rnea_nominal(q_d, dq_d, ddq_d) + M_nominal(q_enc) (Kp (q_d - q_enc) + Kd (dq_d - v))``
(:class:`ControllerGains`), and holds it while the truth moves: forward dynamics of the truth with the
friction and drive effects as joint torques, semi-implicit Euler in substeps with the
velocity-dependent torques linearly implicit (:class:`TrackingLoop`; the method is described in
:mod:`dynid.sim.simulator`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from dynid.sim.sensors import NoiseModel
from dynid.sim.truth import Truth

__all__ = ["ControllerGains", "TrackingLoop"]


@dataclass(frozen=True, eq=False)
class ControllerGains:
    """PD + feedforward joint controller: ``rnea_nominal(q_d, dq_d, ddq_d) + M_nominal(q) (kp e + kd de)``.

    Attributes
    ----------
    kp : ndarray, shape (n,)
        Position gains (1/s^2), multiplied by the nominal mass matrix.
    kd : ndarray, shape (n,)
        Velocity gains (1/s), multiplied by the nominal mass matrix.
    bandwidth : float
        Design bandwidth (Hz) with which the gains were chosen.
    damping : float
        Design damping ratio.
    velocity_cutoff : float
        Cut-off (Hz) of the first-order low-pass on the differentiated encoder angle.
    """

    kp: np.ndarray
    kd: np.ndarray
    bandwidth: float = 10.0
    damping: float = 0.7
    velocity_cutoff: float = 100.0

    @classmethod
    def design(cls, n: int, *, bandwidth: float = 10.0, damping: float = 0.7) -> ControllerGains:
        """Gains ``kp = w^2``, ``kd = 2 zeta w`` with ``w = 2 pi bandwidth`` for n joints.

        Parameters
        ----------
        n : int
            Number of joints.
        bandwidth : float
            Closed-loop natural frequency (Hz).
        damping : float
            Damping ratio zeta.
        """
        w = 2 * math.pi * bandwidth
        return cls(kp=np.full(n, w * w), kd=np.full(n, 2 * damping * w), bandwidth=bandwidth, damping=damping)

    def to_dict(self) -> dict:
        return {
            "law": "tau = rnea_nominal(q_d, dq_d, ddq_d) + M_nominal(q_encoder) (kp (q_d - q_encoder) + "
            "kd (dq_d - v_filtered))",
            "kp": self.kp.tolist(),
            "kd": self.kd.tolist(),
            "bandwidth_hz": self.bandwidth,
            "damping": self.damping,
            "velocity_cutoff_hz": self.velocity_cutoff,
            "units": "1/s^2, 1/s (times the nominal mass matrix)",
        }


class TrackingLoop:
    """The closed-loop integration of one run (a workspace: Pinocchio model and data, arrays).

    Parameters
    ----------
    truth : Truth
        The robot driven.
    controller : ControllerGains
    noise : NoiseModel
        Its encoder resolutions quantise the angles the controller reads and the log records.
    control_rate : float
        Controller rate (Hz).
    substeps : int or None
        Integration steps per tick; None: at least 2 and enough for the stiffest spring.
    """

    def __init__(
        self,
        truth: Truth,
        controller: ControllerGains,
        noise: NoiseModel,
        control_rate: float,
        substeps: int | None,
    ) -> None:
        import pinocchio as pin

        self.truth = truth
        self.controller = controller
        self.noise = noise
        self.dt = 1.0 / control_rate
        n = truth.nominal.n
        self.n = n
        self.model = pin.Model(truth.link_robot.pin_model)  # a copy: the loop changes its armature
        self.data = self.model.createData()
        self.nominal = truth.nominal.pin_model
        self.nominal_data = self.nominal.createData()
        tr = truth.transmission
        self.flex = np.array([], dtype=int) if tr is None else tr.joints
        self.rigid = np.ones(n, dtype=bool)
        self.rigid[self.flex] = False
        if substeps is None:
            substeps = 2
            if tr is not None:
                link = truth.scales.inertia[self.flex]
                omega = np.sqrt(tr.stiffness * (1 / tr.motor_inertia + 1 / link))
                substeps = max(substeps, math.ceil(float(omega.max()) * self.dt / 0.3))
        self.substeps = int(substeps)
        # Drive-side torque terms: (name, callable(t, x, dx, tau_m) -> (f, J)).
        terms = []
        temperature = truth.effect("temperature")
        if truth.friction.active:
            fric = truth.friction
            if temperature is None:
                terms.append(("friction", lambda t, x, dx, tau: fric.torque(dx)))
            else:
                terms.append(("friction", lambda t, x, dx, tau: fric.torque(dx, temperature.factor(t))))  # type: ignore[attr-defined]
        for effect in truth.effects:
            if effect.role == "drive":
                terms.append((effect.name, effect.drive))
        self.terms = terms
        self.encoder_step = 0.0 if noise.encoder_bits == 0 else 2 * math.pi / 2**noise.encoder_bits
        self.control_step = 0.0 if noise.control_bits == 0 else 2 * math.pi / 2**noise.control_bits

    def _drive(self, t, x, dx, tau_m, store=None):
        n = self.n
        f = np.zeros(n)
        jd = np.zeros(n)
        jfull = None
        for name, term in self.terms:
            fi, ji = term(t, x, dx, tau_m)
            f += fi
            if store is not None:
                store[name] = fi
            if ji.ndim == 1:
                jd += ji
            else:
                jfull = ji if jfull is None else jfull + ji
        return f, jd, jfull

    def integrate(self, t_ctrl, qd, dqd, ddqd) -> dict[str, Any]:
        """Track the commanded ``qd, dqd, ddqd`` (ticks, n) at the ticks ``t_ctrl``.

        Returns
        -------
        dict
            Per tick (ticks, n): ``q, dq, ddq`` (true link states), ``theta, dtheta, ddtheta`` (drive side),
            ``q_meas`` (logged encoder angles), ``tau_drive`` (controller output), and ``components``
            (drive-side torque of each term by name).
        """
        const = self._run_constants()
        ff = self._feedforward(qd, dqd, ddqd)
        ticks = t_ctrl.size
        out = {
            name: np.empty((ticks, self.n))
            for name in ("q", "dq", "ddq", "theta", "dtheta", "ddtheta", "q_meas", "tau_drive")
        }
        comps = {name: np.empty((ticks, self.n)) for name, _ in self.terms}
        state = self._initial_state(qd[0], dqd[0], ddqd[0])
        v = dqd[0].copy()
        x_prev = None
        store: dict[str, np.ndarray] = {}
        for k in range(ticks):
            x, dx = self._drive_side(state)
            x_ctrl = _quantise(x, self.control_step)
            if x_prev is not None:
                v = const.alpha * v + (1 - const.alpha) * (x_ctrl - x_prev) / self.dt
            x_prev = x_ctrl
            tau_m = self._command(ff[k], qd[k], dqd[k], x_ctrl, v)
            out["q_meas"][k] = _quantise(x, self.encoder_step)
            out["tau_drive"][k] = tau_m
            lin = self._linearise(t_ctrl[k], x, dx, tau_m, store, const)
            torques = self._link_torques(state, tau_m, lin.f0)
            self._record_tick(out, comps, k, state, x, dx, torques, store, const.armature)
            state = self._substeps(state, dx, tau_m, torques, lin, const)
        out["components"] = comps
        return out

    def _run_constants(self) -> _RunConstants:
        """The constants of one integration: substep, velocity-filter factor, base armature, rigid masks."""
        rigid_f = self.rigid.astype(float)
        return _RunConstants(
            h=self.dt / self.substeps,
            alpha=math.exp(-2 * math.pi * self.controller.velocity_cutoff * self.dt),
            armature=np.array(self.model.armature),
            rigid_f=rigid_f,
            rigid_outer=np.outer(rigid_f, rigid_f),
        )

    def _feedforward(self, qd, dqd, ddqd) -> np.ndarray:
        """The nominal inverse dynamics of the command at every tick (ticks, n)."""
        import pinocchio as pin

        ff = np.empty((qd.shape[0], self.n))
        for k in range(qd.shape[0]):
            ff[k] = pin.rnea(self.nominal, self.nominal_data, qd[k], dqd[k], ddqd[k])
        return ff

    def _initial_state(self, q0, dq0, ddq0) -> _State:
        """The truth at the first commanded state, flexible joints' motors at their static deflection."""
        import pinocchio as pin

        q = q0.copy()
        dq = dq0.copy()
        if self.flex.size == 0:
            return _State(q=q, dq=dq, theta=None, dtheta=None)
        tr = self.truth.transmission
        assert tr is not None
        tau_s0 = pin.rnea(self.model, self.data, q, dq, ddq0)[self.flex]
        half = 0.5 * tr.gap
        theta = q[self.flex] + tau_s0 / tr.stiffness + half * np.sign(tau_s0)
        return _State(q=q, dq=dq, theta=theta, dtheta=dq[self.flex].copy())

    def _drive_side(self, state: _State) -> tuple[np.ndarray, np.ndarray]:
        """The drive-side angles and speeds (n,): the link's, the motor's on the flexible joints."""
        if state.theta is None:
            return state.q, state.dq
        x = state.q.copy()
        x[self.flex] = state.theta
        dx = state.dq.copy()
        dx[self.flex] = state.dtheta
        return x, dx

    def _command(self, ff, qd, dqd, x_ctrl, v) -> np.ndarray:
        """The controller's drive torque: feedforward plus the PD weighted by the nominal mass matrix."""
        import pinocchio as pin

        kp, kd = self.controller.kp, self.controller.kd
        weight = pin.crba(self.nominal, self.nominal_data, x_ctrl)
        return ff + weight @ (kp * (qd - x_ctrl) + kd * (dqd - v))

    def _linearise(self, t, x, dx, tau_m, store, const: _RunConstants) -> _Linearisation:
        """The drive-side torques at the tick and their speed derivatives, held through its substeps."""
        f0, jd, jfull = self._drive(t, x, dx, tau_m, store)
        dx0 = dx.copy()
        has_flex = self.flex.size > 0
        jr = jd
        if self.terms:
            jr = jd * const.rigid_f if has_flex else jd
            if jfull is not None and has_flex:
                jfull = jfull * const.rigid_outer
        return _Linearisation(f0=f0, dx0=dx0, jd=jd, jr=jr, jfull=jfull)

    def _link_torques(self, state: _State, tau_m, f) -> _LinkTorques:
        """The torques on the links (the springs' on flexible joints) and the net torque on their motors."""
        tau_link = tau_m - f
        if state.theta is None:
            return _LinkTorques(tau_link=tau_link, motor_rhs=None)
        tr = self.truth.transmission
        assert tr is not None
        flex = self.flex
        tau_s = tr.spring(state.theta - state.q[flex], state.dtheta - state.dq[flex])
        tau_link[flex] = tau_s
        return _LinkTorques(tau_link=tau_link, motor_rhs=tau_m[flex] - tau_s - f[flex])

    def _record_tick(
        self, out, comps, k, state: _State, x, dx, torques: _LinkTorques, store, armature
    ) -> None:
        """Record the tick's states, the continuous model's accelerations there, and the torque components."""
        import pinocchio as pin

        self.model.armature = armature
        ddq = pin.aba(self.model, self.data, state.q, state.dq, torques.tau_link)
        out["q"][k] = state.q
        out["dq"][k] = state.dq
        out["ddq"][k] = ddq
        for name in comps:
            comps[name][k] = store[name]
        out["theta"][k] = x
        out["dtheta"][k] = dx
        acc = ddq.copy()
        if state.theta is not None:
            assert self.truth.transmission is not None
            acc[self.flex] = torques.motor_rhs / self.truth.transmission.motor_inertia
        out["ddtheta"][k] = acc

    def _substeps(
        self, state: _State, dx, tau_m, torques: _LinkTorques, lin: _Linearisation, const
    ) -> _State:
        """Integrate the truth through one tick under the held drive torque, the drive terms linearised."""
        jd, jfull, f0, dx0 = lin.jd, lin.jfull, lin.f0, lin.dx0
        for i in range(self.substeps):
            if i > 0:
                f = f0 + (jd * (dx - dx0) if jfull is None else jd * (dx - dx0) + jfull @ (dx - dx0))
                torques = self._link_torques(state, tau_m, f)
            acc = self._implicit_acceleration(state, torques.tau_link, lin, const)
            state = self._euler_step(state, acc, torques.motor_rhs, jd, const.h)
            dx = self._drive_side(state)[1]
        return state

    def _implicit_acceleration(self, state: _State, tau_link, lin: _Linearisation, const) -> np.ndarray:
        """The link accelerations of the step ``(M + h df/ddq) a = tau - b - f``."""
        import pinocchio as pin

        model, data, h = self.model, self.data, const.h
        if lin.jfull is None:
            # (M + diag(h J)) a = tau - b - f is forward dynamics with h J added to the armature.
            if self.terms:
                model.armature = const.armature + h * lin.jr
            return pin.aba(model, data, state.q, state.dq, tau_link)
        model.armature = const.armature
        mass = pin.crba(model, data, state.q)
        mass.flat[slice(None, None, self.n + 1)] += h * lin.jr
        mass += h * lin.jfull
        return np.linalg.solve(mass, tau_link - pin.nle(model, data, state.q, state.dq))

    def _euler_step(self, state: _State, acc, motor_rhs, jd, h: float) -> _State:
        """One semi-implicit Euler step (speed first, then angle) of links and flexible joints' motors."""
        dq = state.dq + h * acc
        q = state.q + h * dq
        if state.theta is None:
            return _State(q=q, dq=dq, theta=None, dtheta=None)
        assert self.truth.transmission is not None
        motor = self.truth.transmission.motor_inertia
        dtheta = state.dtheta + h * motor_rhs / (motor + h * jd[self.flex])
        return _State(q=q, dq=dq, theta=state.theta + h * dtheta, dtheta=dtheta)


@dataclass(frozen=True)
class _RunConstants:
    """What stays fixed through one integration."""

    h: float
    alpha: float
    armature: np.ndarray
    rigid_f: np.ndarray
    rigid_outer: np.ndarray


@dataclass(frozen=True)
class _State:
    """The truth's state: link angles and speeds, motor angles and speeds of the flexible joints (or None)."""

    q: np.ndarray
    dq: np.ndarray
    theta: np.ndarray | None
    dtheta: np.ndarray | None


@dataclass(frozen=True)
class _Linearisation:
    """The drive-side torques at a tick, their diagonal and full speed derivatives, and the tick's speeds."""

    f0: np.ndarray
    dx0: np.ndarray
    jd: np.ndarray
    jr: np.ndarray
    jfull: np.ndarray | None


@dataclass(frozen=True)
class _LinkTorques:
    """The torques driving the links (n,) and the net torques on the flexible joints' motors (or None)."""

    tau_link: np.ndarray
    motor_rhs: np.ndarray | None


def _quantise(x: np.ndarray, step: float) -> np.ndarray:
    """Angles rounded to an encoder's grid of ``step`` rad (a copy of them for step 0)."""
    return np.round(x / step) * step if step else x.copy()
