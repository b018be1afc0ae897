"""The validation report: one self-contained HTML file (figures inside as base64 PNG), optionally a PDF.

>>> report = render_report([validate(model, data)], figures=result.figures())
>>> report.write("R.html")                      # opens offline in any browser
>>> report.write("R.pdf")                       # the same figures and tables through PdfPages

What it shows, for the first model (the one validated) and the others (compared on the same data):

* the held-out error per joint (RMS, normalised RMS, R^2, largest error) against the measured noise
  floor, and the methods side by side (table and bar chart);
* measured against predicted torque, one joint per panel;
* the residual before and after the GMM layer, against the noise floor;
* friction torque against velocity with each model's friction law over the data (the paper's figure 6);
* condition numbers, the base parameters with their relative standard deviation, and the physically
  consistent link parameters (every physical fit, the default, and ``method="consistent"``; not an
  ``--unconstrained`` one).

Every number in the tables carries its exact value in a ``data-value`` attribute, and the figures of
``--json`` are embedded verbatim (``<script type="application/json" id="dynid-figures">``), so a
program can read the report and check it against the JSON.
"""

from __future__ import annotations

import datetime as _dt
import html
import io
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from dynid._io import write_bytes
from dynid.exceptions import UsageError
from dynid.validation.html_page import (
    check_report_path,
    figure_html,
    format_number,
    heading,
    html_page,
    html_table,
    json_script,
    table_cell,
)
from dynid.validation.validate import ValidationResult

__all__ = [
    "Report",
    "ReportFigure",
    "check_report_path",
    "format_number",
    "html_table",
    "render_report",
]


@dataclass(frozen=True)
class ReportFigure:
    """One embedded figure.

    Attributes
    ----------
    key : str
        Short identifier (``torque``, ``residual``, ``friction``, ``methods``).
    title : str
        Section title.
    caption : str
        What it shows.
    png : bytes
        The image.
    """

    key: str
    title: str
    caption: str
    png: bytes


@dataclass(frozen=True)
class Report:
    """A rendered report: the HTML text, its figures and, if asked, the PDF.

    Attributes
    ----------
    html : str
        The self-contained HTML document.
    figures : tuple of ReportFigure
        The embedded figures, in order.
    pdf : bytes or None
        The PDF (figures and the main tables), when rendered with ``pdf=True``.
    """

    html: str
    figures: tuple[ReportFigure, ...]
    pdf: bytes | None = field(default=None, repr=False)

    def write(self, path: str | os.PathLike[str]) -> Path:
        """Write the report (``.html``, or ``.pdf`` if rendered with ``pdf=True``) atomically.

        Parameters
        ----------
        path : str or path-like
            File in an existing folder.

        Returns
        -------
        Path
        """
        path = check_report_path(path, pdf=self.pdf is not None)
        if path.suffix.lower() == ".pdf":
            if self.pdf is None:
                raise UsageError(
                    f"the report '{path}' is a PDF but it was rendered without pdf=True; render it again."
                )
            write_bytes(path, self.pdf)
        else:
            write_bytes(path, self.html.encode("utf-8"))
        return path


# ---------------------------------------------------------------------------- figures
def _friction_curves(results: Sequence[ValidationResult], j: int) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    dq = results[0].dq[:, j]
    lo, hi = (float(dq.min()), float(dq.max())) if dq.size else (-1.0, 1.0)
    v = np.linspace(lo, hi, 801)
    curves = {}
    for r in results:
        fr = r.model.friction
        if fr is None:
            continue
        grid = np.zeros((v.size, r.n))
        grid[:, j] = v
        curves[r.label] = (v, fr.predict(grid)[:, j])
    return curves


def _render_figures(results: Sequence[ValidationResult], pdf_pages: Any | None) -> list[ReportFigure]:
    from dynid.validation.plots import (
        figure_png,
        joint_grid,
        plot_friction,
        plot_method_rms,
        plot_residuals,
        plot_torque,
        tidy_grid,
    )

    first = results[0]
    n = first.n
    out: list[ReportFigure] = []

    def emit(key: str, title: str, caption: str, fig: Any) -> None:
        fig.suptitle(title, fontsize=12)
        if pdf_pages is not None:
            pdf_pages.savefig(fig)
        out.append(ReportFigure(key, title, caption, figure_png(fig)))

    # methods side by side
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11, 3.6), layout="constrained")
    ax = fig.subplots()
    plot_method_rms(
        ax, [r.label for r in results], [r.metrics["rms"] for r in results], noise=first.noise.std
    )
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.0, 1.0))
    emit(
        "methods",
        "Held-out RMS per joint, model by model",
        "Root mean square of the prediction error on the held-out data (log scale); the black bar is the "
        "measured noise floor, below which no model can go.",
        fig,
    )

    # measured vs predicted
    fig, axes = joint_grid(n)
    for j, ax in enumerate(axes):
        plot_torque(ax, first.t, first.tau[:, j], {r.label: r.tau_pred[:, j] for r in results}, joint=j + 1)
    tidy_grid(axes)
    axes[0].legend(fontsize=7, loc="best")
    emit(
        "torque",
        "Measured and predicted joint torque",
        f"Held-out data ({first.data}); the measured torque is {first.reference}, as compared.",
        fig,
    )

    # residual before / after GMM
    with_gmm = next((r for r in results if r.model.gmr is not None), first)
    fig, axes = joint_grid(n)
    after = with_gmm.residual if with_gmm.model.gmr is not None else None
    for j, ax in enumerate(axes):
        plot_residuals(
            ax,
            with_gmm.t,
            with_gmm.residual_before_gmm[:, j],
            None if after is None else after[:, j],
            joint=j + 1,
            noise=float(with_gmm.noise.std[j]),
        )
    axes[0].legend(fontsize=7, loc="upper right")
    tidy_grid(axes)
    caption = (
        f"Residual of '{with_gmm.label}' before (link and friction layers) and after the GMM layer; the band is "
        "+-1 noise standard deviation."
        if after is not None
        else f"Residual of '{with_gmm.label}'; no model here has a GMM layer, so there is no 'after'."
    )
    emit("residual", "Residual before and after the GMM layer", caption, fig)

    # friction against velocity
    fig, axes = joint_grid(n, sharex=False, height=2.6)
    for j, ax in enumerate(axes):
        plot_friction(
            ax, first.dq[:, j], first.friction_estimate[:, j], _friction_curves(results, j), joint=j + 1
        )
    axes[0].legend(fontsize=7, loc="best", markerscale=3)
    emit(
        "friction",
        "Friction torque against velocity",
        f"Points: measured torque minus the rigid-body prediction of '{first.label}' on the held-out data; "
        "lines: each model's friction law.",
        fig,
    )
    return out


# ---------------------------------------------------------------------------- tables
def _metrics_table(figures: Mapping[str, Any], n: int) -> str:
    rows = []
    for j in range(n):
        rows.append(
            [
                f"joint {j + 1}",
                *(
                    table_cell(figures[key][j], key=key, joint=j + 1)
                    for key in ("rms", "nrms", "r2", "max_error", "noise_floor", "rms_over_noise")
                ),
            ]
        )
    body = html_table(
        ["", "RMS (N m)", "NRMS", "R^2", "max error (N m)", "noise floor (N m)", "RMS / noise"],
        rows,
        table_id="metrics",
    )
    mean = (
        f'<tr class="mean"><td class="text">mean (the paper&#39;s average RMS)</td>{table_cell(figures["rms_mean"], key="rms_mean")}'
        f"<td></td><td></td><td></td>{table_cell(figures['noise_floor_mean'], key='noise_floor_mean')}<td></td></tr>"
    )
    return body.replace("</tbody>", mean + "</tbody>")


def _methods_table(results: Sequence[ValidationResult]) -> str:
    n = results[0].n
    rows = []
    for k, r in enumerate(results):
        s = r.summary()
        rows.append(
            [
                r.label,
                s["description"],
                table_cell(s["cond"], key=f"models.{k}.cond"),
                *(table_cell(s["rms"][j], key=f"models.{k}.rms", joint=j + 1) for j in range(n)),
                table_cell(s["rms_mean"], key=f"models.{k}.rms_mean"),
                table_cell(s["rms_mean_before_gmm"], key=f"models.{k}.rms_mean_before_gmm"),
            ]
        )
    noise = results[0].noise.std
    rows.append(["noise floor", results[0].noise.method, None, *noise.tolist(), float(noise.mean()), None])
    return html_table(
        ["model", "layers", "cond", *(f"RMS {j + 1}" for j in range(n)), "mean RMS", "mean before GMM"],
        rows,
        table_id="methods",
        text_columns=2,
    )


def _parameter_table(result: ValidationResult) -> str:
    m = result.model
    rows = []
    for name, expr, kind, v, s, pct in zip(
        m.columns.names, m.columns.expressions, m.columns.kinds, m.params, m.std, m.std_percent, strict=True
    ):
        rows.append([name, kind, expr, float(v), float(s), float(pct)])
    return html_table(
        ["name", "kind", "expression", "value (SI)", "std", "std (%)"],
        rows,
        table_id="parameters",
        text_columns=3,
    )


def _consistent_section(results: Sequence[ValidationResult]) -> str:
    r = next((r for r in results if "consistency" in r.model.info), None)
    if r is None:
        return (
            '<p class="note">No model here carries physically consistent link parameters (it was identified '
            "with <code>--unconstrained</code>, or by an older dynid), so there are none to show: base "
            "parameters are combinations of them.</p>"
        )
    c = r.model.info["consistency"]
    std = np.asarray(c["standard_params"], dtype=float)
    robot = r.model.robot
    nominal = np.asarray(robot.params, dtype=float)
    eig = c.get("min_eigenvalues") or [None] * robot.n
    rows = []
    for i in range(robot.n):
        v = std[10 * i : 10 * i + 10]
        mass = v[0]
        com = v[1:4] / mass if mass > 0 else np.full(3, np.nan)
        # Pinocchio's order: Ixx, Ixy, Iyy, Ixz, Iyz, Izz (about the joint frame)
        rows.append(
            [
                f"link {i + 1}",
                float(mass),
                float(nominal[10 * i]),
                *(float(x) for x in com),
                float(v[4]),
                float(v[6]),
                float(v[9]),
                float(v[5]),
                float(v[7]),
                float(v[8]),
                eig[i],
            ]
        )
    note = (
        f"<p class=\"note\">Model '{html.escape(r.label)}': distance from the unconstrained estimate "
        f"{format_number(c.get('mahalanobis'))} standard deviations (relative {format_number(c.get('relative_distance'))}); "
        "inertias about the joint frame (kg m^2), centre of mass in the joint frame (m); the last column is "
        "the smallest eigenvalue of each link's pseudo-inertia (positive: physically consistent). The data "
        "determine only the base parameters (combinations of these); this is one physically consistent split "
        "of them, pulled toward the URDF where the model was fitted with a reference weight.</p>"
    )
    return note + html_table(
        [
            "",
            "mass (kg)",
            "URDF mass (kg)",
            "c_x (m)",
            "c_y (m)",
            "c_z (m)",
            "Ixx",
            "Iyy",
            "Izz",
            "Ixy",
            "Ixz",
            "Iyz",
            "min eig.",
        ],
        rows,
        table_id="consistent",
    )


def _context_table(first: ValidationResult, figures: Mapping[str, Any], context: Mapping[str, Any]) -> str:
    rows: list[list[Any]] = [
        ["robot", f"{first.model.robot.name} ({first.n} joints)"],
        ["model", first.info.get("model_file", first.label)],
        ["layers", figures.get("description", "")],
        [
            "held-out data",
            f"{first.data}: {first.t.size} samples over {figures.get('duration_s', 0.0):.4g} s",
        ],
        ["measured torque compared", first.reference],
        ["noise floor", f"{first.noise.method}: {first.noise.detail}"],
    ]
    rows += [[str(k), str(v)] for k, v in context.items()]
    return html_table(None, rows, table_id="context", text_columns=2)


def _figure_html(fig: ReportFigure) -> str:
    return figure_html(fig.png, title=fig.title, caption=fig.caption, figure_id=f"figure-{fig.key}")


def _pdf_table_page(
    pdf_pages: Any, title: str, headers: Sequence[str], rows: Sequence[Sequence[str]]
) -> None:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11, 0.5 + 0.3 * (len(rows) + 2)))
    ax = fig.subplots()
    ax.axis("off")
    ax.set_title(title, loc="left")
    table = ax.table(
        cellText=[list(r) for r in rows], colLabels=list(headers), loc="upper left", cellLoc="right"
    )
    table.auto_set_font_size(False)
    table.set_fontsize(8)
    pdf_pages.savefig(fig)


# ---------------------------------------------------------------------------- the document
def render_report(
    results: Sequence[ValidationResult],
    *,
    figures: Mapping[str, Any] | None = None,
    title: str | None = None,
    context: Mapping[str, Any] | None = None,
    sections: Sequence[tuple[str, str]] = (),
    conditions: Sequence[tuple[str, float | None]] = (),
    pdf: bool = False,
) -> Report:
    """Render the report of one or more models validated on the same data.

    Parameters
    ----------
    results : sequence of ValidationResult
        The model validated first, then those compared with it (same data, same preprocessing).
    figures : mapping, optional
        The figures written as JSON (default ``results[0].figures()``); embedded verbatim, and the tables
        show these numbers.
    title : str, optional
        Title (default: ``Validation of <label> on <data>``).
    context : mapping, optional
        More lines for the table at the top (e.g. the demo's settings).
    sections : sequence of (str, str)
        More sections: a title and an HTML fragment (escaped by the caller) each, placed before the
        parameters.
    conditions : sequence of (str, float)
        More condition numbers (e.g. the excitation design's), shown with the models'.
    pdf : bool
        Also render a PDF (matplotlib's PdfPages): the figures and the main tables.

    Returns
    -------
    Report
    """
    if not results:
        raise UsageError("render_report needs at least one ValidationResult; validate a model first.")
    first = results[0]
    figures = dict(first.figures() if figures is None else figures)
    title = title or f"Validation of {first.label} on {first.data}"
    context = dict(context or {})

    pdf_buf = io.BytesIO() if pdf else None
    pdf_pages = None
    if pdf_buf is not None:
        from matplotlib.backends.backend_pdf import PdfPages

        pdf_pages = PdfPages(pdf_buf)
    try:
        if pdf_pages is not None:
            n = first.n
            _pdf_table_page(
                pdf_pages,
                title,
                ["model", *(f"RMS {j + 1}" for j in range(n)), "mean"],
                [
                    [
                        r.label[:40],
                        *(format_number(v) for v in r.metrics["rms"]),
                        format_number(r.metrics["rms_mean"]),
                    ]
                    for r in results
                ]
                + [
                    [
                        "noise floor",
                        *(format_number(v) for v in first.noise.std),
                        format_number(first.noise.rms_mean),
                    ]
                ],
            )
        figs = _render_figures(results, pdf_pages)
    finally:
        if pdf_pages is not None:
            pdf_pages.close()
    by_key = {f.key: f for f in figs}

    cond_rows = [[r.label, r.model.cond if np.isfinite(r.model.cond) else None] for r in results]
    cond_rows += [[label, value] for label, value in conditions]
    notes = [str(note) for note in first.model.info.get("notes", [])]
    if first.model.gmr is not None and first.model.gmr.fallback_:
        notes.append(f"GMM layer: {first.model.gmr.fallback_}")

    parts = [
        f'<p class="lead">dynid report, {html.escape(_dt.datetime.now().strftime("%Y-%m-%d %H:%M"))}. '
        "Everything is in this one file; it needs no network.</p>",
        _context_table(first, figures, context),
        heading("Held-out error per joint", "section-error"),
        f"<p class=\"note\">Model '{html.escape(first.label)}'. NRMS: RMS over the standard deviation of the "
        "measured torque; R^2: share of its variance explained; RMS / noise: 1 is as good as the sensor allows.</p>",
        _metrics_table(figures, first.n),
        heading("Methods side by side", "section-methods"),
        _methods_table(results),
        _figure_html(by_key["methods"]),
        heading(by_key["torque"].title, "section-torque"),
        _figure_html(by_key["torque"]),
        heading(by_key["residual"].title, "section-residual"),
        _figure_html(by_key["residual"]),
        heading(by_key["friction"].title, "section-friction"),
        _figure_html(by_key["friction"]),
        heading("Condition numbers", "section-conditions"),
        '<p class="note">Of the noise-weighted regressor each model was identified from (lower is better '
        "conditioned; the URDF baseline estimated no rigid-body parameter).</p>",
        html_table(["", "condition number"], cond_rows, table_id="conditions"),
    ]
    for section_title, fragment in sections:
        anchor = "".join(ch if ch.isalnum() else "-" for ch in section_title.lower()).strip("-")
        parts += [heading(section_title, f"section-{anchor}"), fragment]
    parts += [
        heading("Base parameters", "section-parameters"),
        f"<p class=\"note\">Model '{html.escape(first.label)}' ({html.escape(first.model.method)}): identified "
        "parameters with their standard deviation from the identification's covariance; std (%) relative to "
        "|value| (large: poorly excited by the data).</p>",
        _parameter_table(first),
        heading("Physically consistent link parameters", "section-consistent"),
        _consistent_section(results),
    ]
    if notes:
        parts += [
            heading("Notes", "section-notes"),
            "<ul>" + "".join(f"<li>{html.escape(x)}</li>" for x in notes) + "</ul>",
        ]
    parts.append(json_script(figures, "dynid-figures"))
    return Report(
        html=html_page(title, parts), figures=tuple(figs), pdf=None if pdf_buf is None else pdf_buf.getvalue()
    )
