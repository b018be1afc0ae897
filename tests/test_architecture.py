"""The package's structure, read from the source (nothing is imported).

* Layers import one way: symbolic <- optim <- data <- identify <- sim <- validation <- simmodel <- diagnosis <-
  fleet <- commands.
  The bottom holds ``dynid._io``, ``dynid._threads``, ``dynid.exceptions`` and any other top-level helper; the top
  holds ``dynid.cli``, the package's face ``dynid/__init__.py`` and the demo's library module, which
  sits beside the commands.
* No module imports :mod:`dynid.cli`.
* Modules import each other without a circle (a package's face, which imports its modules on demand,
  aside).
* No module uses another module's private name (``from dynid.x import _y``, ``dynid_module._y``).
  A private module (``dynid.symbolic._export``) belongs to its package: modules of that package may
  import it; ``dynid._io`` and ``dynid._threads`` are private to ``dynid`` and so open to every module.
* Every module has a docstring and an ``__all__``.

Imports inside functions and under ``TYPE_CHECKING`` count like any other: a lazy import of a higher
layer is still a dependency on it.
"""

from __future__ import annotations

import ast
import graphlib
import pkgutil
from dataclasses import dataclass
from pathlib import Path

import pytest

import dynid

PACKAGE = Path(dynid.__file__).resolve().parent

# The layers, lowest first.  A module may import modules of its own layer or of lower ones.
LAYERS = (
    "symbolic",
    "optim",
    "data",
    "identify",
    "sim",
    "validation",
    "simmodel",
    "diagnosis",
    "fleet",
    "commands",
)
BOTTOM = -1  # dynid._io, dynid.exceptions, other top-level helpers
TOP = len(LAYERS)  # dynid.cli and the package's face
# Top-level modules that are not helpers: their layer.
TOP_LEVEL = {"cli": TOP, "__main__": TOP, "demo": LAYERS.index("commands")}


def _module_files() -> dict[str, Path]:
    """Every module of dynid, by dotted name, from the source tree (pkgutil, no import)."""
    modules = {"dynid": PACKAGE / "__init__.py"}

    def walk(path: Path, prefix: str) -> None:
        for info in pkgutil.iter_modules([str(path)]):
            name = f"{prefix}.{info.name}"
            if info.ispkg:
                modules[name] = path / info.name / "__init__.py"
                walk(path / info.name, name)
            else:
                modules[name] = path / f"{info.name}.py"

    walk(PACKAGE, "dynid")
    return modules


MODULES = _module_files()
PACKAGES = {name for name, path in MODULES.items() if path.name == "__init__.py"}


def layer(module: str) -> int:
    """The layer of a dynid module (``dynid`` itself: the top, as the importer of everything)."""
    parts = module.split(".")
    if len(parts) == 1:
        return TOP
    head = parts[1]
    if head in LAYERS:
        return LAYERS.index(head)
    return TOP_LEVEL.get(head, BOTTOM)


def layer_name(rank: int) -> str:
    return "bottom" if rank == BOTTOM else "top" if rank == TOP else LAYERS[rank]


def _package_of(module: str) -> str:
    return module if module in PACKAGES else module.rpartition(".")[0]


def _resolve_relative(module: str, level: int, name: str | None) -> str:
    base = _package_of(module).split(".")
    base = base[: len(base) - (level - 1)]
    return ".".join([*base, name] if name else base)


@dataclass(frozen=True)
class Import:
    """One import of a dynid module: the module imported, the names taken from it, the line."""

    target: str
    names: tuple[str, ...]
    line: int


def _imports(module: str, tree: ast.AST) -> list[Import]:
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [Import(a.name, (), node.lineno) for a in node.names if a.name.split(".")[0] == "dynid"]
        elif isinstance(node, ast.ImportFrom):
            target = _resolve_relative(module, node.level, node.module) if node.level else (node.module or "")
            if target.split(".")[0] == "dynid":
                found.append(Import(target, tuple(a.name for a in node.names), node.lineno))
        elif (
            isinstance(node, ast.Call)
            and isinstance(node.func, ast.Attribute | ast.Name)
            and (node.func.attr if isinstance(node.func, ast.Attribute) else node.func.id) == "import_module"
            and node.args
            and isinstance(node.args[0], ast.Constant)
            and isinstance(node.args[0].value, str)
            and node.args[0].value.startswith("dynid")
        ):
            found.append(Import(node.args[0].value, (), node.lineno))
    return found


def _private_allowed(importer: str, private_module: str) -> bool:
    """A private module belongs to its package: the package's own modules may import it."""
    owner = private_module.rpartition(".")[0]
    return importer == owner or importer.startswith(owner + ".")


def _private_parts(dotted: str) -> list[int]:
    return [
        i for i, part in enumerate(dotted.split(".")) if part.startswith("_") and not part.startswith("__")
    ]


def _check_private_module(importer: str, target: str) -> str | None:
    """A private component in an imported module's path that the importer may not reach."""
    parts = target.split(".")
    for i in _private_parts(target):
        private = ".".join(parts[: i + 1])
        if not _private_allowed(importer, private):
            return private
    return None


def _dotted(node: ast.expr) -> list[str] | None:
    """``a.b.c`` as ``['a', 'b', 'c']``; None for anything that is not a plain attribute chain."""
    parts = []
    while isinstance(node, ast.Attribute):
        parts.append(node.attr)
        node = node.value
    if not isinstance(node, ast.Name):
        return None
    return [node.id, *reversed(parts)]


def _violations(module: str, path: Path) -> dict[str, list[str]]:
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    out: dict[str, list[str]] = {"layers": [], "cli": [], "private": []}
    here = f"{module} ({path.relative_to(PACKAGE.parent) if path.is_relative_to(PACKAGE.parent) else path})"
    bound: dict[str, str] = {}  # local name -> dynid module it is bound to
    for imp in _imports(module, tree):
        targets = [imp.target]
        # `from dynid.x import y`: y may itself be a module
        targets += [f"{imp.target}.{n}" for n in imp.names if f"{imp.target}.{n}" in MODULES]
        for target in targets:
            if target == "dynid.cli" or target.startswith("dynid.cli."):
                if module not in ("dynid.cli", "dynid.__main__"):  # ``python -m dynid`` runs the cli
                    out["cli"].append(f"{here}:{imp.line} imports dynid.cli")
            elif layer(target) > layer(module) and target != "dynid":
                out["layers"].append(
                    f"{here}:{imp.line} ({layer_name(layer(module))}) imports {target} "
                    f"({layer_name(layer(target))})"
                )
            private = _check_private_module(module, target)
            if private is not None:
                out["private"].append(f"{here}:{imp.line} imports the private module {private}")
        for name in imp.names:
            full = f"{imp.target}.{name}"
            if name.startswith("_") and not name.startswith("__") and full not in MODULES:
                out["private"].append(f"{here}:{imp.line} imports the private name {full}")
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                if a.name.split(".")[0] == "dynid":
                    if a.asname:
                        bound[a.asname] = a.name
                    else:
                        bound[a.name.split(".")[0]] = "dynid"
        elif isinstance(node, ast.ImportFrom):
            target = _resolve_relative(module, node.level, node.module) if node.level else (node.module or "")
            for a in node.names:
                if f"{target}.{a.name}" in MODULES:
                    bound[a.asname or a.name] = f"{target}.{a.name}"
    for node in ast.walk(tree):
        if not isinstance(node, ast.Attribute):
            continue
        chain = _dotted(node)
        if chain is None or chain[0] not in bound:
            continue
        resolved = bound[chain[0]].split(".")
        rest = chain[1:]
        # follow submodules, then the first attribute of the last module is the name used
        while rest and ".".join([*resolved, rest[0]]) in MODULES:
            resolved.append(rest.pop(0))
        if rest and rest[0].startswith("_") and not rest[0].startswith("__"):
            name = ".".join([*resolved, rest[0]])
            if ".".join(resolved) != module:
                out["private"].append(f"{here}:{node.lineno} uses the private name {name}")
    for key in out:
        out[key] = sorted(set(out[key]))
    return out


@pytest.fixture(scope="module")
def violations() -> dict[str, list[str]]:
    found: dict[str, list[str]] = {"layers": [], "cli": [], "private": []}
    for module, path in sorted(MODULES.items()):
        for key, items in _violations(module, path).items():
            found[key] += items
    return found


def test_the_walk_finds_every_layer():
    """The checks below see the whole package, so an empty list of violations means something."""
    assert len(MODULES) > 40
    for name in LAYERS:
        assert f"dynid.{name}" in PACKAGES, name
    assert {"dynid._io", "dynid.exceptions", "dynid.cli"} <= MODULES.keys()
    assert layer("dynid.symbolic.robot") < layer("dynid.optim.excitation") < layer("dynid.data.dataset")
    assert layer("dynid.data.dataset") < layer("dynid.identify.model")
    assert layer("dynid.identify.model") < layer("dynid.sim.simulator") < layer("dynid.validation.validate")
    assert layer("dynid.validation.validate") < layer("dynid.diagnosis.core") < layer("dynid.commands.demo")
    assert layer("dynid.validation.validate") < layer("dynid.simmodel.export") < layer("dynid.diagnosis.core")
    assert layer("dynid.diagnosis.core") < layer("dynid.fleet.core") < layer("dynid.commands.fleet")
    assert layer("dynid._io") < layer("dynid.symbolic.robot") and layer("dynid.commands.demo") < layer(
        "dynid.cli"
    )


def test_the_checks_catch_what_they_forbid(tmp_path):
    """Each rule fires on a module written to break it."""
    bad = tmp_path / "bad.py"
    bad.write_text(
        '"""A module that breaks every rule."""\n'
        "import dynid.identify.model as m\n"
        "from dynid.cli import main\n"
        "from dynid.validation.metrics import _private\n"
        "import dynid.symbolic._export.loader\n"
        "from dynid.identify import _helper\n"
        "def f():\n"
        "    from dynid.diagnosis import core\n"
        "    return m._hidden, core.diagnose\n"
    )
    found = _violations("dynid.optim.bad", bad)
    assert any("imports dynid.identify.model (identify)" in v for v in found["layers"])
    assert any("imports dynid.diagnosis.core (diagnosis)" in v for v in found["layers"])
    assert any("imports dynid.cli" in v for v in found["cli"])
    assert any("private name dynid.validation.metrics._private" in v for v in found["private"])
    assert any("private module dynid.symbolic._export" in v for v in found["private"])
    assert any("private name dynid.identify._helper" in v for v in found["private"])
    assert any("uses the private name dynid.identify.model._hidden" in v for v in found["private"])
    good = tmp_path / "good.py"
    good.write_text(
        '"""A module that keeps them."""\n'
        "from dynid._io import write_json\n"
        "from dynid.exceptions import DataError\n"
        "from dynid.symbolic.robot import load_robot\n"
        "from dynid.symbolic._export import loader\n"
    )
    assert _violations("dynid.symbolic.good", good) == {"layers": [], "cli": [], "private": []}


def test_layers_import_one_way(violations):
    assert violations["layers"] == []


def test_modules_import_without_a_circle():
    graph = {}
    for module, path in MODULES.items():
        if module in PACKAGES:
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"))
        targets = {
            target
            for imp in _imports(module, tree)
            for target in [imp.target, *(f"{imp.target}.{n}" for n in imp.names)]
            if target in MODULES and target not in PACKAGES and target != module
        }
        graph[module] = targets
    try:
        tuple(graphlib.TopologicalSorter(graph).static_order())
    except graphlib.CycleError as err:
        pytest.fail(f"modules import each other in a circle: {' -> '.join(err.args[1])}")


def test_no_module_imports_the_command_line(violations):
    assert violations["cli"] == []


def test_no_module_uses_another_modules_private_names(violations):
    assert violations["private"] == []


def test_every_module_has_a_docstring_and_all():
    missing_doc, missing_all = [], []
    for module, path in sorted(MODULES.items()):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        if not ast.get_docstring(tree):
            missing_doc.append(module)
        # Assigned names, also from a tuple target (``__all__, __getattr__, __dir__ = lazy_exports(...)``).
        targets = [
            t
            for node in tree.body
            if isinstance(node, ast.Assign | ast.AnnAssign | ast.AugAssign)
            for t in (node.targets if isinstance(node, ast.Assign) else [node.target])
        ]
        names = {
            n.id
            for t in targets
            for n in ([t] if isinstance(t, ast.Name) else getattr(t, "elts", []))
            if isinstance(n, ast.Name)
        }
        if "__all__" not in names:
            missing_all.append(module)
    assert missing_doc == [], f"modules without a docstring: {missing_doc}"
    assert missing_all == [], f"modules without __all__: {missing_all}"


def test_no_package_exports_a_name_of_its_own_submodules():
    # a lazily exported function named like its submodule is the function on first attribute access
    # and the submodule ever after (importing the submodule sets the package's attribute)
    import importlib

    clashes = []
    packages = ["dynid"] + [i.name for i in pkgutil.walk_packages(dynid.__path__, "dynid.") if i.ispkg]
    for name in packages:
        package = importlib.import_module(name)
        submodules = {m.name for m in pkgutil.iter_modules(package.__path__)}
        clashes += [f"{name}.{sub}" for sub in getattr(package, "__all__", ()) if sub in submodules]
    assert not clashes, clashes
