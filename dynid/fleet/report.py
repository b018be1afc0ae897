"""The fleet's HTML page: flagged robots with the parameter and the recording of change, parameters over time.

One self-contained file built from :mod:`dynid.validation.html_page` (the kit of every dynid report):

* a warning when some robot has fewer than :data:`MIN_RECORDINGS` recordings: too few for its drift test;
* the flagged robots, each parameter with its values before and after, the shift in standard
  deviations, the recording (and time) of change and the adjusted p-value (a sentence when there are none);
* per flagged robot, its flagged parameters over its recordings with +-2 standard deviation bands and
  the change marked;
* the tested parameters that came closest to a change (at most :data:`MAX_OVERVIEW`), every robot's values
  over time (relative to the robot's first recording) with their bands, the flagged robots in colour;
* the robots that differ from the fleet, the inflation factors, the refused recordings;
* the figures as JSON (``<script id="fleet-figures">``) for a program to read back.
"""

from __future__ import annotations

import html
import os
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

from dynid._io import write_text
from dynid.fleet.drift import MIN_FLEET

__all__ = ["MAX_OVERVIEW", "MIN_RECORDINGS", "few_recordings", "write_fleet_report"]

_MAX_FLAGGED_PLOTS = 12
MAX_OVERVIEW = 12
"""Most parameters drawn over time (those whose change test came closest; every test is in drift.csv)."""
MIN_RECORDINGS = 3
"""Fewest recordings per robot for a drift test that can see a change (see :func:`few_recordings`)."""


def few_recordings(result: Any) -> dict[str, int]:
    """Robots with fewer than :data:`MIN_RECORDINGS` identified recordings, and how many they have.

    With one recording a robot is not tested.  With two, its constancy test has one degree of freedom and
    its change-point scan one split (the same statistic), and the fleet's inflation factors
    (:mod:`dynid.fleet.drift`) are measured on those same pairs: wherever a factor is above 1 the median
    robot's chi^2 comes out at the median of its distribution under no change (0.455, p = 0.5) by
    construction, and a change is read as spread between recordings.

    Parameters
    ----------
    result : FleetResult
        The fleet.
    """
    counts = Counter(r["robot"] for r in result.rows if not r.get("error"))
    return {robot: k for robot, k in sorted(counts.items()) if k < MIN_RECORDINGS}


def _few_warning(few: dict[str, int], robots: int) -> str:
    two = [r for r, k in few.items() if k == 2]
    one = [r for r, k in few.items() if k < 2]

    def named(items: list[str]) -> str:
        return ", ".join(items[:8]) + (f" and {len(items) - 8} more" if len(items) > 8 else "")

    parts = []
    if two:
        parts.append(
            f"{'all ' if len(two) == robots else ''}{len(two)} robot{'s' if len(two) != 1 else ''} "
            f"({named(two)}) ha{'ve' if len(two) != 1 else 's'} only 2 recordings"
        )
    if one:
        parts.append(f"{named(one)} ha{'ve' if len(one) != 1 else 's'} 1 (not tested)")
    text = (
        "Too few recordings for the drift test: " + "; ".join(parts) + ". With two recordings a robot's test "
        "has one degree of freedom and one possible split, and the inflation factors below are measured on "
        "the same pairs: where a factor is above 1, the median robot's chi^2 is the median under no change "
        "(0.455, p = 0.5) by construction, and a change is taken for spread between recordings. Record at "
        f"least {MIN_RECORDINGS} per robot (more to place a change)."
    )
    return (
        '<p class="verdict" id="few-recordings" style="border-left-color: #ff7f0e; background: #fff6ec">'
        f"{html.escape(text)}</p>"
    )


def _figure(nplots: int, ncols: int = 3, height: float = 2.3):
    from matplotlib.figure import Figure

    ncols = max(1, min(ncols, nplots))
    nrows = max(1, -(-nplots // ncols))
    # at most 11 inches wide, as the page shows it nearly 1:1: its 8-point text stays above 11 px
    fig = Figure(figsize=(min(11.0, 3.7 * ncols), height * nrows + 0.4), layout="constrained")
    axes = fig.subplots(nrows, ncols, squeeze=False).ravel()
    for ax in axes[nplots:]:
        ax.set_visible(False)
    return fig, axes


def _flagged_figure(drift: Any, robot: str, tests: list[Any]) -> bytes:
    from dynid.validation.plots import figure_png

    tests = tests[:6]
    fig, axes = _figure(len(tests))
    for ax, t in zip(axes, tests, strict=False):
        s = drift.series[f"{robot}\t{t.parameter}"]
        order, value, std = np.array(s["order"]), np.array(s["value"]), np.array(s["std"])
        ax.fill_between(order, value - 2 * std, value + 2 * std, color="#1f77b4", alpha=0.2, lw=0)
        ax.plot(order, value, "o-", color="#1f77b4", ms=4)
        ax.axvline(t.change_order - 0.5, color="#d62728", ls="--", lw=1)
        ax.hlines(
            [t.before, t.after],
            [order[0], t.change_order],
            [t.change_order - 1, order[-1]],
            color="#d62728",
            lw=1,
        )
        ax.set_title(f"{t.parameter}: change at recording {t.change_order} ({t.change_time})", fontsize=9)
        ax.set_xticks(order, [str(x) for x in s["time"]], rotation=30, ha="right")
        ax.set_xlabel("recording", fontsize=8)
        ax.tick_params(labelsize=8)
    png = figure_png(fig)
    return png


def _overview_figure(drift: Any, names: list[str], flagged: set[tuple[str, str]]) -> bytes:
    from dynid.validation.plots import figure_png

    fig, axes = _figure(len(names), ncols=3, height=2.1)
    robots = sorted({key.split("\t")[0] for key in drift.series})
    colours = ["#d62728", "#ff7f0e", "#2ca02c", "#9467bd", "#8c564b", "#e377c2"]
    for ax, name in zip(axes, names, strict=False):
        k = 0
        for robot in robots:
            s = drift.series.get(f"{robot}\t{name}")
            if s is None or not s["value"]:
                continue
            order, value, std = np.array(s["order"]), np.array(s["value"]), np.array(s["std"])
            shift = value - value[0]
            hot = (robot, name) in flagged
            colour = colours[k % len(colours)] if hot else "0.4"
            k += hot
            ax.fill_between(
                order, shift - 2 * std, shift + 2 * std, color=colour, alpha=0.15 if hot else 0.05, lw=0
            )
            ax.plot(
                order,
                shift,
                "o-",
                color=colour,
                lw=1.6 if hot else 0.9,
                ms=3 if hot else 2,
                alpha=1.0 if hot else 0.7,
                label=robot if hot else None,
                zorder=3 if hot else 2,
            )
            ax.set_xticks(order)
        ax.set_title(f"{name}: change since the first", fontsize=9)
        ax.set_xlabel("recording", fontsize=8)
        ax.tick_params(labelsize=8)
        ax.yaxis.get_offset_text().set_fontsize(8)
        if k:
            ax.legend(fontsize=8, loc="best")
    return figure_png(fig)


def _closest(drift: Any) -> list[str]:
    """The tested parameters, those whose change test came closest first: smallest adjusted p over the robots,
    then (the adjusted ones are often all 1) smallest unadjusted p."""
    best: dict[str, tuple[float, float]] = {}
    for t in drift.tests:
        a, b = best.get(t.parameter, (1.0, 1.0))
        best[t.parameter] = (min(a, t.p_adjusted), min(b, t.p_change))
    return sorted(drift.parameters, key=lambda p: (*best.get(p, (1.0, 1.0)), drift.parameters.index(p)))


def write_fleet_report(result: Any, path: str | os.PathLike[str]) -> Path:
    """Write the fleet's HTML page (atomically).

    Parameters
    ----------
    result : FleetResult
        With its drift tests (a result without them gets the table's summary only).
    path : str or path-like
        The ``.html`` file.

    Returns
    -------
    Path
    """
    from dynid.validation.html_page import figure_html, heading, html_page, html_table, json_script

    drift = result.drift
    body = [
        f'<p class="lead">{len(result.rows)} recordings of {len(result.robots)} robots ({result.info.get("robot", "")}); '
        f"each identified by {result.settings.method}, friction {result.settings.friction}, gmm "
        f"{result.settings.gmm}; the last {result.settings.holdout:.0%} of each recording held out.</p>"
    ]
    if drift is not None:
        flagged = drift.flagged_robots
        few = few_recordings(result)
        body.append(
            f'<p class="verdict">{len(flagged)} robot{"s" if len(flagged) != 1 else ""} flagged for drift: '
            f"{', '.join(flagged) or 'none'}{' (see the warning below)' if few else ''}.</p>"
        )
        if few:
            body.append(_few_warning(few, len(result.robots)))
        body.append(heading("Flagged robots", "flagged"))
        tested = len({t.robot for t in drift.tests})
        body.append(
            html_table(
                [
                    "robot",
                    "parameter",
                    "change at recording",
                    "time",
                    "before",
                    "after",
                    "shift (sd)",
                    "p (Holm)",
                ],
                [
                    [
                        t.robot,
                        t.parameter,
                        str(t.change_order),
                        t.change_time,
                        t.before,
                        t.after,
                        t.shift_sigma,
                        t.p_adjusted,
                    ]
                    for t in drift.flagged
                ],
                text_columns=4,
            )
            if drift.flagged
            else f'<p class="note">None: no parameter of the {tested} robot{"s" if tested != 1 else ""} tested '
            f"({len(drift.parameters)} parameters each) changed over time at the family-wise error rate "
            f"{drift.alpha:g} (Holm).</p>"
        )
        for robot, tests in list(flagged.items())[:_MAX_FLAGGED_PLOTS]:
            body.append(
                figure_html(
                    _flagged_figure(drift, robot, tests),
                    title=f"{robot}: flagged parameters over time",
                    caption="Identified value per recording with +-2 sd bands (inflated as the tests use them); "
                    "the dashed line marks the change, the red lines the levels before and after.",
                    show_title=True,
                )
            )
        overview = _closest(drift)[:MAX_OVERVIEW]
        if overview:
            shown = len(overview) < len(drift.parameters)
            body.append(heading("Parameters over time", "over-time"))
            body.append(
                figure_html(
                    _overview_figure(drift, overview, {(t.robot, t.parameter) for t in drift.flagged}),
                    title="tested parameters over time, every robot",
                    caption="Each robot's value minus its value in its first recording (SI units), with +-2 sd "
                    "bands; flagged robots in colour, the others grey."
                    + (
                        f" The {len(overview)} of the {len(drift.parameters)} tested parameters whose change test "
                        "came closest (smallest adjusted p over the robots); every test is in drift.csv."
                        if shown
                        else ""
                    ),
                )
            )
        outliers = drift.fleet_outliers
        body.append(heading("Robots that differ from the fleet", "outliers"))
        body.append(
            html_table(
                ["robot", "parameter", "mean", "fleet median", "fleet spread", "z", "p (Holm)"],
                [
                    [o.robot, o.parameter, o.mean, o.fleet_median, o.fleet_spread, o.z, o.p_adjusted]
                    for items in outliers.values()
                    for o in items
                ],
                text_columns=2,
            )
            if outliers
            else f'<p class="note">None at the family-wise error rate {drift.alpha:g}.</p>'
            if drift.outliers
            else f'<p class="note">Not tested: the fleet has {len(result.robots)} robot'
            f"{'s' if len(result.robots) != 1 else ''}; the comparison with the fleet needs at least {MIN_FLEET} "
            "(its spread is a median of absolute deviations).</p>"
        )
        body.append(heading("How the tests read the standard deviations", "inflation"))
        inflated = [[k, v] for k, v in drift.inflation.items() if v > 1.0]
        body.append(
            '<p class="note">Each parameter\'s variances are multiplied by a factor measured on the fleet (the '
            "median over robots of the constancy statistic over its median under no change, at least 1): "
            + (
                "the spread between recordings is within the identifications' own for every parameter (factor 1)."
                if not inflated
                else "factors above 1 below; every other parameter's is 1."
            )
            + "</p>"
        )
        if inflated:
            body.append(html_table(["parameter", "factor"], inflated))
    if result.errors:
        body.append(heading("Refused recordings", "errors"))
        body.append(
            html_table(["path", "why"], [[r["path"], r["error"]] for r in result.errors], text_columns=2)
        )
    body.append(json_script(result.figures(), "fleet-figures"))
    return write_text(path, html_page(f"Fleet of {result.info.get('robot', 'robots')}", body))
