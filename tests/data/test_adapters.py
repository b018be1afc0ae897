"""Tests of dynid.data.adapters on the real recordings in ../shared/data (skipped when absent).

The physics checks compare the measured torque with the rigid-body torque of the recording's URDF,
computed by numeric Pinocchio (``pin.rnea``) on states from dynid's own preprocessing.  Measured on
this data (Panda filtered at 10 Hz, TX40 at 100 Hz, both decimated by 10):

* Panda, rigid body only: r = 0.991 0.9997 0.9995 0.995 0.967 0.990 0.03.  Joint 7's rigid-body torque
  (std 0.05 N m) is far below its friction (Coulomb ~0.22 N m): with a per-joint friction term
  (viscous, Coulomb, offset; rigid-body coefficient fixed at 1) every joint reaches r >= 0.965.
* TX40, rigid body only: r = 0.52 0.69 0.42 0.32 0.04 ~0 (link 6 is massless).  Rotor inertia seen
  through the gears and friction dominate (the recording's README says so); with a per-joint armature
  and friction term joints 1-4 reach r >= 0.98, joint 5 0.83 and joint 6 0.93 (coupled wrist not
  modelled), and a free fit gives the rigid-body term a gain of 0.90-0.98 on joints 1-3, which checks the
  motor-to-joint conversion.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray

from dynid.data.adapters import (
    ADAPTERS,
    ENV_VAR,
    find_shared_data,
    load_panda_gaz2019,
    load_recording,
    load_tx40,
    recording_model_path,
    tx40_coupling_matrices,
)
from dynid.data.dataset import Dataset
from dynid.data.preprocess import preprocess
from dynid.exceptions import DataError

DATA = Path(os.environ.get(ENV_VAR) or Path(__file__).resolve().parents[3] / "shared" / "data")
skip_without_data = pytest.mark.skipif(
    not DATA.is_dir(), reason=f"the real recordings are not at {DATA} (../shared/data)"
)


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(3)


# ---------------------------------------------------------------------- without the data
def test_unknown_recording_lists_the_known_ones(tmp_path: Path) -> None:
    with pytest.raises(DataError, match="unknown recording 'ur5'; known recordings: kuka_lwr4_flobaroid, panda_gaz2019, tx40"):
        load_recording("ur5", tmp_path)


def test_missing_recording_folder_says_what_to_do(tmp_path: Path) -> None:
    with pytest.raises(DataError, match=r"holds no recording 'tx40' .*set DYNID_SHARED_DATA"):
        load_tx40(tmp_path)
    (tmp_path / "panda_gaz2019").mkdir()
    with pytest.raises(DataError, match="the Panda time stamps is missing: no file"):
        load_panda_gaz2019(tmp_path)


def test_environment_variable_naming_no_folder(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(ENV_VAR, str(tmp_path / "absent"))
    with pytest.raises(DataError, match=f"{ENV_VAR} is set to .*, which is not a folder"):
        find_shared_data()


def test_environment_variable_is_used(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(ENV_VAR, str(tmp_path))
    assert find_shared_data() == tmp_path


def test_tx40_coupling_conserves_power(rng: np.random.Generator) -> None:
    Rm, Rt = tx40_coupling_matrices()
    np.testing.assert_array_equal(Rt, Rm.T)
    assert Rm[5, 4] == 32.0
    assert np.count_nonzero(Rm - np.diag(np.diag(Rm))) == 1
    dq, tau_motor = rng.normal(size=6), rng.normal(size=6)
    assert (Rt @ tau_motor) @ dq == pytest.approx(tau_motor @ (Rm @ dq), rel=1e-12)


# ---------------------------------------------------------------------- with the data
def rigid_body_torque(urdf: Path, ds: Dataset) -> NDArray[np.float64]:
    """tau = M(q) ddq + C(q, dq) dq + g(q) from the URDF, shape (m, n), by numeric Pinocchio."""
    pin = pytest.importorskip("pinocchio")
    model = pin.buildModelFromUrdf(str(urdf))
    data = model.createData()
    assert model.nq == ds.n
    return np.array([pin.rnea(model, data, ds.q[k], ds.dq[k], ds.ddq[k]) for k in range(ds.m)])


def correlations(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.array([np.corrcoef(a[:, j], b[:, j])[0, 1] for j in range(a.shape[1])])


def drive_columns(ds: Dataset, j: int, *, armature: bool) -> NDArray[np.float64]:
    """Per-joint terms beyond rigid-body dynamics: viscous, Coulomb, offset (and armature ddq)."""
    cols = [ds.dq[:, j], np.sign(ds.dq[:, j]), np.ones(ds.m)]
    if armature:
        cols.append(ds.ddq[:, j])
    return np.column_stack(cols)


def with_drive_terms(rb: NDArray[np.float64], ds: Dataset, *, armature: bool) -> NDArray[np.float64]:
    """Rigid-body torque (gain fixed at 1) plus per-joint drive terms fitted by least squares."""
    out = np.empty_like(rb)
    for j in range(ds.n):
        A = drive_columns(ds, j, armature=armature)
        x, *_ = np.linalg.lstsq(A, ds.tau[:, j] - rb[:, j], rcond=None)
        out[:, j] = rb[:, j] + A @ x
    return out


def rigid_body_gains(rb: NDArray[np.float64], ds: Dataset, *, armature: bool) -> NDArray[np.float64]:
    """Least-squares gain of the rigid-body torque when fitted freely beside the drive terms."""
    gains = []
    for j in range(ds.n):
        A = np.column_stack([rb[:, j], drive_columns(ds, j, armature=armature)])
        x, *_ = np.linalg.lstsq(A, ds.tau[:, j], rcond=None)
        gains.append(x[0])
    return np.array(gains)


@pytest.fixture(scope="module")
def panda_raw() -> Dataset:
    return load_recording("panda_gaz2019", DATA)


@pytest.fixture(scope="module")
def tx40_raw() -> Dataset:
    return load_recording("tx40", DATA)


@pytest.fixture(scope="module")
def panda_prepared(panda_raw: Dataset) -> tuple[Dataset, NDArray[np.float64]]:
    ds = preprocess(panda_raw, cutoff=10.0, decimate=10)
    return ds, rigid_body_torque(recording_model_path("panda_gaz2019", DATA), ds)


@pytest.fixture(scope="module")
def tx40_prepared(tx40_raw: Dataset) -> tuple[Dataset, NDArray[np.float64]]:
    ds = preprocess(tx40_raw, cutoff=100.0, decimate=10)  # the source filtered at 100 Hz
    return ds, rigid_body_torque(recording_model_path("tx40", DATA), ds)


@pytest.mark.realdata
@skip_without_data
def test_registry_names_models() -> None:
    for name, recording in ADAPTERS.items():
        path = recording_model_path(name, DATA)
        assert path.suffix == ".urdf"
        assert path.is_file()
        assert recording.model_path(DATA / name) == path  # the recording's own folder works too


@pytest.mark.realdata
@skip_without_data
class TestPanda:
    def test_shape_and_time(self, panda_raw: Dataset) -> None:
        assert panda_raw.n == 7
        assert panda_raw.meta["rows_recorded"] == 20544
        assert panda_raw.meta["dropped_repeated_rows"] == 1255
        assert panda_raw.m == 20544 - 1255
        assert np.all(np.diff(panda_raw.t) > 0)
        assert not panda_raw.is_uniform  # raw stamps kept
        assert panda_raw.dt == pytest.approx(1e-3, rel=1e-3)
        assert panda_raw.dq is not None
        assert not np.any(np.all(np.diff(panda_raw.q, axis=0) == 0, axis=1))  # no stale rows left

    def test_rigid_body_matches_joints_1_to_6(
        self, panda_prepared: tuple[Dataset, NDArray[np.float64]]
    ) -> None:
        ds, rb = panda_prepared
        r = correlations(rb, ds.tau)
        assert np.all(r[:6] >= 0.95), np.round(r, 4)
        gains = rigid_body_gains(rb, ds, armature=False)
        assert np.all((gains[:6] > 0.9) & (gains[:6] < 1.1)), np.round(gains, 3)

    def test_rigid_body_plus_friction_matches_every_joint(
        self, panda_prepared: tuple[Dataset, NDArray[np.float64]]
    ) -> None:
        ds, rb = panda_prepared
        r = correlations(with_drive_terms(rb, ds, armature=False), ds.tau)
        assert np.all(r >= 0.95), np.round(r, 4)


@pytest.mark.realdata
@skip_without_data
class TestTX40:
    def test_shape_and_time(self, tx40_raw: Dataset) -> None:
        assert (tx40_raw.m, tx40_raw.n) == (45000, 6)
        assert tx40_raw.is_uniform
        assert tx40_raw.dt == pytest.approx(0.0002, rel=1e-9)
        assert tx40_raw.t[-1] == pytest.approx(44999 * 0.0002, rel=1e-12)
        assert tx40_raw.dq is None

    def test_first_sample_is_the_urdf_zero_with_gravity_on_joint_2(self, tx40_raw: Dataset) -> None:
        pin = pytest.importorskip("pinocchio")
        model = pin.buildModelFromUrdf(str(recording_model_path("tx40", DATA)))
        q0 = tx40_raw.q[0]
        np.testing.assert_allclose(q0, 0.0, atol=1e-4)  # upper arm horizontal after the offsets
        gravity = pin.rnea(model, model.createData(), q0, np.zeros(6), np.zeros(6))
        assert tx40_raw.tau[0, 1] == pytest.approx(-24.3, abs=0.1)
        assert abs(tx40_raw.tau[0, 1] - gravity[1]) < 1.0

    def test_rigid_body_plus_drive_terms_match_joints_1_to_3(
        self, tx40_prepared: tuple[Dataset, NDArray[np.float64]]
    ) -> None:
        ds, rb = tx40_prepared
        r = correlations(with_drive_terms(rb, ds, armature=True), ds.tau)
        assert np.all(r[:3] >= 0.9), np.round(r, 4)
        gains = rigid_body_gains(rb, ds, armature=True)
        assert np.all((gains[:3] > 0.8) & (gains[:3] < 1.2)), np.round(gains, 3)
