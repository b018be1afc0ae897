"""The verdict and its notes (dynid.diagnosis.verdict) on hand-made stage records.

A verdict of none beside a candidate reported significant must say why that candidate is not named: it
closes too little of its joints' gap (issue 37: what is reported significant is a finding the verdict
accounts for), and which motion would show it larger.
"""

from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace

import numpy as np

from dynid.diagnosis.candidates import Candidate
from dynid.diagnosis.result import RankedCandidate
from dynid.diagnosis.settings import DiagnosisSettings
from dynid.diagnosis.verdict import small_candidate_notes, verdict_and_notes

STD = np.array([0.1, 0.2])


def _ranked(effect, joint, closure, *, significant=True, p_holm=1e-3):
    cand = Candidate(effect, joint, (joint,), {}, f"{effect} on joint {joint + 1}")
    return RankedCandidate(cand, 0.2, closure, p_holm / 10, p_holm, significant=significant)


def _verdict(ranking, *, significant_joint=(False, False), accepted=()):
    sel = SimpleNamespace(accepted=list(accepted), notes=[], ranking=list(ranking))
    excess = {"significant": any(significant_joint), "significant_joint": np.array(significant_joint)}
    consistency = SimpleNamespace(leads=lambda alpha: np.zeros(2, dtype=bool))
    noise = SimpleNamespace(std=STD, method="periods", std_interval=lambda level: (STD, STD))
    base = SimpleNamespace(settled=True, passes=1)
    return verdict_and_notes(sel, excess, consistency, None, noise, base, DiagnosisSettings(), ["j1", "j2"])


def test_a_significant_candidate_beside_none_is_explained_with_its_deciding_motion():
    small = _ranked("stribeck", 1, 0.3)
    verdict, notes = _verdict([small, _ranked("offset", 0, 0.9, significant=False)])
    assert verdict == ["none"]
    said = [n for n in notes if "beyond chance" in n]
    assert said == [
        "stribeck on joint 2 lowers the held-out error beyond chance (adjusted p = 0.001) but closes 30 % of the "
        "gap to the floor on its joints, less than the 50 % a cause must close where no joint's excess is "
        "significant: it is not named.  If it is there, a recording with slow motion and many velocity "
        "reversals of joint 2 would show it larger."
    ]  # the offset, not significant, gets no such note


def test_no_significant_candidate_no_note_and_at_most_three():
    assert not [
        n for n in _verdict([_ranked("offset", 0, 0.9, significant=False)])[1] if "beyond chance" in n
    ]
    many = [_ranked("stribeck", j % 2, 0.1 * (j + 1)) for j in range(5)]
    sel = SimpleNamespace(ranking=many)
    assert len(small_candidate_notes(sel, {"significant_joint": np.zeros(2, bool)}, DiagnosisSettings())) == 3


def test_on_a_joint_whose_excess_is_significant_the_rule_is_min_closure():
    settings = replace(DiagnosisSettings(), min_closure=0.2)
    sel = SimpleNamespace(ranking=[_ranked("stribeck", 1, 0.1)])
    (note,) = small_candidate_notes(sel, {"significant_joint": np.array([False, True])}, settings)
    assert "less than the 20 % a cause must close: it is not named" in note
    (note,) = small_candidate_notes(sel, {"significant_joint": np.array([True, False])}, settings)
    assert "less than the 50 % a cause must close where no joint's excess is significant" in note


def test_an_accepted_candidate_is_the_verdict_and_gets_no_such_note():
    found = replace(_ranked("stribeck", 1, 0.9), accepted=True)
    verdict, notes = _verdict([found], significant_joint=(False, True), accepted=[found])
    assert verdict == ["stribeck"]
    assert not [n for n in notes if "beyond chance" in n]
