"""The ONE effect catalogue: the simulator, the diagnosis, the command line and the docs name the same effects.

:data:`dynid.sim.effects.EFFECT_NAMES` (derived from :data:`dynid.sim.effects.EFFECTS`) is the
catalogue; everything else that lists effects must list exactly these, and the diagnosis must be able
to test every one of them.  Fast: nothing is simulated.
"""

from __future__ import annotations

import itertools
import math
import re

import numpy as np
import pytest

import dynid.diagnosis.candidates as candidates
import dynid.identify.effect_builders as effect_builders
import dynid.sim.effect_classes as effect_classes
import dynid.sim.effects as effects
from dynid.cli import main
from dynid.diagnosis.screening import _nested
from dynid.diagnosis.stats import principal_angles
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
    """The table beside the classes (:mod:`dynid.sim.effect_classes`)."""
    assert tuple(_table_names(effect_classes.__doc__, "name")) == effects.EFFECT_NAMES


def test_the_diagnosis_docs_list_the_catalogue():
    """The table of columns beside the builders (:mod:`dynid.identify.effect_builders`)."""
    names = _table_names(effect_builders.__doc__, "effect")
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


# Candidates whose columns contain a simpler one's by design, (simpler, richer): the motor-inertia column
# of a flexible transmission is the armature's; backlash's first-order columns hold the teeth's stiffness,
# elasticity's column.  The simpler-candidate test (dynid.diagnosis.screening.parsimonious) tells them
# apart, which needs the nesting to be exact.
NESTED = {("armature", "elasticity"), ("armature", "backlash"), ("elasticity", "backlash")}
MIN_ANGLE_DEG = 5.0  # below this, two candidates' columns are one column under two names


def _generic_source(ur5):
    """A generic random motion of the UR5 and an unrelated random torque: no column is tied to another by
    the motion (a torque that never changes sign, a wrist torque that is mostly friction), only by the
    catalogue's algebra."""
    rng = np.random.default_rng(37)
    fs, m, n = 100.0, 800, ur5.n
    t = np.arange(m) / fs

    def smooth(scale):
        w = 2 * math.pi * rng.uniform(0.05, 1.5, size=(5, n))
        a, p = rng.normal(size=(5, n)), rng.uniform(0, 2 * math.pi, size=(5, n))
        x = sum(a[k] * np.sin(np.outer(t, w[k]) + p[k]) for k in range(5))
        dx = sum(a[k] * w[k] * np.cos(np.outer(t, w[k]) + p[k]) for k in range(5))
        ddx = sum(-a[k] * w[k] ** 2 * np.sin(np.outer(t, w[k]) + p[k]) for k in range(5))
        return scale * x, scale * dx, scale * ddx

    q, dq, ddq = smooth(0.5)
    tau = smooth(10.0)[0] + rng.normal(size=(m, n))
    return candidates.FeatureSource(
        t=t, q=q, dq=dq, ddq=ddq, tau_pred=tau, robot=ur5, fs=fs, runs=[slice(0, m)]
    )


def test_no_two_candidates_on_a_joint_span_the_same_columns(ur5):
    """Every pair of candidates acting on one joint (every hyper-parameter variant of the screen) has
    columns at least 5 degrees apart on a generic motion, unless one is nested in the other by design
    (then exactly, and with fewer columns).  Issue 37, item 5: load friction's second column
    sign(dq) |tau| sign(dq tau) is tau, the drive gain's column, and the two tied on every joint."""
    src = _generic_source(ur5)
    groups = candidates.enumerate_candidates(src, effects.EFFECT_NAMES, motor_inertia=True)
    cols = {}
    for group in groups:
        for cand in group:
            C = candidates.candidate_columns(src, cand)
            cols[(cand.key, repr(sorted(cand.hyper.items())))] = (cand, C.reshape(-1, C.shape[2]))
    tied = []
    for (a, A), (b, B) in itertools.combinations(cols.values(), 2):
        if a.key == b.key or not set(a.joints) & set(b.joints):
            continue
        if (a.effect, b.effect) in NESTED or (b.effect, a.effect) in NESTED:
            small, big = ((a, A), (b, B)) if (a.effect, b.effect) in NESTED else ((b, B), (a, A))
            assert _nested(small[1][:, None, :], big[1][:, None, :]), (small[0].key, big[0].key)
            assert small[1].shape[1] < big[1].shape[1]
            continue
        angle = math.degrees(float(principal_angles(A, B)[0]))
        if angle < MIN_ANGLE_DEG:
            tied.append((a.key, b.key, round(angle, 2)))
    assert not tied, tied
