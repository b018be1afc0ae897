"""C export: the compiled library, the CasADi functions and numeric Pinocchio agree; the example builds."""

from __future__ import annotations

import json
import re
import shutil
import subprocess

import numpy as np
import pinocchio as pin
import pytest
from conftest import DATA

from dynid.exceptions import GeneratorError, UsageError
from dynid.symbolic import base_parameters, load_robot, robot_functions
from dynid.symbolic.export import CompiledLibrary, compiled_functions, export_c


@pytest.fixture(
    scope="module", params=["ur5", "panda", str(DATA / "rrpr_mdh.toml")], ids=["ur5", "panda", "mdh"]
)
def exported(request, tmp_path_factory):
    robot = load_robot(request.param)
    out = tmp_path_factory.mktemp("export") / "lib"
    export_c(
        robot, out, functions=("base_regressor", "regressor", "rnea", "friction_columns", "gravity", "fk")
    )
    return robot, out


def test_export_writes_every_file(exported):
    robot, out = exported
    stem = "dynid_" + re.sub(r"\W", "_", robot.name)
    for name in (
        f"{stem}.c",
        f"{stem}.h",
        f"{stem}_batch.c",
        f"lib{stem}.so",
        "example.c",
        "Makefile",
        "manifest.json",
        "dynid_loader.py",
    ):
        assert (out / name).is_file(), name
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["n"] == robot.n
    assert [f["name"] for f in manifest["functions"]][:2] == ["base_regressor", "regressor"]
    assert len(manifest["base_parameters"]["names"]) == manifest["functions"][0]["outputs"][0]["cols"]


def test_compiled_casadi_and_pinocchio_agree(exported, rng):
    robot, out = exported
    lib = CompiledLibrary(out)
    funcs = robot_functions(robot)
    base = base_parameters(funcs)
    model, data = robot.pin_model, robot.pin_model.createData()
    m = 40
    q = rng.uniform(robot.q_min, robot.q_max, size=(m, robot.n))
    dq, ddq = rng.normal(size=(2, m, robot.n))
    Y = lib.regressor(q, dq, ddq)
    Yb = lib.base_regressor(q, dq, ddq)
    tau = lib.rnea(q, dq, ddq)
    g = lib.gravity(q)
    F = lib.friction_columns(dq)
    p, R = lib.fk(q)
    assert Y.shape == (m, robot.n, 10 * robot.n) and Yb.shape == (m, robot.n, base.n_base)
    np.testing.assert_allclose(Y, funcs.regressor_numeric(q, dq, ddq), atol=1e-10)
    np.testing.assert_allclose(Yb, base.evaluate(q, dq, ddq), atol=1e-10)
    np.testing.assert_allclose(F, funcs.evaluate("friction_columns", dq), atol=1e-14)
    fk_p, fk_R = funcs.evaluate("fk", q)
    np.testing.assert_allclose(p, fk_p, atol=1e-12)
    np.testing.assert_allclose(R, fk_R, atol=1e-12)
    for k in range(m):
        np.testing.assert_allclose(
            Y[k], pin.computeJointTorqueRegressor(model, data, q[k], dq[k], ddq[k]), atol=1e-10
        )
        np.testing.assert_allclose(tau[k], pin.rnea(model, data, q[k], dq[k], ddq[k]), atol=1e-10)
        np.testing.assert_allclose(g[k], pin.computeGeneralizedGravity(model, data, q[k]), atol=1e-10)
    np.testing.assert_allclose(Yb @ base.to_base(robot.params), Y @ robot.params, atol=1e-10)


def test_the_c_example_builds_and_runs(exported):
    robot, out = exported
    cc = shutil.which("cc") or shutil.which("gcc")
    assert cc is not None, "the C export needs a C compiler on this machine"
    stem = "dynid_" + re.sub(r"\W", "_", robot.name)
    subprocess.run([cc, "-O2", "example.c", f"{stem}.c", "-o", "example", "-lm"], cwd=out, check=True)
    if shutil.which("make"):  # the Makefile written beside it builds the same program
        (out / "example").unlink()
        subprocess.run(["make", "-s", "-C", str(out), f"CC={cc}"], check=True, capture_output=True)
    run = subprocess.run([str(out / "example")], capture_output=True, text=True, check=True)
    lines = run.stdout.strip().splitlines()
    assert lines[0].startswith(f"Y_b of {robot.name}")
    printed = np.array([[float(v) for v in line.split()] for line in lines[1:]])
    q = 0.1 * np.arange(1, robot.n + 1)
    expected = base_parameters(robot_functions(robot)).evaluate(
        q, np.full(robot.n, 0.2), np.full(robot.n, -0.3)
    )[0]
    np.testing.assert_allclose(printed, expected, rtol=1e-6, atol=1e-12)


def test_loader_works_without_dynid(exported, rng):
    """The loader copied into the export needs only numpy: run it in a clean interpreter."""
    robot, out = exported
    code = (
        "import sys, numpy as np; sys.path.insert(0, sys.argv[1]); import dynid_loader as L; "
        "lib = L.CompiledLibrary(sys.argv[1]); q = np.zeros((3, lib.manifest['n'])); "
        "print(lib.base_regressor(q, q, q).shape)"
    )
    import sys

    run = subprocess.run(
        [sys.executable, "-I", "-c", code, str(out)], capture_output=True, text=True, check=True
    )
    assert (
        run.stdout.strip()
        == f"(3, {robot.n}, {len(json.loads((out / 'manifest.json').read_text())['base_parameters']['names'])})"
    )


def test_batch_path_is_cached_per_robot(ur5):
    first = compiled_functions(ur5)
    assert compiled_functions(load_robot("ur5")) is first


def test_bad_export_requests(tmp_path, ur5, rng):
    with pytest.raises(
        UsageError, match=r"cannot export jacobian; the exportable functions are base_regressor"
    ):
        export_c(ur5, tmp_path / "x", functions=("jacobian",))
    assert not (tmp_path / "x").exists()
    assert not list(tmp_path.iterdir())  # nothing half written
    with pytest.raises(GeneratorError, match=r"the folder '.*missing' does not exist"):
        export_c(ur5, tmp_path / "missing" / "x")
    lib = compiled_functions(ur5)
    with pytest.raises(ValueError, match=r"input q of base_regressor has shape \(4, 7\); expected \(N, 6\)"):
        lib.base_regressor(np.zeros((4, 7)), np.zeros((4, 6)), np.zeros((4, 6)))
