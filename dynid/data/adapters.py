"""Readers for the real robot recordings kept beside the project (``../shared/data``).

Each adapter turns one recording, as its README describes it, into a joint-space :class:`Dataset`
(time in s, angles in rad, torques in N m, joints in the model's order) and knows the URDF model that
goes with it.  The recordings are test fixtures, never part of the package; a fresh clone has none, and
:func:`find_shared_data` then raises a :class:`DataError` that says where it looked.

========================  ==========================================================================
``panda_gaz2019``          Franka Emika Panda, 7 joints, ~1 kHz irregular stamps, q and dq from the
                           robot, link-side torque sensors (Gaz et al., RA-L 2019).
``tx40``                   Staubli TX40, 6 joints, 5 kHz, motor-side angles and torques converted to
                           the joint side through the gear ratios and the coupled wrist.
``kuka_lwr4_flobaroid``    KUKA LWR4+, 7 joints, ~200 Hz jittered stamps, joint torque sensors, three
                           runs (FloBaRoID); positions and torques pre-filtered by the recording software.
========================  ==========================================================================

Examples
--------
>>> from dynid.data.adapters import load_recording, recording_model_path
>>> ds = load_recording("tx40")                       # doctest: +SKIP
>>> urdf = recording_model_path("tx40")               # doctest: +SKIP
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from dynid.data.dataset import Dataset
from dynid.exceptions import DataError, UsageError

__all__ = [
    "ADAPTERS",
    "ENV_VAR",
    "TX40_GEAR_RATIOS",
    "TX40_SAMPLE_TIME",
    "Recording",
    "find_shared_data",
    "load_kuka_lwr4",
    "load_panda_gaz2019",
    "load_recording",
    "load_tx40",
    "recording_folder",
    "recording_model_path",
    "recording_robot",
    "tx40_coupling_matrices",
    "tx40_transmission",
]

#: Environment variable naming the folder that holds the recordings (``panda_gaz2019/``, ``tx40/``).
ENV_VAR = "DYNID_SHARED_DATA"

#: TX40 reduction ratios N_1..N_6 (motor angle / joint angle), as the recording's README states.
TX40_GEAR_RATIOS: tuple[float, ...] = (32.0, 32.0, 45.0, -48.0, 45.0, 32.0)

#: TX40 sample time (s): t = k * 0.0002, 5 kHz.
TX40_SAMPLE_TIME = 0.0002


# ---------------------------------------------------------------------- locating the data
def _project_roots(start: Path) -> list[Path]:
    """``start`` and its parents that look like the project root (a pyproject.toml or .git inside)."""
    return [d for d in (start, *start.parents) if (d / "pyproject.toml").is_file() or (d / ".git").exists()]


def find_shared_data() -> Path:
    """The folder holding the recordings.

    Looked for, in order: the environment variable ``DYNID_SHARED_DATA``; ``<project>/../shared/data`` for
    each project root (a folder with ``pyproject.toml`` or ``.git``) at or above the current working
    directory; the same beside the source tree this package was imported from.

    Returns
    -------
    Path

    Raises
    ------
    DataError
        When the variable names a missing folder, or no candidate exists.
    """
    env = os.environ.get(ENV_VAR)
    if env:
        path = Path(env).expanduser()
        if not path.is_dir():
            raise DataError(
                f"{ENV_VAR} is set to {env!r}, which is not a folder; point it at the folder that holds "
                "panda_gaz2019/ and tx40/, or unset it"
            )
        return path
    candidates: list[Path] = []
    for start in (Path.cwd().resolve(), Path(__file__).resolve().parents[2]):
        for root in _project_roots(start):
            candidate = root.parent / "shared" / "data"
            if candidate not in candidates:
                candidates.append(candidate)
    for candidate in candidates:
        if candidate.is_dir():
            return candidate
    looked = ", ".join(str(c) for c in candidates) or "no project root found above the working directory"
    raise DataError(
        f"no folder of robot recordings found (looked in {looked}); set {ENV_VAR} to the folder that holds "
        "panda_gaz2019/ and tx40/"
    )


def recording_folder(name: str, root: str | os.PathLike[str] | None = None) -> Path:
    """Folder of one recording.

    Parameters
    ----------
    name : str
        A key of :data:`ADAPTERS`.
    root : str or path-like, optional
        The folder holding the recordings (default :func:`find_shared_data`), or the recording's own folder.

    Returns
    -------
    Path
    """
    recording = _recording(name)
    base = find_shared_data() if root is None else Path(root).expanduser()
    if (base / recording.name).is_dir():
        return base / recording.name
    if base.name == recording.name and base.is_dir():
        return base
    raise DataError(
        f"{base} holds no recording '{recording.name}' (no folder {base / recording.name}); pass the folder "
        f"that holds {recording.name}/, or set {ENV_VAR}"
    )


def _require(path: Path, what: str) -> Path:
    if not path.is_file():
        raise DataError(
            f"{what} is missing: no file {path}; restore the recording folder as its README lists it"
        )
    return path


# ---------------------------------------------------------------------- Panda (Gaz et al. 2019)
_PANDA_LOG = Path("data", "Trajectory_1", "rbt_log")
_PANDA_MODEL = Path("model", "panda_arm_gaz2019_nohand.urdf")
_PANDA_JOINTS = 7


def _read_column(path: Path) -> NDArray[np.float64]:
    try:
        return np.loadtxt(path, dtype=np.float64, ndmin=1)
    except ValueError as err:
        raise DataError(
            f"{path.name} could not be read as one number a line ({err}); restore the file"
        ) from None


def load_panda_gaz2019(root: str | os.PathLike[str] | None = None) -> Dataset:
    """Franka Emika Panda exciting-trajectory log (Gaz et al., RA-L 2019), in joint space.

    The log holds time (s), q (rad), dq (rad/s, from the robot state) and the link-side joint torque
    sensors' tau (N m, gravity included), 7 values a sample.  The stamps are irregular (~1 kHz) and
    about 1255 samples repeat the previous sample's q exactly (the controller logged a stale state):
    those rows are dropped and the remaining stamps kept as they are.  Resample before differentiating
    (:func:`dynid.data.preprocess.preprocess` does it).

    Parameters
    ----------
    root : str or path-like, optional
        Folder holding the recordings, or ``panda_gaz2019/`` itself; default :func:`find_shared_data`.

    Returns
    -------
    Dataset
        m ~ 19300 samples, n = 7, with ``dq``; ``meta`` names the recording, the model file and the rows
        dropped.
    """
    folder = recording_folder("panda_gaz2019", root)
    log = folder / _PANDA_LOG
    t = _read_column(_require(log / "exciting_traj_time.txt", "the Panda time stamps"))
    m = len(t)
    signals = {}
    for key, file in (("q", "positions"), ("dq", "velocity"), ("tau", "torques")):
        values = _read_column(_require(log / f"exciting_traj_{file}.txt", f"the Panda {key} log"))
        if values.size != m * _PANDA_JOINTS:
            raise DataError(
                f"exciting_traj_{file}.txt holds {values.size} values; with {m} time stamps and 7 joints "
                f"{m * _PANDA_JOINTS} were expected; restore the recording"
            )
        signals[key] = values.reshape(m, _PANDA_JOINTS)
    q = signals["q"]
    stale = np.concatenate(([False], np.all(q[1:] == q[:-1], axis=1)))
    keep = ~stale
    return Dataset(
        t[keep],
        q[keep],
        signals["tau"][keep],
        dq=signals["dq"][keep],
        meta={
            "recording": "panda_gaz2019",
            "robot": "panda_arm_gaz2019_nohand",
            "model": str(folder / _PANDA_MODEL),
            "torque": "link-side joint torque sensors, gravity included",
            "dropped_repeated_rows": int(stale.sum()),
            "rows_recorded": m,
            "reference": "raw",
        },
        n_joints=_PANDA_JOINTS,
        robot_name="panda",
    )


# ---------------------------------------------------------------------- Staubli TX40
_TX40_POSITIONS = Path("data", "pos_read_data.csv")
_TX40_TORQUES = Path("data", "curr_data.csv")
_TX40_MODEL = Path("model", "tx40_mdh_modified.urdf")
_TX40_HEADER = [f"Joint_{j}" for j in range(1, 7)]


def tx40_coupling_matrices() -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Motor-to-joint matrices of the TX40, as the recording's README states them.

    Returns
    -------
    Rm : ndarray, shape (6, 6)
        ``q_motor = Rm @ q``: ``diag(N)`` with ``Rm[5, 4] = N_6`` (motor 6 also turns with joint 5).
    Rt : ndarray, shape (6, 6)
        ``tau = Rt @ tau_motor``: ``diag(N)`` with ``Rt[4, 5] = N_6`` (the transpose of ``Rm``, so power is
        conserved: ``tau . dq = tau_motor . dq_motor``).
    """
    ratios = np.asarray(TX40_GEAR_RATIOS)
    Rm = np.diag(ratios)
    Rm[5, 4] = ratios[5]
    Rt = np.diag(ratios)
    Rt[4, 5] = ratios[5]
    return Rm, Rt


def tx40_transmission() -> NDArray[np.float64]:
    """The TX40's coupled wrist as a robot transmission ``R`` (:attr:`RobotModel.transmission`).

    ``R = diag(N)^-1 Rm`` with ``Rm`` of :func:`tx40_coupling_matrices`: motor angles in joint units,
    unit diagonal, ``R[5, 4] = 1`` (motor 6 turns by ``q_5 + q_6``).  Give it to the robot of the
    recording's URDF (``load_robot(urdf).with_transmission(tx40_transmission())``, or
    ``dynid identify --transmission`` with ``coupled = [[5, 6, 1.0]]``) to identify motor 6's inertia
    and friction on both wrist joints.
    """
    Rm, _ = tx40_coupling_matrices()
    return np.diag(1.0 / np.asarray(TX40_GEAR_RATIOS)) @ Rm


def _read_tx40_csv(path: Path) -> NDArray[np.float64]:
    with path.open("r", encoding="utf-8") as f:
        header = [name.strip() for name in f.readline().strip().split(",")]
        if header != _TX40_HEADER:
            raise DataError(
                f"{path.name} has header {','.join(header)!r}; the TX40 recording's files start with "
                f"{','.join(_TX40_HEADER)!r}; restore the file"
            )
        try:
            table = np.loadtxt(f, delimiter=",", dtype=np.float64, ndmin=2)
        except ValueError as err:
            raise DataError(f"{path.name} could not be read as numbers ({err}); restore the file") from None
    return table


def load_tx40(root: str | os.PathLike[str] | None = None) -> Dataset:
    """Staubli TX40 recording (FIGAROH examples), converted from motor side to joint side.

    Conversions, exactly as the recording's README gives them: ``t = k * 0.0002`` s;
    ``q = Rm^-1 q_motor`` and ``tau = Rt tau_motor`` with :func:`tx40_coupling_matrices`; then
    ``q_2 -= pi/2`` and ``q_3 += pi/2`` to match the URDF's zero (modified DH).  No velocities are
    recorded: differentiate (:func:`dynid.data.preprocess.preprocess`; the source filtered at 100 Hz).

    Parameters
    ----------
    root : str or path-like, optional
        Folder holding the recordings, or ``tx40/`` itself; default :func:`find_shared_data`.

    Returns
    -------
    Dataset
        m = 45000 samples at 5 kHz, n = 6, joint angles (rad) and joint torques (N m), no ``dq``.
    """
    folder = recording_folder("tx40", root)
    q_motor = _read_tx40_csv(_require(folder / _TX40_POSITIONS, "the TX40 motor angles"))
    tau_motor = _read_tx40_csv(_require(folder / _TX40_TORQUES, "the TX40 motor torques"))
    if q_motor.shape != tau_motor.shape:
        raise DataError(
            f"pos_read_data.csv has {q_motor.shape[0]} rows but curr_data.csv has {tau_motor.shape[0]}; "
            "the two files must have one row per sample; restore the recording"
        )
    Rm, Rt = tx40_coupling_matrices()
    q = np.linalg.solve(Rm, q_motor.T).T
    q[:, 1] -= np.pi / 2
    q[:, 2] += np.pi / 2
    tau = tau_motor @ Rt.T
    t = np.arange(len(q)) * TX40_SAMPLE_TIME
    return Dataset(
        t,
        q,
        tau,
        meta={
            "recording": "tx40",
            "robot": "tx40_mdh_modified",
            "model": str(folder / _TX40_MODEL),
            "torque": "motor torque times the transmission (joint side)",
            "gear_ratios": list(TX40_GEAR_RATIOS),
            "reference": "raw",
        },
        n_joints=6,
        robot_name="tx40",
    )


# ---------------------------------------------------------------------- KUKA LWR4+
_KUKA_MODEL = Path("model", "kuka_lwr4.urdf")
_KUKA_RUNS = (1, 2, 3)
_KUKA_JOINTS = 7


def load_kuka_lwr4(root: str | os.PathLike[str] | None = None, *, run: int = 1) -> Dataset:
    """KUKA LWR4+ recording (FloBaRoID), one of its three runs, in joint space.

    Each run (``data/measurements_<run>.npz``) holds Unix time stamps at ~200 Hz with jitter (steps
    3.2-6.8 ms), positions and velocities (rad, rad/s; the velocities derived by the recording software)
    and the joint torque sensors' torque (N m), in the URDF's joint order.  The recording software stored
    the positions low-pass filtered (3 Hz, zero-phase) and the torques median- and low-pass filtered:
    they are not raw, and a model is scored against them as they are.  Runs 1 and 2 execute the same
    excitation; run 3 is another motion (identify on 1, hold out 3).  Time starts at 0; the irregular
    stamps are kept (preprocessing resamples them).

    Parameters
    ----------
    root : str or path-like, optional
        Folder holding the recordings, or ``kuka_lwr4_flobaroid/`` itself; default :func:`find_shared_data`.
    run : {1, 2, 3}
        Which run.

    Returns
    -------
    Dataset
        m = 5027 samples, n = 7, with ``dq``.
    """
    if run not in _KUKA_RUNS:
        raise DataError(f"run is {run!r}; the KUKA LWR4+ recording has runs 1, 2 and 3")
    folder = recording_folder("kuka_lwr4_flobaroid", root)
    path = _require(folder / "data" / f"measurements_{run}.npz", f"the KUKA LWR4+ run {run}")
    try:
        with np.load(path, allow_pickle=False) as arrays:
            t = np.asarray(arrays["times"], dtype=np.float64)
            q = np.asarray(arrays["positions"], dtype=np.float64)
            dq = np.asarray(arrays["velocities"], dtype=np.float64)
            tau = np.asarray(arrays["torques"], dtype=np.float64)
    except (KeyError, ValueError, OSError) as err:
        raise DataError(
            f"{path.name} could not be read as the KUKA LWR4+ run (times, positions, velocities, torques: "
            f"{err}); restore the file"
        ) from None
    if not (q.shape == dq.shape == tau.shape == (len(t), _KUKA_JOINTS)):
        raise DataError(
            f"{path.name} holds positions {q.shape}, velocities {dq.shape}, torques {tau.shape} for "
            f"{len(t)} time stamps; ({len(t)}, 7) each was expected; restore the file"
        )
    return Dataset(
        t - t[0],
        q,
        tau,
        dq=dq,
        meta={
            "recording": "kuka_lwr4_flobaroid",
            "run": run,
            "robot": "kuka_lwr4",
            "model": str(folder / _KUKA_MODEL),
            "torque": "link-side joint torque sensors, median and low-pass filtered by the recording software",
            "reference": "as recorded (pre-filtered)",
        },
        n_joints=_KUKA_JOINTS,
        robot_name="kuka_lwr4",
    )


# ---------------------------------------------------------------------- registry
@dataclass(frozen=True)
class Recording:
    """One real recording: its folder name, loader and model.

    Parameters
    ----------
    name : str
        Folder name under the shared data folder, and registry key.
    loader : callable
        ``loader(root) -> Dataset``.
    model : Path
        URDF path relative to the recording's folder.
    n_joints : int
        Joint count.
    description : str
        One line for listings.
    transmission : callable, optional
        ``() -> R``: the robot's coupled transmission (:attr:`RobotModel.transmission`), if it has one.
    runs : int
        How many runs it holds (its loader then takes ``run=1..runs``).
    """

    name: str
    loader: Callable[..., Dataset]
    model: Path
    n_joints: int
    description: str
    transmission: Callable[[], NDArray[np.float64]] | None = None
    runs: int = 1

    def __call__(self, root: str | os.PathLike[str] | None = None, *, run: int | None = None) -> Dataset:
        """Load the recording, or one of its runs.

        Parameters
        ----------
        root : str or path-like, optional
            Folder holding the recordings, or the recording's own folder; default :func:`find_shared_data`.
        run : int, optional
            The run, 1 to :attr:`runs` (default 1) of a recording of several.

        Returns
        -------
        Dataset

        Raises
        ------
        UsageError
            A run the recording does not hold.
        """
        if run is not None and not 1 <= run <= self.runs:
            raise UsageError(
                f"--run {run}: the recording {self.name} "
                + (f"has runs 1 to {self.runs}; give one of them" if self.runs > 1 else "is one run; leave --run out")
            )
        return self.loader(root) if self.runs == 1 else self.loader(root, run=run or 1)

    def model_path(self, root: str | os.PathLike[str] | None = None) -> Path:
        """Path of the recording's URDF model.

        Parameters
        ----------
        root : str or path-like, optional
            Folder holding the recordings, or the recording's own folder; default :func:`find_shared_data`.

        Returns
        -------
        Path
        """
        return _require(recording_folder(self.name, root) / self.model, f"the {self.name} model")


#: The recordings dynid can read, by name.
ADAPTERS: dict[str, Recording] = {
    "panda_gaz2019": Recording(
        name="panda_gaz2019",
        loader=load_panda_gaz2019,
        model=_PANDA_MODEL,
        n_joints=_PANDA_JOINTS,
        description="Franka Emika Panda, 7 DOF, ~1 kHz irregular stamps, joint torque sensors (Gaz 2019)",
    ),
    "tx40": Recording(
        name="tx40",
        loader=load_tx40,
        model=_TX40_MODEL,
        n_joints=6,
        description="Staubli TX40, 6 DOF, 5 kHz, motor-side data converted through a coupled wrist",
        transmission=tx40_transmission,
    ),
    "kuka_lwr4_flobaroid": Recording(
        name="kuka_lwr4_flobaroid",
        loader=load_kuka_lwr4,
        model=_KUKA_MODEL,
        n_joints=_KUKA_JOINTS,
        description="KUKA LWR4+, 7 DOF, ~200 Hz, joint torque sensors, 3 runs (FloBaRoID; pre-filtered)",
        runs=3,
    ),
}


def _recording(name: str) -> Recording:
    try:
        return ADAPTERS[name]
    except KeyError:
        raise DataError(
            f"unknown recording {name!r}; known recordings: {', '.join(sorted(ADAPTERS))}"
        ) from None


def load_recording(name: str, root: str | os.PathLike[str] | None = None, *, run: int | None = None) -> Dataset:
    """Load a real recording by name.

    Parameters
    ----------
    name : str
        A key of :data:`ADAPTERS` (``"panda_gaz2019"``, ``"tx40"``).
    root : str or path-like, optional
        Folder holding the recordings; default :func:`find_shared_data`.
    run : int, optional
        The run of a recording of several (:attr:`Recording.runs`; default 1).

    Returns
    -------
    Dataset
    """
    return _recording(name)(root, run=run)


def recording_model_path(name: str, root: str | os.PathLike[str] | None = None) -> Path:
    """Path of the URDF model that goes with a recording.

    Parameters
    ----------
    name : str
        A key of :data:`ADAPTERS`.
    root : str or path-like, optional
        Folder holding the recordings; default :func:`find_shared_data`.

    Returns
    -------
    Path
    """
    return _recording(name).model_path(root)


def recording_robot(name: str, root: str | os.PathLike[str] | None = None, *, coupled: bool = True):
    """The robot of a recording: its URDF, with its coupled transmission declared when it has one.

    Parameters
    ----------
    name : str
        A key of :data:`ADAPTERS`.
    root : str or path-like, optional
        Folder holding the recordings; default :func:`find_shared_data`.
    coupled : bool
        Declare the recording's coupled transmission (the TX40's wrist: motor 6's armature and friction
        identified on both wrist joints); False gives the URDF alone.

    Returns
    -------
    RobotModel
    """
    from dynid.symbolic.robot import load_robot

    rec = _recording(name)
    robot = load_robot(rec.model_path(root))
    if coupled and rec.transmission is not None:
        robot = robot.with_transmission(rec.transmission())
    return robot
