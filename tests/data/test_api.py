"""Meta-tests of the public API of dynid.data's modules: every argument is documented."""

from __future__ import annotations

import inspect
import re
from collections.abc import Callable
from types import ModuleType
from typing import Any

import pytest

from dynid.data import adapters, dataset, files, preprocess, rosbag

MODULES = (dataset, files, rosbag, preprocess, adapters)


def documented_parameters(obj: Any) -> set[str]:
    """Names listed in the numpydoc 'Parameters' section of ``obj``'s docstring."""
    doc = inspect.getdoc(obj) or ""
    match = re.search(r"^Parameters\n-+\n(.*?)(?:\n\n[A-Z][a-z]+\n-+\n|\Z)", doc, flags=re.S | re.M)
    if match is None:
        return set()
    names: set[str] = set()
    for line in match.group(1).splitlines():
        if line and not line.startswith(" ") and " : " in line:
            names.update(name.strip() for name in line.split(" : ")[0].split(","))
    return names


def public_callables(module: ModuleType) -> list[tuple[str, Callable[..., Any]]]:
    out = []
    for name in module.__all__:
        obj = getattr(module, name)
        if inspect.isfunction(obj):
            out.append((f"{module.__name__}.{name}", obj))
        elif inspect.isclass(obj):
            out.append((f"{module.__name__}.{name}", obj))
            for attr, member in vars(obj).items():
                func = member.__func__ if isinstance(member, classmethod) else member
                if inspect.isfunction(func) and not attr.startswith("_"):
                    out.append((f"{module.__name__}.{name}.{attr}", func))
    return out


CASES = [case for module in MODULES for case in public_callables(module)]


@pytest.mark.parametrize(("name", "obj"), CASES, ids=[name for name, _ in CASES])
def test_every_argument_is_documented(name: str, obj: Callable[..., Any]) -> None:
    target = obj.__init__ if inspect.isclass(obj) else obj  # type: ignore[misc]
    if inspect.isclass(obj) and target is object.__init__:
        pytest.skip(f"{name} takes no arguments")
    wanted = {
        p.name
        for p in inspect.signature(target).parameters.values()
        if p.name not in ("self", "cls", "_") and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)
    }
    missing = wanted - documented_parameters(obj)
    assert not missing, f"{name} does not document {sorted(missing)}"


def test_every_module_lists_its_public_names() -> None:
    for module in MODULES:
        for name in module.__all__:
            assert hasattr(module, name), f"{module.__name__}.__all__ names {name}, which does not exist"
