"""``dynid demo`` end to end (quick mode: shorter trajectories, every stage)."""

from __future__ import annotations

import contextlib
import io
import json
import re
import subprocess
import sys

import pytest

from dynid.cli import main

VALIDATE_KEYS = {"rms", "rms_mean", "nrms", "r2", "noise_floor", "reference"}


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    out = tmp_path_factory.mktemp("demo")
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        code = main(["demo", "--out", str(out / "run"), "--quick", "--json", str(out / "demo.json")])
    return code, buf.getvalue(), json.loads((out / "demo.json").read_text()), out / "run"


def test_demo_runs_every_stage(demo):
    code, text, figures, _ = demo
    assert code == 0, text
    stages = figures["stages"]
    assert [s["stage"].split(" ")[0] for s in stages] == [
        "symbolic",
        "excitation",
        "simulated",
        "identification:",
        "validation",
        "sim-to-real",
        "HTML",
    ]
    for stage in stages:
        # a stage whose part of dynid is missing says so; none is skipped silently or faked
        assert stage["status"] in ("done", "not built"), stage
        if stage["status"] == "not built":
            assert "not built yet" in stage["summary"]
    assert [s["stage"] for s in stages if s["status"] != "done"] == figures["stages_missing"]
    # progress: one counter line per stage, then the summary table with the report's path
    assert len(re.findall(r"^\[\d/7\] ", text, flags=re.M)) == 7
    assert re.search(r"^report: .*report\.html$", text, flags=re.M)


def test_demo_json_holds_the_validate_keys(demo):
    _, _, figures, _ = demo
    assert VALIDATE_KEYS <= figures.keys()
    n = 6
    for key in ("rms", "nrms", "r2", "noise_floor"):
        assert len(figures[key]) == n
    assert figures["noise_floor_method"] == "periods"  # the validation run repeats its trajectory
    assert figures["reference"] == "filtered, decimated and trimmed"
    assert figures["n_base"] == 36 and figures["c_export_max_error"] < 1e-10


def test_demo_identifies_something_worth_having(demo):
    _, _, figures, _ = demo
    by_label = {m["label"]: m for m in figures["models"]}
    assert set(by_label) == {"full", "OLS", "IRLS"}
    assert figures["rms"] == by_label["full"]["rms"]
    # the full method is better than OLS on the held-out run, and its rigid body is close to the truth
    assert by_label["full"]["rms_mean"] < by_label["OLS"]["rms_mean"]
    assert figures["truth_relative_error"]["full"]["rigid_body"] < 0.05
    # and no model beats the measured noise floor
    for model in figures["models"]:
        assert all(r > f for r, f in zip(model["rms"], figures["noise_floor"], strict=True))


def test_demo_writes_its_files(demo):
    _, _, figures, run = demo
    names = {p.name for p in run.iterdir()}
    assert {
        "excitation.json",
        "identification.csv",
        "identification.csv.truth.json",
        "validation.csv",
        "validation.csv.truth.json",
        "model.json",
        "model.npz",
        "model_ols.json",
        "model_irls.json",
        "report.html",
    } <= names
    from dynid.demo import DEMO_FILES

    assert names <= set(DEMO_FILES)  # the list the command protects from --json is the demo's whole output
    assert not [n for n in names if n.startswith(".")], "temporary files left behind"
    if figures.get("diagnosis_report"):  # the diagnosis' own report, linked from the demo's
        assert "diagnosis.html" in names
        assert '<a href="diagnosis.html">' in (run / "report.html").read_text(encoding="utf-8")
    html = (run / "report.html").read_text(encoding="utf-8")
    # the GMM's before/after figure only where the mixture corrects some joint; a sentence otherwise
    gmm = json.loads((run / "model.json").read_text())["gmm"]
    active = bool(gmm and any(gmm["active"]))
    assert html.count('<img src="data:image/png;base64,') == (4 if active else 3)
    assert active or "changed nothing on these data" in html
    assert "Sim-to-real gap diagnosis" in html and "Against the simulated truth" in html
    assert figures["report"].endswith("report.html")


def test_demo_models_can_be_validated_again(demo, tmp_path):
    _, _, figures, run = demo
    out = tmp_path / "again.json"
    argv = [
        "validate",
        "--model",
        str(run / "model.json"),
        "--data",
        str(run / "validation.csv"),
        "--json",
        str(out),
    ]
    assert main(argv) == 0
    again = json.loads(out.read_text())
    assert again["rms"] == pytest.approx(figures["rms"], rel=1e-9)


def test_demo_models_load_in_a_fresh_process(demo, tmp_path):
    """What a user does next, in a new process: nothing cached from the demo's own run may be needed."""
    _, _, figures, run = demo
    out = tmp_path / "fresh.json"
    argv = ["validate", "--model", str(run / "model.json"), "--data", str(run / "validation.csv")]
    proc = subprocess.run(
        [sys.executable, "-m", "dynid.cli", *argv, "--json", str(out)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr
    assert json.loads(out.read_text())["rms"] == pytest.approx(figures["rms"], rel=1e-9)


def test_demo_out_must_be_a_folder(tmp_path, capsys):
    target = tmp_path / "file.txt"
    target.write_text("x")
    assert main(["demo", "--out", str(target), "--quick"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"dynid demo: error: --out '{target}' is a file; give a folder for the demo's files."]
