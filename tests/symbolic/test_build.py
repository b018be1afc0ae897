"""The generator build's parallel runner and its settings (no compiler run: plain shell commands)."""

from __future__ import annotations

import pytest

from dynid.exceptions import GeneratorError
from dynid.symbolic.build import _run_parallel, build_jobs


def test_parallel_runner_runs_every_command_and_reports_progress(tmp_path):
    lines: list[str] = []
    commands = [(f"part{k}", ["sh", "-c", f"echo {k} > {tmp_path / f'out{k}'}"]) for k in range(5)]
    _run_parallel(commands, "building", "a moment", 2, lines.append)
    assert sorted(p.read_text().strip() for p in tmp_path.glob("out*")) == [str(k) for k in range(5)]
    assert lines[0] == "dynid: building (once; a moment)..."
    assert sum(" done (" in line for line in lines) == 5
    assert lines[-1].startswith("dynid: building: done in ")


def test_a_failing_unit_stops_the_build_with_the_compiler_output(tmp_path):
    commands = [
        ("slow.cpp", ["sh", "-c", f"sleep 30; touch {tmp_path / 'late'}"]),
        ("bad.cpp", ["sh", "-c", "echo 'bad.cpp:1: error: expected ;' >&2; exit 3"]),
    ]
    with pytest.raises(GeneratorError, match=r"(?s)building \(bad.cpp\) failed \(exit 3\).*expected ;"):
        _run_parallel(commands, "building", "a moment", 2, None)
    assert not (tmp_path / "late").exists()  # the other unit was stopped


def test_build_jobs_from_the_environment(monkeypatch):
    monkeypatch.setenv("DYNID_BUILD_JOBS", "3")
    assert build_jobs() == 3
    monkeypatch.delenv("DYNID_BUILD_JOBS")
    assert build_jobs() >= 1
    monkeypatch.setenv("DYNID_BUILD_JOBS", "two")
    with pytest.raises(GeneratorError, match=r"DYNID_BUILD_JOBS is 'two'; give a whole number"):
        build_jobs()
