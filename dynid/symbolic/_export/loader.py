"""Load a library exported by ``dynid export-c`` and evaluate its functions on batches of states.

Standalone: needs only numpy and the standard library, so this file can be copied next to an
exported library and used without dynid.

>>> lib = CompiledLibrary("ur5_c")                 # the folder written by dynid export-c
>>> Yb = lib.base_regressor(q, dq, ddq)            # q, dq, ddq: (N, n) arrays -> (N, n, n_b)
"""

from __future__ import annotations

import ctypes
import json
import os
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

__all__ = ["CompiledLibrary"]


def _env_threads() -> int | None:
    """``$DYNID_NUM_THREADS`` if it is a whole number of 1 or more, else None (the same rule as
    ``dynid._threads``; this file is copied beside exported libraries, so it imports nothing of dynid)."""
    try:
        value = int(os.environ.get("DYNID_NUM_THREADS", "").strip())
    except ValueError:
        return None
    return value if value >= 1 else None


def _cores() -> int:
    """CPUs this process may run on."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


class CompiledLibrary:
    """The compiled functions of one robot, evaluated on N samples in one C call each.

    Parameters
    ----------
    folder : str or Path
        Folder holding ``manifest.json`` and the shared library it names.
    threads : int, optional
        Threads that share a large batch (ctypes releases the GIL during the C call).  Default:
        ``$DYNID_NUM_THREADS`` (a whole number of 1 or more; any other value is ignored), else the
        CPUs this process may use, at most 8.  Batches under 20,000 samples run on one thread.
    """

    MIN_SAMPLES_PER_THREAD = 10_000

    def __init__(self, folder: str | Path, *, threads: int | None = None) -> None:
        self.folder = Path(folder)
        if threads is None:
            threads = _env_threads() or min(_cores(), 8)
        self.threads = max(1, int(threads))
        manifest_path = self.folder / "manifest.json"
        if not manifest_path.is_file():
            raise FileNotFoundError(
                f"{manifest_path} does not exist; give the folder written by 'dynid export-c'."
            )
        self.manifest = json.loads(manifest_path.read_text())
        self._lib = ctypes.CDLL(str(self.folder / self.manifest["library"]))
        self._functions = {f["name"]: f for f in self.manifest["functions"]}
        for spec in self.manifest["functions"]:
            fn = getattr(self._lib, spec["symbol"] + "_batch")
            fn.argtypes = [
                ctypes.POINTER(ctypes.c_void_p),
                ctypes.POINTER(ctypes.c_void_p),
                ctypes.c_longlong,
            ]
            fn.restype = ctypes.c_int
            spec["_fn"] = fn

    @property
    def functions(self) -> tuple[str, ...]:
        return tuple(self._functions)

    def __getattr__(self, name: str):
        functions = self.__dict__.get("_functions", {})
        if name in functions:
            return lambda *inputs, out=None: self(name, *inputs, out=out)
        raise AttributeError(f"the library has no function {name!r}; it has {', '.join(functions)}")

    def __call__(self, name: str, *inputs, out=None):
        """Evaluate function ``name`` on N samples.

        Each input is an (N, k) array (or (k,) for one sample).  Each output comes as (N, rows, cols),
        or (N, rows) for a column; several outputs come as a tuple.  ``out`` (an array, or a tuple for
        several outputs, C-contiguous float64 of those shapes) receives the result instead of new
        arrays: reusing a buffer saves the allocation, which costs as much as the evaluation for the
        big regressors.
        """
        if name not in self._functions:
            raise KeyError(f"the library has no function {name!r}; it has {', '.join(self._functions)}")
        spec = self._functions[name]
        if len(inputs) != len(spec["inputs"]):
            raise TypeError(
                f"{name} takes {len(spec['inputs'])} inputs ({', '.join(i['name'] for i in spec['inputs'])}); "
                f"{len(inputs)} were given."
            )
        arrays = []
        n_samples = None
        for value, info in zip(inputs, spec["inputs"], strict=True):
            arr = np.ascontiguousarray(value, dtype=np.float64)
            if arr.ndim == 1:
                arr = arr[None, :]
            if arr.ndim != 2 or arr.shape[1] != info["size"]:
                raise ValueError(
                    f"input {info['name']} of {name} has shape {np.shape(value)}; expected (N, {info['size']})."
                )
            if n_samples is None:
                n_samples = arr.shape[0]
            elif arr.shape[0] != n_samples:
                raise ValueError(f"the inputs of {name} have different numbers of samples.")
            arrays.append(arr)
        shapes = [(n_samples, o["rows"], o["cols"]) for o in spec["outputs"]]
        if out is None:
            outs = [np.empty(shape) for shape in shapes]
        else:
            given = list(out) if isinstance(out, (tuple, list)) else [out]
            if len(given) != len(shapes):
                raise ValueError(f"{name} has {len(shapes)} outputs; out holds {len(given)} arrays.")
            outs = []
            for arr, shape in zip(given, shapes, strict=True):
                if (
                    not isinstance(arr, np.ndarray)
                    or arr.dtype != np.float64
                    or not arr.flags.c_contiguous
                    or arr.size != int(np.prod(shape))
                ):
                    raise ValueError(f"out for {name} must be a C-contiguous float64 array of shape {shape}.")
                outs.append(arr.reshape(shape))
        chunks = max(1, min(self.threads, n_samples // self.MIN_SAMPLES_PER_THREAD))
        bounds = np.linspace(0, n_samples, chunks + 1).astype(int)

        def run(lo: int, hi: int) -> int:
            ins = (ctypes.c_void_p * len(arrays))(*(a[lo:].ctypes.data for a in arrays))
            res = (ctypes.c_void_p * len(outs))(*(o[lo:].ctypes.data for o in outs))
            return spec["_fn"](ins, res, hi - lo)

        if chunks == 1:
            statuses = [run(0, n_samples)]
        else:
            with ThreadPoolExecutor(max_workers=chunks) as pool:
                statuses = list(pool.map(run, bounds[:-1], bounds[1:]))
        bad = [s for s in statuses if s != 0]
        if bad:
            raise RuntimeError(f"the compiled {name} failed with status {bad[0]}.")
        outs = [o[:, :, 0] if o.shape[2] == 1 else o for o in outs]
        return outs[0] if len(outs) == 1 else tuple(outs)
