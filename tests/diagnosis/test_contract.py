"""The diagnosis on the user's default path, end to end on the command line.

A user designs two excitations (``dynid excite --criterion logdet``), records a training and a held-out
run of each (``dynid simulate`` with its defaults: three periods), identifies the model and diagnoses it.
The simulator stands in for the robot; its truth carries Stribeck friction on every joint, or nothing.

At the catalogue's default size (a bump of half the Coulomb level below 2 % of the top speed), Stribeck
friction shows on a fast excitation only in the few milliseconds of each velocity reversal: on this held-out
run it adds about 0.02 noise variances per sample to joint 2, under the 0.15 the diagnosis asks of an
effect.  The diagnosis must then not name it from that run, nor call the gap unexplained, but say which
candidate is undecided and print the command that records the motion that decides; run as printed, on
the same robot, that recording must name it.  The effect-free robot must come out "none" on both runs.
"""

from __future__ import annotations

import json
import shlex

import pytest

from dynid.cli import main

pytestmark = pytest.mark.slow


def _run(argv: list[str], capsys) -> str:
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert "Traceback" not in out + err
    return out


def _diagnose(argv: list[str], js, capsys) -> tuple[dict, str]:
    out = _run([*argv, "--json", js], capsys)
    return json.loads(js.read_text()), out


@pytest.fixture(scope="module")
def designs(tmp_path_factory):
    d = tmp_path_factory.mktemp("contract")
    for seed in (0, 1):
        assert main(["excite", "--robot", "ur5", "--criterion", "logdet", "--seed", str(seed), "--out",
                     str(d / f"T{seed}.json")]) == 0  # fmt: skip
    return d


def _record(d, effect: str | None, capsys) -> dict:
    """Training and held-out runs, the identified model and its diagnosis: the user's default path."""
    tag = effect or "none"
    effects = ["--effects", effect] if effect else []
    train, held, model = d / f"train_{tag}.csv", d / f"held_{tag}.csv", d / f"M_{tag}.json"
    _run(["simulate", "--robot", "ur5", "--trajectory", d / "T0.json", *effects, "--out", train], capsys)
    _run(["simulate", "--robot", "ur5", "--trajectory", d / "T1.json", *effects, "--seed", "1", "--truth-seed", "0",
          "--out", held], capsys)  # fmt: skip
    _run(["identify", "--robot", "ur5", "--data", train, "--method", "irls", "--friction", "linear", "--gmm", "off",
          "--out", model], capsys)  # fmt: skip
    figures, out = _diagnose(
        ["diagnose", "--model", model, "--data", train, "--heldout", held], d / f"D_{tag}.json", capsys
    )
    return {"train": train, "model": model, "figures": figures, "out": out}


def test_default_path_leaves_stribeck_undecided_and_the_printed_recording_names_it(
    designs, capsys, monkeypatch
):
    case = _record(designs, "stribeck", capsys)
    fig = case["figures"]
    # Too small on this run to be named, and not a gap nobody can explain: undecided, with the command.
    # (A diagnosis that names it from this run would pass an 84-way correction on 0.02 noise variances
    # per sample: this test is to change with the evidence, not to be loosened.)
    assert fig["verdict"] == ["none"], fig["verdict"]
    assert fig["undecided"] and fig["undecided"][0]["effect"] == "stribeck", fig["undecided"]
    lead = fig["undecided"][0]
    assert lead["closure"] >= 0.5 and lead["p_raw"] < 0.05 and not lead["significant"]
    assert 0 < lead["gain"] < 0.15  # below min_gain: no longer run of this motion would decide
    assert "Undecided: stribeck on joint" in case["out"]
    settle = fig["settle"]
    assert settle["candidate"] == f"stribeck@{lead['joint']}"
    excite, comment, diagnose = settle["commands"]
    assert excite in case["out"] and diagnose in case["out"]
    assert "--dq-max" in excite and comment.startswith("# play heldout_excitation.csv on the robot")
    # Record it as printed; the simulator plays the excitation on the same robot (new noise).
    monkeypatch.chdir(designs)
    _run(shlex.split(excite)[1:], capsys)
    _run(["simulate", "--robot", "ur5", "--trajectory", "heldout_excitation.json", "--effects", "stribeck",
          "--seed", "2", "--truth-seed", "0", "--out", "heldout.csv"], capsys)  # fmt: skip
    settled, _ = _diagnose(shlex.split(diagnose)[1:], designs / "D_settled.json", capsys)
    # Stribeck friction acts on every joint of this robot: the slow recording may show it on others too.
    assert settled["verdict"] and set(settled["verdict"]) == {"stribeck"}, settled["verdict"]
    named = {a["joint"]: a for a in settled["accepted"]}
    assert lead["joint"] in named and named[lead["joint"]]["closure"] >= 0.5, settled["accepted"]


def test_default_path_on_an_effect_free_robot_says_none_with_nothing_undecided(designs, capsys, monkeypatch):
    case = _record(designs, None, capsys)
    fig = case["figures"]
    assert fig["verdict"] == ["none"], fig["verdict"]
    # The training run's three periods were checked for a misfit that repeats, and none was found.
    assert fig["lack_of_fit"]["periods"] > 2.5 and not any(fig["lack_of_fit"]["lead_joint"]), fig["lack_of_fit"]
    assert fig["undecided"] == [] and "settle" not in fig and "Undecided" not in case["out"]
    # The slow recording the Stribeck case asks for is no trap either: on this robot it says none too.
    monkeypatch.chdir(designs)
    _run(["excite", "--robot", "ur5", "--criterion", "cond", "--seed", "11", "--dq-max", "3.15,0.3136,3.15,3.2,3.2,3.2",
          "--out", "slow.json"], capsys)  # fmt: skip
    _run(["simulate", "--robot", "ur5", "--trajectory", "slow.json", "--seed", "2", "--truth-seed", "0", "--out",
          "slow_none.csv"], capsys)  # fmt: skip
    slow, _ = _diagnose(
        ["diagnose", "--model", case["model"], "--data", case["train"], "--heldout", "slow_none.csv"],
        designs / "D_slow_none.json",
        capsys,
    )
    assert slow["verdict"] == ["none"], slow["verdict"]
