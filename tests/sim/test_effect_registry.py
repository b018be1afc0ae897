"""An unmodelled effect of one's own, added through the catalogue's registry.

The target of the house's third step: adding an unmodelled effect touches at most three files (its class
in ``dynid/sim/effect_classes.py``, its column builder in ``dynid/identify/effect_builders.py``, a test).
Here it touches one (this one): a toy effect registered from the test is simulated by
``dynid simulate --effects toy@2``, diagnosed by ``dynid diagnose --effects toy,...`` and named on its
joint, all in the same process, and forgotten after.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np
import pytest

from dynid.cli import main
from dynid.data.files import load_dataset
from dynid.diagnosis.candidates import CANDIDATES, excitation_hint
from dynid.diagnosis.settings import DiagnosisSettings
from dynid.exceptions import UsageError
from dynid.identify.effect_builders import BUILDERS, EFFECT_GRIDS, Candidate
from dynid.identify.effect_terms import parse_effect_terms
from dynid.identify.model import identify, save_model
from dynid.sim.cases import case_excitation
from dynid.sim.effects import (
    EFFECT_NAMES,
    EFFECTS,
    Effect,
    effect_names,
    parse_effects,
    register_effect,
    unregister_effect,
)


@dataclass(frozen=True, eq=False)
class AngleViscous(Effect):
    """Viscous friction that varies with the angle, ``c (1 + cos x) dx`` (a seal pressed harder on one side).

    Its ``c dx`` part is the model's viscous friction; ``c cos(x) dx`` is no catalogue candidate's column.
    """

    name: ClassVar[str] = "toy"
    role: ClassVar[str] = "drive"
    summary: ClassVar[str] = "viscous friction c (1 + cos q) dq, c v = 5% of the torque scale"
    excites: ClassVar[str] = "fast motion of joint {j} over a wide range of angles"
    coef: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @classmethod
    def build(cls, ctx, value, joints, rng):
        c = np.zeros(ctx.robot.n)
        js = list(joints)
        c[js] = 0.05 * value * ctx.scales.torque[js] / ctx.scales.speed[js]
        return cls(value, joints, coef=c)

    def drive(self, t, x, dx, tau_m):
        g = self.coef * (1.0 + np.cos(x))
        return g * dx, g

    def details(self):
        return {"c": self.coef, "units": "N m s/rad"}


def angle_viscous_columns(src, cand: Candidate) -> np.ndarray:
    """``cos(q_j) dq_j`` on the candidate's joint: (M, n, 1)."""
    out = np.zeros((src.m, src.n, 1))
    j = cand.joint
    out[:, j, 0] = np.cos(src.q[:, j]) * src.dq[:, j]
    return out


@pytest.fixture
def toy():
    """The toy effect registered for one test, and forgotten after it."""
    register_effect(AngleViscous, angle_viscous_columns)
    yield AngleViscous
    unregister_effect("toy")


# ---------------------------------------------------------------------------- the catalogue
def test_a_registered_effect_joins_every_list_and_leaves_it(toy) -> None:
    assert effect_names() == (*EFFECT_NAMES, "toy")
    assert EFFECTS["toy"] is AngleViscous and BUILDERS["toy"] is angle_viscous_columns
    assert parse_effects("toy@2:2")[0].joints == (2,)  # simulate --effects
    (term,) = parse_effect_terms("toy@2", 6)  # identify --effects
    assert (term.effect, term.joint) == ("toy", 1)
    assert DiagnosisSettings().effects == effect_names()  # diagnose's default catalogue
    assert tuple(CANDIDATES) == effect_names() and CANDIDATES["toy"].per_joint
    assert excitation_hint(term) == "fast motion of joint 2 over a wide range of angles"
    unregister_effect("toy")
    assert effect_names() == EFFECT_NAMES and "toy" not in BUILDERS and "toy" not in CANDIDATES
    with pytest.raises(UsageError, match="unknown effect 'toy'"):
        parse_effects("toy")
    with pytest.raises(UsageError, match="unknown effect 'toy'"):
        parse_effect_terms("toy", 6)
    with pytest.raises(UsageError, match="unknown effect 'toy'"):
        DiagnosisSettings(effects=("toy",))
    register_effect(AngleViscous, angle_viscous_columns)  # the fixture forgets it again


def test_simulate_help_names_a_registered_effect(toy, capsys) -> None:
    with pytest.raises(SystemExit):
        main(["simulate", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "toy (viscous friction c (1 + cos q) dq, c v = 5% of the torque scale). Example:" in text


def test_builtin_effects_keep_their_grids_and_descriptions() -> None:
    """What the diagnosis reads of a built-in effect: per joint where the simulator takes a joint, the
    identify side's grid, the class's words."""
    for name in EFFECT_NAMES:
        spec = CANDIDATES[name]
        assert spec.per_joint == EFFECTS[name].selectable
        assert spec.grid is EFFECT_GRIDS.get(name)
        assert spec.excites and spec.excites == EFFECTS[name].excites
        assert EFFECTS[name].summary, name


def test_registration_refuses_what_the_catalogue_cannot_use(toy) -> None:
    class NoDrive(AngleViscous):
        name = "no_drive"
        drive = Effect.drive

    class Sensor(AngleViscous):
        name = "toy_sensor"
        role = "sensor"

    class Builtin(AngleViscous):
        name = "stribeck"

    class Taken(AngleViscous):
        pass  # the name "toy" again

    class Shouting(AngleViscous):
        name = "Toy"

    cases = [
        ((int, angle_viscous_columns), r"^int is not an effect; subclass dynid\.sim\.effects\.Effect\.$"),
        ((Effect, angle_viscous_columns), r"^Effect is not an effect; subclass"),
        ((AngleViscous, None), r"^the effect 'toy' has no column builder; give register_effect\(AngleViscous, builder\)"),
        ((AngleViscous, "columns"), r"^the effect 'toy' has no column builder"),
        ((NoDrive, angle_viscous_columns), r"^the effect 'no_drive' \(NoDrive\) does not define drive"),
        ((Sensor, angle_viscous_columns), r"^the effect 'toy_sensor' has the role 'sensor'; an effect of one's own"),
        ((Builtin, angle_viscous_columns), r"^the effect name 'stribeck' is a built-in effect's"),
        ((Taken, angle_viscous_columns), r"^the effect name 'toy' is taken by AngleViscous; choose another name"),
        ((Shouting, angle_viscous_columns), r"^the effect Shouting has the name 'Toy'; give it a name of lower case"),
    ]
    for args, message in cases:
        with pytest.raises(UsageError, match=message) as err:
            register_effect(*args)
        assert str(err.value).count(". ") == 0 and str(err.value).endswith("."), str(err.value)  # one sentence
    assert effect_names() == (*EFFECT_NAMES, "toy")  # nothing refused was added
    assert register_effect(AngleViscous, angle_viscous_columns) is AngleViscous  # the same again: no change
    assert register_effect(Taken, angle_viscous_columns, replace=True) is Taken
    assert EFFECTS["toy"] is Taken and effect_names()[-1] == "toy"
    with pytest.raises(UsageError, match="is built in; only registered effects can be forgotten"):
        unregister_effect("stribeck")


# ---------------------------------------------------------------------------- simulated and diagnosed
def test_a_registered_effect_is_simulated_and_diagnosed_on_its_joint(ur5, toy, tmp_path) -> None:
    case_excitation(ur5, 14).save(tmp_path / "T.json")
    case_excitation(ur5, 15).save(tmp_path / "T2.json")
    common = ["--robot", "ur5", "--duration", "20", "--rate", "200", "--effects", "toy@2:3"]
    for traj, out, seed in (("T.json", "D.csv", "1"), ("T2.json", "V.csv", "2")):
        argv = ["simulate", "--trajectory", str(tmp_path / traj), "--seed", seed, "--truth-seed", "3"]
        assert main([*argv, *common, "--out", str(tmp_path / out)]) == 0
    truth = json.loads((tmp_path / "D.csv.truth.json").read_text())
    (realised,) = truth["effects"]
    assert (realised["name"], realised["joints"]) == ("toy", [2]) and realised["c"][1] > 0

    model = identify(ur5, load_dataset(tmp_path / "D.csv"), method="ols", friction="linear", gmm="off")
    save_model(model, tmp_path / "M.json")
    argv = ["diagnose", "--model", str(tmp_path / "M.json"), "--data", str(tmp_path / "D.csv")]
    argv += ["--heldout", str(tmp_path / "V.csv"), "--effects", "toy,nonlinear_viscous,stribeck"]
    assert main([*argv, "--json", str(tmp_path / "G.json")]) == 0
    found = json.loads((tmp_path / "G.json").read_text())
    assert found["verdict"] == ["toy"], found["verdict"]
    (accepted,) = found["accepted"]
    assert (accepted["effect"], accepted["joint"]) == ("toy", 2)  # named on its joint (from 1)
