"""Build and cache the symbolic generator and each robot's CasADi functions.

The PyPI ``pin`` wheel has no ``pinocchio.casadi`` module.  dynid therefore compiles a small C++
program (``_generator/generator.cpp``) against the headers the ``pin`` wheel ships and the headers and
``libcasadi`` the ``casadi`` wheel ships: Pinocchio's own templates run with ``Scalar = casadi::SX``.
The program is built once per environment; each robot's functions are generated once per robot.
Its templates are instantiated for the joint types a dynid specification can name only (a joint
collection of 9 types instead of Pinocchio's 25, see ``_generator/generator.hpp``): with the two
translation units built in parallel and -O0, the build takes about 86 s of CPU instead of 210 s.
Both are cached under :func:`cache_dir`, keyed on the casadi and pin versions, the generator source
and (for a robot) the content of its canonical tree.
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import os
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from importlib import metadata
from pathlib import Path
from typing import Any

from dynid._io import atomic_dir
from dynid.exceptions import CompilerNotFoundError, GeneratorError

__all__ = [
    "FUNCTION_NAMES",
    "Progress",
    "build_jobs",
    "cache_dir",
    "file_lock",
    "find_compiler",
    "full_disk",
    "generator_is_built",
    "generator_path",
    "robot_function_dir",
    "stderr_progress",
]

FUNCTION_NAMES = ("regressor", "rnea", "gravity", "mass_matrix", "aba", "fk")
"""Functions the generator writes for every robot."""

_GENERATOR_DIR = Path(__file__).parent / "_generator"
_SOURCES = tuple(sorted(_GENERATOR_DIR.glob("*.cpp")))
"""Translation units of the generator, compiled in parallel (see :func:`generator_path`): ``generator.cpp``
(the specification, regressor, inverse dynamics, gravity, kinematics) and ``gen_mass.cpp`` (mass
matrix, forward dynamics), about equally long.  Each unit parses the same heavy headers (about 8 s of
CPU), so on 2 cores two units build fastest: measured at -O0, one unit 76 s of CPU, two 86 s (43 s
each), one per algorithm (six) 152 s."""
_HEADERS = tuple(sorted(_GENERATOR_DIR.glob("*.hpp")))
_OPT = "-O0"
"""Optimisation level of the generator.  It runs once per robot, for a fraction of a second (0.01-0.15 s
for the UR5 and the Panda at -O0), while the optimiser costs build time (one unit: 88 s of CPU at -O1,
76 s at -O0).  Its output does not depend on it: the saved Functions are identical byte for byte."""
_DEFINES = (
    "BOOST_MPL_CFG_NO_PREPROCESSED_HEADERS",
    "BOOST_MPL_LIMIT_LIST_SIZE=30",
    "BOOST_MPL_LIMIT_VECTOR_SIZE=30",
    "BOOST_FUSION_INVOKE_MAX_ARITY=12",
    "PINOCCHIO_ENABLE_TEMPLATE_INSTANTIATION",
)

Progress = Callable[[str], None]
"""A callback that shows one line of progress of a long build."""


def stderr_progress(message: str) -> None:
    """The default :data:`Progress`: print the line to stderr at once.

    Parameters
    ----------
    message : str
        One line of progress.
    """
    from dynid import _progress

    session = _progress.active()
    if session is not None:
        session.say(message)
    else:
        print(message, file=sys.stderr, flush=True)


def cache_dir() -> Path:
    """Root of dynid's cache: ``$DYNID_CACHE_DIR``, else ``$XDG_CACHE_HOME/dynid``, else ``~/.cache/dynid``."""
    env = os.environ.get("DYNID_CACHE_DIR")
    if env:
        return Path(env).expanduser()
    xdg = os.environ.get("XDG_CACHE_HOME")
    return (Path(xdg).expanduser() if xdg else Path.home() / ".cache") / "dynid"


def _versions() -> str:
    return f"casadi={metadata.version('casadi')};pin={metadata.version('pin')}"


def _site_package(name: str) -> Path:
    import importlib.util

    spec = importlib.util.find_spec(name)
    if spec is None or spec.origin is None:
        raise GeneratorError(
            f"the package '{name}' is not importable; install dynid's dependencies with pip."
        )
    return Path(spec.origin).parent


def _prefixes() -> tuple[Path, Path]:
    """(cmeel prefix with Pinocchio's headers and libraries, casadi package folder)."""
    casadi_dir = _site_package("casadi")
    for root in [casadi_dir.parent, *(Path(p) for p in sys.path if p)]:
        prefix = root / "cmeel.prefix"
        if (prefix / "include" / "pinocchio").is_dir():
            return prefix, casadi_dir
    raise GeneratorError(
        "Pinocchio's C++ headers (cmeel.prefix/include/pinocchio) were not found beside the 'pin' package; "
        "reinstall it with 'pip install --force-reinstall pin'."
    )


def find_compiler(kind: str = "c++") -> str:
    """Path of a C++ (``kind='c++'``) or C (``kind='c'``) compiler, honouring ``$CXX`` / ``$CC``.

    Raises
    ------
    CompilerNotFoundError
        If none is found, with the command to install one.
    """
    env, names = ("CXX", ("c++", "g++", "clang++")) if kind == "c++" else ("CC", ("cc", "gcc", "clang"))
    candidates = [os.environ[env]] if os.environ.get(env) else []
    candidates += list(names)
    for name in candidates:
        found = shutil.which(name.split()[0])
        if found:
            return found
    raise CompilerNotFoundError(
        f"no {kind.upper() if kind == 'c' else 'C++'} compiler was found (looked for ${env}, "
        f"{', '.join(names)}); dynid compiles its symbolic dynamics once, install one with "
        f"'apt-get install {'g++' if kind == 'c++' else 'gcc'}' or set {env}."
    )


def _generator_key() -> str:
    digest = hashlib.sha256()
    digest.update(_versions().encode())
    for path in (*_SOURCES, *_HEADERS):
        digest.update(path.name.encode())
        digest.update(path.read_bytes())
    digest.update(" ".join((*_DEFINES, _OPT)).encode())
    return digest.hexdigest()[:16]


@contextlib.contextmanager
def file_lock(path: Path) -> Iterator[None]:
    """Hold an exclusive lock on the file ``path`` so that parallel processes build a thing once.

    Parameters
    ----------
    path : Path
        The lock file (created, with its folders, if missing).
    """
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


def build_jobs() -> int:
    """Compilers run at once while building the generator: ``$DYNID_BUILD_JOBS``, else the usable cores."""
    env = os.environ.get("DYNID_BUILD_JOBS", "").strip()
    if env:
        try:
            jobs = int(env)
        except ValueError:
            jobs = 0
        if jobs < 1:
            raise GeneratorError(
                f"DYNID_BUILD_JOBS is {env!r}; give a whole number of parallel compilers of at least 1, e.g. 2."
            )
        return jobs
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not Linux
        return max(1, os.cpu_count() or 1)


#: Below this much free space a failed build is put down to the full disk, not to the compiler: the
#: generator alone is about 13 MB, and its objects take more while it is built.
LOW_SPACE = 100 * 2**20


def full_disk(what: str, folder: Path) -> GeneratorError | None:
    """The error of a build that failed on a disk with no room (less than :data:`LOW_SPACE` free at ``folder``
    or its nearest existing parent), in one sentence; None when there is room (the build failed otherwise)."""
    place = Path(folder)
    while not place.exists() and place != place.parent:
        place = place.parent
    try:
        free = shutil.disk_usage(place).free
    except OSError:
        return None
    if free >= LOW_SPACE:
        return None
    return GeneratorError(
        f"{what} failed: no space left on the disk of '{place}' ({free / 2**20:.3g} MB free, {LOW_SPACE // 2**20} MB "
        "needed); free space there, or set DYNID_CACHE_DIR to a folder on a disk with room, and run again"
    )


def _compiler_failed(what: str, proc_out: str, code: int, folder: Path | None = None) -> GeneratorError:
    full = None if folder is None else full_disk(what, folder)
    if full is not None:
        return full
    tail = "\n".join(proc_out.strip().splitlines()[-15:])
    return GeneratorError(f"{what} failed (exit {code}); the compiler said:\n{tail}")


def _run_parallel(
    commands: list[tuple[str, list[str]]],
    what: str,
    expected: str,
    jobs: int,
    progress: Progress | None,
    folder: Path | None = None,
) -> None:
    """Run the named commands, ``jobs`` at a time; report each one done and the elapsed time every 4 s.

    The first failure stops the others and raises :class:`GeneratorError` with the compiler's last lines
    (or, when ``folder``'s disk is full, saying so: :func:`full_disk`).
    """
    start = time.monotonic()
    if progress:
        progress(f"dynid: {what} (once; {expected})...")
    done = threading.Event()
    finished = [0]

    def tick() -> None:
        while not done.wait(4.0):  # no silence longer than the commands' heartbeat
            if progress:
                progress(
                    f"dynid: {what}: {finished[0]}/{len(commands)} parts compiled, {time.monotonic() - start:.0f} s "
                    f"({expected.split(',')[0]})"
                )

    ticker = threading.Thread(target=tick, daemon=True)
    ticker.start()
    pending = list(commands)
    running: list[tuple[str, subprocess.Popen, Any]] = []
    try:
        while pending or running:
            while pending and len(running) < jobs:
                name, cmd = pending.pop(0)
                log = tempfile.TemporaryFile(mode="w+")  # a pipe could fill up with a long error and block
                running.append(
                    (name, subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, text=True), log)
                )
            ended = next((entry for entry in running if entry[1].poll() is not None), None)
            if ended is None:
                time.sleep(0.05)
                continue
            running.remove(ended)
            name, proc, log = ended
            log.seek(0)
            output = log.read()
            log.close()
            if proc.returncode != 0:
                raise _compiler_failed(f"{what} ({name})", output, proc.returncode, folder)
            finished[0] += 1
            if progress and len(commands) > 1:
                progress(
                    f"dynid: {what}: {name} done ({finished[0]}/{len(commands)}, {time.monotonic() - start:.0f} s)"
                )
    finally:
        done.set()
        for _, proc, log in running:
            proc.kill()
            proc.wait()
            log.close()
    if progress:
        progress(f"dynid: {what}: done in {time.monotonic() - start:.0f} s")


def generator_is_built() -> bool:
    """Whether the generator of this environment is compiled already (no one-time build ahead)."""
    return (cache_dir() / "generator" / _generator_key() / "dynid-generator").is_file()


def generator_path(progress: Progress | None = stderr_progress) -> Path:
    """Path of the compiled generator, building it on first use (about 40 s on 2 idle cores).

    Its translation units compile in parallel (:func:`build_jobs` at a time), then link.
    """
    key = _generator_key()
    folder = cache_dir() / "generator" / key
    exe = folder / "dynid-generator"
    if exe.is_file():
        return exe
    with file_lock(cache_dir() / "generator" / f"{key}.lock"):
        if exe.is_file():  # built by another process while we waited
            return exe
        compiler = find_compiler("c++")
        prefix, casadi_dir = _prefixes()
        lib_dirs = [prefix / "lib", casadi_dir]
        full = full_disk("building the symbolic generator", folder)
        if full is not None:  # said now, not after a minute of compiling
            raise full
        folder.mkdir(parents=True, exist_ok=True)
        objects = folder / f"objects.tmp{os.getpid()}"
        objects.mkdir(exist_ok=True)
        tmp = folder / f"dynid-generator.tmp{os.getpid()}"
        flags = [
            "-std=c++17",
            _OPT,
            "-w",
            *(f"-D{d}" for d in _DEFINES),
            f"-I{_GENERATOR_DIR}",
            f"-I{prefix / 'include'}",
            f"-I{casadi_dir / 'include'}",
            f"-I{casadi_dir / 'include' / 'eigen3'}",
        ]
        # largest units first: on 2 cores the parallel build then ends with the small ones
        units = sorted(_SOURCES, key=lambda p: -p.stat().st_size)
        compile_cmds = [
            (src.name, [compiler, *flags, "-c", str(src), "-o", str(objects / f"{src.stem}.o")])
            for src in units
        ]
        link_cmd = [
            compiler,
            *(str(objects / f"{src.stem}.o") for src in _SOURCES),
            "-o",
            str(tmp),
            *(f"-L{d}" for d in lib_dirs),
            "-lpinocchio_default",
            "-lcasadi",
            *(f"-Wl,-rpath,{d}" for d in lib_dirs),
        ]
        jobs = build_jobs()
        try:
            _run_parallel(
                compile_cmds,
                "building the symbolic generator (Pinocchio on CasADi SX)",
                f"about 40 s on 2 idle cores, {jobs} compiler{'s' if jobs > 1 else ''} in parallel, cached for "
                "this environment",
                jobs,
                progress,
                folder,
            )
            _run_parallel([("link", link_cmd)], "linking the symbolic generator", "a few seconds", 1, None, folder)
            os.replace(tmp, exe)
        finally:
            tmp.unlink(missing_ok=True)
            shutil.rmtree(objects, ignore_errors=True)
    return exe


def robot_function_dir(
    spec: str, progress: Progress | None = stderr_progress, *, rebuild: bool = False
) -> Path:
    """Folder of a robot's saved CasADi functions (``<name>.casadi``), generating them on first use.

    Parameters
    ----------
    spec : str
        The canonical tree of the robot (:attr:`dynid.symbolic.robot.RobotModel.spec`).
    rebuild : bool
        Generate them again even if the folder holds them (a damaged cache).
    """
    key = hashlib.sha256((_generator_key() + spec).encode()).hexdigest()[:20]
    folder = cache_dir() / "robots" / key
    if not rebuild and all((folder / f"{name}.casadi").is_file() for name in FUNCTION_NAMES):
        return folder
    exe = generator_path(progress)
    with file_lock(cache_dir() / "robots" / f"{key}.lock"):
        if not rebuild and all((folder / f"{name}.casadi").is_file() for name in FUNCTION_NAMES):
            return folder
        with atomic_dir(folder) as work:
            (work / "robot.spec").write_text(spec)
            proc = subprocess.run(
                [str(exe), str(work / "robot.spec"), str(work)], capture_output=True, text=True
            )
            if proc.returncode != 0:
                raise full_disk("generating the robot's functions", work) or GeneratorError(
                    f"the symbolic generator could not build this robot: {proc.stderr.strip()}; "
                    "check the robot description."
                )
    return folder
