"""The tests are laid out like the code, and every module is tested somewhere a reader can find.

The tests of ``dynid/<room>/<module>.py`` live in ``tests/<room>/test_<module>.py`` (a leading underscore
dropped: ``dynid/_progress.py`` -> ``tests/test_progress.py``). A module without a file of its own is listed
below with the test file that tests it, and this file checks the claim:

- ``IMPORTED_BY``: the named test file imports the module;
- ``PART_OF``: the module is a step of a larger module (split out for size) that imports it, and that larger
  module is tested (its own file, or listed here in turn);
- ``RUN_BY``: a command-line module, run by the named test file through ``dynid`` (the file names the
  command and runs the command line).

Tests that hold the whole project (architecture, docs, README, layout) sit at the top of ``tests/``.
"""

from __future__ import annotations

import ast
from functools import cache
from pathlib import Path

import pytest

from tests.conftest import REPO

PACKAGE = REPO / "dynid"
TESTS = REPO / "tests"

IMPORTED_BY = {
    "dynid._cluster": "tests/fleet/test_fleet.py",
    "dynid._io": "tests/identify/test_payload.py",
    "dynid._threads": "tests/identify/test_refine.py",
    "dynid.commands.common": "tests/commands/test_fuzz_inputs.py",
    "dynid.commands.diagnose": "tests/commands/test_defaults.py",
    "dynid.commands.excite": "tests/commands/test_defaults.py",
    "dynid.commands.fleet": "tests/commands/test_defaults.py",
    "dynid.commands.identify": "tests/commands/test_defaults.py",
    "dynid.commands.info": "tests/commands/test_fuzz_inputs.py",
    "dynid.commands.simulate": "tests/commands/test_defaults.py",
    "dynid.data.files": "tests/data/test_api.py",
    "dynid.data.periodic": "tests/commands/test_fuzz_inputs.py",
    "dynid.data.preparation": "tests/data/test_cutoff.py",
    "dynid.diagnosis.baseline": "tests/diagnosis/test_diagnosis.py",
    "dynid.diagnosis.candidates": "tests/diagnosis/test_catalogue.py",
    "dynid.diagnosis.cases": "tests/diagnosis/test_common_delay.py",
    "dynid.diagnosis.core": "tests/diagnosis/test_diagnosis.py",
    "dynid.diagnosis.crossfold": "tests/diagnosis/test_consistency.py",
    "dynid.diagnosis.field_cases": "tests/diagnosis/test_field_recordings.py",
    "dynid.diagnosis.fitting": "tests/diagnosis/test_diagnosis.py",
    "dynid.diagnosis.report": "tests/diagnosis/test_gapmap.py",
    "dynid.diagnosis.result": "tests/diagnosis/test_diagnosis.py",
    "dynid.diagnosis.screening": "tests/diagnosis/test_catalogue.py",
    "dynid.diagnosis.settings": "tests/diagnosis/test_parameter_change.py",
    "dynid.exceptions": "tests/commands/test_bad_inputs.py",
    "dynid.fleet.core": "tests/fleet/test_fleet.py",
    "dynid.fleet.drift": "tests/fleet/test_fleet.py",
    "dynid.fleet.recordings": "tests/fleet/test_fleet.py",
    "dynid.fleet.report": "tests/fleet/test_fleet.py",
    "dynid.fleet.simulated": "tests/fleet/test_fleet.py",
    "dynid.identify._qr": "tests/identify/test_linear_system.py",
    "dynid.identify.columns": "tests/identify/test_physical_layers.py",
    "dynid.optim.approach": "tests/optim/test_excitation.py",
    "dynid.optim.criteria": "tests/optim/test_excitation.py",
    "dynid.optim.payload_motion": "tests/identify/test_payload.py",
    "dynid.optim.problem": "tests/optim/test_excitation.py",
    "dynid.optim.trajectory": "tests/optim/test_excitation.py",
    "dynid.sim.cases": "tests/sim/test_simulate.py",
    "dynid.sim.effects": "tests/sim/test_simulate.py",
    "dynid.sim.sensors": "tests/diagnosis/test_quantised.py",
    "dynid.sim.simulator": "tests/sim/test_simulate.py",
    "dynid.sim.synthetic": "tests/sim/test_simulate.py",
    "dynid.sim.truth": "tests/identify/test_effect_terms.py",
    "dynid.simmodel.checks": "tests/simmodel/test_export.py",
    "dynid.simmodel.mjcf": "tests/diagnosis/test_sim_diagnose.py",
    "dynid.simmodel.nominal": "tests/simmodel/test_export.py",
    "dynid.simmodel.parameters": "tests/identify/test_registry.py",
    "dynid.simmodel.rollout": "tests/diagnosis/test_sim_diagnose.py",
    "dynid.symbolic.bodies": "tests/identify/test_payload.py",
    "dynid.symbolic.export": "tests/identify/test_export_c.py",
    "dynid.symbolic.functions": "tests/identify/test_estimators.py",
    "dynid.symbolic.transmission": "tests/commands/test_fuzz.py",
    "dynid.symbolic.urdf": "tests/identify/test_cad_description.py",
    "dynid.validation.html_page": "tests/identify/test_effect_terms.py",
    "dynid.validation.noise": "tests/validation/test_validate.py",
    "dynid.validation.plots": "tests/validation/test_report.py",
}

PART_OF = {
    "dynid.identify.effect_builders": "dynid.identify.effect_terms",
    "dynid.identify.friction_base": "dynid.identify.friction",
    "dynid.identify.friction_fitting": "dynid.identify.friction",
    "dynid.identify.friction_models": "dynid.identify.friction",
    "dynid.identify.mixture": "dynid.identify.gmr",
    "dynid.identify.fit_figures": "dynid.identify.three_layer",
    "dynid.identify.identified": "dynid.identify.model",
    "dynid.identify.model_file": "dynid.identify.model",
    "dynid.identify.three_layer": "dynid.identify.model",
    "dynid.demo_records": "dynid.demo",
    "dynid.validation.baseline": "dynid.validation.validate",
    "dynid.validation.result": "dynid.validation.validate",
    "dynid.data.filters": "dynid.data.preprocess",
    "dynid.data.resampling": "dynid.data.preprocess",
    "dynid.data.rows": "dynid.data.preprocess",
    "dynid.sim.effect_classes": "dynid.sim.effects",
    "dynid.sim.scales": "dynid.sim.effects",
    "dynid.sim.truth_friction": "dynid.sim.effects",
    "dynid._lazy": "dynid.identify",
    "dynid._memory": "dynid.identify.pipeline",
    "dynid.identify.bodies": "dynid.identify.consistent",
    "dynid.identify.checks": "dynid.identify.estimators",
    "dynid.optim.baseline": "dynid.optim.excitation",
    "dynid.optim.interrupts": "dynid.optim.excitation",
    "dynid.optim.nlp": "dynid.optim.tries",
    "dynid.optim.results": "dynid.optim.excitation",
    "dynid.optim.tries": "dynid.optim.excitation",
    "dynid.sim.results": "dynid.sim.simulator",
    "dynid.symbolic._export.loader": "dynid.symbolic.export",
    "dynid.symbolic.inertia": "dynid.symbolic.robot",
    "dynid.symbolic.mdh": "dynid.symbolic.robot",
    "dynid.symbolic.robot_model": "dynid.symbolic.robot",
    "dynid.validation.payload_report": "dynid.commands.payload",
}
"""A module split out of a larger one, and the module that imports it."""

RUN_BY = {
    "dynid.__main__": ("tests/test_cli.py", '"-m", "dynid"'),
    "dynid.commands.convert": ("tests/data/test_convert.py", '"convert"'),
    "dynid.commands.demo": ("tests/test_demo.py", '"demo"'),
    "dynid.commands.export": ("tests/simmodel/test_export.py", '"export"'),
    "dynid.commands.export_c": ("tests/test_cli.py", '"export-c"'),
    "dynid.commands.payload": ("tests/identify/test_payload.py", '"payload"'),
    "dynid.commands.validate": ("tests/validation/test_validate.py", '"validate"'),
}
"""A command-line module, the test file that runs its command, and the text that shows it does."""


def _modules() -> list[str]:
    names = []
    for path in sorted(PACKAGE.rglob("*.py")):
        if path.name != "__init__.py":
            names.append(".".join(path.relative_to(REPO).with_suffix("").parts))
    return names


def _own_test(module: str) -> Path:
    *room, name = module.split(".")[1:]
    return TESTS.joinpath(*room, f"test_{name.lstrip('_')}.py")


def _source(module: str) -> Path:
    path = REPO.joinpath(*module.split(".")).with_suffix(".py")
    return path if path.exists() else REPO.joinpath(*module.split("."), "__init__.py")


@cache
def _imports(path: Path) -> frozenset[str]:
    """The dotted names a file imports: modules, and module.name for every name taken from one."""
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            out.add(node.module)
            out.update(f"{node.module}.{alias.name}" for alias in node.names)
        elif isinstance(node, ast.Import):
            out.update(alias.name for alias in node.names)
    return frozenset(out)


def _tested(module: str, seen: tuple[str, ...] = ()) -> bool:
    if _own_test(module).exists():
        return True
    if module in IMPORTED_BY:
        return module in _imports(REPO / IMPORTED_BY[module])
    if module in PART_OF and module not in seen:
        parent = PART_OF[module]
        if module not in _imports(_source(parent)):
            return False
        importers = [t for t in TESTS.rglob("test_*.py") if parent in _imports(t)]
        return bool(importers) or _tested(parent, (*seen, module))
    if module in RUN_BY:
        test, evidence = RUN_BY[module]
        text = (REPO / test).read_text()
        return evidence in text and ("dynid.cli" in _imports(REPO / test) or '"-m", "dynid"' in text)
    return False


@pytest.mark.parametrize("module", _modules())
def test_every_module_is_tested_where_a_reader_looks(module):
    own = _own_test(module)
    assert _tested(module), (
        f"{module} has no {own.relative_to(REPO)}; write one, or list the test file that tests it in "
        "tests/test_layout.py (and make that file import it)"
    )


def test_the_lists_name_no_module_twice_or_gone():
    modules = set(_modules())
    listed = [*IMPORTED_BY, *PART_OF, *RUN_BY]
    assert len(listed) == len(set(listed))
    assert not set(listed) - modules, "listed modules that no longer exist"
    has_own = [m for m in listed if _own_test(m).exists()]
    assert not has_own, f"these have a test file of their own now; drop them from the lists: {has_own}"
    for test in [*IMPORTED_BY.values(), *(t for t, _ in RUN_BY.values())]:
        assert (REPO / test).exists(), test


def test_every_room_has_its_test_folder():
    rooms = {p.parent.name for p in PACKAGE.glob("*/__init__.py")}
    for room in rooms:
        assert (TESTS / room / "__init__.py").exists(), f"tests/{room}/ is missing"
    folders = {p.name for p in TESTS.iterdir() if p.is_dir() and (p / "__init__.py").exists()}
    assert folders <= rooms, f"test folders without a room in dynid/: {folders - rooms}"
