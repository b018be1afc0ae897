"""``diagnose --out``: the model refitted with the accepted effects never does worse (dynid.diagnosis.model_refit).

Issue 37, item 3: with a 5 ms delay on every joint the diagnosis accepted delays on three joints, and the
model refitted with them raised another joint's held-out RMS (17 % on the reported MuJoCo recording).
An effect now goes into ``--out`` only if, cross-fitted as the diagnosis scores it, it lowers the held-out
error on its joints, and the refitted model raises no joint's held-out RMS by more than 2 % over the
model before it; a delay goes in at the delay the diagnosis measured.  The accepted effects are written
here as the diagnosis reported them on these runs (the delay of the refit column, theta, and the delay
it measured, theta times the column's coefficient), so that no diagnosis runs.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from dynid.diagnosis.model_refit import MAX_RISE, refit_with_effects
from dynid.diagnosis.result import RankedCandidate
from dynid.identify.effect_terms import Candidate, parse_effect_terms
from dynid.identify.model import identify
from dynid.sim.cases import case_excitation
from dynid.sim.simulator import simulate
from dynid.validation.validate import validate


def _runs(robot, seed: int, effects: str):
    kw = {"duration": 20.0, "friction": "linear", "effects": effects}
    tr = simulate(robot, case_excitation(robot, 2 * seed, base_freq=0.2), seed=seed, **kw)
    ho = simulate(
        robot, case_excitation(robot, 2 * seed + 1, base_freq=0.2), seed=seed + 100_000, truth_seed=seed, **kw
    )
    return tr.to_dataset(), ho.to_dataset()


def _rms(model, data):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        v = validate(model, data)
    return np.sqrt(np.mean((v.tau - v.tau_pred) ** 2, axis=0))


def _accepted_delay(joint: int, theta: float, measured: float) -> RankedCandidate:
    cand = Candidate("delay", joint - 1, (joint - 1,), {"d": theta, "exact": 1.0}, f"delay on joint {joint}")
    return RankedCandidate(
        candidate=cand,
        gain=1.0,
        closure=0.9,
        p_value=1e-6,
        accepted=True,
        refit={"effective": {"d": measured}, "coefficient": measured / theta},
    )


@pytest.mark.slow
def test_a_refit_that_raises_another_joint_is_not_written(ur5):
    """A 5 ms delay on every joint, a physically consistent model; a diagnosis of such a run accepted delays
    on joints 4, 6 and 1 (the --max-effects cap).  Refitted with them (irls: consistent takes no effect
    terms), another joint whose own delay was not accepted comes out worse on held-out data through the
    shared link parameters: joint 3 by 11 % on this run (seed 9; on seed 8, where the test was written,
    joint 5 by 3.7 %, and by 1.7 % since a joint at rest has no friction direction)."""
    train, held = _runs(ur5, 9, "delay:1.25")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = identify(ur5, train, method="consistent")
    accepted = [_accepted_delay(4, 0.01329, 0.004499), _accepted_delay(6, 0.01519, 0.004711)]
    accepted.append(_accepted_delay(1, 0.01539, 0.004044))
    before = _rms(model, held)
    # Without the held-out data every effect goes in, as --out did: joint 5 is raised beyond 2 %.
    blind, _ = refit_with_effects(model, train, accepted)
    assert np.max(_rms(blind, held) / before) > 1.0 + MAX_RISE
    refitted, notes = refit_with_effects(model, train, accepted, heldout=held)
    ratio = _rms(refitted, held) / before
    assert np.all(ratio <= 1.0 + MAX_RISE), (ratio, notes)
    left = [t.key for t in (*refitted.effects,)]
    for key in ("delay@4", "delay@6", "delay@1"):
        assert key in left or any(note.startswith(f"{key}: left out") for note in notes), notes
    if refitted is model:  # nothing added: the last note gives the figures and how to take the refit anyway
        assert "no accepted effect is added" in notes[-1] and "--effects 'delay@4:d=0.004499" in notes[-1]
        spec = notes[-1].split("--effects '")[1].rstrip("'")
        assert [t.key for t in parse_effect_terms(spec, ur5.n)] == ["delay@4", "delay@6", "delay@1"]


@pytest.mark.slow
def test_a_delay_goes_in_at_the_delay_the_diagnosis_measured(ur5):
    """A 5 ms delay on joint 4: its term goes in at the measured delay (not the refit column's theta, 13 ms,
    whose coefficient the refit would size again) and mends joint 4 without raising another joint."""
    train, held = _runs(ur5, 7, "delay@4:1.25")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = identify(ur5, train, method="irls", friction="linear", gmm="off")
    refitted, notes = refit_with_effects(model, train, [_accepted_delay(4, 0.013, 0.005)], heldout=held)
    assert [t.key for t in refitted.effects] == ["delay@4"], notes
    assert refitted.effects[0].hyper["d"] == 0.005
    # the refit keeps the delay (coefficient near 1) or says how far it moved it and why
    (note,) = [note for note in notes if note.startswith("delay@4")]
    assert note.startswith("delay@4: kept at the measured delay, 5 ms") or "read the lag differently" in note
    ratio = _rms(refitted, held) / _rms(model, held)
    assert ratio[3] < 0.5 and np.all(ratio <= 1.0 + MAX_RISE), ratio


@pytest.mark.slow
def test_an_effect_the_heldout_run_does_not_show_stays_out(ur5):
    """Delays on joints 2-4 in the training run, on joint 4 alone in the held-out run: the delay on joint 2
    fits the training run but, cross-fitted, does not lower joint 2's held-out error (refitted with it
    blindly, joint 2's held-out RMS rose by a quarter)."""
    kw = {"duration": 20.0, "friction": "linear"}
    train = simulate(ur5, case_excitation(ur5, 14, base_freq=0.2), seed=7, effects="delay@2-4:1.25", **kw)
    held = simulate(
        ur5, case_excitation(ur5, 15, base_freq=0.2), seed=100_007, truth_seed=7, effects="delay@4:1.25", **kw
    )
    train, held = train.to_dataset(), held.to_dataset()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = identify(ur5, train, method="irls", friction="linear", gmm="off")
    accepted = [_accepted_delay(4, 0.013, 0.005), _accepted_delay(2, 0.013, 0.005)]
    before = _rms(model, held)
    blind, _ = refit_with_effects(model, train, accepted)
    assert _rms(blind, held)[1] > 1.1 * before[1]
    refitted, notes = refit_with_effects(model, train, accepted, heldout=held)
    assert "delay@2" not in [t.key for t in refitted.effects]
    assert any(note.startswith("delay@2: left out: cross-fitted on the held-out folds") for note in notes), (
        notes
    )
    assert np.all(_rms(refitted, held) / before <= 1.0 + MAX_RISE)


def test_an_effect_the_model_carries_already_is_said_so(ur5):
    """A default model gives a joint a drive gain; the diagnosis screens the model's own effect terms like
    any other candidate, so it can accept drive_gain@2 on such a model.  --out adds nothing then, and the
    note and the diagnosis both say the model carries it (before: no note, and a verdict that read as a gap)."""
    from types import SimpleNamespace

    from dynid.diagnosis.core import _held_by_the_model

    train, _ = _runs(ur5, 3, "drive_gain@2:1.5")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = identify(ur5, train, method="ols", friction="linear", gmm="off", effects="drive_gain@2")
    (term,) = parse_effect_terms("drive_gain@2", ur5.n)
    accepted = RankedCandidate(candidate=term, gain=1.0, closure=0.99, p_value=1e-9, accepted=True)
    refitted, notes = refit_with_effects(model, train, [accepted])
    assert refitted is model
    assert notes == ["drive_gain@2: the model carries it already (an effect term refitted with the links)"]
    said = _held_by_the_model(model, SimpleNamespace(accepted=[accepted]))
    assert len(said) == 1 and said[0].startswith("The model carries drive_gain@2 already as effect term(s)")
    other = RankedCandidate(candidate=parse_effect_terms("stribeck@3", ur5.n)[0], gain=1.0, closure=0.9,
                            p_value=1e-9, accepted=True)  # fmt: skip
    assert _held_by_the_model(model, SimpleNamespace(accepted=[other])) == []
    assert _held_by_the_model(None, SimpleNamespace(accepted=[accepted])) == []
