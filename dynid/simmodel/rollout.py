"""A forward check in MuJoCo: a trajectory tracked by dynid's controller, in MuJoCo and in dynid's simulator.

:func:`mujoco_tracking` replays a commanded motion in MuJoCo under the controller of
:class:`dynid.sim.tracking.TrackingLoop`: per control tick ``tau = rnea_nominal(q_d, dq_d, ddq_d) +
M_nominal(q) (kp (q_d - q) + kd (dq_d - v))`` with ``v`` the first-order low-passed difference of the
angle, held for the tick while MuJoCo integrates (its semi-implicit Euler, ``substeps`` steps per tick,
the torque applied as ``qfrc_applied``).  The controller's model is dynid's nominal robot, as in dynid's
simulator; the plant is the MJCF (its bodies, armature, damping and frictionloss constraint).

:func:`forward_agreement` runs the same commanded motion through dynid's own simulator
(:func:`dynid.sim.simulator.simulate`, noise off) on a truth and through MuJoCo on an MJCF of that truth,
and reports the agreement of the tracking error and of the drive torque.  MuJoCo's ``frictionloss`` is a
soft constraint while dynid's truth smooths ``sign`` over a small speed; they agree while the joints slide
and differ in the reversals, which the figures show.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["forward_agreement", "mujoco_tracking"]


def mujoco_tracking(
    path: str | os.PathLike[str],
    nominal,
    t: NDArray[np.float64],
    qd: NDArray[np.float64],
    dqd: NDArray[np.float64],
    ddqd: NDArray[np.float64],
    *,
    controller=None,
    substeps: int = 2,
) -> dict[str, NDArray[np.float64]]:
    """Track a commanded motion in MuJoCo with dynid's PD + feedforward controller.

    Parameters
    ----------
    path : str or path-like
        The MJCF (the plant).
    nominal : RobotModel
        The controller's model (its Pinocchio model gives the feedforward and the mass matrix).
    t : ndarray, shape (ticks,)
        Control ticks (s), evenly spaced from 0.
    qd, dqd, ddqd : ndarray, shape (ticks, n)
        Commanded angles (rad), speeds (rad/s) and accelerations (rad/s^2).
    controller : ControllerGains, optional
        Default :meth:`ControllerGains.design` (10 Hz, damping 0.7), as dynid's simulator.
    substeps : int
        MuJoCo steps per control tick (dynid's simulator: 2 for a rigid robot).

    Returns
    -------
    dict
        Per tick (ticks, n): ``q``, ``dq`` (MuJoCo's states at the tick) and ``tau_drive`` (controller
        output, N m).
    """
    import pinocchio as pin

    from dynid.sim.tracking import ControllerGains
    from dynid.simmodel.mjcf import import_mujoco

    mujoco = import_mujoco()
    n = nominal.n
    controller = controller or ControllerGains.design(n)
    m = mujoco.MjModel.from_xml_path(str(path))
    dt = float(t[1] - t[0])
    m.opt.timestep = dt / substeps
    m.opt.integrator = int(mujoco.mjtIntegrator.mjINT_EULER)
    d = mujoco.MjData(m)
    ids = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, name) for name in nominal.joint_names]
    qadr, dadr = np.asarray(m.jnt_qposadr[ids]), np.asarray(m.jnt_dofadr[ids])
    pm = nominal.pin_model
    pd = pm.createData()
    kp, kd = controller.kp, controller.kd
    alpha = math.exp(-2 * math.pi * controller.velocity_cutoff * dt)
    d.qpos[qadr], d.qvel[dadr] = qd[0], dqd[0]
    mujoco.mj_forward(m, d)
    ticks = len(t)
    out = {name: np.empty((ticks, n)) for name in ("q", "dq", "tau_drive")}
    v = dqd[0].copy()
    q_prev = None
    for k in range(ticks):
        q = np.array(d.qpos[qadr])
        if q_prev is not None:
            v = alpha * v + (1 - alpha) * (q - q_prev) / dt
        q_prev = q
        feedback = pin.crba(pm, pd, q) @ (kp * (qd[k] - q) + kd * (dqd[k] - v))
        tau = pin.rnea(pm, pd, qd[k], dqd[k], ddqd[k]) + feedback
        out["q"][k], out["dq"][k], out["tau_drive"][k] = q, d.qvel[dadr], tau
        d.qfrc_applied[:] = 0.0
        d.qfrc_applied[dadr] = tau
        for _ in range(substeps):
            mujoco.mj_step(m, d)
    return out


def forward_agreement(
    truth,
    trajectory,
    path: str | os.PathLike[str],
    *,
    duration: float | None = None,
    control_rate: float = 1000.0,
) -> dict[str, Any]:
    """The same commanded motion in dynid's simulator (on ``truth``) and in MuJoCo (on the MJCF ``path``).

    Parameters
    ----------
    truth : Truth
        dynid's plant (:func:`dynid.sim.truth.build_truth`); ``path`` should describe the same robot.
    trajectory : FourierTrajectory or SampledTrajectory
        The commanded motion.
    path : str or path-like
        The MJCF.
    duration : float, optional
        Length of the run (s; default the trajectory's).
    control_rate : float
        Controller rate (Hz).

    Returns
    -------
    dict
        Per joint: ``tracking_rms_dynid``, ``tracking_rms_mujoco`` (RMS of ``q_d - q``, rad),
        ``tracking_difference_rms`` (RMS of the difference of the two tracking errors, rad),
        ``torque_rms`` (RMS of dynid's drive torque, N m), ``torque_difference_rms`` (N m) and
        ``torque_relative`` (their ratio); ``duration``, ``control_rate``; ``series`` (the time, both
        drive torques and both angle histories, (ticks, n)).
    """
    from dynid.sim.simulator import simulate

    nominal = truth.nominal
    result = simulate(
        nominal,
        trajectory,
        truth=truth,
        noise="off",
        rate=control_rate,
        control_rate=control_rate,
        duration=duration,
    )
    t = result.t
    mj = mujoco_tracking(
        Path(path), nominal, t, result.q_desired, result.dq_desired, result.ddq_desired, substeps=result.substeps
    )

    def rms(a):
        return np.sqrt(np.mean(a**2, axis=0))

    e_dynid = result.q_desired - result.q_true
    e_mj = result.q_desired - mj["q"]
    torque = rms(result.tau_drive)
    dtau = rms(result.tau_drive - mj["tau_drive"])
    return {
        "duration": float(t[-1] - t[0]),
        "control_rate": float(control_rate),
        "tracking_rms_dynid": rms(e_dynid).tolist(),
        "tracking_rms_mujoco": rms(e_mj).tolist(),
        "tracking_difference_rms": rms(e_dynid - e_mj).tolist(),
        "torque_rms": torque.tolist(),
        "torque_difference_rms": dtau.tolist(),
        "torque_relative": (dtau / np.maximum(torque, 1e-300)).tolist(),
        "series": {
            "t": t,
            "tau_dynid": result.tau_drive,
            "tau_mujoco": mj["tau_drive"],
            "q_dynid": result.q_true,
            "q_mujoco": mj["q"],
        },
    }
