"""Files and JSON for every part of dynid: one atomic writer, one JSON cleaner.

Every file dynid writes goes through :func:`atomic_path` (or its shorthands :func:`write_text`,
:func:`write_bytes`, :func:`write_json`): the content goes to a temporary file in the target folder,
is flushed to disk, gets the mode a plain ``open()`` would give it (an existing file's own mode, else
``0666`` less the umask; not ``mkstemp``'s private ``0600``), and replaces the target in one
:func:`os.replace`.  An interrupted or failed write leaves no partial file, no stray temporary file,
and an older file intact.  :func:`atomic_dir` does the same for a whole folder.

Every JSON document goes through :func:`to_jsonable`: arrays to lists, numpy scalars to Python
numbers, paths to text, non-finite floats to ``null`` (JSON has no NaN).
"""

from __future__ import annotations

import contextlib
import glob
import json
import math
import os
import re
import shutil
import tempfile
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "atomic_dir",
    "atomic_path",
    "dumps_json",
    "file_mode",
    "jsonable",
    "to_jsonable",
    "write_bytes",
    "write_json",
    "write_text",
    "write_together",
]


# ---------------------------------------------------------------------------- JSON
def to_jsonable(value: Any) -> Any:
    """A JSON-ready copy of ``value``: arrays to lists, numpy scalars to numbers, paths to text,
    non-finite floats to None, mapping keys to text, tuples to lists.

    Parameters
    ----------
    value : Any
        Figures: mappings, sequences, numbers, arrays, paths.
    """
    if isinstance(value, Mapping):
        return {str(k): to_jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [to_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return to_jsonable(value.tolist())
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def jsonable(value: Any) -> Any:
    """The ``default`` of :func:`json.dumps` for what it cannot write: arrays, numpy scalars, paths.

    Parameters
    ----------
    value : Any
        What :func:`json.dumps` met and could not write.

    Raises
    ------
    TypeError
        Anything else, as :func:`json.dumps` expects of its ``default``.
    """
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    raise TypeError(f"{type(value).__name__} is not JSON serialisable")


def dumps_json(value: Any, *, indent: int | None = 2, default: Callable[[Any], Any] | None = None) -> str:
    """``value`` as strict JSON text (cleaned by :func:`to_jsonable`), ending in a newline.

    Parameters
    ----------
    value : Any
        Figures: mappings, sequences, numbers, arrays, paths.
    indent : int or None
        Indentation of nested values; None writes one line.
    default : callable, optional
        What to write for a value nothing above knows (e.g. ``str``: its text); default
        :func:`jsonable`, which raises :class:`TypeError`.
    """
    text = json.dumps(to_jsonable(value), indent=indent, default=default or jsonable, allow_nan=False)
    return text + "\n"


# ---------------------------------------------------------------------------- atomic files
def file_mode(path: str | os.PathLike[str]) -> int:
    """Mode for a file written at ``path``: the existing file's own, else ``0666`` less the umask."""
    path = Path(path)
    if path.is_file():
        return path.stat().st_mode & 0o777
    return 0o666 & ~_umask()


def _umask() -> int:
    umask = os.umask(0)
    os.umask(umask)
    return umask


def _remove_orphans(path: Path) -> None:
    """Remove the temporary folders of ``path`` that a killed run left: those named by a process that is gone.

    :func:`atomic_dir` names its temporary folder ``.NAME.PID.XXXX.tmp``; one whose process still runs
    (a concurrent run writing the same folder) is left alone.
    """
    for stale in path.parent.glob(f".{glob.escape(path.name)}.*.tmp"):
        named = re.fullmatch(r"(\d+)\.[^.]+\.tmp", stale.name[len(path.name) + 2 :])
        if named is None or not stale.is_dir() or stale.is_symlink():
            continue
        try:
            os.kill(int(named[1]), 0)
        except ProcessLookupError:
            shutil.rmtree(stale, ignore_errors=True)
        except OSError:  # another user's process: alive
            continue


def _check_folder(path: Path) -> None:
    if not path.parent.is_dir():
        raise FileNotFoundError(f"the folder '{path.parent}' does not exist; create it or write elsewhere.")


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """A temporary path beside ``path`` that replaces ``path`` when the block ends without error.

    Write the content to the yielded path in any way (``np.savez``, ``open``, a compiler's ``-o``); on
    leaving the block it is flushed to disk, given :func:`file_mode` and renamed onto ``path`` in one
    step.  On an error (or an interrupt) it is removed and ``path`` is left as it was.

    Parameters
    ----------
    path : str or path-like
        The file to write; its folder must exist.

    Yields
    ------
    Path
        The temporary file (created empty, in ``path``'s folder, named ``.NAME.XXXX.tmp``).

    Raises
    ------
    FileNotFoundError
        If the folder of ``path`` does not exist (nothing is written).
    """
    path = Path(path)
    _check_folder(path)
    fd, tmp_name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        yield tmp
        with open(tmp, "rb+") as handle:
            os.fsync(handle.fileno())
        os.chmod(tmp, file_mode(path))
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def write_bytes(path: str | os.PathLike[str], data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (see :func:`atomic_path`); returns the path."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def write_text(path: str | os.PathLike[str], text: str) -> Path:
    """Write ``text`` (UTF-8, ``\\n`` line ends) to ``path`` atomically; returns the path."""
    return write_bytes(path, text.encode("utf-8"))


def write_json(path: str | os.PathLike[str], value: Any) -> Path:
    """Write ``value`` as strict, indented JSON (see :func:`dumps_json`) to ``path`` atomically."""
    return write_text(path, dumps_json(value))


def write_together(writers: Sequence[tuple[str | os.PathLike[str], Callable[[Path], object]]]) -> None:
    """Write several files so that they replace the old ones together or not at all.

    Each writer writes its file's content to the temporary path it is given; only when every one has
    succeeded are the files renamed onto their paths (renames need no space: a full disk stops the
    writes, never the renames).  On an error or an interrupt every temporary file is removed and every
    old file stands.

    Parameters
    ----------
    writers : sequence of (path, write)
        ``write(tmp)`` writes the content of ``path`` to the temporary path ``tmp``.
    """
    with contextlib.ExitStack() as stack:
        for path, write in writers:
            write(stack.enter_context(atomic_path(path)))


@contextlib.contextmanager
def atomic_dir(path: str | os.PathLike[str]) -> Iterator[Path]:
    """A temporary folder beside ``path`` that replaces the folder ``path`` when the block ends without error.

    Write the folder's files into the yielded folder; on leaving the block an older ``path`` is
    removed and the new folder renamed onto it.  On an error (or an interrupt) the temporary folder
    is removed and ``path`` is left as it was.

    Parameters
    ----------
    path : str or path-like
        The folder to write; its parent must exist.

    Yields
    ------
    Path
        The temporary folder (created empty with the mode a plain ``mkdir`` gives, beside ``path``, named
        ``.NAME.PID.XXXX.tmp``; such folders of a run that was killed are removed by the next one).

    Raises
    ------
    FileNotFoundError
        If the parent folder of ``path`` does not exist (nothing is written).
    """
    path = Path(path)
    _check_folder(path)
    cwd, target = os.path.realpath(Path.cwd()), os.path.realpath(path)
    if cwd == target or cwd.startswith(target.rstrip(os.sep) + os.sep):
        raise ValueError(f"the folder '{path}' holds the current folder and cannot be replaced; write elsewhere.")
    _remove_orphans(path)
    work = Path(tempfile.mkdtemp(dir=path.parent, prefix=f".{path.name}.{os.getpid()}.", suffix=".tmp"))
    try:
        os.chmod(work, 0o777 & ~_umask())  # the mode a plain mkdir gives, not mkdtemp's private 0700
        yield work
        if path.exists():
            shutil.rmtree(path)
        os.replace(work, path)
    finally:
        if work.exists():
            shutil.rmtree(work, ignore_errors=True)
