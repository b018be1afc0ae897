"""The documentation site: its pages, its API reference and the gallery's scripts.

The fast tests read the sources (no Sphinx build: ``sphinx-build -W -b html docs docs/_build/html`` is
the full check); the slow tier runs every example script in a folder of its own and checks what it
wrote against the simulated truth.
"""

from __future__ import annotations

import importlib
import importlib.util
import json
import os
import re
import runpy
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import REPO

DOCS = REPO / "docs"
EXAMPLES = REPO / "examples"
GALLERY = "auto_examples"  # sphinx_gallery_conf["gallery_dirs"]: made by the build from EXAMPLES
SCRIPTS = sorted(EXAMPLES.glob("[0-9][0-9]_*.py"))
# Written by the build, never sources: not pages that must sit in a toctree.
GENERATED = ("_build", "_templates", "api/generated", GALLERY, "sg_execution_times")


# --------------------------------------------------------------------------------------------------
# Pages and toctrees


def _toctree_entries(page: Path) -> list[str]:
    """Document names listed in the page's toctrees (MyST ``{toctree}`` fences or rST directives)."""
    text = page.read_text(encoding="utf-8")
    if page.suffix == ".md":
        blocks = re.findall(r"^```\{toctree\}[^\n]*\n(.*?)^```", text, flags=re.M | re.S)
    else:
        blocks = re.findall(r"^\.\. toctree::[^\n]*\n((?:[ \t]+[^\n]*\n|[ \t]*\n)*)", text, flags=re.M)
    entries = []
    for block in blocks:
        for line in block.splitlines():
            line = line.strip()
            if not line or line.startswith(":"):
                continue
            titled = re.fullmatch(r".*<([^<>]+)>", line)  # "Title <doc>"
            entries.append(titled.group(1) if titled else line)
    return entries


def _source(docname: str, suffixes: tuple[str, ...]) -> Path | None:
    """The file a document name is built from: a page under docs/, or a gallery script."""
    if docname == f"{GALLERY}/index":
        return EXAMPLES / "GALLERY_HEADER.rst"
    if docname.startswith(f"{GALLERY}/"):
        script = EXAMPLES / f"{docname.split('/', 1)[1]}.py"
        return script if script.is_file() else None
    for suffix in suffixes:
        path = DOCS / f"{docname}{suffix}"
        if path.is_file():
            return path
    return None


def _walk_toctrees(root: str, suffixes: tuple[str, ...]) -> tuple[set[str], list[str]]:
    """Every document reachable from ``root`` through toctrees, and the entries that name no file."""
    seen, missing, todo = {root}, [], [root]
    while todo:
        docname = todo.pop()
        page = _source(docname, suffixes)
        if page is None or page.parent == EXAMPLES:
            continue
        folder = docname.rpartition("/")[0]
        for entry in _toctree_entries(page):
            name = entry.lstrip("/") if entry.startswith("/") else "/".join(p for p in (folder, entry) if p)
            name = os.path.normpath(name)
            if _source(name, suffixes) is None:
                missing.append(f"{entry!r} in {page.relative_to(REPO)}")
            elif name not in seen:
                seen.add(name)
                todo.append(name)
    return seen, missing


def test_every_page_in_the_toctrees_exists():
    """Every toctree entry, from the root page down, names a page (or a gallery script), and every
    page under docs/ is reached: none is left out of the navigation."""
    pytest.importorskip("sphinx", reason="the documentation needs Sphinx: pip install -e '.[docs]'")
    conf = runpy.run_path(str(DOCS / "conf.py"))
    missing_ext = [ext for ext in conf["extensions"] if importlib.util.find_spec(ext) is None]
    assert not missing_ext, f"docs/conf.py needs {missing_ext}: pip install -e '.[docs]'"
    suffixes = tuple(conf["source_suffix"])
    root = conf.get("root_doc", "index")
    assert _source(root, suffixes) is not None, f"docs/ has no root page {root!r}"

    reached, missing = _walk_toctrees(root, suffixes)
    assert not missing, "toctree entries without a page: " + "; ".join(missing)
    pages = {
        str(path.relative_to(DOCS).with_suffix(""))
        for suffix in suffixes
        for path in DOCS.rglob(f"*{suffix}")
        if not str(path.relative_to(DOCS)).startswith(GENERATED)
    }
    assert pages - reached == set(), f"pages in no toctree: {sorted(pages - reached)}"
    # the existing guides, the concepts, the gallery and the API reference are all in the site
    for name in ("commands", "robots", "architecture", "getting-started", "concepts/index", "api/index"):
        assert name in reached, name
    assert f"{GALLERY}/index" in reached
    assert conf["sphinx_gallery_conf"]["examples_dirs"] == str(EXAMPLES)


def test_gallery_scripts_have_a_title_and_run_headless():
    """sphinx-gallery takes each script's docstring title (underlined with '=') as its page title; the
    scripts write only where they are told (a folder argument, else a temporary folder)."""
    assert len(SCRIPTS) >= 4, SCRIPTS
    for script in SCRIPTS:
        text = script.read_text(encoding="utf-8")
        head = re.match(r'"""\n(.+)\n(=+)\n', text)
        assert head, f"{script.name}: starts with a docstring whose title is underlined with '='"
        assert len(head.group(2)) == len(head.group(1)), f"{script.name}: title underline length"
        assert "plt.show(" not in text, f"{script.name}: plots are saved, never shown"
        assert "sys.argv[1]" in text and "tempfile.mkdtemp" in text, f"{script.name}: output folder"


# --------------------------------------------------------------------------------------------------
# The API reference


def _api_page(module: str) -> Path:
    return DOCS / "api" / ("dynid.rst" if module == "dynid" else f"{module.split('.', 1)[1]}.rst")


API_MODULES = [
    "dynid",
    "dynid.symbolic",
    "dynid.optim",
    "dynid.data",
    "dynid.identify",
    "dynid.sim",
    "dynid.validation",
    "dynid.simmodel",
    "dynid.diagnosis",
    "dynid.fleet",
    "dynid.exceptions",
]


@pytest.mark.parametrize("module", API_MODULES)
def test_the_api_reference_lists_every_public_name(module):
    """Each public package has its page, which names every entry of its ``__all__``, and every name
    its autosummary tables list imports (a renamed function breaks this test, not the build)."""
    page = _api_page(module)
    assert page.is_file(), f"no API page for {module}"
    text = page.read_text(encoding="utf-8")
    assert f".. automodule:: {module}\n" in text
    public = [name for name in importlib.import_module(module).__all__ if not name.startswith("__")]
    absent = [name for name in public if not re.search(rf"(?<!\w){re.escape(name)}(?!\w)", text)]
    assert not absent, f"{page.relative_to(REPO)} does not mention {absent} of {module}.__all__"

    current = re.search(r"^\.\. currentmodule:: (\S+)", text, flags=re.M).group(1)
    listed = []
    for block in re.findall(r"^\.\. autosummary::\n((?:[ \t]+[^\n]*\n|[ \t]*\n)*)", text, flags=re.M):
        listed += [line.strip() for line in block.splitlines() if line.strip() and ":" not in line]
    assert listed, f"{page.name} has no autosummary table"
    for name in listed:
        assert hasattr(importlib.import_module(current), name), f"{current}.{name} (listed in {page.name})"


def test_the_top_level_page_documents_all_of_dynid():
    """``dynid.__all__`` is documented in full on its own page (the subpackages' pages refer to it)."""
    import dynid

    text = _api_page("dynid").read_text(encoding="utf-8")
    listed = set(re.findall(r"^   (\w+)$", text, flags=re.M))
    assert {name for name in dynid.__all__ if not name.startswith("__")} <= listed


# --------------------------------------------------------------------------------------------------
# The gallery's scripts, run (slow tier)


def _files(folder: Path) -> set[Path]:
    return {path for path in folder.rglob("*") if "__pycache__" not in path.parts}


def _run_example(script: Path, out: Path) -> str:
    before = _files(EXAMPLES)
    env = {**os.environ, "MPLBACKEND": "Agg", "PYTHONWARNINGS": "ignore::DeprecationWarning"}
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        env[var] = "1"
    done = subprocess.run(
        [sys.executable, str(script), str(out)],
        cwd=out,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    assert done.returncode == 0, f"{script.name} failed:\n{done.stdout[-3000:]}\n{done.stderr[-3000:]}"
    assert _files(EXAMPLES) == before, f"{script.name} wrote into examples/"
    return done.stdout


def _ur5():
    import dynid

    return dynid.load_robot("ur5")


def _base_errors(robot, params, truth_params) -> float:
    import dynid

    base = dynid.base_parameters(dynid.robot_functions(robot))
    return float(np.abs(base.to_base(np.asarray(params)) - base.to_base(np.asarray(truth_params))).max())


def _check_excitation(out: Path, stdout: str) -> None:
    import dynid

    robot = _ur5().with_limits(dq_max=2.0, ddq_max=6.0)
    trajectory = dynid.load_trajectory(out / "excitation.json")
    t = np.linspace(0.0, trajectory.period, 4001)
    q, dq, ddq = trajectory.evaluate(t)
    assert np.all(q >= robot.q_min - 1e-9) and np.all(q <= robot.q_max + 1e-9)
    assert np.all(np.abs(dq) <= robot.dq_max * (1 + 1e-6))
    assert np.all(np.abs(ddq) <= robot.ddq_max * (1 + 1e-6))
    np.testing.assert_allclose(dq[[0, -1]], 0.0, atol=1e-9)  # at rest at both ends
    np.testing.assert_allclose(ddq[[0, -1]], 0.0, atol=1e-9)
    designed = float(re.search(r"^cond ([\d.]+)", stdout, flags=re.M).group(1))
    baseline = float(re.search(r"random feasible trajectories: cond ([\d.]+)", stdout).group(1))
    assert designed < 0.8 * baseline, (designed, baseline)
    run = dynid.load_trajectory(out / "excitation.csv")  # approach, three periods, retreat
    assert run.duration > 3 * trajectory.period
    assert (out / "excitation.png").stat().st_size > 10_000


def _check_identification(out: Path, stdout: str) -> None:
    import dynid

    robot = _ur5()
    truth = json.loads((out / "D.csv.truth.json").read_text())
    model = dynid.load_model(out / "model.json")
    base = dynid.base_parameters(dynid.robot_functions(robot))
    nb = base.n_base
    true_beta = base.to_base(np.array(truth["params"]["truth"]))
    error = np.abs(model.params[:nb] - true_beta)
    urdf_error = np.abs(base.to_base(robot.params) - true_beta)
    assert error.max() < 0.1 * urdf_error.max(), (error.max(), urdf_error.max())
    # the reported standard deviations mean what they say
    assert np.mean(error < 3 * model.std[:nb]) >= 0.9
    names = list(model.columns.names)
    fc = np.array([model.params[names.index(f"fc{j}")] for j in (1, 2, 3)])
    np.testing.assert_allclose(fc, truth["friction"]["Fc"][:3], rtol=0.05)
    assert "errors within 2 reported std" in stdout


def _check_validation(out: Path, stdout: str) -> None:
    figures = json.loads((out / "validation.json").read_text())
    assert figures["floor_method"] == "periods"
    floor = np.array(figures["floor"])
    ratio = np.array(figures["rms"]) / floor
    ols, default = figures["labels"].index("OLS + linear friction"), figures["labels"].index("dynid default")
    assert np.all(ratio > 0.9), ratio  # no model beats the noise floor
    assert np.all(ratio[default] < 3.0), ratio[default]  # the default comes close to it
    assert ratio[ols].mean() > 2 * ratio[default].mean()  # the paper's friction matters here
    assert (out / "validation.html").stat().st_size > 50_000


def _check_export(out: Path, stdout: str) -> None:
    import dynid

    robot = _ur5()
    truth = np.array(json.loads((out / "D.csv.truth.json").read_text())["params"]["truth"])
    model = dynid.load_model(out / "model.json")
    exported = dynid.load_robot(out / "ur5_identified.urdf")  # an ordinary URDF
    assert exported.n == robot.n == model.robot.n
    masses = exported.params[0::10]
    assert np.all(masses > 0)
    # its bodies carry the identified base parameters: far closer to the truth than the URDF's
    assert _base_errors(robot, exported.params, truth) < 0.1 * _base_errors(robot, robot.params, truth)
    if importlib.util.find_spec("mujoco") is not None:
        assert (out / "ur5_identified.xml").stat().st_size > 1000
    assert (out / "masses.png").is_file()


def _check_payload(out: Path, stdout: str) -> None:
    import dynid

    robot = _ur5()
    figures = json.loads((out / "payload.json").read_text())
    # the simulator's payload: 5 % of the arm's mass, 5 cm along the tool's z axis (dynid.sim.effects)
    mass = 0.05 * robot.params[0::10].sum()
    assert abs(figures["mass"] - mass) < 0.01 * mass, (figures["mass"], mass)
    np.testing.assert_allclose(figures["com"], [0.0, 0.0, 0.05], atol=0.003)
    assert all(figures["determined"][name] for name in ("m", "mx", "my", "mz"))
    loaded = dynid.load_model(out / "model_with_payload.json")
    assert loaded.info["payload"]["mass"] == pytest.approx(figures["mass"])


def _check_diagnosis(out: Path, stdout: str) -> None:
    assert json.loads((out / "diagnosis.json").read_text())["verdict"] == ["cogging"]
    assert "cogging on joint 2" in stdout
    assert (out / "diagnosis.html").stat().st_size > 50_000
    assert (out / "residual_joint2.png").is_file()


CHECKS = {
    "01_design_excitation": _check_excitation,
    "02_identify_simulated_ur5": _check_identification,
    "03_validate_noise_floor": _check_validation,
    "04_export_urdf": _check_export,
    "05_identify_payload": _check_payload,
    "06_diagnose_injected_effect": _check_diagnosis,
}


def test_every_example_has_a_check():
    assert sorted(CHECKS) == [script.stem for script in SCRIPTS]


@pytest.mark.slow
@pytest.mark.parametrize("script", SCRIPTS, ids=[script.stem for script in SCRIPTS])
def test_example_runs_and_writes_what_it_says(script, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    stdout = _run_example(script, out)
    CHECKS[script.stem](out, stdout)
