"""Fleet identification: every recording of many robots identified with one model definition, on Dask.

>>> result = identify_fleet("ur5", "recordings/**/*.csv")          # a LocalCluster of 2 workers
>>> result = identify_fleet("ur5", "recordings/**/*.csv", scheduler="tcp://10.0.0.5:8786")
>>> result.write("fleet/")                     # fleet.parquet, fleet.csv, drift.csv, report.html, summary.json
>>> result.drift.flagged_robots                # {"robot_07": [DriftTest(parameter="fc3", ...)]}

Each recording is read by the one dataset reader (:func:`dynid.data.files.load_dataset`), split
in time: the first ``1 - holdout`` of its duration identifies the model (:func:`dynid.identify.model.identify`,
the function ``dynid identify`` calls, with the same defaults unless given), the last ``holdout``
(default 20 %) is predicted by it (:func:`dynid.validation.validate.validate`) for the held-out error,
and, when asked, diagnosed (:func:`dynid.diagnosis.diagnose`) for its verdict.  One recording is one
task handed to Dask (``client.map``) on the client of :func:`dynid._cluster.cluster_client`; ``serial``
runs the same function in this process, so both give the same table.

The table has one row per recording: ``path, robot, time, order``, ``error`` (empty, or the sentence
that refused the recording: one bad recording does not stop the fleet), ``warnings`` (dynid's warnings
on the recording, joined by `` | ``), ``elapsed_s`` and ``cpu_s`` (the identification's wall and CPU
time, s; the CPU time is its process's, which the machine's load does not inflate: in a Dask worker it
includes Dask's own threads, and tasks that share a worker share it), the samples used, ``cond``,
every layer-1 parameter ``<name>`` with its standard deviation ``<name>_std`` (base parameters,
armature ``ia<j>``, Coulomb ``fc<j>``, viscous ``fv<j>`` and offset ``fo<j>`` friction, SI units), the
refitted friction coefficients ``friction.<coef><j>`` when layer 2 refits them, the held-out RMS per
joint ``heldout_rms_<j>`` and its mean (N m), and ``verdict`` with ``diagnose``.
"""

from __future__ import annotations

import csv
import io
import os
import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from dynid._extras import install_hint
from dynid._io import atomic_dir, atomic_path, write_json, write_text
from dynid.exceptions import DataError, DynidError, UsageError
from dynid.fleet.recordings import Recording, find_recordings

__all__ = ["FleetResult", "FleetSettings", "identify_fleet", "identify_recording", "run_fleet"]

TOOL_MASS = 1.0
"""Mass (kg) of the tool whose effect on the parameters chooses the payload-sensitive ones (:mod:`drift`)."""

FILES = ("fleet.parquet", "fleet.csv", "drift.csv", "report.html", "summary.json")
"""What :meth:`FleetResult.write` puts in the output folder."""


@dataclass(frozen=True)
class FleetSettings:
    """How every recording of the fleet is identified (the options of ``dynid identify``).

    One pipeline for every recording, so that their parameters compare: the paper's (irls, seed
    friction, the mixture sized by validation) by default, not the pipeline ``dynid identify`` would
    choose per recording, and no pull toward the description's bodies (its strength would be chosen per
    recording too).

    Parameters
    ----------
    method : str
        Layer-1 method (:func:`dynid.identify.registry.method_names`).
    friction : str
        Friction model, a name of :data:`~dynid.identify.registry.FRICTION_MODELS`.
    gmm : "off" or "auto" or int
        Layer-3 correction.
    cutoff : float or "auto" or None
        Low-pass cut-off (Hz) of torque and regressor.
    holdout : float
        Fraction of each recording's duration, at its end, kept out of the identification and predicted
        for the held-out error; 0 identifies on the whole recording (no held-out error).
    diagnose : bool
        Diagnose each recording's model on its held-out part and report the verdict.
    degrees : bool
        The recordings' angles are in degrees.
    topic : str, optional
        The ``sensor_msgs/JointState`` topic of ROS 2 recordings that hold several.
    """

    method: str = "irls"
    friction: str = "seed"
    gmm: str | int = "auto"
    cutoff: float | str | None = "auto"
    holdout: float = 0.2
    diagnose: bool = False
    degrees: bool = False
    topic: str | None = None

    def __post_init__(self) -> None:
        if not (0.0 <= float(self.holdout) < 0.9):
            raise UsageError(
                f"the held-out fraction is {self.holdout}; give a fraction of each recording in [0, 0.9), e.g. 0.2."
            )
        if self.diagnose and self.holdout <= 0:
            raise UsageError("the diagnosis needs held-out data; give a held-out fraction above 0 with it.")


@lru_cache(maxsize=8)
def _robot(spec: str) -> Any:
    from dynid.symbolic.robot import load_robot

    return load_robot(spec)


def _resolve_robot(robot: Any) -> Any:
    return _robot(str(robot)) if isinstance(robot, str | os.PathLike) else robot


def _split(data: Any, holdout: float) -> tuple[Any, Any]:
    if holdout <= 0:
        return data, None
    t0, t1 = float(data.t[0]), float(data.t[-1])
    cut = t0 + (1.0 - holdout) * (t1 - t0)
    rows = np.arange(data.m)
    train, held = rows[data.t <= cut], rows[data.t > cut]
    if len(train) < 10 or len(held) < 10:
        raise DataError(
            f"the recording has {data.m} samples; {holdout:.0%} held out leaves too few on one side; give a "
            "longer recording or another held-out fraction."
        )
    return data.select_rows(train), data.select_rows(held)


def parameter_table(model: Any) -> list[dict[str, Any]]:
    """Name, kind, joint and the shift a :data:`TOOL_MASS` kg tool at the tool frame gives each parameter.

    Parameters
    ----------
    model : IdentifiedModel

    Returns
    -------
    list of dict
        ``name``, ``kind`` (``link``, ``armature``, ``coulomb``, ``viscous``, ``offset``, ...), ``joint``
        (from 1) and ``tool_shift`` (the parameter's change in SI units for the tool).
    """
    from dynid.symbolic.robot import standard_from_com

    robot = model.robot
    cols = model.columns
    n = robot.n
    link = int(robot.tool_parent) - 1
    delta = np.zeros(cols.P.shape[1])
    if 0 <= link < n:
        delta[10 * link : 10 * link + 10] = standard_from_com(
            TOOL_MASS, np.asarray(robot.tool_translation, dtype=float), np.zeros((3, 3))
        )
    shift = cols.P @ delta
    return [
        {"name": name, "kind": kind, "joint": int(j), "tool_shift": float(s)}
        for name, kind, j, s in zip(cols.names, cols.kinds, cols.joints, shift, strict=True)
    ]


def _failed_row(recording: Recording, error: str) -> dict[str, Any]:
    """The row of a recording that gave no model (``error`` says why; empty while it is being identified)."""
    return {
        "path": recording.path,
        "robot": recording.robot,
        "time": recording.time,
        "order": recording.order,
        "error": error,
        "warnings": "",
        "elapsed_s": 0.0,
        "cpu_s": 0.0,
    }


def identify_recording(robot: Any, recording: Recording, settings: FleetSettings) -> dict[str, Any]:
    """Identify one recording (the task Dask runs): its row of the fleet table.

    Parameters
    ----------
    robot : RobotModel or str
        The model definition (a name or path is loaded once per process).
    recording : Recording
    settings : FleetSettings

    Returns
    -------
    dict
        ``row`` (the table row; ``error`` holds the sentence when the recording was refused) and
        ``parameters`` (:func:`parameter_table`, None on error).
    """
    from dynid.data.files import load_dataset
    from dynid.data.preparation import Preprocessing
    from dynid.identify.model import identify
    from dynid.validation.validate import validate

    robot = _resolve_robot(robot)
    row = _failed_row(recording, "")
    del row["warnings"], row["elapsed_s"], row["cpu_s"]
    started, cpu_started = time.perf_counter(), time.process_time()
    caught: list[warnings.WarningMessage] = []
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            extra = {} if settings.topic is None else {"topic": settings.topic}
            data = load_dataset(recording.path, robot.n, robot=robot, degrees=settings.degrees, **extra)
            train, held = _split(data, settings.holdout)
            model = identify(
                robot,
                train,
                method=settings.method,
                friction=settings.friction,
                gmm=settings.gmm,
                preprocessing=Preprocessing(cutoff=settings.cutoff),
                # no pull toward the description: a strength chosen per recording would bias each
                # recording's parameters by its own amount, and the drift tests compare them
                reference_weight=0.0,
            )
            row.update(
                samples=int(data.m), duration_s=float(data.t[-1] - data.t[0]),
                heldout_s=0.0 if held is None else float(held.t[-1] - held.t[0]), cond=float(model.cond),
            )
            for name, value, std in zip(model.columns.names, model.params, model.std, strict=True):
                row[name] = float(value)
                row[f"{name}_std"] = float(std)
            if model.friction is not None and model.friction_source == "layer2":
                for j, coefs in enumerate(model.friction.to_dict()["joints"], start=1):
                    row.update({f"friction.{k}{j}": float(v) for k, v in coefs.items() if not k.endswith("_held") and k not in ("ks_shared", "vmax")})
            if held is not None:
                rms = np.asarray(validate(model, held).metrics["rms"], dtype=float)
                row.update({f"heldout_rms_{j}": float(v) for j, v in enumerate(rms, start=1)})
                row["heldout_rms_mean"] = float(np.mean(rms))
            if settings.diagnose:
                from dynid.diagnosis import diagnose

                row["verdict"] = "+".join(diagnose(model, train, held).verdict)
    except Exception as exc:  # one bad recording does not stop the fleet: its row carries the reason
        row["error"] = str(exc) if isinstance(exc, DynidError) else f"{type(exc).__name__}: {exc}"
        row["warnings"] = _warning_text(caught)
        row["elapsed_s"] = time.perf_counter() - started
        row["cpu_s"] = time.process_time() - cpu_started
        return {"row": row, "parameters": None}
    row["warnings"] = _warning_text(caught)
    row["elapsed_s"] = time.perf_counter() - started
    row["cpu_s"] = time.process_time() - cpu_started
    return {"row": row, "parameters": parameter_table(model)}


def _warning_text(caught: list[warnings.WarningMessage]) -> str:
    """dynid's own warnings of one recording, each once, joined by `` | `` (others, from libraries, left out)."""
    from dynid.exceptions import DynidWarning

    texts = [str(w.message) for w in caught if issubclass(w.category, DynidWarning)]
    return " | ".join(dict.fromkeys(texts))


def run_fleet(
    robot: Any,
    recordings: Sequence[Recording],
    settings: FleetSettings,
    *,
    client: Any = None,
) -> list[dict[str, Any]]:
    """Identify recordings on a Dask client (``client.map``), or in this process when ``client`` is None.

    Parameters
    ----------
    robot : RobotModel or str
    recordings : sequence of Recording
    settings : FleetSettings
    client : distributed.Client, optional

    Returns
    -------
    list of dict
        :func:`identify_recording`'s output per recording, in the order given.
    """
    if client is None:
        return [identify_recording(robot, rec, settings) for rec in recordings]
    robot_ref = client.scatter(robot, broadcast=True) if not isinstance(robot, str | os.PathLike) else str(robot)
    futures = client.map(identify_recording, [robot_ref] * len(recordings), list(recordings), [settings] * len(recordings), pure=False)
    out = []
    for rec, future in zip(recordings, futures, strict=True):
        try:
            out.append(future.result())
        except Exception as exc:  # a worker lost (out of memory, killed): that recording's row says so
            out.append({"row": _failed_row(rec, f"{type(exc).__name__}: {exc}"), "parameters": None})
    return out


@dataclass(frozen=True, eq=False)
class FleetResult:
    """The fleet's table, its drift tests and how it was run.

    Attributes
    ----------
    rows : list of dict
        One row per recording (see the module's docstring), in (robot, time) order.
    columns : list of str
        The table's columns, in order (a row may lack some: a refused recording has no parameters).
    parameters : list of dict
        :func:`parameter_table` of the model definition (empty when no recording was identified).
    settings : FleetSettings
    drift : DriftResult or None
        :func:`dynid.fleet.drift.detect_drift` on the table.
    info : dict
        ``robot``, ``pattern``, ``scheduler`` (``"serial"``, ``"local"`` or the address), ``workers``,
        ``elapsed_s``.
    """

    rows: list[dict[str, Any]]
    columns: list[str]
    parameters: list[dict[str, Any]]
    settings: FleetSettings
    drift: Any = None
    info: dict[str, Any] = field(default_factory=dict)

    @property
    def robots(self) -> list[str]:
        """The robots, in the table's order."""
        return list(dict.fromkeys(r["robot"] for r in self.rows))

    @property
    def errors(self) -> list[dict[str, Any]]:
        """The rows of refused recordings."""
        return [r for r in self.rows if r.get("error")]

    def column(self, name: str) -> np.ndarray:
        """One column as an array (NaN where a row lacks it; object dtype for text columns)."""
        values = [r.get(name) for r in self.rows]
        if all(v is None or isinstance(v, int | float) for v in values):
            return np.array([np.nan if v is None else v for v in values], dtype=float)
        return np.array(values, dtype=object)

    def to_arrow(self) -> Any:
        """The table as a ``pyarrow.Table`` (missing values null)."""
        try:
            import pyarrow as pa
        except ImportError:
            raise UsageError(
                "writing the fleet table as Parquet needs pyarrow, which is not installed; install it with "
                f"{install_hint('fleet')}."
            ) from None
        return pa.table({c: [r.get(c) for r in self.rows] for c in self.columns})

    def to_csv(self) -> str:
        """The table as CSV text (empty cells where a row lacks a column)."""
        buffer = io.StringIO()
        writer = csv.DictWriter(buffer, fieldnames=self.columns, restval="", lineterminator="\n")
        writer.writeheader()
        for row in self.rows:
            writer.writerow({k: repr(v) if isinstance(v, float) else v for k, v in row.items()})
        return buffer.getvalue()

    def summary(self) -> str:
        """A few lines: recordings, robots, errors, where it ran, and the drift findings."""
        ok = len(self.rows) - len(self.errors)
        lines = [
            f"{len(self.rows)} recordings of {len(self.robots)} robots, {ok} identified "
            f"({self.info.get('scheduler', '?')}, {self.info.get('workers', 1)} workers, "
            f"{self.info.get('elapsed_s', float('nan')):.1f} s)"
        ]
        lines += [f"  refused {r['path']}: {r['error']}" for r in self.errors[:10]]
        if self.drift is not None:
            lines.append(self.drift.summary())
        return "\n".join(lines)

    def figures(self) -> dict[str, Any]:
        """JSON-ready figures: the run, the errors and the drift findings."""
        return {
            **self.info,
            "settings": {k: getattr(self.settings, k) for k in self.settings.__dataclass_fields__},
            "recordings": len(self.rows),
            "robots": self.robots,
            "errors": [{"path": r["path"], "error": r["error"]} for r in self.errors],
            "rows": self.rows,
            "drift": None if self.drift is None else self.drift.figures(),
        }

    def write(self, out_dir: str | os.PathLike[str]) -> Path:
        """Write the folder :data:`FILES` (all or nothing: built beside it, then renamed into place).

        Parameters
        ----------
        out_dir : str or path-like
            The folder; an existing one is replaced.

        Returns
        -------
        Path
        """
        table = self.to_arrow()  # says in one sentence when pyarrow is missing
        import pyarrow.parquet as pq

        from dynid.fleet.report import write_fleet_report

        with atomic_dir(out_dir) as work:
            with atomic_path(work / "fleet.parquet") as tmp:
                pq.write_table(table, tmp)
            write_text(work / "fleet.csv", self.to_csv())
            write_text(work / "drift.csv", "" if self.drift is None else self.drift.to_csv())
            write_fleet_report(self, work / "report.html")
            # the files of the folder, so that a later run replaces only what it wrote
            files = sorted([*(p.name for p in work.iterdir()), "summary.json"])
            write_json(work / "summary.json", {**self.figures(), "files": files})
        return Path(out_dir)


def _columns(rows: list[dict[str, Any]]) -> list[str]:
    columns: dict[str, None] = {}
    for row in rows:
        columns.update(dict.fromkeys(row))
    return list(columns)


def identify_fleet(
    robot: Any,
    data: str | Sequence[Recording],
    *,
    manifest: str | os.PathLike[str] | None = None,
    scheduler: str | None = None,
    workers: int = 2,
    serial: bool = False,
    client: Any = None,
    settings: FleetSettings | None = None,
    drift: bool = True,
    alpha: float = 0.05,
    **options: Any,
) -> FleetResult:
    """Identify every recording of a fleet on Dask and test each robot's parameters for drift.

    Parameters
    ----------
    robot : RobotModel or str
        The one model definition (a built-in name, URDF or table path, or a loaded robot).
    data : str or sequence of Recording
        A glob pattern (see :mod:`dynid.fleet.recordings`) or recordings already found.
    manifest : str or path-like, optional
        CSV with ``path, robot, time`` per recording; without it robot and time come from the path.
    scheduler : str, optional
        Address of a running Dask scheduler; default a LocalCluster of ``workers`` single-thread workers.
    workers : int
        Workers of the local cluster (default 2).
    serial : bool
        Identify in this process, one recording after another (no Dask).
    client : distributed.Client, optional
        An open client to use (then ``scheduler`` and ``workers`` are not used).
    settings : FleetSettings, optional
        How each recording is identified; or give its fields as keywords (``friction="linear"``, ...).
    drift : bool
        Run the drift tests (:func:`dynid.fleet.drift.detect_drift`).
    alpha : float
        Family-wise error rate of the drift tests.
    **options
        Fields of :class:`FleetSettings`.

    Returns
    -------
    FleetResult

    Raises
    ------
    UsageError
        No recording matches, a manifest without a recording, an unknown option, no scheduler at the address.
    DataError
        No recording could be identified (the message quotes the first recording's sentence).
    """
    from dynid._cluster import cluster_client

    if settings is None:
        unknown = sorted(set(options) - set(FleetSettings.__dataclass_fields__))
        if unknown:
            raise UsageError(
                f"identify_fleet has no option {', '.join(unknown)}; give fields of FleetSettings: "
                f"{', '.join(FleetSettings.__dataclass_fields__)}."
            )
        settings = FleetSettings(**options)
    elif options:
        raise UsageError("give either settings= or its fields as keywords to identify_fleet, not both.")
    recordings = find_recordings(data, manifest) if isinstance(data, str | os.PathLike) else list(data)
    robot = _resolve_robot(robot)
    started = time.perf_counter()
    if serial:
        outputs, where, count = run_fleet(robot, recordings, settings), "serial", 1
    elif client is not None:
        outputs = run_fleet(robot, recordings, settings, client=client)
        where, count = "client", len(client.scheduler_info().get("workers", {}))
    else:
        with cluster_client(scheduler, workers=workers) as opened:
            outputs = run_fleet(robot, recordings, settings, client=opened)
            count = len(opened.scheduler_info().get("workers", {}))
        where = "local" if scheduler is None else str(scheduler)
    elapsed = time.perf_counter() - started
    rows = [o["row"] for o in outputs]
    parameters = next((o["parameters"] for o in outputs if o["parameters"] is not None), None)
    if parameters is None:
        raise DataError(
            f"none of the {len(rows)} recordings could be identified; the first: {rows[0]['path']}: "
            f"{rows[0]['error'].rstrip('.')}; fix the recordings or the robot."
        )
    info = {
        "robot": getattr(robot, "name", str(robot)),
        "pattern": str(data) if isinstance(data, str | os.PathLike) else "(recordings)",
        "scheduler": where,
        "workers": count,
        "elapsed_s": elapsed,
    }
    result = FleetResult(rows, _columns(rows), parameters, settings, None, info)
    if drift:
        from dynid.fleet.drift import detect_drift

        result = FleetResult(rows, result.columns, parameters, settings, detect_drift(result, alpha=alpha), info)
    return result
