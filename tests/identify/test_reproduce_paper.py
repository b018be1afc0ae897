"""scripts/reproduce_paper.py runs end to end in its quick mode and prints the paper's table."""

from __future__ import annotations

import runpy
from pathlib import Path
from types import SimpleNamespace

import pytest

REPO = Path(__file__).resolve().parents[2]


def load_script() -> SimpleNamespace:
    return SimpleNamespace(
        **runpy.run_path(str(REPO / "scripts" / "reproduce_paper.py"), run_name="dynid_script")
    )


@pytest.mark.slow
def test_quick_reproduction_prints_every_figure_of_the_table() -> None:
    script = load_script()
    lines: list[str] = []
    figures = script.main(quick=True, progress=lines.append)
    for key in ("cond_ls", "cond_iterative", "cond_seed", "rms_ols", "rms_irls", "rms_full", "noise_floor"):
        assert figures[key] > 0, key
    # the designs are no worse than the best random trajectory, and the full method beats OLS held out
    assert max(figures["cond_ls"], figures["cond_iterative"], figures["cond_seed"]) < figures["cond_random"]
    assert figures["rms_full"] < figures["rms_ols"]
    assert figures["noise_floor"] < figures["rms_full"]
    text = script.table(figures)
    for label in ("cond, plain LS criterion", "avg residual RMS, OLS", "full / OLS", "329", "6.14 mA"):
        assert label in text
    assert len(lines) == 6  # one line per step and method
