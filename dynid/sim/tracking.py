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
        import pinocchio as pin

        model, data = self.model, self.data
        armature = np.array(model.armature)
        n, dt, ns = self.n, self.dt, self.substeps
        h = dt / ns
        ticks = t_ctrl.size
        tr = self.truth.transmission
        flex, rigid = self.flex, self.rigid
        has_flex = flex.size > 0
        kp, kd = self.controller.kp, self.controller.kd
        alpha = math.exp(-2 * math.pi * self.controller.velocity_cutoff * dt)
        step, cstep = self.encoder_step, self.control_step

        ff = np.empty((ticks, n))
        for k in range(ticks):
            ff[k] = pin.rnea(self.nominal, self.nominal_data, qd[k], dqd[k], ddqd[k])

        out = {
            name: np.empty((ticks, n))
            for name in ("q", "dq", "ddq", "theta", "dtheta", "ddtheta", "q_meas", "tau_drive")
        }
        comps = {name: np.empty((ticks, n)) for name, _ in self.terms}

        q = qd[0].copy()
        dq = dqd[0].copy()
        if has_flex:
            assert tr is not None
            tau_s0 = pin.rnea(model, data, q, dq, ddqd[0])[flex]
            half = 0.5 * tr.gap
            theta = q[flex] + tau_s0 / tr.stiffness + half * np.sign(tau_s0)
            dtheta = dq[flex].copy()
            motor = tr.motor_inertia
        x = q.copy()
        dx = dq.copy()
        v = dqd[0].copy()
        x_prev = None
        diag = slice(None, None, n + 1)
        rigid_f = rigid.astype(float)
        rigid_outer = np.outer(rigid_f, rigid_f)
        store: dict[str, np.ndarray] = {}

        for k in range(ticks):
            if has_flex:
                x[:] = q
                x[flex] = theta
                dx[:] = dq
                dx[flex] = dtheta
            else:
                x, dx = q, dq
            x_ctrl = np.round(x / cstep) * cstep if cstep else x.copy()
            if x_prev is not None:
                v = alpha * v + (1 - alpha) * (x_ctrl - x_prev) / dt
            x_prev = x_ctrl
            weight = pin.crba(self.nominal, self.nominal_data, x_ctrl)
            tau_m = ff[k] + weight @ (kp * (qd[k] - x_ctrl) + kd * (dqd[k] - v))
            out["q_meas"][k] = np.round(x / step) * step if step else x
            out["tau_drive"][k] = tau_m
            # Drive-side torques at the tick, linearised in the speed for the substeps of this tick.
            f0, jd, jfull = self._drive(t_ctrl[k], x, dx, tau_m, store)
            dx0 = dx.copy()
            if self.terms:
                jr = jd * rigid_f if has_flex else jd
                if jfull is not None and has_flex:
                    jfull = jfull * rigid_outer
            for i in range(ns):
                f = (
                    f0
                    if i == 0
                    else f0 + (jd * (dx - dx0) if jfull is None else jd * (dx - dx0) + jfull @ (dx - dx0))
                )
                tau_link = tau_m - f
                if has_flex:
                    tau_s = tr.spring(theta - q[flex], dtheta - dq[flex])
                    tau_link[flex] = tau_s
                    motor_rhs = tau_m[flex] - tau_s - f[flex]
                if i == 0:
                    model.armature = armature
                    ddq = pin.aba(model, data, q, dq, tau_link)
                    out["q"][k] = q
                    out["dq"][k] = dq
                    out["ddq"][k] = ddq
                    for name in comps:
                        comps[name][k] = store[name]
                    out["theta"][k] = x
                    out["dtheta"][k] = dx
                    acc = ddq.copy()
                    if has_flex:
                        acc[flex] = motor_rhs / motor
                    out["ddtheta"][k] = acc
                if jfull is None:
                    # (M + diag(h J)) a = tau - b - f is forward dynamics with h J added to the armature.
                    if self.terms:
                        model.armature = armature + h * jr
                    acc = pin.aba(model, data, q, dq, tau_link)
                else:
                    model.armature = armature
                    mass = pin.crba(model, data, q)
                    mass.flat[diag] += h * jr
                    mass += h * jfull
                    acc = np.linalg.solve(mass, tau_link - pin.nle(model, data, q, dq))
                dq = dq + h * acc
                q = q + h * dq
                if has_flex:
                    dtheta = dtheta + h * motor_rhs / (motor + h * jd[flex])
                    theta = theta + h * dtheta
                    x = q.copy()
                    x[flex] = theta
                    dx = dq.copy()
                    dx[flex] = dtheta
                else:
                    x, dx = q, dq
        out["components"] = comps
        return out
