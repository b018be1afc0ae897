"""What a simulation gives and how it is written: the measured data and the ``.truth.json`` sidecar.

:class:`SimulationResult` holds the measured data of a run with its truth, noise and controller;
:func:`write_simulation` writes the data (``.csv`` or ``.npz``) and the sidecar ``<file>.truth.json``
beside it, both or neither.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from dynid._io import atomic_path, jsonable, write_text
from dynid.data.dataset import Dataset
from dynid.data.files import save_dataset
from dynid.exceptions import DataError
from dynid.sim.sensors import SENSOR_ORDER, NoiseModel
from dynid.sim.tracking import ControllerGains
from dynid.sim.truth import Truth

__all__ = ["SimulationResult", "check_output_path", "truth_path", "write_simulation"]


@dataclass(frozen=True, eq=False)
class SimulationResult:
    """What a simulated run gives: the measured data and the truth behind them.

    All arrays have one row per output sample (``rate``); joints in the model's order.

    Attributes
    ----------
    t : ndarray, shape (m,)
        Time (s).
    q : ndarray, shape (m, n)
        Measured angles (rad): the encoders, quantised; drive (motor) side on flexible joints.
    tau : ndarray, shape (m, n)
        Measured torque (N m): drive torque through the sensor effects, noise and quantisation.
    q_true, dq_true, ddq_true : ndarray, shape (m, n)
        True link-side states (rad, rad/s, rad/s^2); ``ddq_true`` is the instantaneous acceleration.
    tau_drive : ndarray, shape (m, n)
        Torque the drives apply (controller output, N m), held until the next control tick.
    q_desired, dq_desired, ddq_desired : ndarray, shape (m, n)
        The commanded trajectory.
    theta, dtheta, ddtheta : ndarray, shape (m, n)
        Drive-side states: the motor on flexible joints, equal to the link states elsewhere.
    components : dict of str to ndarray (m, n)
        Drive-side torque of each term (N m, opposing the drive): ``friction`` and each drive effect.
        On a rigid joint ``tau_drive = rnea_link_truth(true states) + sum(components)``.
    truth : Truth
    noise : NoiseModel
    controller : ControllerGains
    seed : int
    rate, control_rate : float
        Output and control rates (Hz).
    substeps : int
        Integration steps per control tick.
    elapsed : float
        Wall time of the simulation (s).
    """

    t: np.ndarray
    q: np.ndarray
    tau: np.ndarray
    q_true: np.ndarray
    dq_true: np.ndarray
    ddq_true: np.ndarray
    tau_drive: np.ndarray
    q_desired: np.ndarray
    dq_desired: np.ndarray
    ddq_desired: np.ndarray
    theta: np.ndarray
    dtheta: np.ndarray
    ddtheta: np.ndarray
    components: dict[str, np.ndarray]
    truth: Truth
    noise: NoiseModel
    controller: ControllerGains
    seed: int
    rate: float
    control_rate: float
    substeps: int
    elapsed: float
    meta: dict = field(default_factory=dict)

    @property
    def n(self) -> int:
        return self.q.shape[1]

    def to_dataset(self, *, true_states: bool = False) -> Dataset:
        """The measured data as a :class:`Dataset` (``t, q, tau``; ``dq, ddq`` true ones if asked)."""
        extra = {"dq": self.dq_true, "ddq": self.ddq_true} if true_states else {}
        return Dataset(
            self.t,
            self.q,
            self.tau,
            **extra,
            meta={"source": "dynid simulate", "reference": "raw", **self.meta},
        )

    def truth_dict(self) -> dict:
        """Everything about the truth, noise, controller and run, for ``<out>.truth.json``."""
        s = self.truth.scales.torque
        noise = self.noise.to_dict()
        noise["absolute"] = {
            "torque_std": (self.noise.torque * s).tolist(),
            "coloured_std": (self.noise.coloured * s).tolist(),
            "current_lsb": (self.noise.current_lsb * s).tolist(),
            "encoder_step": 0.0 if self.noise.encoder_bits == 0 else 2 * math.pi / 2**self.noise.encoder_bits,
            "units": "N m, rad",
        }
        noise["note"] = "torque, coloured, current_lsb: fractions of the torque scale s_j (scales.torque)"
        err = self.q_true - self.q_desired
        return {
            "format": "dynid-truth 1",
            "seed": self.seed,
            **self.truth.to_dict(),
            "noise": noise,
            "controller": self.controller.to_dict(),
            "sampling": {
                "rate_hz": self.rate,
                "control_rate_hz": self.control_rate,
                "substeps": self.substeps,
                "duration_s": float(self.t[-1] - self.t[0]),
                "samples": int(self.t.size),
                "integrator": "semi-implicit Euler, velocity-dependent torques linearly implicit",
            },
            "tracking_error_rms": np.sqrt(np.mean(err**2, axis=0)).tolist(),
            "sensor_effect_order": list(SENSOR_ORDER),
            "trajectory": self.meta.get("trajectory"),
        }


def check_output_path(path: str | os.PathLike[str]) -> Path:
    """Check that a dataset can be written at ``path`` (.csv or .npz, existing folder); return it."""
    path = Path(path)
    if path.suffix.lower() not in (".csv", ".npz"):
        raise DataError(
            f"the output '{path}' has the extension '{path.suffix}'; give a .csv or .npz file name."
        )
    if not path.parent.is_dir():
        raise DataError(
            f"the folder '{path.parent}' for the output does not exist; create it or write elsewhere."
        )
    return path


def truth_path(path: str | os.PathLike[str]) -> Path:
    """Sidecar of a dataset file: ``<file>.truth.json``."""
    path = Path(path)
    return path.with_name(path.name + ".truth.json")


def write_simulation(
    result: SimulationResult, path: str | os.PathLike[str], *, true_states: bool = False
) -> tuple[Path, Path]:
    """Write the measured data and the sidecar ``<path>.truth.json``, both or neither.

    The data go to a temporary file in the target folder, the sidecar is written (atomically), and only
    then the data file takes its name; if any step fails nothing new is left behind.

    Parameters
    ----------
    result : SimulationResult
    path : str or path-like
        ``.csv`` or ``.npz`` file in an existing folder.
    true_states : bool
        Also write the true ``dq_i`` and ``ddq_i`` (for debugging; a real robot gives none).

    Returns
    -------
    (Path, Path)
        The data file and the sidecar.
    """
    path = check_output_path(path)
    sidecar = truth_path(path)
    text = json.dumps(result.truth_dict(), indent=2, default=jsonable) + "\n"
    dataset = result.to_dataset(true_states=true_states)
    sidecar_written = False
    try:
        with atomic_path(path) as tmp:  # the data take their name last, after the sidecar
            staged = tmp.with_name(tmp.name + path.suffix)  # save_dataset reads the format from the suffix
            try:
                save_dataset(dataset, staged)
                staged.replace(tmp)
            finally:
                staged.unlink(missing_ok=True)
            write_text(sidecar, text)
            sidecar_written = True
    except BaseException:
        if sidecar_written:
            sidecar.unlink(missing_ok=True)
        raise
    return path, sidecar
