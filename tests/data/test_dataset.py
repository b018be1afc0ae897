"""Tests of dynid.data.dataset and dynid.data.files: the Dataset type, its checks, and its files."""

from __future__ import annotations

import dataclasses
import warnings
from pathlib import Path

import numpy as np
import pytest

from dynid.data.dataset import Dataset
from dynid.data.files import load_dataset, save_dataset
from dynid.exceptions import DataError, DataWarning


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20240611)


def make_dataset(rng: np.random.Generator, m: int = 50, n: int = 3, *, derivatives: bool = False) -> Dataset:
    t = 0.5 + 0.004 * np.arange(m)
    extra = {}
    if derivatives:
        extra = {"dq": rng.normal(size=(m, n)), "ddq": rng.normal(size=(m, n))}
    return Dataset(t, rng.uniform(-3, 3, size=(m, n)), rng.normal(scale=20, size=(m, n)), **extra)


def write_csv(path: Path, header: str, rows: list[list[float]]) -> Path:
    lines = [header] + [",".join(repr(float(v)) for v in row) for row in rows]
    path.write_text("\n".join(lines) + "\n")
    return path


def good_rows(m: int = 6) -> list[list[float]]:
    """Rows for the header t,q_1,q_2,tau_1,tau_2."""
    return [[0.01 * k, 0.1 * k, -0.1 * k, 1.0 + k, 2.0 - k] for k in range(m)]


def assert_same(a: Dataset, b: Dataset) -> None:
    np.testing.assert_array_equal(a.t, b.t)
    for name in ("q", "tau", "dq", "ddq"):
        x, y = getattr(a, name), getattr(b, name)
        assert (x is None) == (y is None), name
        if x is not None:
            np.testing.assert_array_equal(x, y)


# ---------------------------------------------------------------------- construction and checks
def test_sizes_and_time(rng: np.random.Generator) -> None:
    ds = make_dataset(rng, m=40, n=2)
    assert (ds.m, ds.n) == (40, 2)
    assert ds.dt == pytest.approx(0.004, rel=1e-12)
    assert ds.is_uniform
    assert ds.duration == pytest.approx(39 * 0.004)
    assert ds.columns == ["t", "q_1", "q_2", "tau_1", "tau_2"]
    assert ds.runs == [slice(0, 40)]
    assert "m=40, n=2" in repr(ds)


def test_irregular_time_is_not_uniform(rng: np.random.Generator) -> None:
    t = np.cumsum(rng.uniform(0.8e-3, 1.6e-3, size=100))
    ds = Dataset(t, np.zeros((100, 1)), np.zeros((100, 1)))
    assert not ds.is_uniform
    assert ds.dt == pytest.approx(np.median(np.diff(t)))


def test_arrays_are_read_only_copies(rng: np.random.Generator) -> None:
    q = rng.normal(size=(10, 2))
    ds = Dataset(np.arange(10.0), q, np.zeros((10, 2)))
    q[0, 0] = 99.0
    assert ds.q[0, 0] != 99.0
    with pytest.raises(ValueError, match="read-only"):
        ds.q[0, 0] = 1.0
    with pytest.raises(dataclasses.FrozenInstanceError, match="cannot assign"):
        ds.q = q  # type: ignore[misc]


def test_one_dimensional_q_is_one_joint() -> None:
    ds = Dataset(np.arange(4.0), np.zeros(4), np.ones(4))
    assert ds.q.shape == (4, 1)
    assert ds.tau.shape == (4, 1)


def test_nan_names_column_and_first_bad_row(rng: np.random.Generator) -> None:
    tau = rng.normal(size=(20, 3))
    tau[7, 2] = np.nan
    tau[9, 0] = np.inf
    with pytest.raises(DataError, match=r"tau_3 is nan at row 7 \(t = 0\.07 s; 2 bad rows in all\)"):
        Dataset(0.01 * np.arange(20), np.zeros((20, 3)), tau)


def test_nan_in_time_is_named() -> None:
    t = np.arange(5.0)
    t[3] = np.nan
    with pytest.raises(DataError, match=r"t is nan at row 3"):
        Dataset(t, np.zeros((5, 1)), np.zeros((5, 1)))


@pytest.mark.parametrize("bad", [0.02, 0.01], ids=["repeated", "backwards"])
def test_time_must_increase_strictly(bad: float) -> None:
    t = np.array([0.0, 0.01, 0.02, bad, 0.05])
    with pytest.raises(DataError, match=r"t must increase strictly, but t\[3\]"):
        Dataset(t, np.zeros((5, 2)), np.zeros((5, 2)))


def test_shapes_must_agree() -> None:
    t = np.arange(5.0)
    with pytest.raises(DataError, match="tau has 3 columns but q has 2"):
        Dataset(t, np.zeros((5, 2)), np.zeros((5, 3)))
    with pytest.raises(DataError, match="q has 4 rows but t has 5"):
        Dataset(t, np.zeros((4, 2)), np.zeros((5, 2)))
    with pytest.raises(DataError, match="dq has 1 columns but q has 2"):
        Dataset(t, np.zeros((5, 2)), np.zeros((5, 2)), dq=np.zeros((5, 1)))
    with pytest.raises(DataError, match="at least 2 samples"):
        Dataset(np.array([0.0]), np.zeros((1, 2)), np.zeros((1, 2)))
    with pytest.raises(DataError, match="could not be read as numbers"):
        Dataset(t, [["a"] * 2] * 5, np.zeros((5, 2)))


def test_joint_count() -> None:
    t = np.arange(5.0)
    with pytest.raises(DataError, match="q has 7 columns; the robot 'ur5' has 6 joints"):
        Dataset(t, np.zeros((5, 7)), np.zeros((5, 7)), n_joints=6, robot_name="ur5")
    ds = Dataset(t, np.zeros((5, 6)), np.zeros((5, 6)))
    assert ds.check_joints(6, "ur5") is ds
    with pytest.raises(DataError, match="q has 6 columns; the robot has 7 joints"):
        ds.check_joints(7)


def test_degrees_warn(rng: np.random.Generator) -> None:
    q_deg = np.rad2deg(rng.uniform(-2.5, 2.5, size=(30, 3)))
    q_deg[:, 1] = 170.0  # the largest: rad2deg(2.5) = 143
    with pytest.warns(DataWarning, match=r"q_2 reaches 170, more than 10 rad; the angles look like degrees"):
        Dataset(np.arange(30.0), q_deg, np.zeros((30, 3)))


def test_radians_do_not_warn(rng: np.random.Generator) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error", DataWarning)
        Dataset(np.arange(30.0), rng.uniform(-2 * np.pi, 2 * np.pi, size=(30, 3)), np.zeros((30, 3)))


# ---------------------------------------------------------------------- selection and joining
def test_slice_time_is_inclusive(rng: np.random.Generator) -> None:
    ds = make_dataset(rng, m=100)  # t = 0.5 + 0.004 k
    part = ds.slice_time(0.6, 0.7)
    np.testing.assert_allclose(part.t[[0, -1]], [0.6, 0.7], atol=1e-12)
    np.testing.assert_array_equal(part.q, ds.q[25:51])
    with pytest.raises(DataError, match=r"slice_time\(5, 6\) keeps 0 sample"):
        ds.slice_time(5.0, 6.0)
    with pytest.raises(DataError, match="needs t0 < t1"):
        ds.slice_time(0.7, 0.6)


def test_concat_restamps_and_records_runs(rng: np.random.Generator) -> None:
    a, b = make_dataset(rng, m=30), make_dataset(rng, m=20)
    b = dataclasses.replace(b, t=b.t + 100.0, meta={"robot": "x", "run": 2})
    a = dataclasses.replace(a, meta={"robot": "x", "run": 1})
    ab = Dataset.concat([a, b])
    assert ab.m == 50
    np.testing.assert_allclose(np.diff(ab.t), 0.004, rtol=1e-9)  # runs follow each other
    assert ab.t[0] == a.t[0]
    assert ab.is_uniform
    assert ab.runs == [slice(0, 30), slice(30, 50)]
    assert ab.meta["robot"] == "x"
    assert "run" not in ab.meta
    assert [p["run"] for p in ab.meta["parts"]] == [1, 2]
    np.testing.assert_array_equal(ab.tau[30:], b.tau)
    abc = Dataset.concat([ab, make_dataset(rng, m=10)])  # runs inside parts are kept
    assert [r.start for r in abc.runs] == [0, 30, 50]


def test_concat_refuses_mismatches(rng: np.random.Generator) -> None:
    with pytest.raises(DataError, match="dataset 1 has 2 joints but dataset 0 has 3"):
        Dataset.concat([make_dataset(rng, n=3), make_dataset(rng, n=2)])
    with pytest.raises(DataError, match="dataset 1 has dq but dataset 0 has not"):
        Dataset.concat([make_dataset(rng), make_dataset(rng, derivatives=True)])
    with pytest.raises(DataError, match="needs at least one dataset"):
        Dataset.concat([])


def test_select_rows_moves_run_boundaries(rng: np.random.Generator) -> None:
    ab = Dataset.concat([make_dataset(rng, m=10), make_dataset(rng, m=10)])
    sub = ab.select_rows([2, 4, 6, 8, 12, 14])
    assert [r.start for r in sub.runs] == [0, 4]
    only_second = ab.select_rows([12, 14, 16])
    assert only_second.runs == [slice(0, 3)]
    with pytest.raises(DataError, match="strictly increasing indices"):
        ab.select_rows([3, 2])


def test_bad_run_starts_are_refused(rng: np.random.Generator) -> None:
    ds = make_dataset(rng, m=10)
    with pytest.raises(DataError, match=r"meta\['run_starts'\] must be strictly increasing"):
        dataclasses.replace(ds, meta={"run_starts": [0, 12]})


# ---------------------------------------------------------------------- files
@pytest.mark.parametrize("suffix", [".csv", ".npz"])
@pytest.mark.parametrize("derivatives", [False, True])
def test_round_trip(rng: np.random.Generator, tmp_path: Path, suffix: str, derivatives: bool) -> None:
    ds = make_dataset(rng, m=64, n=4, derivatives=derivatives)
    path = save_dataset(ds, tmp_path / f"data{suffix}")
    back = load_dataset(path, n_joints=4)
    assert_same(ds, back)
    assert back.meta["source"] == str(path)
    assert sorted(p.name for p in tmp_path.iterdir()) == [f"data{suffix}"]  # no temporary file left


def test_saved_file_is_readable_by_others(rng: np.random.Generator, tmp_path: Path) -> None:
    path = save_dataset(make_dataset(rng), tmp_path / "d.npz")
    assert path.stat().st_mode & 0o044 == 0o044  # not the 0600 of a temporary file


def test_csv_header_follows_the_contract(rng: np.random.Generator, tmp_path: Path) -> None:
    path = save_dataset(make_dataset(rng, n=2, derivatives=True), tmp_path / "d.csv")
    header = path.read_text().splitlines()[0]
    assert header == "t,q_1,q_2,tau_1,tau_2,dq_1,dq_2,ddq_1,ddq_2"


def test_csv_column_order_free_and_extra_columns_ignored(tmp_path: Path) -> None:
    rows = [[r[3], r[0], r[1], r[2], r[4], 7.0] for r in good_rows()]
    path = write_csv(tmp_path / "d.csv", "tau_1, t, q_1, q_2, tau_2, note", rows)
    ds = load_dataset(path)
    np.testing.assert_allclose(ds.q[:, 1], [-0.1 * k for k in range(6)])
    np.testing.assert_allclose(ds.tau[:, 0], [1.0 + k for k in range(6)])
    assert ds.meta["ignored_columns"] == ["note"]


def test_npz_keeps_meta_and_run_boundaries(rng: np.random.Generator, tmp_path: Path) -> None:
    joined = Dataset.concat([make_dataset(rng, m=20), make_dataset(rng, m=30)])
    back = load_dataset(save_dataset(joined, tmp_path / "runs.npz"))
    assert back.runs == joined.runs


def test_npz_accepts_stacked_arrays(rng: np.random.Generator, tmp_path: Path) -> None:
    t, q, tau = 0.01 * np.arange(8.0), rng.normal(size=(8, 2)), rng.normal(size=(8, 2))
    np.savez(tmp_path / "stacked.npz", t=t, q=q, tau=tau)
    ds = load_dataset(tmp_path / "stacked.npz")
    np.testing.assert_array_equal(ds.q, q)
    np.testing.assert_array_equal(ds.tau, tau)


def bad_csv_cases() -> list[tuple[str, str, list[list[float]], str]]:
    rows = good_rows()
    nan_rows = [list(r) for r in rows]
    nan_rows[3][4] = float("nan")
    backwards = [list(r) for r in rows]
    backwards[4][0] = 0.02
    return [
        ("missing_tau", "t,q_1,q_2,tau_1,x", [[*r[:4], 0.0] for r in rows], "no column 'tau_2'; a dataset"),
        ("missing_t", "time,q_1,q_2,tau_1,tau_2", rows, "has no column 't'"),
        ("missing_q", "t,tau_1,tau_2,x,y", rows, "has no column 'q_1'"),
        ("gap_in_q", "t,q_1,q_3,tau_1,tau_2", rows, "has no column 'q_2'"),
        ("nan_row", "t,q_1,q_2,tau_1,tau_2", nan_rows, r"tau_2 is nan at row 3 \(t = 0\.03 s"),
        ("non_monotonic", "t,q_1,q_2,tau_1,tau_2", backwards, r"t must increase strictly, but t\[4\]"),
        ("no_header", "0,1,2,3,4", rows, "has no header"),
    ]


@pytest.mark.parametrize(("name", "header", "rows", "message"), bad_csv_cases(), ids=lambda c: str(c)[:14])
def test_bad_csv_raises_and_writes_nothing(
    tmp_path: Path, name: str, header: str, rows: list[list[float]], message: str
) -> None:
    source = write_csv(tmp_path / f"{name}.csv", header, rows)
    out = tmp_path / "out.npz"
    with pytest.raises(DataError, match=message):
        save_dataset(load_dataset(source), out)
    assert sorted(tmp_path.iterdir()) == [source]


def test_half_the_velocities_is_refused(tmp_path: Path) -> None:
    rows = [[*r, 0.5] for r in good_rows()]
    source = write_csv(tmp_path / "d.csv", "t,q_1,q_2,tau_1,tau_2,dq_1", rows)
    with pytest.raises(DataError, match=r"d\.csv has no column 'dq_2'; give all of dq_1\.\.dq_2 or none"):
        load_dataset(source)


def test_wrong_joint_count_raises_and_writes_nothing(tmp_path: Path) -> None:
    source = write_csv(tmp_path / "d.csv", "t,q_1,q_2,tau_1,tau_2", good_rows())
    out = tmp_path / "out.csv"
    with pytest.raises(DataError, match=r"d\.csv: q has 2 columns; the robot 'ur5' has 6 joints"):
        save_dataset(load_dataset(source, n_joints=6, robot_name="ur5"), out)
    assert not out.exists()


def test_text_in_numbers(tmp_path: Path) -> None:
    source = tmp_path / "d.csv"
    source.write_text("t,q_1,tau_1\n0,0.1,1\n0.1,abc,2\n")
    with pytest.raises(DataError, match=r"d\.csv could not be read as numbers"):
        load_dataset(source)


def test_missing_file_and_unknown_extension(rng: np.random.Generator, tmp_path: Path) -> None:
    with pytest.raises(DataError, match="no dataset file at"):
        load_dataset(tmp_path / "absent.csv")
    # a rosbag2 folder's name mistyped: not there, not an 'unknown extension'
    with pytest.raises(DataError, match=r"no file or folder at .*run_2026_11_23; give a dataset file"):
        load_dataset(tmp_path / "run_2026_11_23")
    (tmp_path / "data.txt").write_text("t,q_1,tau_1\n0,0,0\n1,0,0\n")
    with pytest.raises(DataError, match=r"data\.txt: unknown extension '\.txt'; a dataset file ends in"):
        load_dataset(tmp_path / "data.txt")
    with pytest.raises(DataError, match=r"unknown extension '.json'"):
        save_dataset(make_dataset(rng), tmp_path / "out.json")
    with pytest.raises(DataError, match=r"the folder .* does not exist"):
        save_dataset(make_dataset(rng), tmp_path / "nowhere" / "out.csv")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["data.txt"]


@pytest.mark.parametrize(("suffix", "writer"), [(".csv", "savetxt"), (".npz", "savez")])
def test_failed_write_keeps_the_old_file(
    rng: np.random.Generator, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, suffix: str, writer: str
) -> None:
    path = tmp_path / f"data{suffix}"
    old = make_dataset(rng)
    save_dataset(old, path)
    before = path.read_bytes()

    def disk_full(*args: object, **kwargs: object) -> None:
        raise OSError("disk full")

    monkeypatch.setattr(np, writer, disk_full)
    with pytest.raises(OSError, match="disk full"):
        save_dataset(make_dataset(rng), path)
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == [path.name]
