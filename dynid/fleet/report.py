"""The fleet's HTML page: flagged robots with the parameter and the recording of change, parameters over time.

One self-contained file built from :mod:`dynid.validation.html_page` (the kit of every dynid report):

* the flagged robots, each parameter with its values before and after, the shift in standard
  deviations, the recording (and time) of change and the adjusted p-value;
* per flagged robot, its flagged parameters over its recordings with +-2 standard deviation bands and
  the change marked;
* per tested friction and armature parameter, every robot's values over time (relative to the robot's
  first recording) with their bands, the flagged robots in colour;
* the robots that differ from the fleet, the inflation factors, the refused recordings;
* the figures as JSON (``<script id="fleet-figures">``) for a program to read back.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from dynid._io import write_text

__all__ = ["write_fleet_report"]

_MAX_FLAGGED_PLOTS = 12
_MAX_OVERVIEW = 24


def _figure(nplots: int, ncols: int = 3, height: float = 2.3):
    from matplotlib.figure import Figure

    ncols = max(1, min(ncols, nplots))
    nrows = max(1, -(-nplots // ncols))
    fig = Figure(figsize=(3.8 * ncols, height * nrows + 0.4), layout="constrained")
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
        ax.hlines([t.before, t.after], [order[0], t.change_order], [t.change_order - 1, order[-1]],
                  color="#d62728", lw=1)
        ax.set_title(f"{t.parameter}: change at recording {t.change_order} ({t.change_time})", fontsize=9)
        ax.set_xticks(order, [str(x) for x in s["time"]], rotation=30, ha="right")
        ax.set_xlabel("recording", fontsize=8)
        ax.tick_params(labelsize=7)
    png = figure_png(fig)
    return png


def _overview_figure(drift: Any, names: list[str], flagged: set[tuple[str, str]]) -> bytes:
    from dynid.validation.plots import figure_png

    fig, axes = _figure(len(names), ncols=4, height=2.0)
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
            colour = colours[k % len(colours)] if hot else "#999999"
            k += hot
            ax.fill_between(order, shift - 2 * std, shift + 2 * std, color=colour, alpha=0.15 if hot else 0.04, lw=0)
            ax.plot(order, shift, "-", color=colour, lw=1.4 if hot else 0.6, label=robot if hot else None,
                    zorder=3 if hot else 2)
            ax.set_xticks(order)
        ax.set_title(f"{name}: change since the first recording", fontsize=9)
        ax.set_xlabel("recording", fontsize=8)
        ax.tick_params(labelsize=7)
        if k:
            ax.legend(fontsize=6, loc="best")
    return figure_png(fig)


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
        body.append(
            f'<p class="verdict">{len(flagged)} robot{"s" if len(flagged) != 1 else ""} flagged for drift: '
            f"{', '.join(flagged) or 'none'}.</p>"
        )
        body.append(heading("Flagged robots", "flagged"))
        body.append(
            html_table(
                ["robot", "parameter", "change at recording", "time", "before", "after", "shift (sd)", "p (Holm)"],
                [
                    [t.robot, t.parameter, str(t.change_order), t.change_time, t.before, t.after, t.shift_sigma,
                     t.p_adjusted]
                    for t in drift.flagged
                ],
                text_columns=4,
            )
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
        overview = [p for p in drift.parameters if not p[0] == "I" and not p.startswith("m")][:_MAX_OVERVIEW]
        overview += [p for p in drift.parameters if p not in overview][: max(0, _MAX_OVERVIEW - len(overview))]
        if overview:
            body.append(heading("Parameters over time", "over-time"))
            body.append(
                figure_html(
                    _overview_figure(drift, overview, {(t.robot, t.parameter) for t in drift.flagged}),
                    title="tested parameters over time, every robot",
                    caption="Each robot's value minus its value in its first recording (SI units), with +-2 sd "
                    "bands; flagged robots in colour, the others grey.",
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
            else '<p class="note">None at the family-wise error rate '
            f"{drift.alpha:g}.</p>"
        )
        body.append(heading("How the tests read the standard deviations", "inflation"))
        inflated = [[k, v] for k, v in drift.inflation.items() if v > 1.0]
        body.append(
            '<p class="note">Each parameter\'s variances are multiplied by a factor measured on the fleet (the '
            "median over robots of the constancy statistic over its median under no change, at least 1): "
            + ("the spread between recordings is within the identifications' own for every parameter (factor 1)."
               if not inflated else "factors above 1 below; every other parameter's is 1.")
            + "</p>"
        )
        if inflated:
            body.append(html_table(["parameter", "factor"], inflated))
    if result.errors:
        body.append(heading("Refused recordings", "errors"))
        body.append(html_table(["path", "why"], [[r["path"], r["error"]] for r in result.errors], text_columns=2))
    body.append(json_script(result.figures(), "fleet-figures"))
    return write_text(path, html_page(f"Fleet of {result.info.get('robot', 'robots')}", body))
