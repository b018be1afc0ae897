"""Build and cache the symbolic generator and each robot's CasADi functions.

The PyPI ``pin`` wheel has no ``pinocchio.casadi`` module.  dynid therefore compiles a small C++
program (``_generator/generator.cpp``) against the headers the ``pin`` wheel ships and the headers and
``libcasadi`` the ``casadi`` wheel ships: Pinocchio's own templates run with ``Scalar = casadi::SX``.
The program is built once per environment; each robot's functions are generated once per robot.
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
import threading
import time
from collections.abc import Callable, Iterator
from importlib import metadata
from pathlib import Path

from dynid._io import atomic_dir
from dynid.exceptions import CompilerNotFoundError, GeneratorError

__all__ = [
    "FUNCTION_NAMES",
    "Progress",
    "cache_dir",
    "file_lock",
    "find_compiler",
    "generator_is_built",
    "generator_path",
    "robot_function_dir",
    "stderr_progress",
]

FUNCTION_NAMES = ("regressor", "rnea", "gravity", "mass_matrix", "aba", "fk")
"""Functions the generator writes for every robot."""

_SOURCE = Path(__file__).parent / "_generator" / "generator.cpp"
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
    digest.update(_SOURCE.read_bytes())
    digest.update(" ".join(_DEFINES).encode())
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


def _run_with_progress(cmd: list[str], what: str, expected: str, progress: Progress | None) -> None:
    """Run ``cmd``; report elapsed time every 15 s while it runs."""
    start = time.monotonic()
    if progress:
        progress(f"dynid: {what} (once; {expected})...")
    done = threading.Event()

    def tick() -> None:
        while not done.wait(15.0):
            if progress:
                progress(f"dynid: {what}: {time.monotonic() - start:.0f} s")

    ticker = threading.Thread(target=tick, daemon=True)
    ticker.start()
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
    finally:
        done.set()
    if proc.returncode != 0:
        tail = "\n".join((proc.stderr or proc.stdout).strip().splitlines()[-15:])
        raise GeneratorError(f"{what} failed (exit {proc.returncode}); the compiler said:\n{tail}")
    if progress:
        progress(f"dynid: {what}: done in {time.monotonic() - start:.0f} s")


def generator_is_built() -> bool:
    """Whether the generator of this environment is compiled already (no one-time build ahead)."""
    return (cache_dir() / "generator" / _generator_key() / "dynid-generator").is_file()


def generator_path(progress: Progress | None = stderr_progress) -> Path:
    """Path of the compiled generator, building it on first use (about 1-2 minutes on 2 cores)."""
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
        folder.mkdir(parents=True, exist_ok=True)
        tmp = folder / f"dynid-generator.tmp{os.getpid()}"
        cmd = [
            compiler,
            "-std=c++17",
            "-O1",
            "-w",
            *(f"-D{d}" for d in _DEFINES),
            f"-I{prefix / 'include'}",
            f"-I{casadi_dir / 'include'}",
            f"-I{casadi_dir / 'include' / 'eigen3'}",
            str(_SOURCE),
            "-o",
            str(tmp),
            *(f"-L{d}" for d in lib_dirs),
            "-lpinocchio_default",
            "-lcasadi",
            *(f"-Wl,-rpath,{d}" for d in lib_dirs),
        ]
        try:
            _run_with_progress(
                cmd,
                "building the symbolic generator (Pinocchio on CasADi SX)",
                "about 1-2 minutes on 2 cores, cached for this environment",
                progress,
            )
            os.replace(tmp, exe)
        finally:
            tmp.unlink(missing_ok=True)
    return exe


def robot_function_dir(spec: str, progress: Progress | None = stderr_progress) -> Path:
    """Folder of a robot's saved CasADi functions (``<name>.casadi``), generating them on first use.

    Parameters
    ----------
    spec : str
        The canonical tree of the robot (:attr:`dynid.symbolic.robot.RobotModel.spec`).
    """
    key = hashlib.sha256((_generator_key() + spec).encode()).hexdigest()[:20]
    folder = cache_dir() / "robots" / key
    if all((folder / f"{name}.casadi").is_file() for name in FUNCTION_NAMES):
        return folder
    exe = generator_path(progress)
    with file_lock(cache_dir() / "robots" / f"{key}.lock"):
        if all((folder / f"{name}.casadi").is_file() for name in FUNCTION_NAMES):
            return folder
        with atomic_dir(folder) as work:
            (work / "robot.spec").write_text(spec)
            proc = subprocess.run(
                [str(exe), str(work / "robot.spec"), str(work)], capture_output=True, text=True
            )
            if proc.returncode != 0:
                raise GeneratorError(
                    f"the symbolic generator could not build this robot: {proc.stderr.strip()}; "
                    "check the robot description."
                )
    return folder
