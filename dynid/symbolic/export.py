"""Export a robot's regressors as C source, a header, a compiled shared library and an example.

``dynid export-c --robot ur5 --out ur5_c`` writes::

    ur5_c/
      dynid_ur5.c, dynid_ur5.h          CasADi-generated functions (one sample per call)
      dynid_ur5_batch.c                 ``<fn>_batch``: N samples per call, row-major numpy layout
      libdynid_ur5.so                   both, compiled with the system C compiler
      example.c, Makefile               a short program that evaluates the base regressor once
      manifest.json                     functions, shapes, base parameter names and expressions
      dynid_loader.py                   numpy + ctypes loader (no dynid needed)

The same library, built in dynid's cache, is dynid's fast path for large batches
(:func:`compiled_functions`).
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import subprocess
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path
from typing import Any

import casadi as ca

from dynid._io import atomic_dir, dumps_json
from dynid.exceptions import GeneratorError, UsageError
from dynid.symbolic._export.loader import CompiledLibrary
from dynid.symbolic.base import BaseParameters, base_parameters
from dynid.symbolic.build import Progress, cache_dir, file_lock, find_compiler, full_disk, stderr_progress
from dynid.symbolic.functions import RobotFunctions, robot_functions
from dynid.symbolic.robot import RobotModel

__all__ = ["DEFAULT_EXPORT", "CompiledLibrary", "ExportResult", "compiled_functions", "export_c"]

_HERE = Path(__file__).parent / "_export"

DEFAULT_EXPORT = ("base_regressor", "regressor", "rnea", "friction_columns", "gravity", "fk")
"""Functions exported by default."""


@dataclass(frozen=True)
class ExportResult:
    """Paths written by :func:`export_c`."""

    folder: Path
    source: Path
    header: Path
    batch_source: Path
    library: Path
    example: Path
    manifest: Path
    loader: Path


def c_identifier(name: str) -> str:
    """A valid C identifier made from a robot name (``tx40-mdh`` -> ``tx40_mdh``).

    ASCII letters and digits only, each run of anything else one underscore (CasADi refuses two in a
    row, and C compilers non-ASCII names): ``bras-é`` -> ``bras``, ``we"ird*`` -> ``we_ird``.
    """
    ident = re.sub(r"[^A-Za-z0-9]+", "_", name).strip("_")
    if not ident:
        return "robot"
    return ident if not ident[0].isdigit() else f"r_{ident}"


def _c_text(name: str, *, literal: bool = False) -> str:
    """A robot name safe inside a C comment (no ``*/``), or with ``literal`` inside a printf format string."""
    text = re.sub(r"[\x00-\x1f\x7f]", " ", name).replace("*/", "* /")
    if literal:
        text = text.replace("\\", "\\\\").replace('"', '\\"').replace("%", "%%").replace("??", "?\\?")
    return text


def _functions_to_export(funcs: RobotFunctions, base: BaseParameters, names) -> list[ca.Function]:
    available = {
        "base_regressor": base.base_regressor,
        "regressor": funcs.regressor,
        "rnea": funcs.rnea,
        "gravity": funcs.gravity,
        "mass_matrix": funcs.mass_matrix,
        "aba": funcs.aba,
        "fk": funcs.fk,
        "friction_columns": funcs.friction_columns,
        "armature_columns": funcs.armature_columns,
    }
    unknown = [n for n in names if n not in available]
    if unknown:
        raise UsageError(
            f"cannot export {', '.join(unknown)}; the exportable functions are {', '.join(available)}."
        )
    return [available[n] for n in names]


def _renamed(f: ca.Function, name: str) -> tuple[ca.Function, list[tuple[int, int]]]:
    """The same function under another name, for C: dense outputs stored row-major.

    CasADi stores a matrix column by column; the exported function returns the transpose, whose
    column-major storage is the row-major (C and numpy) storage of the matrix itself.  The batch
    entry point then writes every sample straight into the caller's array, with no copy.
    Returns the function and the (rows, cols) of each original output.
    """
    args = f.sx_in()
    outs = f.call(args)
    shapes = [(int(o.size1()), int(o.size2())) for o in outs]
    dense = [ca.densify(o.T) for o in outs]
    return ca.Function(name, args, dense, f.name_in(), f.name_out(), {"cse": True}), shapes


def _write_sources(
    folder: Path, robot: RobotModel, functions: list[tuple[str, ca.Function]]
) -> tuple[str, list[dict]]:
    """Generate C for the named functions into ``folder``; return the file stem and the manifest entries."""
    prefix = c_identifier(robot.name)
    stem = f"dynid_{prefix}"
    gen = ca.CodeGenerator(f"{stem}.c", {"with_header": True})
    entries = []
    wrappers = []
    for name, f in functions:
        symbol = f"{prefix}_{name}"
        g, shapes = _renamed(f, symbol)
        gen.add(g)
        entries.append(
            {
                "name": name,
                "symbol": symbol,
                "inputs": [{"name": g.name_in(i), "size": g.numel_in(i)} for i in range(g.n_in())],
                "outputs": [
                    {"name": g.name_out(i), "rows": rows, "cols": cols}
                    for i, (rows, cols) in enumerate(shapes)
                ],
            }
        )
        wrappers.append(
            f"\nint {symbol}_batch(const double* const* in, double* const* out, long long n) {{\n"
            f"  return dynid_batch({symbol}, {symbol}_work, {symbol}_sparsity_in, {symbol}_sparsity_out,\n"
            f"                     {g.n_in()}, {g.n_out()}, in, out, n);\n}}\n"
        )
    gen.generate(str(folder) + os.sep)
    batch = (
        (_HERE / "batch.c")
        .read_text()
        .replace("@HEADER@", f"{stem}.h")
        .replace("@WRAPPERS@", "".join(wrappers))
    )
    (folder / f"{stem}_batch.c").write_text(batch)
    # Declare the batch functions in the header too.
    header = folder / f"{stem}.h"
    decls = "".join(
        f"int {e['symbol']}_batch(const double* const* in, double* const* out, long long n);\n"
        for e in entries
    )
    text = header.read_text()
    marker = '#ifdef __cplusplus\n} /* extern "C" */'
    text = (
        text.replace(
            marker,
            "/* N samples per call, row-major (N, k) inputs and (N, rows, cols) outputs. */\n"
            + decls
            + "\n"
            + marker,
        )
        if marker in text
        else text + decls
    )
    header.write_text(text)
    return stem, entries


def _compile(folder: Path, stem: str, progress: Progress | None) -> Path:
    cc = find_compiler("c")
    lib = folder / f"lib{stem}.so"
    tmp = folder / f"lib{stem}.so.tmp{os.getpid()}"
    cmd = [cc, "-O3", "-fPIC", "-shared", f"{stem}.c", f"{stem}_batch.c", "-o", tmp.name, "-lm"]
    if progress:
        progress(f"dynid: compiling {lib.name} with {Path(cc).name}...")
    proc = subprocess.run(cmd, cwd=folder, capture_output=True, text=True, check=False)
    if proc.returncode != 0:
        tmp.unlink(missing_ok=True)
        full = full_disk(f"compiling {lib.name}", folder)
        if full is not None:
            raise full
        tail = "\n".join(proc.stderr.strip().splitlines()[-10:])
        raise GeneratorError(f"the C compiler failed on {stem}.c (exit {proc.returncode}):\n{tail}")
    os.replace(tmp, lib)
    return lib


def _example(stem: str, prefix: str, robot: RobotModel, entry: dict, label: str) -> tuple[str, str]:
    """example.c (evaluate the function of ``entry``, of inputs q, dq, ddq, at one state and print it) and
    its Makefile."""
    n = robot.n
    name = entry["name"]
    rows, cols = entry["outputs"][0]["rows"], entry["outputs"][0]["cols"]
    var = re.sub(r"\W", "", label) or "out"
    example = f"""/* Evaluate {name} of {_c_text(robot.name)} at one state and print it.
 * Build: make   (or: cc -O2 example.c {stem}.c -o example -lm)   Run: ./example */
#include <stdio.h>

#include "{stem}.h"

int main(void) {{
  double q[{n}], dq[{n}], ddq[{n}];
  double {var}[{rows} * {cols}]; /* row-major (C order): {rows} rows x {cols} columns */
  const casadi_real* arg[{prefix}_{name}_SZ_ARG];
  casadi_real* res[{prefix}_{name}_SZ_RES];
  casadi_int iw[{prefix}_{name}_SZ_IW + 1];
  casadi_real w[{prefix}_{name}_SZ_W + 1];
  int i, j;
  for (i = 0; i < {n}; ++i) {{
    q[i] = 0.1 * (i + 1);
    dq[i] = 0.2;
    ddq[i] = -0.3;
  }}
  arg[0] = q;
  arg[1] = dq;
  arg[2] = ddq;
  res[0] = {var};
  if ({prefix}_{name}(arg, res, iw, w, 0)) return 1;
  printf("{label} of {_c_text(robot.name, literal=True)} ({rows} x {cols}) at q_i = 0.1 i, dq = 0.2, ddq = -0.3:\\n");
  for (i = 0; i < {rows}; ++i) {{
    for (j = 0; j < {cols}; ++j) printf("% .6e ", {var}[i * {cols} + j]);
    printf("\\n");
  }}
  return 0;
}}
"""
    makefile = f"""CC ?= cc
CFLAGS ?= -O2

example: example.c {stem}.c {stem}.h
\t$(CC) $(CFLAGS) example.c {stem}.c -o example -lm

clean:
\trm -f example
"""
    return example, makefile


def _manifest(robot: RobotModel, base: BaseParameters, stem: str, entries: list[dict]) -> dict:
    return {
        "robot": robot.name,
        "robot_key": robot.key,
        "n": robot.n,
        "joint_names": list(robot.joint_names),
        "library": f"lib{stem}.so",
        "casadi": metadata.version("casadi"),
        "pin": metadata.version("pin"),
        "base_parameters": {
            "names": list(base.names),
            "expressions": list(base.expressions),
            "gravity_related": [bool(g) for g in base.gravity_related],
            "independent": [int(i) for i in base.independent],
        },
        "functions": entries,
    }


def export_c(
    robot: RobotModel,
    out: str | Path,
    *,
    functions=DEFAULT_EXPORT,
    extra: Sequence[ca.Function] = (),
    manifest: dict[str, Any] | None = None,
    example: str = "base_regressor",
    check: Callable[[Path], dict[str, Any]] | None = None,
    progress: Progress | None = stderr_progress,
) -> ExportResult:
    """Write C source, header, shared library, example and loader for ``robot`` into ``out``.

    The folder is written in a temporary sibling and moved into place at the end, so a failure
    (of the compiler, of ``check``) leaves nothing half written.

    Parameters
    ----------
    robot : RobotModel
        The robot.
    out : str or Path
        The folder to write (its parent must exist; an existing folder is replaced).
    functions : sequence of str
        Names of the robot's functions to export (:data:`DEFAULT_EXPORT`).
    extra : sequence of casadi.Function
        Further functions exported first, each under its CasADi name, with its named inputs and outputs
        (an identified model's prediction: :func:`dynid.identify.export_c.export_model_c`).
    manifest : dict, optional
        Entries added to ``manifest.json``.
    example : str
        The function, of inputs ``(q, dq, ddq)``, that ``example.c`` evaluates and prints (no example when it
        is not exported).
    check : callable, optional
        ``check(folder) -> dict``, called on the written and compiled folder before it is moved into place;
        what it returns is stored as ``check`` in ``manifest.json``; an error it raises leaves nothing written.
    progress : callable, optional
        Receives progress messages.
    """
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise GeneratorError(f"'{out}' exists and is not a folder; give a folder path for the export.")
    if not out.parent.exists():
        raise GeneratorError(f"the folder '{out.parent}' does not exist; create it or choose another --out.")
    funcs = robot_functions(robot, progress=progress)
    base = base_parameters(funcs)
    names = tuple(functions)
    named = [(f.name(), f) for f in extra] + list(
        zip(names, _functions_to_export(funcs, base, names), strict=True)
    )
    seen = [name for name, _ in named]
    twice = sorted({name for name in seen if seen.count(name) > 1})
    if twice:
        raise UsageError(f"the functions {', '.join(twice)} are named twice; export each function once.")
    with atomic_dir(out) as work:
        stem, entries = _write_sources(work, robot, named)
        _compile(work, stem, progress)
        shown = next((e for e in entries if e["name"] == example), None)
        if shown is not None and [i["name"] for i in shown["inputs"]] == ["q", "dq", "ddq"]:
            label = "Y_b" if example == "base_regressor" else example
            text, makefile = _example(stem, c_identifier(robot.name), robot, shown, label)
            (work / "example.c").write_text(text)
            (work / "Makefile").write_text(makefile)
        shutil.copyfile(_HERE / "loader.py", work / "dynid_loader.py")
        document = {**_manifest(robot, base, stem, entries), **(manifest or {})}
        # every file of the folder, so that a later export replaces only what dynid wrote
        document["files"] = sorted([*(p.name for p in work.iterdir()), "manifest.json"])
        (work / "manifest.json").write_text(dumps_json(document))
        if check is not None:
            document["check"] = check(work)
            (work / "manifest.json").write_text(dumps_json(document))
    return ExportResult(
        folder=out,
        source=out / f"{stem}.c",
        header=out / f"{stem}.h",
        batch_source=out / f"{stem}_batch.c",
        library=out / f"lib{stem}.so",
        example=out / "example.c",
        manifest=out / "manifest.json",
        loader=out / "dynid_loader.py",
    )


_COMPILED: dict[str, CompiledLibrary] = {}


def compiled_functions(
    robot: RobotModel, *, functions=DEFAULT_EXPORT, progress: Progress | None = stderr_progress
) -> CompiledLibrary:
    """The robot's functions compiled to C in dynid's cache (built once per robot), for fast batches.

    >>> lib = compiled_functions(load_robot("ur5"))
    >>> lib.base_regressor(q, dq, ddq).shape        # (N, 6, 36)
    """
    funcs = robot_functions(robot, progress=progress)
    base = base_parameters(funcs)
    digest = hashlib.sha256(
        "|".join(
            [
                funcs.folder.name,
                ",".join(functions),
                ",".join(map(str, base.independent)),
                metadata.version("casadi"),
            ]
        ).encode()
        + (_HERE / "batch.c").read_bytes()
        # the functions built at run time (friction_columns' rest rule): a change to them is a new library
        + (Path(__file__).with_name("functions.py")).read_bytes()
    ).hexdigest()[:20]
    if digest in _COMPILED:
        return _COMPILED[digest]
    folder = cache_dir() / "compiled" / digest
    if _cache_damage(folder) is not None:
        with file_lock(cache_dir() / "compiled" / f"{digest}.lock"):
            damage = _cache_damage(folder)
            if damage is not None:
                if damage:
                    _say_rebuilt(folder, damage)
                export_c(robot, folder, functions=functions, progress=progress)
    try:
        lib = CompiledLibrary(folder)
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as exc:  # what the check cannot see
        with file_lock(cache_dir() / "compiled" / f"{digest}.lock"):
            _say_rebuilt(folder, f"it could not be loaded: {' '.join(str(exc).split())[:160]}")
            export_c(robot, folder, functions=functions, progress=progress)
        lib = CompiledLibrary(folder)
    _COMPILED[digest] = lib
    return lib


def _say_rebuilt(folder: Path, damage: str) -> None:
    import warnings

    from dynid.exceptions import CacheWarning

    warnings.warn(
        f"the compiled library cached in {folder} was damaged ({damage}); it was built again",
        CacheWarning,
        stacklevel=3,
    )


def _cache_damage(folder: Path) -> str | None:
    """None when a cached build looks whole; ``""`` when there is none; else what is wrong with it.

    A truncated shared library still loads (the loader maps it), then kills the process with SIGBUS when
    code past the end is run: its size is checked against what its ELF headers say it holds.
    """
    manifest_path = folder / "manifest.json"
    if not manifest_path.is_file():
        return ""
    try:
        manifest = json.loads(manifest_path.read_text())
        library = folder / manifest["library"]
        if not isinstance(manifest["functions"], list):
            return "its manifest.json lists no functions"
        data = library.read_bytes()
    except (OSError, ValueError, KeyError, TypeError) as exc:
        return f"its manifest.json or library cannot be read: {type(exc).__name__}"
    return _elf_damage(data, library.name)


def _elf_damage(data: bytes, name: str) -> str | None:
    """None when ``data`` is a whole 64-bit little-endian ELF file, else what is wrong with it."""
    import struct

    if len(data) < 64 or data[:4] != b"\x7fELF":
        return f"{name} is not a shared library ({len(data)} bytes)"
    if data[4] != 2 or data[5] != 1:  # not ELF64 little-endian: not what dynid builds here
        return None
    phoff, shoff = struct.unpack_from("<QQ", data, 0x20)
    phentsize, phnum, shentsize, shnum = struct.unpack_from("<HHHH", data, 0x36)
    need = max(phoff + phentsize * phnum, shoff + shentsize * shnum)
    if need > len(data):
        return f"{name} holds {len(data)} bytes, its headers say at least {need}: it was cut short"
    for k in range(phnum):
        p_type, _, p_offset, _, _, p_filesz = struct.unpack_from("<IIQQQQ", data, phoff + k * phentsize)
        if p_type == 1 and p_offset + p_filesz > len(data):  # PT_LOAD past the end
            end = p_offset + p_filesz
            return f"{name} holds {len(data)} bytes, a segment ends at {end}: it was cut short"
    return None
