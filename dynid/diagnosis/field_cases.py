"""Withheld-effect cases recorded as a robot in the field records them (the field diagnosis benchmark).

The lab cases (:mod:`dynid.diagnosis.cases`) hold out several periods of a periodic excitation.  A field
case differs in every way a real recording does:

* training on a periodic excitation of three periods (:func:`dynid.sim.cases.case_excitation`, 5 s
  period), as ``dynid simulate`` and ``dynid excite --csv`` record by default;
* held out on an aperiodic motion: minimum-jerk moves between random waypoints, with rests
  (:func:`min_jerk_motion`), so the held-out run repeats no period;
* coloured torque noise: AR(1) with a 100 ms time constant, its std as large as the white part
  (:func:`field_noise`);
* angles quantised like the joint encoders of current arms, 18 bits (``2^18`` counts per revolution; the
  UR e-series and the Panda log 18 to 20 bits); :data:`STRESS_ENCODER_BITS` (14) for a coarse encoder;
* datasets with ``t``, ``q`` and ``tau`` only: no ``dq`` or ``ddq``.

The simulator knows the noise it added (:func:`injected_noise`), so the diagnosis' noise floor can be
compared with the std of that noise after the same filter (:func:`true_noise_std`).

>>> case = run_field_case(load_robot("panda"), ["stribeck@3"], level=3.0, seed=1)
>>> case["verdict"], case["correct"], case["floor_method"], case["floor_over_true"]
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dynid.data.dataset import Dataset
from dynid.diagnosis.cases import case_record, classify, simulate_runs, truth_labels
from dynid.sim.cases import NOISE_STD, case_centre, case_excitation
from dynid.sim.effects import effect_names
from dynid.sim.sensors import NoiseModel, torque_noise
from dynid.sim.simulator import CONTROL_RATE, SimulationResult

__all__ = [
    "FIELD_ENCODER_BITS",
    "FIELD_NOISE_TIME",
    "STRESS_ENCODER_BITS",
    "FieldCase",
    "field_case",
    "field_noise",
    "injected_noise",
    "min_jerk_motion",
    "process_noise_std",
    "run_field_case",
    "true_noise_std",
]

FIELD_NOISE_TIME = 0.1
"""Time constant (s) of the AR(1) torque noise of the field cases."""

FIELD_ENCODER_BITS = 18
"""Resolution of the logged angles of the field cases: ``2^18`` counts per joint revolution, the low end of
current arms (UR e-series joint encoders 18-20 bits on the output, the Panda about 2^19-2^20 counts)."""

STRESS_ENCODER_BITS = 14
"""A coarse encoder (``2^14`` counts per revolution): differentiating its angles leaves several noise
variances of model error on the held-out data; the field benchmark's stress cases."""

TRAIN_PERIODS = 3
"""Periods of the training excitation (what ``dynid simulate`` records by default)."""


def field_noise(white: float = 0.01, *, control_rate: float = CONTROL_RATE) -> NoiseModel:
    """The field cases' sensor model: white + AR(1) torque noise of equal std, 100 ms, 18-bit angles.

    Parameters
    ----------
    white : float
        Std of the white part and of the coloured part, fraction of each joint's torque scale.
    control_rate : float
        Rate (Hz) of the control ticks at which the AR(1) coefficient applies.

    Returns
    -------
    NoiseModel
        ``colour = exp(-1 / (FIELD_NOISE_TIME * control_rate))`` (0.990 at 1 kHz).
    """
    return NoiseModel(
        torque=white,
        coloured=white,
        colour=float(math.exp(-1.0 / (FIELD_NOISE_TIME * control_rate))),
        encoder_bits=FIELD_ENCODER_BITS,
    )


def min_jerk_motion(
    robot, rng: np.random.Generator, duration: float, *, rate: float = CONTROL_RATE, rest: float = 0.4
):
    """Minimum-jerk moves between random waypoints around the robot's case posture, with random rests.

    Each move lasts long enough for half of the speed and acceleration limits, times a random factor in
    [1, 1.6); after a share ``rest`` of the moves the arm rests for 0.3-1.2 s.  Nothing repeats.

    Parameters
    ----------
    robot : RobotModel
        Its limits and centre posture (:func:`dynid.sim.cases.case_centre`, else the middle of each range).
    rng : numpy.random.Generator
        Draws the waypoints, durations and rests.
    duration : float
        Length of the motion (s).
    rate : float
        Sampling rate (Hz) of the returned trajectory.
    rest : float
        Share of the moves followed by a rest.

    Returns
    -------
    SampledTrajectory
        ``t`` (m,), ``q, dq, ddq`` (m, n) in rad, rad/s, rad/s^2; starts at rest at the centre posture.
    """
    from dynid.optim.trajectory import SampledTrajectory

    centre = case_centre(robot)
    if centre is None:
        centre = np.clip(0.5 * (robot.q_min + robot.q_max), -np.pi, np.pi)
    half = np.minimum(0.8, 0.4 * (robot.q_max - robot.q_min))
    vmax, amax = 0.5 * robot.dq_max, 0.5 * robot.ddq_max
    knots_t, knots_q = [0.0], [centre]
    t, q = 0.0, centre
    while t < duration:
        target = rng.uniform(centre - half, centre + half)
        d = np.abs(target - q)
        span = max(np.max(1.875 * d / vmax), np.max(np.sqrt(5.774 * d / amax)), 0.3)
        t += span * rng.uniform(1.0, 1.6)
        knots_t.append(t)
        knots_q.append(target)
        q = target
        if rng.random() < rest:
            t += rng.uniform(0.3, 1.2)
            knots_t.append(t)
            knots_q.append(target)
    kt, kq = np.asarray(knots_t), np.asarray(knots_q)
    tt = np.arange(round(duration * rate) + 1) / rate
    k = np.clip(np.searchsorted(kt, tt, side="right") - 1, 0, len(kt) - 2)
    span = (kt[k + 1] - kt[k])[:, None]
    s = (tt[:, None] - kt[k][:, None]) / span
    step = kq[k + 1] - kq[k]
    return SampledTrajectory(
        tt,
        kq[k] + step * (10 * s**3 - 15 * s**4 + 6 * s**5),
        step * (30 * s**2 - 60 * s**3 + 30 * s**4) / span,
        step * (60 * s - 180 * s**2 + 120 * s**3) / span**2,
        meta={"kind": "minimum-jerk moves between random waypoints, with rests"},
    )


def injected_noise(result: SimulationResult, rng: np.random.Generator | None = None) -> NDArray[np.float64]:
    """The torque noise (m, n) (N m) the simulator added to the measured torque of ``result``.

    Drawn again from the run's noise seed (:func:`dynid.sim.sensors.measured_torque`), at the control
    rate, and kept at the output samples.  The current quantisation (``current_lsb``) is not included.
    With ``rng``, a fresh draw of the same noise model instead.
    """
    ticks = round(float(result.t[-1] - result.t[0]) * result.control_rate) + 1
    stride = round(result.control_rate / result.rate)
    rng = np.random.default_rng([result.seed, 1]) if rng is None else rng
    return torque_noise(result.noise, result.truth.scales.torque, ticks, rng)[::stride][: len(result.t)]


def _measured_only(result: SimulationResult) -> Dataset:
    """What a robot's log holds: ``t``, ``q`` and ``tau`` (no ``dq`` or ``ddq`` columns)."""
    return Dataset(result.t.copy(), result.q.copy(), result.tau.copy(), meta={"source": "field case"})


@dataclass(frozen=True, eq=False)
class FieldCase:
    """One simulated field case before identification.

    Attributes
    ----------
    train, heldout : Dataset
        ``t, q, tau`` only (no ``dq``, ``ddq``): periodic training run, aperiodic held-out run.
    train_run, heldout_run : SimulationResult
        The simulations (truth, true states, noise settings).
    heldout_noise : ndarray, shape (m, n)
        Torque noise (N m) added to the held-out run's measured torque.
    period : float
        Period (s) of the training excitation.
    specs : list of str
        The injected effects with their values (``NAME@J:VALUE``).
    values, achieved : list of float
        Calibrated values and the levels they reached on the training excitation (noise-free).
    """

    train: Dataset
    heldout: Dataset
    train_run: SimulationResult
    heldout_run: SimulationResult
    heldout_noise: NDArray[np.float64]
    period: float
    specs: list[str]
    values: list[float]
    achieved: list[float]


def field_case(
    robot,
    injected: Sequence[str],
    *,
    level: float,
    seed: int,
    heldout_seconds: float = 20.0,
    base_freq: float = 0.2,
    friction: str = "linear",
    armature: bool = True,
    noise: NoiseModel | None = None,
    train_periods: int = TRAIN_PERIODS,
) -> FieldCase:
    """Simulate the training and held-out runs of a field case.

    Parameters
    ----------
    robot : RobotModel
    injected : sequence of str
        Effects as ``NAME`` or ``NAME@J`` (VALUE calibrated to ``level``), or with ``:VALUE``.
    level : float
        RMS torque contribution of each effect on the training excitation, in multiples of the field
        noise's std (white and coloured together), measured noise-free.
    seed : int
        Seed of the truth, the excitations, the waypoints and the noise.
    heldout_seconds : float
        Length (s) of the aperiodic held-out motion.
    base_freq : float
        Base frequency (Hz) of the training excitation.
    friction : str
        Truth friction.
    armature : bool
        Whether the model will identify an armature (the calibration leaves the motor inertia out then).
    noise : NoiseModel, optional
        The sensor model; :func:`field_noise` by default.
    train_periods : int
        Periods of the training run (the effects' level is calibrated on :data:`TRAIN_PERIODS` of them
        whatever this is, so that a case differs only in what was recorded).

    Returns
    -------
    FieldCase
    """
    noise = field_noise() if noise is None else noise
    period = 1.0 / base_freq
    train_traj = case_excitation(robot, 2 * seed, base_freq=base_freq)
    held_traj = min_jerk_motion(robot, np.random.default_rng([seed, 13]), heldout_seconds)
    # calibrate_value measures in units of the lab noise std: rescale to the field noise's.
    scale = math.hypot(noise.torque, noise.coloured) / NOISE_STD
    runs = simulate_runs(
        robot,
        injected,
        train_traj,
        held_traj,
        level=level * scale,
        seed=seed,
        calibration_seconds=min(TRAIN_PERIODS * period, 10.0),
        train_seconds=train_periods * period,
        heldout_seconds=heldout_seconds,
        friction=friction,
        armature=armature,
        noise=noise,
    )
    tr, ho = runs.train, runs.heldout
    return FieldCase(
        train=_measured_only(tr),
        heldout=_measured_only(ho),
        train_run=tr,
        heldout_run=ho,
        heldout_noise=injected_noise(ho),
        period=period,
        specs=runs.specs,
        values=[float(v) for v in runs.values],
        achieved=[float(got / scale) for got in runs.achieved],  # NaN for a value given
    )


def true_noise_std(model, case: FieldCase) -> NDArray[np.float64]:
    """Std (n,) (N m) of the held-out run's injected torque noise after the diagnosis' filter and trim.

    The noise is put through the preprocessing the diagnosis gives the held-out torque (the model's,
    :func:`dynid.diagnosis.baseline.model_structure`), at the rows it keeps.
    """
    return np.sqrt(_filtered_variance(model, case, [case.heldout_noise]))


def process_noise_std(model, case: FieldCase, draws: int = 16) -> NDArray[np.float64]:
    """Std (n,) (N m) of the noise process itself after the diagnosis' filter and trim: the variance
    :func:`true_noise_std` averaged over ``draws`` fresh realisations of the held-out run's noise (the
    same model, other seeds), which is what a floor measured on another run of the robot estimates."""
    run = case.heldout_run
    noises = (injected_noise(run, np.random.default_rng([run.seed, 2, k])) for k in range(draws))
    return np.sqrt(_filtered_variance(model, case, noises))


def _filtered_variance(model, case: FieldCase, noises) -> NDArray[np.float64]:
    """Mean over ``noises`` (each (m, n), N m, at the held-out run's samples) of their variance per joint
    through the diagnosis' preprocessing of the held-out run, at the rows it keeps."""
    from dynid.data.preparation import Preprocessing, prepare
    from dynid.diagnosis.baseline import model_structure

    structure = model_structure(model, None, case.train, case.heldout)
    settings = Preprocessing.from_settings(structure.preprocessing)
    ho = case.heldout
    total, count = np.zeros(structure.robot.n), 0
    for noise in noises:
        prep = prepare(Dataset(ho.t, ho.q, noise), settings, n_joints=structure.robot.n)
        total += np.var(prep.filter(prep.tau)[prep.rows], axis=0)
        count += 1
    return total / count


def run_field_case(
    robot,
    injected: Sequence[str],
    *,
    level: float,
    seed: int,
    catalogue: Sequence[str] | None = None,
    heldout_seconds: float = 20.0,
    friction: str = "linear",
    armature: bool = True,
    noise: NoiseModel | None = None,
    diagnose_options: dict[str, Any] | None = None,
    train_periods: int = TRAIN_PERIODS,
) -> dict[str, Any]:
    """Simulate a field case, identify a model without the effects, diagnose and classify it.

    Parameters
    ----------
    robot : RobotModel
    injected, level, seed, heldout_seconds, friction, armature, noise, train_periods
        As in :func:`field_case`.
    catalogue : sequence of str, optional
        Effects the diagnosis is told about (default the whole catalogue); an injected effect outside it is
        an unknown effect.
    diagnose_options : dict, optional
        Extra keyword arguments of :func:`dynid.diagnosis.core.diagnose`.

    Returns
    -------
    dict
        As :func:`dynid.diagnosis.cases.run_case` (``verdict``, ``excess``, ``diagnosis``, the
        classification), plus ``provisional``, ``floor_method``, ``floor`` and ``true_noise`` (n,) (N m,
        filtered), ``floor_over_true`` (their ratio per joint), ``floor_interval`` (the floor's 95 %
        interval of the std, low and high, NaN where unknown), ``process_noise`` (n,) (the noise process'
        std, :func:`process_noise_std`) and ``mse_refit`` (n,) (N^2 m^2).
    """
    from dynid.diagnosis.core import diagnose
    from dynid.identify.model import identify

    case = field_case(
        robot, injected, level=level, seed=seed, heldout_seconds=heldout_seconds, friction=friction,
        armature=armature, noise=noise, train_periods=train_periods,
    )  # fmt: skip
    catalogue = effect_names() if catalogue is None else tuple(catalogue)
    truth_injected = truth_labels(case.specs, catalogue)
    model = identify(robot, case.train, method="ols", friction="linear", gmm="off", armature=armature)
    d = diagnose(model, case.train, case.heldout, effects=tuple(catalogue), **(diagnose_options or {}))
    true_std = true_noise_std(model, case)
    cls = classify(d, truth_injected)
    return {
        **case_record(
            d, injected, truth_injected, level=level, seed=seed, values=case.values, achieved=case.achieved
        ),
        "provisional": bool(d.provisional),
        "floor_method": d.noise.method,
        "floor": [float(v) for v in d.noise.std],
        "true_noise": [float(v) for v in true_std],
        "floor_over_true": [float(v) for v in d.noise.std / np.maximum(true_std, 1e-12)],
        "floor_interval": [[float(v) for v in side] for side in d.noise.std_interval(0.95)],
        "process_noise": [float(v) for v in process_noise_std(model, case)],
        "mse_refit": [float(v) for v in d.decomposition["mse_refit"]],
        "realised": [e.to_dict() for e in case.train_run.truth.effects],
        "diagnosis": d,
        **cls,
    }
