"""The real recordings under ../shared/data: identify, validate on the later part, diagnose, write the reports.

Runs ``scripts/identify_panda.py`` and ``scripts/identify_tx40.py`` (their ``main``) and the TX40 part
of ``scripts/diagnose_real_robots.py``, and checks what they claim; skipped, with the reason, when the
recordings are not there (a user's fresh clone).
"""

from __future__ import annotations

import contextlib
import io
import runpy
from pathlib import Path

import numpy as np
import pytest

from dynid.identify.consistent import pseudo_inertia

pytestmark = pytest.mark.realdata
REPO = Path(__file__).resolve().parents[2]


def _script(name: str):
    return runpy.run_path(str(REPO / "scripts" / name), run_name="dynid_script")["main"]


@pytest.fixture(scope="module")
def panda(shared_data, tmp_path_factory):
    out = tmp_path_factory.mktemp("panda")
    with contextlib.redirect_stdout(io.StringIO()):
        results = _script("identify_panda.py")(out, root=shared_data)
    return results, out


@pytest.fixture(scope="module")
def tx40(shared_data, tmp_path_factory):
    out = tmp_path_factory.mktemp("tx40")
    with contextlib.redirect_stdout(io.StringIO()):
        results = _script("identify_tx40.py")(out, root=shared_data)
    return results, out


def test_panda_identified_model_beats_its_urdf_on_every_joint(panda):
    results, _ = panda
    by_label = {r.label: r for r in results}
    assert list(by_label) == ["full", "OLS", "IRLS", "URDF"]
    full, urdf = by_label["full"], by_label["URDF"]
    # Held-out, on the last 30 % of the run: the identified model is better than Gaz et al.'s feasible
    # parameters with a linear friction fitted on the same training data, joint by joint.
    assert np.all(full.metrics["rms"] < urdf.metrics["rms"]), (full.metrics["rms"], urdf.metrics["rms"])
    assert np.all(np.asarray(full.metrics["r2"]) > 0.9)
    assert full.reference.startswith("resampled, filtered")


def test_panda_report_and_model_are_written(panda):
    from dynid.validation.report import gmm_changed

    results, out = panda
    html = (out / "panda_report.html").read_text(encoding="utf-8")
    # the GMM's before/after figure only where the mixture changed the prediction
    assert html.count('<img src="data:image/png;base64,') == (4 if gmm_changed(results) is not None else 3)
    assert (out / "panda_model.json").is_file() and (out / "panda_model.npz").is_file()
    assert "Physically consistent link parameters" in html


def test_tx40_identified_model_beats_its_urdf(tx40):
    results, out = tx40
    by_label = {r.label: r for r in results}
    full, urdf = by_label["full"], by_label["URDF"]
    # The first four joints are well explained; the coupled wrist (joints 5 and 6: motor 6's inertia and
    # friction act on both) is modelled by none of these, so only the mean and joints 1-4 are held to a bar.
    assert full.metrics["rms_mean"] < 0.8 * urdf.metrics["rms_mean"]
    assert np.all(full.metrics["rms"][:4] < urdf.metrics["rms"][:4])
    assert np.all(np.asarray(full.metrics["r2"][:4]) > 0.8)
    assert (out / "tx40_report.html").is_file() and (out / "tx40_model.json").is_file()


def test_tx40_diagnosis_points_at_the_coupled_wrist_and_is_provisional(shared_data, tmp_path):
    # The TX40's motor 6 turns with joint 5 (its README): the friction of that motor acts on
    # dq5 + dq6, which the model's per-joint friction cannot hold.  The held-out part is not periodic,
    # so the floor comes from the spectrum and the verdict must say it is provisional.
    script = runpy.run_path(str(REPO / "scripts" / "diagnose_real_robots.py"), run_name="dynid_script")
    split, decimate = script["RECORDINGS"]["tx40"]
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        doc = script["diagnose_recording"]("tx40", split, decimate, tmp_path, shared_data)
    top = doc["ranking"][0]
    assert (top["effect"], top["joint"]) == ("coupled_friction", [5, 6]), doc["ranking"][:3]
    assert top["closure"] > 0.9
    assert doc["provisional"] is True
    # Named, or the reason it is not: on 3 s of held-out data the 95 % closure is not significant after
    # the correction for the ~60 candidates tested, and the summary must say that, not "closes too little",
    # with the command that records the held-out run that decides.
    if doc["verdict"] != ["coupled_friction"]:
        lead = doc["undecided"][0]
        assert (lead["effect"], lead["joint"]) == ("coupled_friction", [5, 6]), doc["undecided"]
        text = printed.getvalue()
        assert "Undecided: coupled friction of joints 5 and 6 would close 95 %" in text
        assert "s of the same kind would too" in text
        assert doc["settle"]["candidate"] == "coupled_friction@5+6"
        assert doc["settle"]["excite"].startswith("dynid excite --robot ") and doc["settle"]["excite"] in text
    assert doc["noise_floor"]["method"] == "spectrum"
    assert (tmp_path / "tx40_diagnosis.html").is_file()
    # 3 s held out: the check that does not rest on the floor cannot confirm the excess either.
    assert doc["remainder"] is not None and not any(doc["remainder"]["predictable_joint"])


def test_panda_diagnosis_names_a_transmission_effect_that_does_not_rest_on_the_spectral_floor(
    shared_data, tmp_path
):
    # 7 s held out, aperiodic: the floor is the spectrum's lower bound.  On joint 2 the accepted effect
    # removes two thirds of the whole held-out error, a share no floor enters: the verdict is not
    # provisional.  What it leaves is checked without the floor.
    script = runpy.run_path(str(REPO / "scripts" / "diagnose_real_robots.py"), run_name="dynid_script")
    split, decimate = script["RECORDINGS"]["panda_gaz2019"]
    with contextlib.redirect_stdout(io.StringIO()):
        doc = script["diagnose_recording"]("panda_gaz2019", split, decimate, tmp_path, shared_data)
    assert doc["noise_floor"]["method"] == "spectrum"
    assert doc["verdict"] == ["elasticity"] and doc["accepted"][0]["joint"] == 2, doc["verdict"]
    assert doc["accepted"][0]["closure"] > 0.5
    assert doc["provisional"] is False and "settle" not in doc
    assert any("The verdict does not rest on its level" in note for note in doc["notes"])
    # The rest of the arm keeps a gap that a state model predicts on held-out folds it did not see.
    rem = doc["remainder"]
    assert sum(rem["predictable_joint"]) >= 3 and not rem["predictable_joint"][1], rem


@pytest.fixture(scope="module")
def panda_defaults(shared_data):
    """Gaz et al.'s split (train t < 15 s), dynid's defaults, OLS + linear friction and the published model,
    scored as ``benchmarks/real_robots_benchmark.py`` scores them (raw torque, 10 Hz, 0.25 s trimmed)."""
    import warnings

    from dynid.data.adapters import load_recording, recording_model_path
    from dynid.data.preparation import Preprocessing, prepare
    from dynid.data.preprocess import lowpass
    from dynid.identify.model import identify
    from dynid.symbolic import load_robot

    bench = runpy.run_path(str(REPO / "benchmarks" / "real_robots_benchmark.py"), run_name="dynid_benchmark")
    full = load_recording("panda_gaz2019", shared_data)
    urdf = str(recording_model_path("panda_gaz2019", shared_data))
    robot = load_robot(urdf)
    split = full.t[0] + 15.0
    train = full.select_rows(np.flatnonzero(full.t < split))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = identify(robot, train)
        ols = identify(robot, train, method="ols", friction="linear", gmm="off", physical=False)
    raw = prepare(full, Preprocessing(cutoff=None, trim=0.0))
    idx = np.flatnonzero(raw.t >= split)
    fs = 1.0 / np.median(np.diff(raw.t))
    th = raw.t[idx]
    keep = (th >= th[0] + 0.25) & (th <= th[-1] - 0.25)

    def score(t, tau):
        tau = np.column_stack([np.interp(raw.t, t, tau[:, j]) for j in range(tau.shape[1])])
        err = lowpass(tau[idx] - raw.tau[idx], fs=fs, cutoff=10.0, order=4)[keep]
        return np.sqrt(np.mean(err**2, axis=0))

    t, phys, whole = bench["model_parts"](model, full)
    t_ols, _, ols_whole = bench["model_parts"](ols, full)
    rms = {
        "phys": score(t, phys),
        "full": score(t, whole),
        "ols": score(t_ols, ols_whole),
        "ref": score(*bench["gaz_reference"](urdf, full)),
    }
    return model, rms


def test_panda_defaults_beat_the_published_model_with_physical_layers_that_stand_alone(panda_defaults):
    model, rms = panda_defaults
    assert np.all(rms["full"] < rms["ref"]), rms  # Gaz et al.'s URDF + Table I friction, all 7 joints
    # joint 6 reads about 6 % above what any rigid body predicts (fitted on the whole recording too): the
    # default gives it a drive gain, 0.089 -> 0.028 N m held out; the mean ratio 0.62 -> 0.53
    assert model.info["pipeline"]["drive_gains"] == [6], model.info["pipeline"]["reason"]
    assert rms["full"][5] < 0.4 * rms["ref"][5] and np.mean(rms["full"] / rms["ref"]) < 0.56, rms
    # link + friction alone: a good model by itself.  1.1x before the links were kept consistent; real
    # bodies cost joint 4 12 % held out (0.161 -> 0.180 N m against 0.161 unconstrained, whatever the
    # projection's metric, margin, friction bounds or pull toward the URDF), the price of a model a
    # simulator accepts.  The unconstrained fit buys it with armatures no drive has (-0.08 kg m^2 on
    # joints 3 and 4): along this motion q_4 and ddq_4 correlate at -0.79, so a negative armature stands
    # in for a torque linear in q_4.  Given that term (a spring per joint), consistent bodies cost
    # nothing (real_robots_benchmark.py --spring: joint 4 at 0.93x, every joint within 1.01x)
    # The pull toward the description (the default) costs joint 4 a further 8 % (0.195 N m, 1.21x): the
    # price of bodies a person believes, below.
    assert np.all(rms["phys"] <= 1.25 * rms["ols"]), rms
    assert np.sum(rms["phys"] <= 1.12 * rms["ols"]) >= 6, rms  # joint 6 at 1.116x with the pull
    # ... the bodies are the arm's: 16.4 kg for the URDF's 16.1 (the unpulled fit: 482 kg), every link of
    # at least 0.2 kg within [0.5, 2] times its URDF mass
    urdf_mass = model.robot.params.reshape(-1, 10)[:, 0]
    mass = model.standard_params[:, 0]
    assert abs(mass.sum() / urdf_mass.sum() - 1) < 0.15, mass
    heavy = urdf_mass >= 0.2
    assert np.all((mass[heavy] >= 0.5 * urdf_mass[heavy]) & (mass[heavy] <= 2 * urdf_mass[heavy])), mass
    assert np.all(rms["full"] <= 1.02 * rms["phys"]), rms  # the correction never makes it worse
    kinds = np.asarray(model.columns.kinds)
    assert np.all(model.params[np.isin(kinds, ("armature", "coulomb", "viscous"))] >= 0)
    assert model.info["bounds"]["physical"]
    # the links are real bodies (the unconstrained fit's are not: 7.8 std from the nearest consistent set)
    J = pseudo_inertia(model.standard_params)
    assert np.all(np.linalg.eigvalsh(J).min(axis=1) > 0) and model.info["consistency"]["mahalanobis"] > 1
    pre = model.preprocessing
    assert pre["cutoff_rule"].startswith("from the data") and 5.0 < pre["cutoff_hz"] < 20.0
    assert pre["dq_evidence"].startswith("measured dq used") and pre["dq"].startswith("measured")


def test_tx40_whole_recording_full_pipeline_keeps_the_torque_in_the_physical_layers(shared_data):
    # Identified on the whole recording with default flags, the joint fit let the position mixture carry
    # joint 2's gravity-like torque: link + friction left 10.8 N m there against 2.2 N m fitted alone,
    # and the mixture brought it down to 1.8 N m (a ratio of 5, under the ratio limit, but a tenth of
    # the joint's torque power).  The physical layers must hold it, and the mixture only add to them.
    import warnings

    from dynid.data.adapters import load_recording, recording_model_path
    from dynid.identify.model import identify
    from dynid.symbolic import load_robot

    full = load_recording("tx40", shared_data)
    robot = load_robot(str(recording_model_path("tx40", shared_data)))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        # the paper's full pipeline, which the defaults may choose (their choice is tested elsewhere)
        model = identify(robot, full, method="irls", friction="seed", gmm="auto")
    check = model.info["physical_check"]
    phys = np.asarray(model.rms_layers["friction"])
    # (1.1 before the pull toward the description; with it joint 2's fit is 1.103x the physical layers alone;
    # 1.17x since a joint at rest has no friction direction and its mixture no correction: the rows where the
    # arm stands still, 12 % of the recording, are the physical layers' alone)
    assert np.all(phys <= 1.2 * np.asarray(check["physical_alone_rms"])), check
    # with the pull toward the description the joint fit's physical layers already hold joint 2 (the check
    # keeps the joint fit); without it the check had to fit the physical layers first
    assert check["kept"] == "joint fit" or (
        check["kept"].startswith("physical layers first") and "joints 2" in check["kept"]
    ), check
    assert np.all(np.asarray(model.rms_layers["gmm"]) <= 1.02 * phys)


def test_irls_reaches_its_fixed_point_on_the_tx40(shared_data):
    # IRLS converges linearly: on the whole recording, where a joint at rest has no friction direction,
    # joint 5's weight and the estimate drift together; 50 steps stop 0.57 standard deviation from the
    # fixed point, which takes 225 (at about 1 ms a step): the default tries 300
    import warnings

    from dynid.data.adapters import load_recording, recording_model_path
    from dynid.identify.estimators import IRLS
    from dynid.identify.linear_system import build_system
    from dynid.symbolic import load_robot

    robot = load_robot(str(recording_model_path("tx40", shared_data)))
    system = build_system(robot, load_recording("tx40", shared_data))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no "IRLS did not converge"
        fixed = IRLS(robot=robot, max_iter=1000, tol=1e-8).fit(system)
        default = IRLS(robot=robot).fit(system)
    assert fixed.converged_ and default.converged_ and 100 < default.n_iter_ < 300
    assert np.max(np.abs(default.params_ - fixed.params_) / fixed.std_) < 0.01
    with pytest.warns(Warning, match="IRLS did not converge in 50 iterations"):
        short = IRLS(robot=robot, max_iter=50).fit(system)
    gap = np.max(np.abs(short.params_ - fixed.params_) / fixed.std_)
    assert 0.1 < gap < 2.0, gap
