"""A robot that follows a trajectory like a real one: synthetic measured data with a known truth.

:func:`simulate` drives a *truth* robot along a commanded trajectory and records what a real arm's
controller would log: quantised encoder angles and the torque the drives apply, read through a noisy,
quantised current sensor.  The truth is the nominal model (URDF) with, optionally,

* its standard parameters perturbed (``perturb``; every link stays physically consistent: mass, centre
  of mass, principal moments and axes of the inertia about the centre of mass are perturbed and the
  link rebuilt from them),
* joint friction (``friction``: none, linear, seed = the paper's model, stribeck; sizes in
  :mod:`dynid.sim.effects`),
* unmodelled effects (``effects``: the catalogue of :mod:`dynid.sim.effects`, e.g.
  ``"offset,elasticity@3:2,delay:1.5"``),

and everything about it (parameters, friction coefficients, effects with their sizes, noise settings,
seed, controller gains) goes to a sidecar ``<out>.truth.json`` written beside the data, never into them.

Loop (per control tick of ``1 / control_rate`` s, 1 kHz by default):

1. the encoders read the drive-side angle (the motor side of an elastic or backlashed joint, else the
   joint angle): the controller reads the motor encoders, ``2^control_bits`` counts per joint revolution
   (2^24 by default: 2^17 counts per motor turn through a 100:1 gear), the log records
   ``2^encoder_bits`` (2^18 by default);
2. a PD + feedforward controller computes the drive torque
   ``tau_m = rnea_nominal(q_d, dq_d, ddq_d) + M_nominal(q_enc) (Kp (q_d - q_enc) + Kd (dq_d - v))``:
   feedforward and PD weighting both use the *nominal* model (never the truth); ``v`` is the backward
   difference of the encoder angle low-pass filtered at 100 Hz; ``Kp = w^2``, ``Kd = 2 zeta w`` with
   ``w = 2 pi 10 Hz``, ``zeta = 0.7``.  Weighting the PD by the mass matrix keeps every motion mode at
   the same bandwidth: gains per joint sized by the diagonal of M make light coupled modes (Panda's
   joints 1 and 3 when their axes align) exceed the stability limit of the 1 kHz sampled loop;
3. the torque is held for the tick (zero-order hold) while the truth moves: forward dynamics of the
   truth (Pinocchio's ``aba`` on the numeric model) with the friction and effect torques entering as
   joint torques, integrated in ``substeps`` steps by semi-implicit Euler (velocity first, then
   position) in which the velocity-dependent torques are *linearly implicit*: the step solves
   ``(M + h df/ddq) a = tau - b - f``, with ``f`` and ``df/ddq`` evaluated at the tick and linearised
   within it.  The diagonal ``h df/ddq`` is added to the armature of the model, so the step is one
   ``aba``; a coupled term (coupled_friction) takes ``crba`` and a solve.  The smoothed
   ``sign(dq) = tanh(dq / eps)`` of the friction has a slope ``Fc / eps`` near zero speed that would
   need sub-microsecond explicit steps; implicitly it is a strong damping the step cannot overshoot,
   so reversals are smooth at any step;
4. the *measured torque* is the drive torque ``tau_m`` (what a current sensor reads), then the sensor
   effects (drive_gain, delay, offset), white + AR(1) coloured noise and the current quantisation.

The recorded true states are the states at the ticks, and the recorded true acceleration is the
instantaneous acceleration of the continuous model there, so that with no friction, effect or noise
``tau = rnea_truth(q_true, dq_true, ddq_true)`` holds to rounding, whatever the step.

Noise settings (``noise=``, or ``--noise key=value,...``; torques are fractions of each joint's torque
scale s_j, see :mod:`dynid.sim.effects`; ``--noise off`` turns all off):

============  =========  =================================================================
key           default    meaning
============  =========  =================================================================
torque        0.01       white torque noise, std as a fraction of s_j
coloured      0.005      AR(1) coloured torque noise, stationary std as a fraction of s_j
colour        0.9        AR(1) coefficient of the coloured noise per control tick, in [0, 1)
encoder_bits  18         resolution of the logged angle, 2^bits counts per joint revolution (0: exact)
control_bits  24         resolution of the angle the controller reads (motor encoders), per joint revolution
current_lsb   0.001      quantisation step of the torque reading, fraction of s_j (0: exact)
============  =========  =================================================================

Seeds: the truth's random choices (perturbation, effect signs and phases) come from
``np.random.default_rng([truth_seed, k])`` (one stream per purpose), the noise from
``np.random.default_rng([seed, 1])``; ``truth_seed`` defaults to ``seed``.  Give two runs the same
``truth_seed`` and different seeds to record one robot on two trajectories with independent noise.

The parts are modules of their own: the truth (:mod:`dynid.sim.truth`), the controller and integrator
(:mod:`dynid.sim.tracking`), the sensors and noise (:mod:`dynid.sim.sensors`), the result and its files
(:mod:`dynid.sim.results`).  This module runs them and re-exports their public names.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from dynid.exceptions import ShapeError, UsageError
from dynid.optim.trajectory import FourierTrajectory, Trajectory
from dynid.sim.effects import EffectRequest, TruthFriction
from dynid.sim.results import SimulationResult, check_output_path, truth_path, write_simulation
from dynid.sim.sensors import NoiseModel, measured_torque
from dynid.sim.tracking import ControllerGains, TrackingLoop
from dynid.sim.truth import Transmission, Truth, build_truth, perturb_params
from dynid.symbolic.robot import RobotModel

__all__ = [
    "CONTROL_RATE",
    "MAX_TICKS",
    "ControllerGains",
    "NoiseModel",
    "SimulationResult",
    "Transmission",
    "Truth",
    "build_truth",
    "check_output_path",
    "perturb_params",
    "simulate",
    "truth_path",
    "write_simulation",
]

CONTROL_RATE = 1000.0
"""Default control and integration rate (Hz)."""

MAX_TICKS = 1_000_000
"""Most control ticks of one run (1000 s at 1 kHz): the run's states are held in memory, about 1 kB per
tick for a 6-joint arm.  Record a longer experiment as several runs."""

_LIMIT_TOL = 1e-6


def simulate(
    robot: RobotModel,
    trajectory: Trajectory,
    *,
    effects: str | Sequence[str | EffectRequest] | None = None,
    friction: str | TruthFriction = "linear",
    noise: str | Mapping[str, float] | NoiseModel | None = None,
    seed: int = 0,
    truth_seed: int | None = None,
    perturb: float = 0.0,
    rate: float = CONTROL_RATE,
    duration: float | None = None,
    control_rate: float = CONTROL_RATE,
    substeps: int | None = None,
    truth: Truth | None = None,
    controller: ControllerGains | None = None,
    source: str = "the trajectory",
) -> SimulationResult:
    """Run the truth robot along a trajectory under a tracking controller and measure it.

    Parameters
    ----------
    robot : RobotModel
        The nominal robot (the controller's model; the truth is built from it).
    trajectory : FourierTrajectory or SampledTrajectory
        Commanded motion; times from 0.
    effects : str or sequence, optional
        Unmodelled effects, ``"NAME[@J|@J-K][:VALUE],..."`` (see :mod:`dynid.sim.effects`).
    friction : {"none", "linear", "seed", "stribeck"} or TruthFriction
        Truth friction.
    noise : str or mapping or NoiseModel, optional
        Sensor model (default :class:`NoiseModel` ()); ``NoiseModel.off()`` or ``"off"`` for exact values.
    seed : int
        Seed of the noise (and of the truth when ``truth_seed`` is None).
    truth_seed : int, optional
        Seed of the truth's random choices.
    perturb : float
        Relative perturbation of the standard parameters, in [0, 0.5].
    rate : float
        Output rate (Hz); ``control_rate / rate`` must be a whole number.
    duration : float, optional
        Length of the run (s); default the trajectory's.  A Fourier trajectory repeats beyond its period.
    control_rate : float
        Controller (and sensor) rate (Hz).
    substeps : int, optional
        Integration steps per tick; default at least 2 and enough for the stiffest spring.
    truth : Truth, optional
        A truth from :func:`build_truth`: the same robot on another trajectory.  Its effects, friction,
        perturbation and seed are fixed already, so ``effects``, ``friction``, ``perturb`` and
        ``truth_seed`` are refused beside it (give them to :func:`build_truth`).
    controller : ControllerGains, optional
        Default :meth:`ControllerGains.design` (10 Hz, damping 0.7).
    source : str
        Name of the trajectory in messages.

    Returns
    -------
    SimulationResult

    Raises
    ------
    UsageError
        Bad effect, friction, noise, rate or duration; a trajectory beyond the joint limits; truth options
        beside ``truth``.
    ShapeError
        A trajectory for another joint count.
    """
    started = time.perf_counter()
    if truth is not None:
        _refuse_truth_options(effects, friction, perturb, truth_seed)
    noise = NoiseModel.parse(noise)
    n = robot.n
    _check_joint_count(robot, trajectory, source)
    stride = _output_stride(rate, control_rate)
    duration = _run_duration(trajectory, duration, control_rate, source)
    _check_two_samples(trajectory, duration, rate, control_rate, stride, source)
    _check_whole_numbers(substeps, seed, truth_seed)
    seed = int(seed)

    command = _command(robot, trajectory, duration, control_rate, source)
    ticks = command.t.size
    truth = _resolve_truth(robot, truth, effects, friction, perturb, seed, truth_seed)
    if controller is None:
        controller = ControllerGains.design(n)

    run = TrackingLoop(truth, controller, noise, control_rate, substeps)
    states = run.integrate(command.t, command.qd, command.dqd, command.ddqd)

    # Sensor chain at the control rate, then decimation.
    tau_meas = measured_torque(truth, noise, command.t, states["tau_drive"], seed)

    pick = slice(0, ticks, stride)
    return SimulationResult(
        t=command.t[pick],
        q=states["q_meas"][pick],
        tau=tau_meas[pick],
        q_true=states["q"][pick],
        dq_true=states["dq"][pick],
        ddq_true=states["ddq"][pick],
        tau_drive=states["tau_drive"][pick],
        q_desired=command.qd[pick],
        dq_desired=command.dqd[pick],
        ddq_desired=command.ddqd[pick],
        theta=states["theta"][pick],
        dtheta=states["dtheta"][pick],
        ddtheta=states["ddtheta"][pick],
        components={k: v[pick] for k, v in states["components"].items()},
        truth=truth,
        noise=noise,
        controller=controller,
        seed=seed,
        rate=float(rate),
        control_rate=float(control_rate),
        substeps=run.substeps,
        elapsed=time.perf_counter() - started,
        meta=_run_meta(trajectory, source, truth),
    )


@dataclass(frozen=True)
class _Command:
    """The commanded motion at the control ticks: times (ticks,) and angles, speeds, accelerations (ticks, n)."""

    t: np.ndarray
    qd: np.ndarray
    dqd: np.ndarray
    ddqd: np.ndarray


def _refuse_truth_options(effects, friction, perturb, truth_seed) -> None:
    """Refuse the truth options that a given truth fixes already."""
    given = [
        name
        for name, value, default in (
            ("effects", effects, None),
            ("friction", friction, "linear"),
            ("perturb", perturb, 0.0),
            ("truth_seed", truth_seed, None),
        )
        if value != default
    ]
    if given:
        raise UsageError(
            f"simulate got truth= and also {', '.join(given)}, which the truth fixes already; give "
            f"{'them' if len(given) > 1 else 'it'} to build_truth(robot, ...) instead, or drop truth=."
        )


def _check_joint_count(robot: RobotModel, trajectory: Trajectory, source: str) -> None:
    """Refuse a trajectory for another joint count than the robot's."""
    if trajectory.n != robot.n:
        raise ShapeError(
            f"{source} has {trajectory.n} joints; the robot '{robot.name}' has {robot.n}: use a trajectory designed "
            "for this robot."
        )


def _output_stride(rate: float, control_rate: float) -> int:
    """The control ticks per output sample, after checking both rates."""
    if not (math.isfinite(control_rate) and control_rate > 0):
        raise UsageError(f"the control rate is {control_rate}; give a positive rate in Hz.")
    if not (math.isfinite(rate) and 0 < rate <= control_rate):
        raise UsageError(
            f"the output rate is {rate} Hz; give a positive rate up to the control rate {control_rate:g} Hz."
        )
    stride = control_rate / rate
    if abs(stride - round(stride)) > 1e-9 * stride:
        raise UsageError(
            f"the output rate {rate:g} Hz does not divide the control rate {control_rate:g} Hz; give e.g. "
            f"{control_rate:g}, {control_rate / 2:g} or {control_rate / 10:g} Hz."
        )
    return round(stride)


def _run_duration(trajectory: Trajectory, duration: float | None, control_rate: float, source: str) -> float:
    """The run's length (s), default the trajectory's, after checking it against the trajectory and memory."""
    if duration is None:
        duration = float(trajectory.duration)
    if not (math.isfinite(duration) and duration > 0):
        raise UsageError(f"the duration is {duration} s; give a positive duration.")
    if duration > trajectory.duration * (1 + 1e-9) and not isinstance(trajectory, FourierTrajectory):
        raise UsageError(
            f"the duration {duration:g} s is longer than {source} ({trajectory.duration:g} s), which does not "
            "repeat; give at most its duration."
        )
    if duration * control_rate >= MAX_TICKS:
        raise UsageError(
            f"the duration {duration:g} s at the control rate {control_rate:g} Hz is {duration * control_rate:.3g} "
            f"control ticks, beyond the {MAX_TICKS:,} that one run holds in memory; give at most "
            f"{(MAX_TICKS - 1) / control_rate:g} s, and simulate a longer experiment as several runs."
        )
    return duration


def _check_two_samples(
    trajectory: Trajectory, duration: float, rate: float, control_rate: float, stride: int, source: str
) -> None:
    """Refuse a run of fewer than two output samples, blaming the trajectory when its period is too short."""
    if round(duration * control_rate) < stride:
        cause = (
            f", {duration * trajectory.base_freq:g} period(s) of {source} at its base frequency "
            f"{trajectory.base_freq:g} Hz"
            if isinstance(trajectory, FourierTrajectory) and trajectory.base_freq * stride / control_rate > 0.5
            else ""  # a period shorter than two samples: the trajectory is at fault, not the duration
        )
        fix = (
            "give a trajectory whose period spans many samples (dynid excite designs e.g. 0.1 Hz)"
            if cause
            else f"give a duration of at least {stride / control_rate:g} s"
        )
        raise UsageError(
            f"the run lasts {duration:g} s{cause}, 1 sample at {rate:g} Hz, but a dataset needs at least 2; {fix}."
        )


def _check_whole_numbers(substeps: int | None, seed: int, truth_seed: int | None) -> None:
    """Refuse a substep count below 1 and negative or fractional seeds."""
    if substeps is not None and (int(substeps) != substeps or substeps < 1):
        raise UsageError(f"substeps is {substeps}; give a whole number >= 1.")
    for label, value in (("seed", seed), ("truth seed", truth_seed)):
        if value is not None and (int(value) != value or value < 0):
            raise UsageError(f"the {label} is {value}; give a whole number of at least 0.")


def _command(
    robot: RobotModel, trajectory: Trajectory, duration: float, control_rate: float, source: str
) -> _Command:
    """The trajectory evaluated at the control ticks, checked against the robot's limits."""
    ticks = round(duration * control_rate) + 1
    t_ctrl = np.arange(ticks) / control_rate
    qd, dqd, ddqd = (np.ascontiguousarray(a) for a in trajectory.evaluate(t_ctrl))
    _check_limits(robot, t_ctrl, qd, dqd, ddqd, source)
    return _Command(t=t_ctrl, qd=qd, dqd=dqd, ddqd=ddqd)


def _resolve_truth(
    robot: RobotModel,
    truth: Truth | None,
    effects: str | Sequence[str | EffectRequest] | None,
    friction: str | TruthFriction,
    perturb: float,
    seed: int,
    truth_seed: int | None,
) -> Truth:
    """The given truth after checking its joint count, or one built from the truth options."""
    if truth is None:
        return build_truth(
            robot,
            effects=effects,
            friction=friction,
            perturb=perturb,
            truth_seed=seed if truth_seed is None else int(truth_seed),
        )
    if truth.nominal.n != robot.n:
        raise ShapeError(f"the truth has {truth.nominal.n} joints; the robot '{robot.name}' has {robot.n}.")
    return truth


def _run_meta(trajectory: Trajectory, source: str, truth: Truth) -> dict:
    """The run's description for the result: the trajectory and the names of the truth's effects."""
    return {
        "trajectory": {
            "source": source,
            "type": type(trajectory).__name__,
            "duration": float(trajectory.duration),
            "meta": dict(getattr(trajectory, "meta", {}) or {}),
        },
        "effects": [e.name for e in truth.effects],
    }


def _check_limits(robot: RobotModel, t: np.ndarray, q, dq, ddq, source: str) -> None:
    for label, values, lo, hi, unit, option in (
        ("q", q, robot.q_min, robot.q_max, "rad", "--q-min/--q-max"),
        ("dq", dq, -robot.dq_max, robot.dq_max, "rad/s", "--dq-max"),
        ("ddq", ddq, -robot.ddq_max, robot.ddq_max, "rad/s^2", "--ddq-max"),
    ):
        tol = _LIMIT_TOL * (1 + np.abs(hi - lo))
        over = (values > hi + tol) | (values < lo - tol)
        if over.any():
            k, j = np.argwhere(over)[0]
            bound = hi[j] if values[k, j] > hi[j] else lo[j]
            raise UsageError(
                f"{source} takes {label}_{j + 1} to {values[k, j]:.4g} {unit} at t = {t[k]:.4g} s, beyond the limit "
                f"{bound:.4g} {unit} of the robot '{robot.name}'; design the trajectory within the limits "
                f"(dynid excite) or override the limit with {option}."
            )
