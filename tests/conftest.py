"""Shared fixtures and markers.

Two tiers: ``pytest`` runs the fast one (the default ``-m "not slow"`` of pyproject.toml: unit tests,
contracts, small recoveries, the command line, bad inputs); ``pytest -m slow`` runs the benchmark-sized
cases, the real recordings and the fleets.  CI runs both.
"""

from __future__ import annotations

import os

# One BLAS / OpenMP thread: several copies load in one process (casadi, pinocchio, numpy).
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")
os.environ.setdefault("MPLBACKEND", "Agg")

from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import pytest  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
DATA = Path(__file__).resolve().parent / "fixtures"
SHARED_DATA = Path(os.environ.get("DYNID_SHARED_DATA") or REPO.parent / "shared" / "data")  # set but empty: unset, as the library reads it

DH_TABLE = """\
name = "my_arm"
[joints]
type  = ["R", "R", "P"]
alpha = [0.0, -1.5707963267948966, 1.5707963267948966]
a     = [0.0, 0.05, 0.3]
d     = [0.35, 0.0, 0.1]
theta = [0.0, -0.3, 0.0]
q_min = [-2.8, -1.9, 0.0]
q_max = [2.8, 1.9, 0.3]
[links]
m   = [5.0, 3.5, 2.0]
cx  = [0.0, 0.12, 0.0]
cy  = [-0.02, 0.0, 0.03]
cz  = [-0.08, 0.01, -0.05]
Ixx = [0.06, 0.02, 0.015]
Iyy = [0.05, 0.07, 0.012]
Izz = [0.03, 0.06, 0.006]
Ixy = [0.0, 0.0, 0.0]
Ixz = [0.0, 0.0, 0.0]
Iyz = [0.0, 0.0, 0.0]
armature = [0.1, 0.08, 0.0]
[tool]
d = 0.06
"""
"""A small modified-DH table (two revolute joints and a prismatic one, armature and a tool frame) that the
bad-input and fuzz tests edit line by line."""


def pytest_collection_modifyitems(config, items):
    """The real recordings are benchmark-sized: every ``realdata`` test runs in the slow tier."""
    for item in items:
        if item.get_closest_marker("realdata") and not item.get_closest_marker("slow"):
            item.add_marker(pytest.mark.slow)


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20231121)


@pytest.fixture(scope="session")
def ur5():
    from dynid.symbolic import load_robot

    return load_robot("ur5")


@pytest.fixture(scope="session")
def panda():
    from dynid.symbolic import load_robot

    return load_robot("panda")


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """The real recordings beside the repository; tests that need them skip when absent."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"the real recordings are not at {SHARED_DATA} (set DYNID_SHARED_DATA to their folder)")
    return SHARED_DATA


def snapshot(folder: Path) -> dict[str, bytes]:
    """Every file of a folder (recursively, following no link) with its bytes; links and pipes by kind."""
    out = {}
    for p in sorted(folder.rglob("*")):
        rel = str(p.relative_to(folder))
        if p.is_symlink():
            out[rel] = b"link->" + os.readlink(p).encode()
        elif p.is_fifo():
            out[rel] = b"fifo"
        elif p.is_file():
            out[rel] = p.read_bytes()
        elif p.is_dir():
            out[rel] = b"dir"
    return out


def assert_refused(argv, folder: Path, pattern: str, capsys, *, ignore_warnings: bool = False) -> str:
    """Run the command line; assert exit 2, one stderr line matching ``pattern``, no traceback, and the
    folder untouched (no file added, lost or changed).  ``ignore_warnings``: Python warnings raised on the
    way are not printed (the line is the refusal alone)."""
    import re
    import warnings

    from dynid.cli import main

    before = snapshot(folder)
    capsys.readouterr()
    with warnings.catch_warnings():
        if ignore_warnings:
            warnings.simplefilter("ignore")
        code = main(argv)
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip()]
    assert "Traceback" not in err, err
    assert code == 2, err
    assert len(lines) == 1, err
    assert re.search(pattern, lines[0]), lines[0]
    after = snapshot(folder)
    assert sorted(after) == sorted(before), f"files added or lost: {set(after) ^ set(before)}"
    assert [k for k in before if after[k] != before[k]] == []
    return lines[0]
