"""The README's promises: its first two commands, and the "Python" section, run as written."""

from __future__ import annotations

import re

import pytest

from tests.conftest import REPO

README = REPO / "README.md"


def _section(text: str, title: str) -> str:
    match = re.search(rf"^## {re.escape(title)}\n(.*?)(?=^## |\Z)", text, flags=re.M | re.S)
    assert match, f"README.md has no section '## {title}'"
    return match.group(1)


def _python_blocks(section: str) -> list[str]:
    return re.findall(r"^```python\n(.*?)^```", section, flags=re.M | re.S)


def test_readme_starts_with_the_two_commands():
    text = README.read_text(encoding="utf-8")
    first = re.search(r"^```bash\n(.*?)^```", text, flags=re.M | re.S)
    assert first is not None
    commands = [line for line in first.group(1).splitlines() if line and not line.startswith("#")]
    assert commands == [
        "python3 -m venv .venv && . .venv/bin/activate && pip install -e . && dynid demo",
        'python3 -m venv .venv && . .venv/bin/activate && pip install -e ".[test]" && pytest -q',
    ]


def test_readme_links_the_architecture():
    text = README.read_text(encoding="utf-8")
    assert "(docs/architecture.md)" in text
    assert (REPO / "docs" / "architecture.md").is_file()


@pytest.mark.slow
def test_the_python_section_runs(tmp_path, monkeypatch, capsys):
    """Every ```python block of "## Python", in order, each standalone (its own namespace: a reader
    copies one block, not the page), in an empty folder."""
    blocks = _python_blocks(_section(README.read_text(encoding="utf-8"), "Python"))
    assert len(blocks) >= 2
    monkeypatch.chdir(tmp_path)
    namespace: dict = {}
    for k, block in enumerate(blocks):
        own: dict = {"__name__": "__readme__"}
        exec(compile(block, f"README.md (## Python, block {k + 1})", "exec"), own)
        namespace.update(own)
    out = capsys.readouterr().out
    # the path ran end to end and wrote its files
    for name in ("excitation.json", "D.csv", "model.json"):
        assert (tmp_path / name).is_file(), name
    assert (tmp_path / "ur5_c" / "libdynid_ur5.so").is_file()
    # and says what the README says it says
    assert namespace["found"].verdict == ["cogging"]
    assert namespace["design"].cond < namespace["design"].baseline_cond
    rms, floor = namespace["result"].metrics["rms"], namespace["result"].noise.std
    assert all(r > 0.9 * f for r, f in zip(rms, floor, strict=True))
    assert "held-out RMS (N m):" in out and "cogging" in out
    assert namespace["base"].n_base == 36
    assert float(out.strip().splitlines()[-1]) < 1e-8  # Yb @ beta is the torque


def test_the_python_section_uses_the_top_level_api():
    """The walk goes through ``import dynid``, the documented face, not through private modules."""
    section = _section(README.read_text(encoding="utf-8"), "Python")
    first = _python_blocks(section)[0]
    assert "import dynid\n" in first
    assert not re.search(r"\bdynid\.\w+\._", section)
