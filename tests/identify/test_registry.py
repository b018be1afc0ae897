"""The registries of friction models and layer-1 estimators, and a model of one's own added through them.

The target of the house's second step: adding a friction model touches at most three files.  Here it
touches one (this one): a toy model registered from the test is identified by ``identify``, run by
``dynid identify --friction toy`` in the same process, written to and read from a model file, and
listed as not carried by the simulator export.
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys

import numpy as np
import pytest

from dynid.cli import main
from dynid.commands import fleet as fleet_command
from dynid.commands import identify as identify_command
from dynid.data.files import save_dataset
from dynid.exceptions import ModelFileError, UsageError
from dynid.identify.columns import column_set
from dynid.identify.estimators import OLS, LinkEstimator, register_estimator
from dynid.identify.friction import FrictionLayer, FrictionModel, register_friction_model
from dynid.identify.model import identify, load_model, save_model
from dynid.identify.registry import CONSTRAINED_METHODS, ESTIMATORS, FRICTION_MODELS, method_names
from dynid.sim.synthetic import random_fourier, synthetic_dataset, true_parameters
from dynid.simmodel.parameters import simulator_parameters
from tests.conftest import REPO

KV2 = np.array([0.8, 1.5, 0.6, 0.3, 0.2, 0.1])  # N m s^2/rad^2 per joint of the UR5


class ToyFriction(FrictionModel):
    """Pure quadratic viscous friction ``F = kv2 dq |dq|``, ``kv2 >= 0``."""

    name = "toy"
    coef_names = ("kv2",)
    bounds = (0.0,)

    def columns(self, dq):
        return (dq * np.abs(dq))[:, None]


class DoubledOLS(LinkEstimator):
    """OLS on the system scaled by 2: the same estimate as OLS, by another weighting."""

    method = "toy_ols"

    def _iterate(self, system):
        sol = self._weighted_fit(system, 2.0 * np.eye(system.n))
        return sol, system.residual_matrix(sol.x) / max(system.m - system.p, 1)


@pytest.fixture
def toy():
    """The toy friction model and estimator registered for one test, and forgotten after it."""
    register_friction_model(ToyFriction)
    register_estimator(DoubledOLS)
    yield ToyFriction
    FRICTION_MODELS.remove("toy")
    ESTIMATORS.remove("toy_ols")


@pytest.fixture(scope="module")
def toy_data(ur5):
    """A UR5 whose only friction is ``kv2 dq |dq|`` per joint (exact states, little noise)."""
    rng = np.random.default_rng(35)
    cols = column_set(ur5)
    x = true_parameters(cols)  # the URDF's bodies; armature and linear friction zero
    return synthetic_dataset(
        cols,
        x,
        random_fourier(ur5, rng),
        rate=50,
        rng=rng,
        noise=0.01,
        extra=lambda q, dq: KV2 * dq * np.abs(dq),
    )


# ---------------------------------------------------------------------------- the registries
def test_builtin_entries_are_classes_of_the_base_under_their_own_names() -> None:
    assert FRICTION_MODELS.names() == ("none", "linear", "seed", "seed_shared", "stribeck", "sigmoid")
    for name in FRICTION_MODELS:
        cls = FRICTION_MODELS[name]
        assert issubclass(cls, FrictionModel) and cls.name == name
        assert cls().__class__ is cls  # a model file rebuilds it without arguments
    assert ESTIMATORS.names() == ("ols", "wls", "gls", "irls")
    for name in ESTIMATORS:
        assert issubclass(ESTIMATORS[name], LinkEstimator) and ESTIMATORS[name].method == name
    assert method_names() == (*ESTIMATORS.names(), *CONSTRAINED_METHODS)


def test_the_names_load_without_the_heavy_modules() -> None:
    """The command modules read the names when ``dynid --help`` builds its parser: no SciPy, no CasADi."""
    code = (
        "import sys, dynid.cli; dynid.cli.build_parser(); "
        "from dynid.identify.registry import FRICTION_MODELS, method_names; FRICTION_MODELS.names(); method_names(); "
        "print(sorted(m for m in ('scipy', 'casadi', 'pinocchio', 'sklearn', 'dynid.identify.friction') "
        "if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=REPO)
    assert out.stdout.strip() == "[]"


def _choices(module, option: str) -> tuple[str, ...]:
    parser = argparse.ArgumentParser()
    module.add_arguments(parser)
    (action,) = [a for a in parser._actions if option in a.option_strings]
    return tuple(action.choices)


def test_the_command_line_choices_are_the_registries(toy) -> None:
    assert _choices(identify_command, "--friction") == ("auto", *FRICTION_MODELS.names())
    assert _choices(identify_command, "--method") == ("auto", *method_names())
    assert _choices(fleet_command, "--friction") == FRICTION_MODELS.names()
    assert _choices(fleet_command, "--method") == method_names()
    assert "toy" in FRICTION_MODELS.names() and "toy_ols" in method_names()


def test_the_docs_list_the_registries() -> None:
    """The friction and estimator modules' tables name every built-in entry; a choice list written out in
    the README or docs/ (``--friction {a,b}``) is the registry's."""
    from dynid.identify import estimators, friction_models

    for name in FRICTION_MODELS:
        assert re.search(rf"^``{name}``\s", friction_models.__doc__, flags=re.M), name
    for name in ESTIMATORS:
        assert re.search(rf"^{name.upper()}\s", estimators.__doc__, flags=re.M), name
    registry = {"--friction": set(FRICTION_MODELS), "--method": set(method_names())}
    for path in [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]:
        for option, listed in re.findall(r"(--friction|--method) \{([a-z_,]+)\}", path.read_text()):
            assert set(listed.split(",")) - {"auto"} == registry[option], f"{path.name}: {option} {{{listed}}}"


def test_registration_refuses_what_the_registry_cannot_use(toy) -> None:
    class NoColumns(FrictionModel):
        name = "no_columns"

    class NeedsArgument(ToyFriction):
        name = "needs_argument"

        def __init__(self, scale: float) -> None:
            self.scale = scale

    class Auto(ToyFriction):
        name = "auto"

    class Consistent(OLS):
        method = "consistent"

    class Taken(ToyFriction):
        pass  # the name "toy" again

    with pytest.raises(UsageError, match="is not a friction model; subclass"):
        register_friction_model(OLS)
    with pytest.raises(UsageError, match="does not define columns"):
        register_friction_model(NoColumns)
    with pytest.raises(UsageError, match="needs the arguments scale; give every constructor argument a default"):
        register_friction_model(NeedsArgument)
    with pytest.raises(UsageError, match="has the name 'auto'"):
        register_friction_model(Auto)
    with pytest.raises(UsageError, match="name 'toy' is taken by ToyFriction"):
        register_friction_model(Taken)
    with pytest.raises(UsageError, match="has the method name 'consistent'"):
        register_estimator(Consistent)
    with pytest.raises(UsageError, match="is not a layer-1 estimator"):
        register_estimator(ToyFriction)
    assert register_friction_model(ToyFriction) is ToyFriction  # the same class again: no change
    assert FRICTION_MODELS["toy"] is ToyFriction


# ---------------------------------------------------------------------------- a friction model of one's own
def test_a_registered_friction_model_is_identified(ur5, toy_data, toy) -> None:
    model = identify(ur5, toy_data, method="ols", friction="toy", gmm="off", reference_weight=0.0)
    assert model.friction.model == "toy"
    assert all(isinstance(m, ToyFriction) for m in model.friction.models_)
    kv2 = np.array([m.coef_[0] for m in model.friction.models_])
    np.testing.assert_allclose(kv2, KV2, rtol=0.02, atol=0.005)
    assert np.max(model.rms_layers["friction"]) < 0.1  # N m: the toy model explains the friction


def test_a_registered_friction_model_runs_from_the_command_line(ur5, toy_data, toy, tmp_path) -> None:
    data = tmp_path / "D.csv"
    save_dataset(toy_data, data)
    out, figs = tmp_path / "M.json", tmp_path / "F.json"
    argv = ["identify", "--robot", "ur5", "--data", str(data), "--method", "toy_ols", "--friction", "toy"]
    argv += ["--gmm", "off", "--reference-weight", "0", "--out", str(out), "--json", str(figs)]
    assert main(argv) == 0
    figures = json.loads(figs.read_text())
    assert figures["friction"]["model"] == "toy" and figures["method"] == "toy_ols"
    loaded = load_model(out)
    assert loaded.friction.model == "toy"
    kv2 = [m.coef_[0] for m in loaded.friction.models_]
    np.testing.assert_allclose(kv2, [j["kv2"] for j in figures["friction"]["joints"]], rtol=1e-12)
    np.testing.assert_allclose(kv2, KV2, rtol=0.02, atol=0.005)
    # the model file reads back only where the model is registered
    FRICTION_MODELS.remove("toy")
    try:
        with pytest.raises(ModelFileError, match=r"friction model 'toy' is not registered.*register_friction_model"):
            load_model(out)
    finally:
        register_friction_model(ToyFriction)


def test_the_export_lists_a_friction_model_it_cannot_carry(ur5, toy_data, toy, tmp_path) -> None:
    """The toy model says nothing of simulators: it is listed, and what is written is the straight line
    closest to it at the training speeds (a file without them: no damping or frictionloss)."""
    from dataclasses import replace

    model = identify(ur5, toy_data, method="ols", friction="toy", gmm="off", reference_weight=0.0)
    params = simulator_parameters(model)
    (item,) = [i for i in params.not_carried if i["what"] == "toy friction"]
    assert item["joints"] == [1, 2, 3, 4, 5, 6]
    assert "no simulator field" in item["detail"] and "the straight line closest" in item["detail"]
    for j, mdl in enumerate(model.friction.models_):
        assert (params.damping[j], params.frictionloss[j]) == mdl.simulator_line(model.info["speed_quantiles"][j])
    assert np.all(params.damping + params.frictionloss > 0)
    save_model(model, tmp_path / "M.json")
    assert simulator_parameters(load_model(tmp_path / "M.json")).not_carried == params.not_carried
    old = simulator_parameters(replace(model, info={k: v for k, v in model.info.items() if k != "speed_quantiles"}))
    assert np.all(old.damping == 0) and np.all(old.frictionloss == 0)
    (item,) = [i for i in old.not_carried if i["what"] == "toy friction"]
    assert "no damping and frictionloss were written for it" in item["detail"]


def test_builtin_friction_models_say_what_a_simulator_holds() -> None:
    """The export's terms come from the models: the linear model is carried whole, the seed model's
    asymmetry and quadratic term are listed."""
    linear = FrictionLayer.from_dict({"model": "linear", "joints": [{"fc": 1.0, "fv": 0.5, "fo": 0.0}]})
    assert linear.models_[0].simulator_terms() == (0.5, 1.0, ())
    seed = FrictionLayer.from_dict(
        {
            "model": "seed",
            "joints": [
                {"kc_pos": 1.0, "kc_neg": 0.8, "kv1": 0.4, "kv2": 0.1, "kv3": 0.0, "ks_pos": 1.0, "ks_neg": 0.8,
                 "lam": 0.05}
            ],
        }
    )
    damping, loss, left = seed.models_[0].simulator_terms()
    assert (damping, loss) == (0.4, pytest.approx(0.9))
    assert left == ("direction-dependent Coulomb friction", "nonlinear viscous friction")
    assert set(left) <= set(type(seed.models_[0]).simulator_items())


def test_a_registered_estimator_is_a_method(ur5, toy_data, toy) -> None:
    toy_fit = ESTIMATORS["toy_ols"](robot=ur5).fit(toy_data)
    ols = OLS(robot=ur5).fit(toy_data)
    np.testing.assert_allclose(toy_fit.params_, ols.params_, rtol=1e-8, atol=1e-10)
    model = identify(ur5, toy_data, method="toy_ols", friction="linear", gmm="off", reference_weight=0.0)
    assert model.method == "toy_ols"
    with pytest.raises(UsageError, match="unknown method 'nope'; choose one of auto, ols, wls, gls, irls, toy_ols"):
        identify(ur5, toy_data, method="nope")
