"""Load a library exported by ``dynid export-c`` and evaluate its functions on batches of states.

Standalone: needs only numpy and the standard library, so this file can be copied next to an
exported library and used without dynid.

>>> lib = CompiledLibrary("ur5_c")                 # the folder written by dynid export-c
>>> Yb = lib.base_regressor(q, dq, ddq)            # q, dq, ddq: (N, n) arrays -> (N, n, n_b)
"""

from __future__ import annotations

import ctypes
import json
from pathlib import Path

import numpy as np

__all__ = ["CompiledLibrary"]


class CompiledLibrary:
    """The compiled functions of one robot, evaluated on N samples in one C call each.

    Parameters
    ----------
    folder : str or Path
        Folder holding ``manifest.json`` and the shared library it names.
    """

    def __init__(self, folder: str | Path) -> None:
        self.folder = Path(folder)
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
            return lambda *inputs: self(name, *inputs)
        raise AttributeError(f"the library has no function {name!r}; it has {', '.join(functions)}")

    def __call__(self, name: str, *inputs):
        """Evaluate function ``name`` on N samples.

        Each input is an (N, k) array (or (k,) for one sample).  Each output comes as (N, rows, cols),
        or (N, rows) for a column; several outputs come as a tuple.
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
        outs = [np.empty((n_samples, o["rows"], o["cols"])) for o in spec["outputs"]]
        in_ptr = (ctypes.c_void_p * len(arrays))(*(a.ctypes.data for a in arrays))
        out_ptr = (ctypes.c_void_p * len(outs))(*(o.ctypes.data for o in outs))
        status = spec["_fn"](in_ptr, out_ptr, n_samples)
        if status != 0:
            raise RuntimeError(f"the compiled {name} failed with status {status}.")
        outs = [o[:, :, 0] if o.shape[2] == 1 else o for o in outs]
        return outs[0] if len(outs) == 1 else tuple(outs)
