"""Timing helpers shared by the benchmarks: CPU time of this process and of its workers, the load.

The benchmarks run as scripts (``python benchmarks/NAME.py``), so they import this module as
``_timing`` from their own folder.
"""

from __future__ import annotations

import os
import resource


def load() -> str:
    """The machine's load averages (1, 5 and 15 minutes), to print beside every time."""
    one, five, fifteen = os.getloadavg()
    return f"load {one:.1f} {five:.1f} {fifteen:.1f}"


def self_cpu() -> float:
    """CPU time (s) of this process, all its threads."""
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def children_cpu() -> float:
    """CPU time (s) of this process's children that have ended and were waited for."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def workers_cpu() -> float:
    """CPU time (s) of the live child processes (joblib's workers), 0 without psutil."""
    try:
        import psutil
    except ImportError:
        return 0.0
    total = 0.0
    for child in psutil.Process().children(recursive=True):
        try:
            t = child.cpu_times()
            total += t.user + t.system
        except psutil.Error:
            pass
    return total


def cpu_seconds() -> float:
    """CPU time (s) of this process and its live children (without psutil, the process only)."""
    return self_cpu() + workers_cpu()


def run_measured(argv: list[str], cwd: str | None = None, env: dict | None = None) -> dict:
    """Run a command to its end: wall time, CPU time and peak memory of it and its children, exit code.

    The child's own resource usage (``os.wait4``), so that runs side by side in one script do not add
    up: ``cpu`` (s, user + system, the command and the processes it waited for), ``rss_mib`` (the
    peak resident memory of the largest of them), ``wall`` (s), ``code`` and the last lines of its
    standard error (``tail``).
    """
    import subprocess
    import tempfile
    import time

    with tempfile.TemporaryFile() as err:
        t0 = time.perf_counter()
        proc = subprocess.Popen(argv, cwd=cwd, env=env, stdout=subprocess.DEVNULL, stderr=err)
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - t0
        proc.returncode = os.waitstatus_to_exitcode(status)
        err.seek(0)
        tail = err.read().decode(errors="replace").strip().splitlines()[-3:]
    return {
        "wall": wall,
        "cpu": usage.ru_utime + usage.ru_stime,
        "rss_mib": usage.ru_maxrss / 1024.0,
        "code": proc.returncode,
        "tail": tail,
    }
