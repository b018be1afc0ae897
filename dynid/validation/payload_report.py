"""The payload report: the loaded run's torque error before and after, and the payload on the flange.

One self-contained HTML file built from :mod:`dynid.validation.html_page`, like the other reports:

* a table of the payload (mass, centre of mass, principal moments, drive gains) with standard deviations;
* the arm model's RMS error on the loaded run per joint, without and with the payload;
* the error over time per joint, before and after;
* the payload on the flange in three views of frame F: its axes, the centre of mass and the solid
  ellipsoid of the same mass and inertia (when the motion determined the inertia).
"""

from __future__ import annotations

import html
from typing import Any

import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Ellipse

from dynid.identify.payload import PayloadResult
from dynid.validation.html_page import figure_html, heading, html_page, html_table, json_script
from dynid.validation.plots import figure_png, joint_grid, thin, tidy_grid

__all__ = ["equivalent_ellipsoid", "payload_report"]

_BEFORE, _AFTER = "#999999", "#1f77b4"


def equivalent_ellipsoid(mass: float, inertia: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """Semi-axes (m) and axes (columns) of the solid ellipsoid with this mass and inertia about its centre.

    ``I_1 = m (b^2 + c^2) / 5`` and so on, so ``a^2 = 5 (I_2 + I_3 - I_1) / (2 m)``; None for a mass
    that is not positive.  A point mass gives zero semi-axes.

    Parameters
    ----------
    mass : float
        kg.
    inertia : ndarray, shape (3, 3)
        About the centre of mass (kg m^2).
    """
    if not mass > 0:
        return None
    moments, axes = np.linalg.eigh(inertia)
    total = moments.sum()
    squares = 5.0 * (total - 2.0 * moments) / (2.0 * mass)
    return np.sqrt(np.maximum(squares, 0.0)), axes


def _rms_figure(figures: dict[str, Any]) -> bytes:
    before, after = np.asarray(figures["rms_before"]), np.asarray(figures["rms_after"])
    n = len(before)
    fig = Figure(figsize=(8.5, 3.2), layout="constrained")
    ax = fig.subplots()
    x = np.arange(1, n + 1)
    ax.bar(x - 0.2, before, 0.4, color=_BEFORE, label="arm model alone")
    ax.bar(x + 0.2, after, 0.4, color=_AFTER, label="with the payload")
    ax.set_xticks(x, [f"joint {j}" for j in x])
    ax.set_ylabel("RMS error (N m)")
    ax.grid(True, axis="y", alpha=0.3)
    ax.legend(frameon=False)
    return figure_png(fig)


def _time_figure(result: PayloadResult) -> bytes:
    assert result.t is not None and result.residual is not None and result.torque is not None
    n = result.residual.shape[1]
    fig, axes = joint_grid(n, height=1.9)
    s = thin(len(result.t))
    t = result.t[s] - result.t[0]
    for j, ax in enumerate(axes):
        ax.plot(t, result.residual[s, j], color=_BEFORE, linewidth=0.8, label="error, arm model alone")
        ax.plot(
            t,
            result.residual[s, j] - result.torque[s, j],
            color=_AFTER,
            linewidth=0.8,
            label="error with the payload",
        )
        ax.set_title(f"joint {j + 1}", fontsize=10, loc="left")
        ax.set_ylabel("N m")
        ax.set_xlabel("time (s)")
    axes[0].legend(frameon=False, fontsize=8, loc="upper right")
    tidy_grid(axes)
    return figure_png(fig)


def _projected_ellipse(ax, centre, shape, plane: tuple[int, int], scale: float, **style) -> None:
    """The ellipse ``scale`` x the (3, 3) ``shape`` (a covariance, or an ellipsoid's semi-axes squared)
    projected on the plane of axes ``plane``, drawn at ``centre``."""
    a, b = plane
    w, v = np.linalg.eigh(shape[np.ix_([a, b], [a, b])])
    angle = float(np.degrees(np.arctan2(v[1, 1], v[0, 1])))
    ax.add_patch(
        Ellipse((centre[a], centre[b]), 2 * scale * np.sqrt(max(w[1], 0)), 2 * scale * np.sqrt(max(w[0], 0)),
                angle=angle, **style)
    )  # fmt: skip


def _flange_figure(result: PayloadResult, figures: dict[str, Any]) -> bytes:
    """Three views of frame F: axes, centre of mass (with its 2-sigma ellipse), equivalent ellipsoid."""
    mass, com_list = figures["mass"], figures["com"]
    com = np.array([np.nan if c is None else c for c in com_list])
    com_ok = np.isfinite(com).all() and mass is not None
    inertia = np.array([[np.nan if v is None else v for v in row] for row in figures["inertia"]])
    ellipsoid = equivalent_ellipsoid(mass, inertia) if com_ok and np.isfinite(inertia).all() else None
    cov = result.cov
    fig = Figure(figsize=(11, 3.9), layout="constrained")
    axes = fig.subplots(1, 3)
    reach = 0.05
    if com_ok:
        reach = max(reach, 1.3 * float(np.abs(com).max()))
        if ellipsoid is not None:
            reach = max(reach, 1.3 * float(np.abs(com).max() + ellipsoid[0].max()))
    names = "xyz"
    colours = ("#d62728", "#2ca02c", "#1f77b4")
    for ax, (a, b) in zip(axes, [(0, 1), (0, 2), (1, 2)], strict=True):
        for k in (a, b):
            d = np.zeros(2)
            d[0 if k == a else 1] = 0.6 * reach
            ax.annotate(
                "", xy=d, xytext=(0, 0), arrowprops={"arrowstyle": "->", "color": colours[k], "lw": 1.6}
            )
            ax.text(*(1.08 * d), names[k], color=colours[k], fontsize=11, ha="center", va="center")
        ax.plot([0], [0], "ks", markersize=5)
        if com_ok:
            if ellipsoid is not None:
                semi, axes3 = ellipsoid
                shape = (axes3 * semi**2) @ axes3.T  # the ellipsoid's "covariance": its projection's block
                _projected_ellipse(ax, com, shape, (a, b), 1.0, facecolor="#1f77b4", alpha=0.25,
                                   edgecolor="#1f77b4", lw=1.2)  # fmt: skip
            # the centre of mass's 2-sigma ellipse, from the covariance of m c (first order, mass fixed)
            h_cov = cov[1:4, 1:4] / max(mass, 1e-9) ** 2
            _projected_ellipse(ax, com, h_cov, (a, b), 2.0, fill=False, edgecolor="k", lw=1.0)
            ax.plot([com[a]], [com[b]], "k+", markersize=10, mew=1.5)
        ax.set_xlim(-reach, reach)
        ax.set_ylim(-reach, reach)
        ax.set_aspect("equal")
        ax.set_xlabel(f"{names[a]} (m)")
        ax.set_ylabel(f"{names[b]} (m)")
        ax.grid(True, alpha=0.3)
        ax.set_title(f"{names[a]}-{names[b]} view of {figures['frame']}", fontsize=10)
    return figure_png(fig)


def _payload_table(figures: dict[str, Any]) -> str:
    def mm(v):
        return None if v is None else 1000.0 * v

    rows: list[list[Any]] = [["mass (kg)", figures["mass"], figures["mass_std"]]]
    for axis, c, s in zip("xyz", figures["com"], figures["com_std"], strict=True):
        rows.append([f"centre of mass {axis} (mm)", mm(c), mm(s)])
    labels = ("xx", "xy", "xz", "yy", "yz", "zz")
    index = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))
    for label, (a, b) in zip(labels, index, strict=True):
        rows.append(
            [
                f"inertia I{label} about the com (kg m^2)",
                figures["inertia"][a][b],
                figures["inertia_std"][a][b],
            ]
        )
    gains = figures.get("drive_gains")
    if gains:
        for j, (g, s) in enumerate(zip(gains["gain"], gains["std"], strict=True)):
            rows.append([f"drive gain, joint {j + 1}", g, s])
    return html_table(["quantity", "value", "standard deviation"], rows)


def payload_report(result: PayloadResult, figures: dict[str, Any], *, title: str) -> str:
    """The whole report as HTML text.

    Parameters
    ----------
    result : PayloadResult
    figures : dict
        ``result.figures()`` (with the command's additions).
    title : str
    """
    undetermined = [k for k, ok in figures["determined"].items() if not ok]
    lead = (
        f"Frame {html.escape(figures['frame'])} on link {figures['link']}; {figures['samples']} samples; "
        + (
            "the difference with the reference run"
            if figures.get("reference")
            else "the arm model's prediction as the reference"
        )
        + "."
    )
    body = [
        f'<p class="lead">{lead}</p>',
        heading("The payload", "payload"),
        _payload_table(figures),
    ]
    if undetermined:
        body.append(
            f'<p class="note">Not determined by this motion: {html.escape(", ".join(undetermined))} '
            "(shown as -; never guessed).</p>"
        )
    for note in figures["notes"]:
        body.append(f'<p class="note">{html.escape(note)}</p>')
    body += [
        heading("The loaded run's torque error", "error"),
        figure_html(
            _rms_figure(figures),
            title="RMS error per joint",
            caption="The arm model's RMS error on the loaded run, alone (grey) and with the payload attached (blue).",
        ),
    ]
    if result.t is not None:
        body.append(
            figure_html(
                _time_figure(result),
                title="Error over time",
                caption="Measured minus predicted torque on the loaded run: the arm model alone (grey) and with the "
                "payload (blue).",
            )
        )
    body += [
        heading("The payload on the flange", "flange"),
        figure_html(
            _flange_figure(result, figures),
            title="Payload on the flange",
            caption=f"Frame {figures['frame']} seen along each axis: its axes, the centre of mass (+) with its "
            "2-sigma ellipse, and the solid ellipsoid of the payload's mass and inertia (blue; absent where "
            "the motion did not determine the inertia).",
        ),
        json_script(figures, "payload-figures"),
    ]
    return html_page(title, body)
