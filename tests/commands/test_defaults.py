"""Defaults held once: every signature that mirrors a settings object agrees with it, and passes it on.

A convenience function that repeats the keywords of what it builds (``identify`` -> ``ThreeLayerModel``,
``diagnose`` -> ``DiagnosisSettings``, ``simulate`` -> ``build_truth``) and a command whose options repeat a
library default must not drift from it: python-control keeps its defaults in one place and tests them;
here the settings objects are that place, and this file holds every mirror to them.
"""

from __future__ import annotations

import argparse
import dataclasses
import inspect

import numpy as np
import pytest

from dynid.commands import diagnose as diagnose_command
from dynid.commands import excite as excite_command
from dynid.commands import fleet as fleet_command
from dynid.commands import identify as identify_command
from dynid.commands import simulate as simulate_command
from dynid.data.preparation import Preprocessing
from dynid.diagnosis import core as diagnosis_core
from dynid.diagnosis.candidates import EFFECT_NAMES
from dynid.diagnosis.settings import DiagnosisSettings
from dynid.exceptions import UsageError
from dynid.fleet.core import FleetSettings, identify_fleet
from dynid.identify import model as identify_model
from dynid.identify.model import ThreeLayerModel, identify
from dynid.optim.excitation import ExcitationProblem, design_excitation
from dynid.sim.effects import FRICTION_KINDS
from dynid.sim.simulator import simulate
from dynid.sim.synthetic import random_fourier
from dynid.sim.truth import build_truth

EMPTY = inspect.Parameter.empty


def _keywords(func, skip: tuple[str, ...] = ()) -> dict[str, inspect.Parameter]:
    """The keyword-only parameters of ``func`` (its keyword arguments), less ``skip``."""
    return {
        name: p
        for name, p in inspect.signature(func).parameters.items()
        if p.kind is p.KEYWORD_ONLY and name not in skip
    }


def _field_defaults(cls) -> dict[str, object]:
    return {f.name: f.default for f in dataclasses.fields(cls)}


def _parser(module) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser()
    module.add_arguments(parser)
    return parser


# ---------------------------------------------------------------------------- library mirrors
def test_identify_mirrors_three_layer_model() -> None:
    """``identify(robot, data, **kw)`` takes exactly ThreeLayerModel's keywords, with its defaults and types."""
    mine = _keywords(identify)
    theirs = _keywords(ThreeLayerModel.__init__, skip=("robot",))
    assert list(mine) == list(theirs)
    for name, p in theirs.items():
        assert p.default is not EMPTY, name
        assert (mine[name].default, mine[name].annotation) == (p.default, p.annotation), name


def test_identify_passes_every_keyword_on(monkeypatch) -> None:
    seen: dict = {}

    class Recorder:
        def __init__(self, **kwargs) -> None:
            seen.update(kwargs)
            self.model_ = "the model"

        def fit(self, data):
            seen["data"] = data
            return self

    monkeypatch.setattr(identify_model, "ThreeLayerModel", Recorder)
    values = {name: object() for name in _keywords(ThreeLayerModel.__init__, skip=("robot",))}
    assert identify("robot", "data", **values) == "the model"
    assert seen == {"robot": "robot", "data": "data", **values}


def test_diagnose_mirrors_diagnosis_settings() -> None:
    """``diagnose(model, train, heldout, robot=..., **settings)``: the settings' fields, with their defaults."""
    mine = _keywords(diagnosis_core.diagnose, skip=("robot",))
    fields = _field_defaults(DiagnosisSettings)
    assert list(mine) == list(fields)
    assert {name: p.default for name, p in mine.items()} == fields


def _other_value(name: str, default):
    """A valid value of a DiagnosisSettings field other than its default."""
    if name == "effects":
        return tuple(EFFECT_NAMES[:2])
    if name == "period":
        return 2.5
    if isinstance(default, bool):
        return not default
    if isinstance(default, int):
        return default + 1
    return default * 0.5  # every float field is a positive size or rate


def test_diagnose_passes_every_setting_on(monkeypatch) -> None:
    seen: dict = {}

    def recorder(model, train, heldout, settings, *, robot=None):
        seen.update(model=model, train=train, heldout=heldout, settings=settings, robot=robot)
        return "the diagnosis"

    monkeypatch.setattr(diagnosis_core, "run_diagnosis", recorder)
    values = {name: _other_value(name, d) for name, d in _field_defaults(DiagnosisSettings).items()}
    assert all(values[k] != d for k, d in _field_defaults(DiagnosisSettings).items())
    assert diagnosis_core.diagnose("m", "d", "v", robot="r", **values) == "the diagnosis"
    assert seen["settings"] == DiagnosisSettings(**values)
    assert (seen["model"], seen["train"], seen["heldout"], seen["robot"]) == ("m", "d", "v", "r")


def test_simulate_mirrors_build_truth() -> None:
    """simulate's truth options are build_truth's; its truth seed defaults to its ``seed``, whose default is
    build_truth's ``truth_seed``."""
    mine, theirs = _keywords(simulate), _keywords(build_truth)
    for name in ("effects", "friction", "perturb"):
        assert (mine[name].default, mine[name].annotation) == (theirs[name].default, theirs[name].annotation), name
    assert mine["truth_seed"].default is None
    assert mine["seed"].default == theirs["truth_seed"].default


@pytest.fixture(scope="module")
def truth_and_motion(ur5):
    return build_truth(ur5), random_fourier(ur5, np.random.default_rng(3))


@pytest.mark.parametrize(
    "options, named",
    [
        ({"effects": "offset"}, "effects"),
        ({"friction": "seed"}, "friction"),
        ({"perturb": 0.1}, "perturb"),
        ({"truth_seed": 4}, "truth_seed"),
        ({"effects": "offset", "perturb": 0.1}, "effects, perturb"),
    ],
)
def test_simulate_refuses_truth_options_beside_a_truth(ur5, truth_and_motion, options, named) -> None:
    truth, motion = truth_and_motion
    with pytest.raises(UsageError, match=rf"^simulate got truth= and also {named}, which the truth fixes already"):
        simulate(ur5, motion, truth=truth, duration=0.01, **options)


def test_simulate_takes_the_defaults_beside_a_truth(ur5, truth_and_motion) -> None:
    truth, motion = truth_and_motion
    defaults = {name: _keywords(simulate)[name].default for name in ("effects", "friction", "perturb", "truth_seed")}
    run = simulate(ur5, motion, truth=truth, duration=0.01, noise="off", **defaults)
    assert run.truth is truth


# ---------------------------------------------------------------------------- command-line mirrors
# option dest -> (the library object whose default it repeats, its parameter or field)
COMMAND_DEFAULTS = {
    identify_command: {
        "method": (identify, "method"),
        "friction": (identify, "friction"),
        "gmm": (identify, "gmm"),
        "rounds": (identify, "rounds"),
        "gmm_mode": (identify, "gmm_mode"),
        "reference_weight": (identify, "reference_weight"),
        "cutoff": (Preprocessing, "cutoff"),
    },
    fleet_command: {
        **{f: (FleetSettings, f) for f in ("method", "friction", "gmm", "cutoff", "holdout", "diagnose", "degrees")},
        "topic": (FleetSettings, "topic"),
        "alpha": (identify_fleet, "alpha"),
        "workers": (identify_fleet, "workers"),
        "serial": (identify_fleet, "serial"),
    },
    diagnose_command: {
        "alpha": (DiagnosisSettings, "alpha"),
        "max_effects": (DiagnosisSettings, "max_effects"),
        "period": (DiagnosisSettings, "period"),
    },
    simulate_command: {
        "friction": (simulate, "friction"),
        "seed": (simulate, "seed"),
        "truth_seed": (simulate, "truth_seed"),
        "perturb": (simulate, "perturb"),
        "rate": (simulate, "rate"),
    },
    excite_command: {
        "harmonics": (ExcitationProblem, "harmonics"),
        "base_freq": (ExcitationProblem, "base_freq"),
        "criterion": (ExcitationProblem, "criterion"),
        "trajectories": (design_excitation, "trajectories"),
        "seed": (design_excitation, "seed"),
        "patience": (design_excitation, "patience"),
        "max_tries": (design_excitation, "max_tries"),
        "baseline": (design_excitation, "baseline"),
        "polish": (design_excitation, "polish"),
    },
}


def _library_default(owner, name: str):
    if dataclasses.is_dataclass(owner):
        return _field_defaults(owner)[name]
    default = inspect.signature(owner).parameters[name].default
    assert default is not EMPTY, f"{owner.__name__}({name}) has no default"
    return default


@pytest.mark.parametrize("module", list(COMMAND_DEFAULTS), ids=lambda m: m.__name__.rsplit(".", 1)[-1])
def test_command_defaults_are_the_librarys(module) -> None:
    parser = _parser(module)
    for dest, (owner, name) in COMMAND_DEFAULTS[module].items():
        assert parser.get_default(dest) == _library_default(owner, name), f"--{dest.replace('_', '-')}"


def test_identify_command_flags_default_to_the_librarys() -> None:
    parser = _parser(identify_command)
    assert parser.get_default("unconstrained") is (not _library_default(identify, "physical"))
    # no --decimate: the library's every sample, thinned only past the memory budget; --decimate 1: never
    assert parser.get_default("decimate") is None
    assert _field_defaults(Preprocessing)["decimate"] == 1 and _field_defaults(Preprocessing)["thin"] is True


@pytest.mark.parametrize(("argv", "expected"), [([], Preprocessing()), (["--decimate", "1"], Preprocessing(thin=False))])
def test_identify_command_passes_the_decimation_on(ur5, tmp_path, monkeypatch, argv, expected) -> None:
    """No --decimate is the library's default (thinned past the memory budget); --decimate 1 keeps all."""
    from dynid.cli import main
    from dynid.sim.simulator import write_simulation

    run = simulate(ur5, random_fourier(ur5, np.random.default_rng(0)), duration=0.2, seed=1, friction="linear")
    data, _ = write_simulation(run, tmp_path / "D.csv")
    seen = {}

    def recorder(robot, dataset, **kwargs):
        seen.update(kwargs)
        raise KeyboardInterrupt  # stop before the fit: the keywords are what is tested

    monkeypatch.setattr(identify_model, "identify", recorder)
    main(["identify", "--robot", "ur5", "--data", str(data), "--out", str(tmp_path / "M.json"), *argv])
    assert seen["preprocessing"] == expected
    assert not (tmp_path / "M.json").exists()


def test_simulate_command_friction_choices_are_the_truth_kinds() -> None:
    (action,) = [a for a in _parser(simulate_command)._actions if "--friction" in a.option_strings]
    assert tuple(action.choices) == FRICTION_KINDS
