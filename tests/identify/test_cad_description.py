"""Robot descriptions as CAD exports write them: rounded right angles keep the exact arm's base parameters."""

from __future__ import annotations

import os
import re
import warnings
from pathlib import Path

import numpy as np
import pytest

import dynid.symbolic.urdf as urdf_module
from dynid.exceptions import RobotModelWarning
from dynid.identify.columns import column_set
from dynid.identify.model import identify
from dynid.sim.synthetic import random_fourier, synthetic_dataset, true_parameters
from dynid.symbolic.robot import example_robot_data_dir, load_robot


def _rounded(values: str, decimals: int) -> str:
    return " ".join(f"{round(float(v), decimals):.{decimals}f}" for v in values.split())


@pytest.fixture(scope="module")
def urdfs(tmp_path_factory):
    """The Panda of example-robot-data (fingers fixed): exact, and with every rpy rounded to 4 decimals."""
    text = (example_robot_data_dir() / "panda_description" / "urdf" / "panda.urdf").read_text()
    text = text.replace('type="prismatic"', 'type="fixed"')
    cad = re.sub(r'rpy="([^"]+)"', lambda m: f'rpy="{_rounded(m.group(1), 4)}"', text)
    assert cad != text
    folder = tmp_path_factory.mktemp("cad")
    (folder / "panda_exact.urdf").write_text(text)
    (folder / "panda_cad.urdf").write_text(cad)
    return folder / "panda_exact.urdf", folder / "panda_cad.urdf"


@pytest.fixture(scope="module")
def exact(urdfs):
    return load_robot(urdfs[0])


def _fit_and_predict(robot, train, heldout):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = identify(robot, train, method="ols", friction="linear", gmm="off", physical=False)
        parts = model.predict_parts(heldout)
    return model, parts["link"] + parts["friction"] + parts["gmm"], model.prepare(heldout).tau_reference


@pytest.fixture(scope="module")
def runs(exact):
    rng = np.random.default_rng(3)
    cols = column_set(exact)
    x = true_parameters(cols, rng)
    train = synthetic_dataset(cols, x, random_fourier(exact, rng, periods=2), rate=100, rng=rng, noise=0.02)
    heldout = synthetic_dataset(cols, x, random_fourier(exact, rng), rate=100, rng=rng, noise=0.02)
    return train, heldout


def test_rounded_angles_are_snapped_with_a_warning(urdfs, exact):
    with pytest.warns(RobotModelWarning, match=r"snapped them, so that the base parameters are those of the exact"):
        cad = load_robot(urdfs[1])
    for joint, same in zip(cad.joints, exact.joints, strict=True):
        np.testing.assert_allclose(joint.rotation, same.rotation, rtol=0, atol=1e-9)
    assert column_set(cad).p == column_set(exact).p  # the same base parameters (the pivots may differ by rounding)


def test_ols_on_the_cad_description_predicts_as_on_the_exact_one(urdfs, exact, runs):
    train, heldout = runs
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RobotModelWarning)
        cad = load_robot(urdfs[1])
    _, exact_pred, tau = _fit_and_predict(exact, train, heldout)
    model, cad_pred, _ = _fit_and_predict(cad, train, heldout)
    scale = np.sqrt(np.mean(tau**2, axis=0))
    diff = np.sqrt(np.mean((cad_pred - exact_pred) ** 2, axis=0))
    assert np.all(diff <= 0.01 * scale), diff / scale
    assert np.all(np.abs(model.params) < 1e3)


def test_without_the_snap_the_rounded_arm_is_another_arm(urdfs, exact, runs, monkeypatch):
    """The control: the rounded arm left as it is gains a base parameter the exact arm does not have."""
    monkeypatch.setattr(urdf_module, "SNAP_RAD", 0.0)
    monkeypatch.setattr(urdf_module, "SNAP_M", 0.0)
    raw = load_robot(urdfs[1])
    assert column_set(raw).p == column_set(exact).p + 1
    train, heldout = runs
    model, _, _ = _fit_and_predict(raw, train, heldout)
    reference, _, _ = _fit_and_predict(exact, train, heldout)
    # the extra direction, seen through 3.7e-6 rad of rounding, is all but unseen: an estimate with no digit
    assert np.nanmax(model.std) > 1000 * np.nanmax(reference.std)


def test_a_model_of_the_cad_description_exports_onto_it(urdfs, runs, tmp_path):
    """The export takes the rounded file itself as its template (the same robot) and writes its angles as
    they are; reloaded by Pinocchio the torque differs from dynid's by the order of the snap, allowed."""
    from dynid.simmodel import export_model

    train, _ = runs
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RobotModelWarning)
        cad = load_robot(urdfs[1])
        model = identify(cad, train, method="ols", friction="linear", gmm="off")
        result = export_model(model, "urdf", tmp_path / "out.urdf")
    check = next(c for c in result.checks if c["check"].startswith("URDF in Pinocchio"))
    assert check["passed"] and 1e-8 < check["tolerance"] <= 10 * urdf_module.SNAP_RAD
    assert "right angles as written" in check["check"] and check["relative_error"] > 1e-12


def test_a_model_of_a_description_with_rounded_axes_exports_onto_it(urdfs, runs, tmp_path):
    """Axes written 3e-5 off a principal direction are snapped like placements, and counted alike in the
    export's reload allowance."""
    from dynid.simmodel import export_model

    text = urdfs[0].read_text()
    rounded = text.replace('<axis xyz="0 0 1"/>', '<axis xyz="0 0.00003 1"/>')
    assert rounded != text
    path = tmp_path / "panda_axes.urdf"
    path.write_text(rounded)
    train, _ = runs
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RobotModelWarning)
        robot = load_robot(path)
        model = identify(robot, train, method="ols", friction="linear", gmm="off")
        result = export_model(model, "urdf", tmp_path / "out.urdf")
    check = next(c for c in result.checks if c["check"].startswith("URDF in Pinocchio"))
    assert check["passed"] and check["tolerance"] > 1e-8 and check["relative_error"] > 1e-8


def test_one_file_named_two_ways_gives_one_warning_text(urdfs, tmp_path, monkeypatch):
    """A model and its --compare may name one description from two folders: the warning names the file
    once, by its absolute path, so that the command line's once-per-message printing shows it once."""
    path = Path(urdfs[1]).resolve()
    (tmp_path / "a").mkdir()
    monkeypatch.chdir(tmp_path / "a")
    texts = set()
    for name in (str(path), os.path.relpath(path), str(Path("..", "a", os.path.relpath(path)))):
        with pytest.warns(RobotModelWarning) as caught:
            load_robot(name)
        texts |= {str(w.message) for w in caught if issubclass(w.category, RobotModelWarning)}
    assert texts and len(texts) == 1
    assert f"'{path}'" in texts.pop()
