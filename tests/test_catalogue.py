"""The ONE effect catalogue: the simulator, the diagnosis, the command line and the docs name the same effects.

:data:`dynid.sim.effects.EFFECT_NAMES` (derived from :data:`dynid.sim.effects.EFFECTS`) is the
catalogue; everything else that lists effects must list exactly these, and the diagnosis must be able
to test every one of them.  Fast: nothing is simulated.
"""

from __future__ import annotations

import re

import pytest

import dynid.diagnosis.candidates as candidates
import dynid.sim.effects as effects
from dynid.cli import main
from dynid.exceptions import UsageError

# The catalogue's order is part of the diagnosis' behaviour: it breaks ties between candidates.
ORDER = (
    "offset",
    "armature",
    "stribeck",
    "load_friction",
    "temperature",
    "cogging",
    "elasticity",
    "backlash",
    "delay",
    "drive_gain",
    "payload",
    "base_tilt",
    "coupled_friction",
    "nonlinear_viscous",
)


def _table_names(doc: str, header: str) -> list[str]:
    """First-column entries of the reStructuredText table of ``doc`` whose first header cell is ``header``."""
    lines = doc.splitlines()
    start = next(
        i for i, line in enumerate(lines) if line.split()[:1] == [header] and lines[i - 1].startswith("=")
    )
    names = []
    for line in lines[start + 2 :]:
        if line.startswith("="):
            break
        if line and not line[0].isspace():
            names.append(line.split()[0])
    return names


def _top_level_items(text: str) -> list[str]:
    """``a (x, y), b (z)`` -> ``["a (x, y)", "b (z)"]``: comma-separated items outside parentheses."""
    items, depth, current = [], 0, []
    for ch in text:
        depth += {"(": 1, ")": -1}.get(ch, 0)
        if ch == "," and depth == 0:
            items.append("".join(current).strip())
            current = []
        else:
            current.append(ch)
    items.append("".join(current).strip())
    return [item for item in items if item]


def test_the_catalogue_is_the_effect_classes_in_order():
    assert effects.EFFECT_NAMES == tuple(effects.EFFECTS) == ORDER
    assert isinstance(effects.EFFECT_NAMES, tuple)


def test_the_diagnosis_reads_the_same_catalogue():
    assert candidates.EFFECT_NAMES is effects.EFFECT_NAMES


def test_the_diagnosis_has_a_candidate_for_every_effect_and_no_other():
    assert tuple(candidates.CANDIDATES) == effects.EFFECT_NAMES


def test_every_effect_has_feature_columns_or_the_parameter_change_test():
    """Columns for every effect but those re-identification absorbs whole (payload: a parameter change)."""
    builders = set(candidates._BUILDERS)
    assert builders <= set(effects.EFFECT_NAMES), builders - set(effects.EFFECT_NAMES)
    without = set(effects.EFFECT_NAMES) - builders
    assert without == {"payload"}
    assert without <= set(candidates.PARAMETRIC_EFFECTS)
    assert set(candidates.PARAMETRIC_EFFECTS) <= set(effects.EFFECT_NAMES)


def test_the_simulator_docs_list_the_catalogue_in_order():
    assert tuple(_table_names(effects.__doc__, "name")) == effects.EFFECT_NAMES


def test_the_diagnosis_docs_list_the_catalogue():
    names = _table_names(candidates.__doc__, "effect")
    assert sorted(names) == sorted(effects.EFFECT_NAMES)


def test_simulate_help_names_the_catalogue_in_order(capsys):
    with pytest.raises(SystemExit) as stop:
        main(["simulate", "--help"])
    assert stop.value.code == 0
    text = " ".join(capsys.readouterr().out.split())
    listed = text.split("Names:", 1)[1].split(". Example:", 1)[0]
    names = tuple(item.split()[0] for item in _top_level_items(listed))
    assert names == effects.EFFECT_NAMES


def test_an_unknown_effect_names_the_catalogue():
    with pytest.raises(UsageError) as err:
        effects.parse_effects("friction_drift")
    message = str(err.value)
    listed = re.search(r"the known effects are (.*)\.$", message)
    assert listed is not None, message
    assert tuple(listed.group(1).split(", ")) == effects.EFFECT_NAMES
