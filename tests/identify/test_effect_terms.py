"""Effects of the catalogue as identified model terms: recovered, written to the model file, refitted from a diagnosis."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

from dynid.cli import main
from dynid.data.files import save_dataset
from dynid.exceptions import UsageError
from dynid.identify import effect_terms
from dynid.identify.effect_terms import Candidate, parse_effect_terms
from dynid.identify.model import identify, load_model, save_model
from dynid.sim import effects as sim_effects
from dynid.sim.cases import case_excitation
from dynid.sim.simulator import simulate
from dynid.sim.truth import build_truth
from dynid.validation.html_page import format_number
from dynid.validation.validate import validate


def _heldout_rms(model, data):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        v = validate(model, data)
    return np.sqrt(np.mean((v.tau - v.tau_pred) ** 2, axis=0))


@pytest.fixture(scope="module")
def coupled(ur5):
    """A UR5 whose wrist motor adds friction on dq5 + dq6 to joints 5 and 6 (the simulator's coupled_friction)."""
    truth = build_truth(ur5, effects="coupled_friction:4", friction="linear", truth_seed=5)
    train = simulate(ur5, case_excitation(ur5, 31, base_freq=0.5), duration=8.0, truth=truth, seed=31)
    held = simulate(ur5, case_excitation(ur5, 32, base_freq=0.5), duration=6.0, truth=truth, seed=32)
    (effect,) = truth.effects
    assert effect.joints == (4, 5)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        plain = identify(ur5, train.to_dataset(), method="ols", friction="linear", gmm="off")
    return effect, train.to_dataset(), held.to_dataset(), plain


def test_identify_and_the_diagnosis_share_the_catalogue() -> None:
    assert set(effect_terms.BUILDERS) | {"payload"} == set(sim_effects.EFFECT_NAMES)


def test_a_coupled_friction_term_is_recovered(ur5, coupled) -> None:
    effect, train, held, plain = coupled
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = identify(
            ur5, train, method="ols", friction="linear", gmm="off", effects="coupled_friction@5+6"
        )
    (fig,) = model.figures()["effects"]
    assert fig["key"] == "coupled_friction@5+6" and fig["hyper"]["sign"] == 1.0  # w = dq5 + dq6, tuned
    fc, std = fig["coefficients"]["fc"], fig["std"]["fc"]
    assert abs(fc - effect.coulomb) < 3 * std, (fc, std, effect.coulomb)
    assert abs(fc - effect.coulomb) < 0.2 * effect.coulomb
    assert 0 < std < 0.2 * effect.coulomb
    # on held-out data the term takes the coupled friction out of joints 5 and 6
    with_term, without = _heldout_rms(model, held), _heldout_rms(plain, held)
    assert np.all(with_term[4:] < without[4:]), (with_term, without)
    assert with_term[5] < 0.6 * without[5]


def test_a_wrong_coupling_is_not_recovered(ur5, coupled) -> None:
    effect, train, held, _ = coupled
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        wrong = identify(
            ur5, train, method="ols", friction="linear", gmm="off", effects="coupled_friction@5+6:sign=-1"
        )
    (fig,) = wrong.figures()["effects"]
    assert abs(fig["coefficients"]["fc"] - effect.coulomb) > 0.5 * effect.coulomb
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        right = identify(
            ur5, train, method="ols", friction="linear", gmm="off", effects="coupled_friction@5+6"
        )
    assert _heldout_rms(wrong, held)[5] > 1.4 * _heldout_rms(right, held)[5]


def test_the_model_file_keeps_the_terms_and_older_files_load(ur5, coupled, tmp_path) -> None:
    _, train, held, plain = coupled
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = identify(
            ur5, train, method="ols", friction="linear", gmm="off", effects="coupled_friction@5+6"
        )
    save_model(model, tmp_path / "M.json")
    doc = json.loads((tmp_path / "M.json").read_text())
    assert doc["version"] == 3 and doc["effects"][0]["key"] == "coupled_friction@5+6"
    again = load_model(tmp_path / "M.json", robot=ur5)
    assert again.effects == model.effects
    np.testing.assert_allclose(again.predict(held), model.predict(held), atol=1e-10)
    # a version-1 file (no effects, no transmission) still loads and predicts as before
    save_model(plain, tmp_path / "V1.json")
    old = json.loads((tmp_path / "V1.json").read_text())
    old["version"] = 1
    del old["effects"]
    del old["robot"]["transmission"]
    (tmp_path / "V1.json").write_text(json.dumps(old))
    v1 = load_model(tmp_path / "V1.json", robot=ur5)
    assert v1.effects == ()
    np.testing.assert_allclose(v1.predict(held), plain.predict(held), atol=1e-10)


@pytest.mark.parametrize(
    ("spec", "match"),
    [
        ("frobnication@2", "unknown effect 'frobnication'; the catalogue's effects with model terms are"),
        ("payload", "the base parameters take in whole"),
        ("coupled_friction@5", "couples two joints; give a pair such as coupled_friction@5\\+6"),
        ("stribeck@9", "give joints in 1..6"),
        ("stribeck@2,stribeck@2", "'stribeck@2' is given twice"),
        ("cogging@2:N", "is not KEY=NUMBER"),
        ("coupled_friction@5+6:mix=2", "mix of the effect .* is 2; give the weight .* or leave it out \\(the default 1\\)"),
    ],
)
def test_a_malformed_effect_is_refused(spec, match) -> None:
    with pytest.raises(UsageError, match=match):
        parse_effect_terms(spec, 6)


def test_terms_the_model_identifies_anyway_are_refused(ur5, coupled) -> None:
    _, train, _, _ = coupled
    with pytest.raises(UsageError, match="identified already as the offset fo_j of the linear friction"):
        identify(ur5, train, method="ols", friction="linear", gmm="off", effects="offset@2")


def test_a_coupled_friction_the_transmission_holds_already_is_refused(ur5, coupled) -> None:
    """Motor 6 declared turning with joints 5 and 6: the effect would be its friction a second time (with
    the paper's friction on the TX40 the pair predicted 26 and 57 N m held out on joints 5 and 6)."""
    _, train, _, _ = coupled
    R = np.eye(6)
    R[5, 4] = 1.0  # motor 6 turns with q5 + q6
    wrist = ur5.with_transmission(R)
    with pytest.raises(UsageError, match="the friction of motor 6, which the robot's transmission already turns"):
        identify(wrist, train, method="ols", friction="linear", gmm="off", effects="coupled_friction@5+6")
    # a pair no motor couples, and the other sign of the coupled pair (q5 - q6, another speed), stay allowed
    model = identify(wrist, train, method="ols", friction="linear", gmm="off", effects="coupled_friction@4+5")
    assert [t.key for t in model.effects] == ["coupled_friction@4+5"]
    other = identify(wrist, train, method="ols", friction="linear", gmm="off", effects="coupled_friction@5+6:sign=-1")
    assert [t.hyper["sign"] for t in other.effects] == [-1.0]


@pytest.fixture(scope="module")
def output_stage(ur5):
    """A UR5 whose wrist motor drives a stage turning with dq6 alone: its friction reaches joints 5 and 6
    (the simulator's coupled_friction with mix 0)."""
    import dataclasses

    truth = build_truth(ur5, effects="coupled_friction:4", friction="linear", truth_seed=5)
    (effect,) = truth.effects
    effect = dataclasses.replace(effect, mix=0.0)
    truth = dataclasses.replace(truth, effects=(effect,))
    train = simulate(ur5, case_excitation(ur5, 31, base_freq=0.5), duration=8.0, truth=truth, seed=31)
    held = simulate(ur5, case_excitation(ur5, 32, base_freq=0.5), duration=6.0, truth=truth, seed=32)
    return effect, train.to_dataset(), held.to_dataset()


def test_an_output_stage_friction_is_recovered_and_the_motor_speed_form_is_not(ur5, output_stage) -> None:
    """``coupled_friction@5+6:mix=0``: friction on dq6 felt by joints 5 and 6."""
    effect, train, held = output_stage
    fit = dict(method="ols", friction="linear", gmm="off")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = identify(ur5, train, effects="coupled_friction@5+6:mix=0", **fit)
        motor = identify(ur5, train, effects="coupled_friction@5+6", **fit)  # w = dq5 + dq6: the wrong speed
    (fig,) = model.figures()["effects"]
    assert fig["key"] == "coupled_friction@5+6:mix=0" and fig["hyper"]["sign"] == 1.0  # tuned: both joints alike
    fc, std = fig["coefficients"]["fc"], fig["std"]["fc"]
    assert abs(fc - effect.coulomb) < 3 * std and abs(fc - effect.coulomb) < 0.2 * effect.coulomb, (fc, std)
    assert abs(motor.figures()["effects"][0]["coefficients"]["fc"] - effect.coulomb) > 0.3 * effect.coulomb
    right, wrong = _heldout_rms(model, held), _heldout_rms(motor, held)
    assert np.all(right[4:] < 0.8 * wrong[4:]), (right, wrong)


def test_an_output_stage_term_round_trips_in_a_version_4_file(ur5, output_stage, tmp_path) -> None:
    """The mix reaches the model file (version 4, which a version-3 reader refuses: it would take the stage
    for the motor's friction), the diagnosis' --effects text and the key, to the bit."""
    from dynid.diagnosis.model_refit import effect_spec
    _, train, held = output_stage
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = identify(ur5, train, method="ols", friction="linear", gmm="off", effects="coupled_friction@5+6:mix=0")
    save_model(model, tmp_path / "M.json")
    doc = json.loads((tmp_path / "M.json").read_text())
    assert doc["version"] == 4 and doc["effects"][0]["hyper"]["mix"] == 0.0
    again = load_model(tmp_path / "M.json")
    assert again.effects[0].hyper == model.effects[0].hyper
    np.testing.assert_allclose(_heldout_rms(again, held), _heldout_rms(model, held), rtol=1e-12)
    spec = effect_spec(model.effects)
    head, _, hyper = spec.partition(":")
    assert head == "coupled_friction@5+6" and sorted(hyper.split(";")) == ["mix=0.0", "sign=1"]
    assert parse_effect_terms(spec, 6)[0].hyper == {"sign": 1.0, "mix": 0.0}
    assert parse_effect_terms("coupled_friction@5+6:mix=0.1234567", 6)[0].key == "coupled_friction@5+6:mix=0.1234567"
    assert parse_effect_terms("coupled_friction@5+6:mix=-0", 6)[0].key == "coupled_friction@5+6:mix=0"


def test_on_a_declared_wrist_the_output_stage_takes_the_transmissions_sign(ur5, output_stage) -> None:
    """Motor 6 turns with q5 + q6 and drives joint 6's output stage: the stage's friction is not the motor's
    (allowed beside it) and reaches joints 5 and 6 with the transmission's sign, not a tuned one."""
    _, train, _ = output_stage
    R = np.eye(6)
    R[5, 4] = 1.0
    wrist = ur5.with_transmission(R)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = identify(wrist, train, method="ols", friction="linear", gmm="off", effects="coupled_friction@5+6:mix=0")
    (term,) = model.effects
    assert term.hyper == {"mix": 0.0, "sign": 1.0}
    R[5, 4] = -1.0  # motor 6 turns with q6 - q5: its torque reaches joint 5 with the other sign
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = identify(
            ur5.with_transmission(R), train, method="ols", friction="linear", gmm="off",
            effects="coupled_friction@5+6:mix=0",
        )  # fmt: skip
    assert model.effects[0].hyper["sign"] == -1.0
    with pytest.raises(UsageError, match="the friction of motor 6"):  # mix 1 with the sign: the motor's own
        identify(
            ur5.with_transmission(R), train, method="ols", friction="linear", gmm="off",
            effects="coupled_friction@5+6:sign=-1",
        )  # fmt: skip


def test_a_term_that_needs_time_is_predicted_from_a_dataset(ur5, coupled) -> None:
    _, train, held, _ = coupled
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = identify(ur5, train, method="ols", friction="linear", gmm="off", effects="delay@2:d=0.002")
    assert model.effects == (Candidate("delay", 1, (1,), {"d": 0.002, "exact": 1.0}, "delay on joint 2"),)
    assert np.all(np.isfinite(model.predict(held)))
    with pytest.raises(UsageError, match="need time stamps; predict from a Dataset"):
        model.predict(held.q, held.q, held.q)


@pytest.mark.slow
def test_diagnose_out_writes_the_refitted_model(ur5, coupled, tmp_path, capsys) -> None:
    _, train, held, plain = coupled
    save_dataset(train, tmp_path / "D.csv")
    save_dataset(held, tmp_path / "V.csv")
    save_model(plain, tmp_path / "M.json")
    code = main(
        [
            "diagnose",
            "--model",
            str(tmp_path / "M.json"),
            "--data",
            str(tmp_path / "D.csv"),
            "--heldout",
            str(tmp_path / "V.csv"),
            "--effects",
            "coupled_friction,stribeck,nonlinear_viscous",
            "--out",
            str(tmp_path / "M2.json"),
            "--json",
            str(tmp_path / "G.json"),
            "--report",
            str(tmp_path / "G.html"),
        ]
    )
    assert code == 0
    out = capsys.readouterr().out
    assert "refitted with coupled_friction@5+6" in out
    refit = json.loads((tmp_path / "G.json").read_text())["refit"]
    assert refit["written"] and refit["effects"] == ["coupled_friction@5+6"]
    # before and after per joint, with their ratio, in the printed summary and in the report
    lines = out[out.index("held-out RMS (N m)  joint  before   after   ratio") :].splitlines()[1:7]
    assert [int(line.split()[0]) for line in lines] == [1, 2, 3, 4, 5, 6]
    assert float(lines[5].split()[3]) == pytest.approx(
        refit["rms_after"][5] / refit["rms_before"][5], abs=0.006
    )
    page = (tmp_path / "G.html").read_text()
    table = page[page.index("The model with the accepted effects") :]
    table = table[: table.index("</table>")]
    assert "after / before" in table and table.count("<tr>") == 7  # header and one row per joint
    for j in range(6):
        for value in (
            refit["rms_before"][j],
            refit["rms_after"][j],
            refit["rms_after"][j] / refit["rms_before"][j],
        ):
            assert format_number(value, 3) in table
    m2 = load_model(tmp_path / "M2.json", robot=ur5)
    assert [t.key for t in m2.effects] == ["coupled_friction@5+6"]
    before, after = _heldout_rms(plain, held), _heldout_rms(m2, held)
    np.testing.assert_allclose(after, refit["rms_after"], rtol=1e-6)
    assert after[5] < 0.6 * before[5] and np.mean(after) < np.mean(before), (before, after)


def test_the_links_shifted_torque_is_the_exact_shift_to_first_order(ur5) -> None:
    """The transmission columns take the links' torque at deflected states to first order (memoised
    derivatives); for a deflection of a fraction of a milliradian that is the exact shift to within the
    deflection's own relative size, on every joint the arm couples it to, gravity included."""
    from dynid.identify.columns import compiled_base_regressor
    from dynid.identify.effect_builders import FeatureSource, _shifted

    t = np.arange(0.0, 4.0, 1e-3)
    n = ur5.n
    w = 2 * np.pi * np.array([0.5, 0.7, 0.3, 0.9, 1.1, 0.6])
    q = 0.8 * np.sin(w * t[:, None] + np.arange(n))
    dq = 0.8 * w * np.cos(w * t[:, None] + np.arange(n))
    ddq = -0.8 * w**2 * np.sin(w * t[:, None] + np.arange(n))
    x = np.random.default_rng(0).normal(size=compiled_base_regressor(ur5, q[:2], dq[:2], ddq[:2]).shape[2])

    def at(q_, dq_, ddq_):
        return np.einsum("mnk,k->mn", compiled_base_regressor(ur5, q_, dq_, ddq_), x)

    tau = at(q, dq, ddq)
    src = FeatureSource(
        t=t,
        q=q,
        dq=dq,
        ddq=ddq,
        tau_pred=tau,
        robot=ur5,
        fs=1000.0,
        runs=[slice(0, t.size)],
        torque_at=at,
        tau_link=tau,
        link_torque_at=at,
    )
    j = 1  # the shoulder: gravity, speed and acceleration terms all matter
    delta = 3e-4 * np.sin(2 * np.pi * 3.0 * t)
    first = _shifted(src, j, delta, links=True)[:, :, 0]
    exact = _shifted(src, j, delta)[:, :, 0]  # the whole torque (here the same) shifted exactly
    err = np.linalg.norm(first - exact, axis=0) / np.linalg.norm(exact, axis=0)
    assert np.all(err < 2e-3), err
    assert f"link_sensitivity_{j}" in src.cache


def test_a_load_friction_term_is_one_column_and_older_two_column_files_keep_theirs(ur5) -> None:
    """Load friction is sign(dq) |tau|: its former second column, sign(dq) |tau| sign(dq tau), is tau, the
    drive gain's column (issue 37, item 5).  A model file written with the two columns still predicts with them."""
    rng = np.random.default_rng(5)
    m, n = 50, ur5.n
    src = effect_terms.FeatureSource(
        t=np.arange(m) / 100.0,
        q=rng.normal(size=(m, n)),
        dq=rng.normal(size=(m, n)),
        ddq=rng.normal(size=(m, n)),
        tau_pred=rng.normal(size=(m, n)),
        robot=ur5,
        fs=100.0,
        runs=[slice(0, m)],
    )
    (term,) = parse_effect_terms("load_friction@2", n)
    C = effect_terms.candidate_columns(src, term)
    assert C.shape == (m, n, 1)
    np.testing.assert_allclose(C[:, 1, 0], np.sign(src.dq[:, 1]) * np.abs(src.tau_pred[:, 1]))
    assert effect_terms.coefficient_names(term, 1) == ("load_friction@2.mu",)
    doc = {**effect_terms.effect_to_dict(term), "coefficients": {"mu": 0.03, "mu_drive": 0.01}}
    old = effect_terms.effect_from_dict(doc)
    assert old.hyper == {"asymmetric": 1.0}
    C2 = effect_terms.candidate_columns(src, old)
    assert C2.shape == (m, n, 2)
    np.testing.assert_allclose(C2[:, 1, 1], src.tau_pred[:, 1])  # the second column is tau itself
    assert (
        effect_terms.effect_from_dict({**effect_terms.effect_to_dict(term), "coefficients": {"mu": 0.03}})
        == term
    )
