"""C export: the compiled library, the CasADi functions and numeric Pinocchio agree; the example builds."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import warnings

import numpy as np
import pinocchio as pin
import pytest

from dynid.exceptions import GeneratorError, IdentificationWarning, UsageError
from dynid.symbolic import base_parameters, load_robot, robot_functions
from dynid.symbolic.export import CompiledLibrary, compiled_functions, export_c
from tests.conftest import DATA


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


# ---------------------------------------------------------------------------- an identified model as C
@pytest.fixture(scope="module")
def model_data(ur5):
    """Ten seconds of a simulated UR5 with Stribeck-like friction and a smooth position-dependent torque."""
    from dynid.identify.columns import column_set
    from dynid.sim.synthetic import random_fourier, synthetic_dataset, true_parameters

    rng = np.random.default_rng(5)
    cols = column_set(ur5, friction=False)
    x = true_parameters(cols, rng)

    def extra(q, dq):
        friction = (0.8 + 0.6 * np.exp(-((dq / 0.1) ** 2))) * np.sign(dq) + 0.4 * dq
        return friction + 1.5 * np.sin(2.0 * q)

    return synthetic_dataset(
        cols, x, random_fourier(ur5, rng, periods=2), rate=100, rng=rng, noise=0.02, extra=extra
    )


def _identified(ur5, data, **options):
    from dynid.identify.model import identify

    settings = {"method": "ols", "gmm": "off", "rounds": 0, **options}
    return identify(ur5, data, **settings)


@pytest.fixture(scope="module")
def model_exports(ur5, model_data, tmp_path_factory):
    """One model per friction kind the C prediction carries, each exported with export_model_c."""
    from dynid.identify.export_c import export_model_c

    out = {}
    for friction in ("linear", "seed", "seed_shared", "stribeck", "sigmoid"):
        model = _identified(ur5, model_data, friction=friction)
        folder = tmp_path_factory.mktemp("model_c") / friction
        out[friction] = (model, export_model_c(model, folder, model_file=f"{friction}.json", progress=None))
    return out


def _states(robot, rng, m=300):
    """States within the limits, a third of them at low speed and a few at rest."""
    q = rng.uniform(robot.q_min, robot.q_max, size=(m, robot.n))
    dq = rng.uniform(-1.0, 1.0, size=(m, robot.n)) * robot.dq_max
    ddq = rng.uniform(-1.0, 1.0, size=(m, robot.n)) * robot.ddq_max
    dq[: m // 3] *= 1e-3
    dq[:5] = 0.0
    return q, dq, ddq


@pytest.mark.parametrize("friction", ["linear", "seed", "seed_shared", "stribeck", "sigmoid"])
def test_the_c_prediction_is_the_models(model_exports, friction, rng):
    model, result = model_exports[friction]
    assert result.not_carried == []
    assert result.check["passed"] and result.check["relative_error"] <= 1e-12
    lib = CompiledLibrary(result.folder)
    q, dq, ddq = _states(model.robot, rng)
    with warnings.catch_warnings():
        warnings.simplefilter(
            "ignore", IdentificationWarning
        )  # random states leave the training torque's range
        want = model.predict(q, dq, ddq)
    got = lib.predict(q, dq, ddq)
    assert got.shape == want.shape
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-9 * np.abs(want).max())
    manifest = json.loads((result.folder / "manifest.json").read_text())
    theta = np.array([p["value"] for p in manifest["model"]["parameters"]])
    np.testing.assert_allclose(
        lib.model_regressor(q, dq, ddq) @ theta, want, rtol=0, atol=1e-9 * np.abs(want).max()
    )
    assert [f["name"] for f in manifest["functions"]] == ["predict", "model_regressor"]
    assert sorted(manifest["files"]) == sorted(p.name for p in result.folder.iterdir())
    assert manifest["model"]["file"] == f"{friction}.json" and manifest["check"]["tolerance"] == 1e-9
    names = [p["name"] for p in manifest["model"]["parameters"]]
    if friction == "linear":  # layer 1's Coulomb, viscous and offset in the prediction
        assert {"fc1", "fv1", "fo1"} <= set(names) and any(n.startswith("ia") for n in names)
        assert "Coulomb (layer 1)" in result.carried
    else:  # layer 2 replaces them; its linear coefficients are columns of the regressor
        assert "fc1" not in names and any(n.startswith("friction1.") for n in names)
        assert f"{friction} friction (layer 2, at its fitted shape)" in result.carried


def test_what_c_cannot_carry_is_listed_and_left_out(ur5, model_data, tmp_path, rng):
    from dataclasses import replace

    from dynid.identify.export_c import export_model_c
    from dynid.identify.friction import FrictionLayer, FrictionModel

    model = _identified(ur5, model_data, friction="seed", gmm=3)
    assert model.gmr is not None and model.gmr.active_.any(), "the mixture should take the sin(2 q) torque"

    class Quadratic(FrictionModel):  # a friction model of a user's own: its form is unknown to the generator
        name = "quadratic"
        coef_names = ("kv2",)
        bounds = (0.0,)

        def columns(self, dq):
            return (dq * np.abs(dq))[:, None]

    layer = FrictionLayer(model="quadratic")
    layer.models_ = []
    for j in range(ur5.n):
        mdl = Quadratic()
        mdl.coef_ = np.array([0.1 * (j + 1)])
        layer.models_.append(mdl)
    own = replace(model, friction=layer, friction_source="layer2")
    result = export_model_c(own, tmp_path / "c", progress=None)
    what = {item["what"]: item for item in result.not_carried}
    assert set(what) == {"layer-3 mixture correction (GMR)", "layer-2 friction (quadratic)"}
    assert what["layer-3 mixture correction (GMR)"]["joints"] == [
        int(j) + 1 for j in np.flatnonzero(model.gmr.active_)
    ]
    assert "not a built-in friction model" in what["layer-2 friction (quadratic)"]["why"]
    manifest = json.loads((tmp_path / "c" / "manifest.json").read_text())
    assert manifest["model"]["not_carried"] == result.not_carried
    assert manifest["model"]["friction"]["carried"] is False
    assert manifest["model"]["friction"]["joints"][2] == {"kv2": pytest.approx(0.3)}
    # the C torque is the model's without the mixture and without the friction it cannot write
    lib = CompiledLibrary(tmp_path / "c")
    q, dq, ddq = _states(ur5, rng)
    rigid = replace(model, gmr=None, friction=None, friction_source="none", info={}).predict(q, dq, ddq)
    np.testing.assert_allclose(lib.predict(q, dq, ddq), rigid, rtol=0, atol=1e-9 * np.abs(rigid).max())
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the mixture fades out of its fitted range
        full = own.predict(q, dq, ddq)
    assert np.abs(full - lib.predict(q, dq, ddq)).max() > 0.1  # what is left out is not nothing


def test_a_library_that_does_not_reproduce_the_model_is_refused(model_exports, tmp_path):
    from dataclasses import replace

    from dynid.identify.export_c import check_prediction, model_functions

    model, result = model_exports["linear"]
    other = replace(model, params=model.params * (1 + 1e-6), info={})
    with pytest.raises(
        GeneratorError,
        match=r"the compiled predict differs from the model's prediction by .* nothing was written",
    ):
        check_prediction(result.folder, other)
    assert check_prediction(result.folder, replace(model, info={}))["relative_error"] <= 1e-12
    # a failing check leaves nothing behind, and an earlier export as it was
    before = sorted(p.name for p in result.folder.iterdir())
    predict, regressor, description = model_functions(model)
    options = {
        "functions": (),
        "extra": (predict, regressor),
        "manifest": {"model": {"parameters": description["parameters"]}},
        "check": lambda folder: check_prediction(folder, other),
        "progress": None,
    }
    with pytest.raises(GeneratorError, match=r"differs from the model's prediction"):
        export_c(model.robot, tmp_path / "new", **options)
    assert not list(tmp_path.iterdir())
    with pytest.raises(GeneratorError, match=r"differs from the model's prediction"):
        export_c(model.robot, result.folder, **options)
    assert sorted(p.name for p in result.folder.iterdir()) == before
    assert check_prediction(result.folder, replace(model, info={}))["passed"]


def test_the_model_example_prints_the_models_torque(model_exports):
    model, result = model_exports["seed"]
    cc = shutil.which("cc") or shutil.which("gcc")
    assert cc is not None, "the C export needs a C compiler on this machine"
    stem = "dynid_" + re.sub(r"\W", "_", model.robot.name)
    subprocess.run(
        [cc, "-O2", "example.c", f"{stem}.c", "-o", "example", "-lm"], cwd=result.folder, check=True
    )
    run = subprocess.run([str(result.folder / "example")], capture_output=True, text=True, check=True)
    lines = run.stdout.strip().splitlines()
    assert lines[0].startswith(f"predict of {model.robot.name} ({model.robot.n} x 1)")
    printed = np.array([float(line) for line in lines[1:]])
    n = model.robot.n
    q = 0.1 * np.arange(1, n + 1)[None, :]
    want = model.predict(q, np.full((1, n), 0.2), np.full((1, n), -0.3))[0]
    np.testing.assert_allclose(printed, want, rtol=1e-6, atol=1e-9)


def test_robot_functions_come_after_the_models_and_are_named_once(model_exports, tmp_path):
    from dynid.identify.export_c import export_model_c, model_functions

    model, _ = model_exports["linear"]
    result = export_model_c(
        model, tmp_path / "c", functions=("predict", "base_regressor", "fk"), progress=None
    )
    manifest = json.loads(result.export.manifest.read_text())
    assert [f["name"] for f in manifest["functions"]] == [
        "predict",
        "model_regressor",
        "base_regressor",
        "fk",
    ]
    predict, _, _ = model_functions(model)
    with pytest.raises(UsageError, match=r"the functions predict are named twice; export each function once"):
        export_c(model.robot, tmp_path / "d", functions=(), extra=(predict, predict), progress=None)


def test_a_coupled_transmission_is_carried(ur5, tmp_path, rng):
    """Motor 6 also turning with joint 5 (the TX40's wrist): armature and friction act on u = R q."""
    from dynid.identify.columns import column_set
    from dynid.identify.export_c import export_model_c
    from dynid.identify.model import identify
    from dynid.sim.synthetic import random_fourier, synthetic_dataset, true_parameters

    R = np.eye(6)
    R[5, 4] = 1.0
    robot = ur5.with_transmission(R)
    cols = column_set(robot)
    assert cols.coupled_mask.any()  # the coupled motor's friction reaches two joints
    data = synthetic_dataset(
        cols, true_parameters(cols, rng), random_fourier(robot, rng), rate=50, rng=rng, noise=0.01
    )
    model = identify(robot, data, method="ols", friction="linear", gmm="off", rounds=0)
    result = export_model_c(model, tmp_path / "c", progress=None)
    assert result.check["relative_error"] <= 1e-12
    q, dq, ddq = _states(robot, rng)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", IdentificationWarning)
        want = model.predict(q, dq, ddq)
    np.testing.assert_allclose(
        CompiledLibrary(result.folder).predict(q, dq, ddq), want, rtol=0, atol=1e-9 * np.abs(want).max()
    )
