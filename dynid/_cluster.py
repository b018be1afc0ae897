"""The one way dynid reaches a Dask cluster: a ``dask.distributed.Client`` for an address, or a local one.

>>> with cluster_client(None, workers=2) as client:           # a LocalCluster of 2 single-thread workers
...     rows = client.gather(client.map(work, items, pure=False))
>>> with cluster_client("tcp://10.0.0.5:8786") as client:    # a running scheduler
...     ...

Every parallel part of dynid (the fleet's identifications, the diagnosis benchmark, the excitation
design's restarts) takes its ``Client`` from :func:`cluster_client` and hands work to Dask's own
engine (``client.map`` / ``client.gather``, or joblib's ``dask`` backend); nothing here distributes
work itself.  ``dask.distributed`` is imported only when a cluster is asked for.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

from dynid._extras import install_hint
from dynid.exceptions import UsageError

__all__ = ["cluster_client", "worker_peak_memory"]

CONNECT_TIMEOUT = "10s"
"""How long a scheduler address is tried before it is refused."""


def _distributed() -> Any:
    try:
        import distributed
    except ImportError:
        raise UsageError(
            "running on a Dask cluster needs the packages dask and distributed, which are not installed; "
            f"install them with {install_hint('fleet')}."
        ) from None
    return distributed


THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "DYNID_NUM_THREADS")
"""Set to 1 in every local worker: each task is single-threaded (BLAS, OpenMP, and dynid's own threads: the
compiled regressors' and the identification's large filters'), and the workers share the machine's cores."""

TRIM_VARIABLE = "MALLOC_TRIM_THRESHOLD_"
"""glibc's heap-trim threshold, which Dask sets to 64 KiB in its workers by default (left unset here)."""


QUIET_WORKERS = {
    "distributed.worker.profile.enabled": False,
    "distributed.admin.tick.interval": "1s",
    "distributed.admin.system-monitor.interval": "2s",
}
"""Dask settings of the local workers: no statistical profiler (a stack sample every 10 ms), the event
loop's tick and the system monitor every 1 s and 2 s instead of 20 ms and 500 ms.  Measured on 24 UR5
identifications under load: Dask's threads of a worker used 3.6 % of a core by default, 1.4 % so (the
dashboard of a local cluster then shows no profile)."""


def _spawn_environment() -> tuple[dict[str, Any], dict[str, str | None]]:
    """The Dask configuration local workers are spawned with, and the caller's values to restore afterwards.

    Dask's nanny copies its ``pre-spawn-environ`` into the calling process's ``os.environ`` before it
    spawns a worker (and again if it restarts one), and prefers the caller's value of a variable to its
    configuration; so the thread variables are set here for the spawn, and :func:`_restore` gives the
    caller its own values back (without it the caller kept ``OMP_NUM_THREADS=1``, ``PYTHONHASHSEED``
    and the trim threshold for good).

    The workers get one BLAS/OpenMP thread and glibc's own heap trimming: Dask's default
    ``MALLOC_TRIM_THRESHOLD_=65536`` hands every freed block above 64 KiB back to the system, so each
    large NumPy array of an identification is mapped and faulted in anew (measured on 24 UR5
    recordings: 12x the page faults and 45 % more CPU time per recording than the same process without
    it).  A trim threshold the caller set in its own environment is kept.

    The workers' own periodic work is also slowed (:data:`QUIET_WORKERS`).

    Returns
    -------
    overrides : dict
        For ``dask.config.set`` around the ``LocalCluster``'s start.
    saved : dict
        The caller's value (None: unset) of every variable the nanny or this function may set.
    """
    import dask

    configured = dict(dask.config.get("distributed.nanny.pre-spawn-environ", default={}) or {})
    saved = {key: os.environ.get(key) for key in {*configured, *THREAD_VARIABLES, TRIM_VARIABLE, "PYTHONHASHSEED"}}
    overrides: dict[str, Any] = {f"distributed.nanny.pre-spawn-environ.{key}": 1 for key in THREAD_VARIABLES}
    overrides.update(QUIET_WORKERS)
    if saved[TRIM_VARIABLE] is None:
        overrides[f"distributed.nanny.pre-spawn-environ.{TRIM_VARIABLE}"] = None
    return overrides, saved


def _restore(saved: dict[str, str | None]) -> None:
    """Put back the caller's values (:func:`_spawn_environment`'s ``saved``)."""
    for key, value in saved.items():
        if value is None:
            os.environ.pop(key, None)
        else:
            os.environ[key] = value


@contextmanager
def cluster_client(
    scheduler: str | None = None, *, workers: int = 2, threads_per_worker: int = 1, timeout: str = CONNECT_TIMEOUT
) -> Iterator[Any]:
    """A ``dask.distributed.Client``: connected to ``scheduler``, or to a LocalCluster started here.

    Parameters
    ----------
    scheduler : str, optional
        Address of a running scheduler (``tcp://host:8786``, or a scheduler file path ending in
        ``.json``).  None starts a ``LocalCluster`` of ``workers`` processes, closed on leaving the block.
    workers : int
        Worker processes of the local cluster (default 2), each with ``threads_per_worker`` threads.
    threads_per_worker : int
        Threads per local worker (default 1: dynid's numerical work is single-threaded per task).
    timeout : str
        How long to try the scheduler before giving up.

    Yields
    ------
    distributed.Client

    Raises
    ------
    UsageError
        The packages are missing, ``workers`` is below 1, no scheduler answers at ``scheduler``, or it
        has no worker.

    Notes
    -----
    A local cluster's workers get one BLAS thread, no heap-trim threshold and quieter Dask threads
    (:func:`_spawn_environment`), and the caller's environment is left as it was.  The workers of a
    running scheduler were started by their owner, with whatever Dask settings they have.
    """
    distributed = _distributed()
    if scheduler is None:
        if int(workers) != workers or workers < 1:
            raise UsageError(f"the local cluster needs at least 1 worker; got {workers}; give --workers 1 or more.")
        _ensure_open_files(int(workers))
        import dask

        overrides, saved = _spawn_environment()
        try:
            with dask.config.set(overrides):
                os.environ.update(dict.fromkeys(THREAD_VARIABLES, "1"))
                cluster = distributed.LocalCluster(
                    n_workers=int(workers),
                    threads_per_worker=int(threads_per_worker),
                    processes=True,
                    dashboard_address=":0",  # a free port: never clash with another cluster
                    silence_logs=40,
                )
            _restore(saved)  # the workers are running: the caller's environment is its own again
            try:
                with distributed.Client(cluster) as client:
                    yield client
            finally:
                cluster.close()
        finally:
            _restore(saved)  # again: a worker restarted by its nanny set the variables once more
        return
    if str(scheduler).endswith(".json") and not os.path.isfile(scheduler):
        # distributed waits for a scheduler file to appear, with no time limit
        raise UsageError(
            f"the scheduler file '{scheduler}' does not exist; give the file a running scheduler wrote "
            "(dask scheduler --scheduler-file), its address (tcp://HOST:8786), or leave --scheduler out."
        )
    if str(scheduler).endswith(".json"):
        _check_scheduler_file(str(scheduler))
    kwargs = {"scheduler_file": scheduler} if str(scheduler).endswith(".json") else {"address": scheduler}
    try:
        client = distributed.Client(**kwargs, timeout=timeout)
    except (OSError, TimeoutError, ValueError) as exc:
        reason = str(exc).splitlines()[0].rstrip(".") if str(exc) else type(exc).__name__
        raise UsageError(
            f"no Dask scheduler answered at '{scheduler}' within {timeout} ({reason}); give the address of a "
            "running scheduler (tcp://HOST:8786) or leave --scheduler out to use a local cluster."
        ) from None
    with client:
        try:  # a scheduler without workers would hold every task (or a scatter) until its own timeout
            client.wait_for_workers(1, timeout=timeout)
        except (OSError, TimeoutError):
            raise UsageError(
                f"the Dask scheduler at '{scheduler}' has no worker (none joined within {timeout}); start "
                f"workers on it (dask worker {client.scheduler.address}), or leave --scheduler out to use a "
                "local cluster."
            ) from None
        yield client


def _ensure_open_files(workers: int) -> None:
    """Raise the soft limit of open files to what a local cluster needs, or refuse if the hard limit is lower.

    A local Dask cluster holds sockets, pipes and ``/proc`` reads for its scheduler, nanny and workers;
    short of descriptors its event loops print tracebacks without end while the fleet crawls on.  A soft
    limit below the need is raised up to the hard limit (no privilege needed); a hard limit below it is
    refused with the fix.
    """
    try:
        import resource
    except ImportError:  # not POSIX
        return
    need = 64 + 16 * workers
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    unlimited = resource.RLIM_INFINITY
    if soft == unlimited or soft >= 4 * need:
        return
    target = 4 * need if hard == unlimited else min(hard, 4 * need)
    if target > soft:
        try:
            resource.setrlimit(resource.RLIMIT_NOFILE, (target, hard))
            soft = target
        except (ValueError, OSError):
            pass
    if soft < need:
        raise UsageError(
            f"the limit of open files is {soft} (ulimit -n), and a local Dask cluster of {workers} worker"
            f"{'s' if workers > 1 else ''} needs at least {need}; raise it (ulimit -n 1024), give fewer --workers, "
            "or run without a cluster (--serial)."
        )


def _check_scheduler_file(path: str) -> None:
    """Refuse a scheduler file that is not the JSON object a Dask scheduler writes (with its ``address``)."""
    import json

    try:
        with open(path, encoding="utf-8") as f:
            doc = json.load(f)
    except (ValueError, UnicodeDecodeError) as exc:
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise UsageError(
            f"the scheduler file '{path}' is not valid JSON ({reason}); give the file a running scheduler wrote "
            "(dask scheduler --scheduler-file), or its address (tcp://HOST:8786)."
        ) from None
    if not isinstance(doc, dict) or not isinstance(doc.get("address"), str) or not doc["address"]:
        got = f"a JSON {type(doc).__name__}"
        if isinstance(doc, dict):
            got = "a JSON object without a text 'address'"
        raise UsageError(
            f"the scheduler file '{path}' holds {got}, not the object with the 'address' a Dask scheduler "
            "writes; give the file a running scheduler wrote (dask scheduler --scheduler-file), or its address "
            "(tcp://HOST:8786)."
        )


def worker_peak_memory(client: Any) -> dict[str, float]:
    """Peak resident memory of each worker process so far (MiB), by worker address.

    Parameters
    ----------
    client : distributed.Client

    Returns
    -------
    dict of str to float
        ``ru_maxrss`` of each worker's process (Linux: KiB, converted to MiB).
    """
    return {address: float(kib) / 1024.0 for address, kib in client.run(_peak_rss_kib).items()}


def _peak_rss_kib() -> int:
    import resource

    return int(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
