"""A recording as it comes into dynid's dataset: dynid.data.convert and the `dynid convert` command."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from dynid.cli import main
from dynid.data.convert import convert_table, read_table
from dynid.data.files import load_dataset


def _raw(path, sep=";"):
    """A controller's log: ms stamps, degrees, mN m, its own names, a comment, semicolons."""
    t = np.arange(0, 2000, 2.0)
    q = np.degrees(0.3 * np.sin(np.outer(t / 1000, np.arange(1, 4))))
    tau = 1000 * np.cos(np.outer(t / 1000, np.arange(1, 4)))
    header = [
        "timestamp",
        *(f"position_{j}" for j in (1, 2, 3)),
        "temperature",
        *(f"effort_{j}" for j in (1, 2, 3)),
    ]
    lines = ["# logged by the cell controller", sep.join(header)]
    for k in range(len(t)):
        lines.append(sep.join(f"{v:.9g}" for v in [t[k], *q[k], 25.0, *tau[k]]))
    path.write_text("\n".join(lines) + "\n")
    return t / 1000, np.radians(q), tau / 1000


@pytest.mark.parametrize("sep", [";", ",", "\t", " "])
def test_a_table_with_its_own_names_and_units_is_converted(tmp_path, sep):
    t, q, tau = _raw(tmp_path / "raw.txt", sep)
    ds = convert_table(
        tmp_path / "raw.txt", time="timestamp", q="position_*", tau="effort_1,effort_2,effort_3",
        time_unit="ms", degrees=True, torque_scale=0.001,
    )  # fmt: skip
    np.testing.assert_allclose(ds.t, t, atol=1e-12)
    np.testing.assert_allclose(ds.q, q, rtol=1e-8)
    np.testing.assert_allclose(ds.tau, tau, rtol=1e-8, atol=1e-12)
    assert ds.meta["columns"]["q"] == ["position_1", "position_2", "position_3"]


def test_the_command_writes_a_dataset_dynid_reads(tmp_path, capsys):
    _, q, _ = _raw(tmp_path / "raw.csv")
    argv = [
        "convert", "--data", str(tmp_path / "raw.csv"), "--time", "timestamp", "--q", "position_*", "--tau",
        "effort_*", "--time-unit", "ms", "--degrees", "--torque-scale", "0.001", "--out", str(tmp_path / "D.csv"),
        "--json", str(tmp_path / "C.json"), "--quiet",
    ]  # fmt: skip
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "1000 samples of 3 joints" in out
    assert "converted: t ms -> s; angles deg -> rad; torques x 0.001 -> N m" in out
    ds = load_dataset(tmp_path / "D.csv")
    np.testing.assert_allclose(ds.q, q, rtol=1e-8)
    assert json.loads((tmp_path / "C.json").read_text())["joints"] == 3


@pytest.mark.parametrize(
    ("extra", "pattern"),
    [
        (
            ["--q", "pos_*", "--tau", "effort_*"],
            r"--q 'pos_\*' matches no column of the table; its columns are: timestamp",
        ),
        (["--q", "position_*", "--tau", "effort_1"], r"--tau names 1 columns and --q 3"),
        (
            ["--q", "position_*", "--tau", "effort_*", "--time-unit", "ms"],
            r"angles reach .* look like degrees; add --degrees",
        ),
        (
            ["--q", "position_*", "--tau", "effort_*", "--torque-scale", "0"],
            r"--torque-scale is 0; give one non-zero",
        ),
        (["--q", "position_*"], r"--data needs --q and --tau"),
        (  # a millisecond clock read as seconds: every later command would refuse the file
            ["--q", "position_*", "--tau", "effort_*", "--degrees"],
            r"'timestamp' read in s gives a median time step of .* give its unit with --time-unit "
            r"\(e\.g\. --time-unit ms\)",
        ),
    ],
)
def test_mistakes_end_in_one_sentence(tmp_path, capsys, extra, pattern):
    import re

    _raw(tmp_path / "raw.csv")
    before = sorted(p.name for p in tmp_path.iterdir())
    capsys.readouterr()
    code = main(
        [
            "convert",
            "--data",
            str(tmp_path / "raw.csv"),
            "--time",
            "timestamp",
            *extra,
            "--out",
            str(tmp_path / "D.csv"),
            "--quiet",
        ]
    )
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 2 and len(lines) == 1 and "Traceback" not in err, err
    assert re.search(pattern, lines[0]), lines[0]
    assert sorted(p.name for p in tmp_path.iterdir()) == before


def test_a_cell_that_is_not_a_number_is_named(tmp_path):
    from dynid.exceptions import DataError

    (tmp_path / "raw.csv").write_text("t,q,tau\n0,0,0\n0.1,abc,1\n")
    with pytest.raises(DataError, match=r"line 3: 'abc' is not a number"):
        read_table(tmp_path / "raw.csv")


def test_the_output_never_overwrites_the_input(tmp_path, capsys):
    _raw(tmp_path / "raw.csv")
    raw = (tmp_path / "raw.csv").read_bytes()
    code = main(["convert", "--data", str(tmp_path / "raw.csv"), "--time", "timestamp", "--q", "position_*",
                 "--tau", "effort_*", "--degrees", "--out", str(tmp_path / "raw.csv"), "--quiet"])  # fmt: skip
    assert code == 2 and "would overwrite the --data file" in capsys.readouterr().err
    assert (tmp_path / "raw.csv").read_bytes() == raw


@pytest.mark.realdata
def test_a_named_recording_is_converted(shared_data, tmp_path, capsys):
    assert (
        main(
            [
                "convert",
                "--recording",
                "tx40",
                "--root",
                str(shared_data),
                "--out",
                str(tmp_path / "tx40.npz"),
                "--quiet",
            ]
        )
        == 0
    )
    ds = load_dataset(tmp_path / "tx40.npz")
    assert ds.n == 6 and ds.m == 45000 and math.isclose(ds.duration, 9.0, rel_tol=1e-3)


@pytest.mark.realdata
def test_a_run_of_a_recording_of_several_is_converted(shared_data, tmp_path, capsys):
    """The KUKA LWR4+ recording holds three runs: --run picks one (run 1 was written silently before); a
    recording of one run refuses --run in one sentence."""
    from dynid.data.adapters import load_kuka_lwr4

    out = tmp_path / "k3.npz"
    argv = ["convert", "--recording", "kuka_lwr4_flobaroid", "--root", str(shared_data), "--out", str(out)]
    assert main([*argv, "--run", "3"]) == 0
    assert "kuka_lwr4_flobaroid, run 3 of 3:" in capsys.readouterr().out
    np.testing.assert_array_equal(load_dataset(out).q, load_kuka_lwr4(shared_data, run=3).q)
    assert main([*argv[:-1], str(tmp_path / "k.npz"), "--run", "4"]) == 2
    assert "--run 4: the recording kuka_lwr4_flobaroid has runs 1 to 3" in capsys.readouterr().err
    assert main(["convert", "--recording", "tx40", "--root", str(shared_data), "--run", "2",
                 "--out", str(tmp_path / "t.npz")]) == 2  # fmt: skip
    assert "the recording tx40 is one run; leave --run out" in capsys.readouterr().err
    assert not (tmp_path / "k.npz").exists() and not (tmp_path / "t.npz").exists()
