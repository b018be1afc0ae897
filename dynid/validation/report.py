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
  consistent link parameters (when a model was identified with ``method="consistent"``).

Every number in the tables carries its exact value in a ``data-value`` attribute, and the figures of
``--json`` are embedded verbatim (``<script type="application/json" id="dynid-figures">``), so a
program can read the report and check it against the JSON.
"""

from __future__ import annotations

import datetime as _dt
import html
import io
import json
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from dynid.exceptions import UsageError
from dynid.validation.validate import ValidationResult

__all__ = [
    "Report",
    "ReportFigure",
    "check_report_path",
    "format_number",
    "html_table",
    "json_ready",
    "render_report",
]

_CSS = """
body { font-family: -apple-system, "Segoe UI", Helvetica, Arial, sans-serif; margin: 2em auto; max-width: 1150px;
       color: #222; line-height: 1.4; padding: 0 1em; }
h1 { font-size: 1.6em; margin-bottom: 0.2em; }
h2 { font-size: 1.25em; margin-top: 1.8em; border-bottom: 1px solid #ccc; padding-bottom: 0.2em; }
p.lead { color: #555; margin-top: 0; }
table { border-collapse: collapse; margin: 0.6em 0; font-size: 0.9em; }
th, td { border: 1px solid #d6d6d6; padding: 0.25em 0.6em; text-align: right; }
th { background: #f3f3f3; }
td.text, th.text { text-align: left; }
tr.mean td { font-weight: bold; background: #fafafa; }
figure { margin: 1em 0; }
figure img { max-width: 100%; height: auto; border: 1px solid #eee; }
figcaption { color: #555; font-size: 0.9em; }
.note { color: #555; font-size: 0.9em; }
code { background: #f5f5f5; padding: 0 0.2em; }
"""


def format_number(value: Any, digits: int = 4) -> str:
    """A number as shown in the report: ``digits`` significant digits, ``-`` for a missing value.

    Parameters
    ----------
    value : float or None
        The number.
    digits : int
        Significant digits.
    """
    if value is None:
        return "-"
    v = float(value)
    if math.isnan(v):
        return "-"
    if math.isinf(v):
        return "inf" if v > 0 else "-inf"
    return f"{v:.{digits}g}"


def _cell(value: Any, *, key: str | None = None, joint: int | None = None, text: bool = False) -> str:
    if text:
        return f'<td class="text">{html.escape(str(value))}</td>'
    attrs = []
    if key is not None:
        attrs.append(f'data-key="{html.escape(key)}"')
    if joint is not None:
        attrs.append(f'data-joint="{joint}"')
    if value is not None and not (isinstance(value, float) and math.isnan(value)):
        attrs.append(f'data-value="{float(value)!r}"')
    return (
        f"<td {' '.join(attrs)}>{format_number(value)}</td>" if attrs else f"<td>{format_number(value)}</td>"
    )


def html_table(
    headers: Sequence[str],
    rows: Sequence[Sequence[Any]],
    *,
    table_id: str | None = None,
    text_columns: int = 1,
) -> str:
    """An HTML table; the first ``text_columns`` columns are text, the others numbers.

    A cell may also be given ready-made as a string starting with ``<td``.

    Parameters
    ----------
    headers : sequence of str
        Column titles.
    rows : sequence of sequence
        Cells.
    table_id : str, optional
        The table's ``id``.
    text_columns : int
        Leading columns shown as text.
    """
    head = "".join(
        f'<th class="text">{html.escape(h)}</th>' if k < text_columns else f"<th>{html.escape(h)}</th>"
        for k, h in enumerate(headers)
    )
    body = []
    for row in rows:
        cells = []
        for k, value in enumerate(row):
            if isinstance(value, str) and value.startswith("<td"):
                cells.append(value)
            else:
                cells.append(_cell(value, text=k < text_columns or isinstance(value, str)))
        body.append("<tr>" + "".join(cells) + "</tr>")
    ident = f' id="{html.escape(table_id)}"' if table_id else ""
    return f"<table{ident}><thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody></table>"


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
            _write_bytes(path, self.pdf)
        else:
            _write_bytes(path, self.html.encode("utf-8"))
        return path


def _write_bytes(path: Path, data: bytes) -> None:
    import tempfile

    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        os.fchmod(fd, 0o644)
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def check_report_path(path: str | os.PathLike[str], *, pdf: bool = True) -> Path:
    """Check that a report can be written at ``path`` (``.html``/``.htm``/``.pdf``, existing folder).

    Parameters
    ----------
    path : str or path-like
        The report file.
    pdf : bool
        Whether a ``.pdf`` name is accepted.

    Returns
    -------
    Path

    Raises
    ------
    UsageError
        A missing folder, a folder given as the file, or another extension.
    """
    path = Path(path)
    allowed = (".html", ".htm", ".pdf") if pdf else (".html", ".htm")
    if path.suffix.lower() not in allowed:
        raise UsageError(
            f"the report '{path}' has the extension '{path.suffix}'; give a file name ending in {' or '.join(allowed)}."
        )
    if not path.parent.is_dir():
        raise UsageError(
            f"the folder '{path.parent}' of the report does not exist; create it or write elsewhere."
        )
    if path.is_dir():
        raise UsageError(f"the report '{path}' is a folder; give a file name.")
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
                    _cell(figures[key][j], key=key, joint=j + 1)
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
        f'<tr class="mean"><td class="text">mean (the paper&#39;s average RMS)</td>{_cell(figures["rms_mean"], key="rms_mean")}'
        f"<td></td><td></td><td></td>{_cell(figures['noise_floor_mean'], key='noise_floor_mean')}<td></td></tr>"
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
                _cell(s["cond"], key=f"models.{k}.cond"),
                *(_cell(s["rms"][j], key=f"models.{k}.rms", joint=j + 1) for j in range(n)),
                _cell(s["rms_mean"], key=f"models.{k}.rms_mean"),
                _cell(s["rms_mean_before_gmm"], key=f"models.{k}.rms_mean_before_gmm"),
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
            '<p class="note">No model here was identified with the physically consistent method '
            "(<code>--method consistent</code>), so there are no link parameters to show: base parameters are "
            "combinations of them.</p>"
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
    return html_table(["", ""], rows, table_id="context", text_columns=2).replace(
        '<thead><tr><th class="text"></th><th class="text"></th></tr></thead>', ""
    )


def _figure_html(fig: ReportFigure) -> str:
    from dynid.validation.plots import png_base64

    return (
        f'<figure id="figure-{html.escape(fig.key)}"><img src="{png_base64(fig.png)}" alt="{html.escape(fig.title)}">'
        f"<figcaption>{html.escape(fig.caption)}</figcaption></figure>"
    )


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
    payload = json.dumps(json_ready(figures), indent=1, allow_nan=False).replace("</", "<\\/")

    parts = [
        "<!DOCTYPE html>",
        '<html lang="en">',
        "<head>",
        '<meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        f"<title>{html.escape(title)}</title>",
        f"<style>{_CSS}</style>",
        "</head>",
        "<body>",
        f"<h1>{html.escape(title)}</h1>",
        f'<p class="lead">dynid report, {html.escape(_dt.datetime.now().strftime("%Y-%m-%d %H:%M"))}. '
        "Everything is in this one file; it needs no network.</p>",
        _context_table(first, figures, context),
        '<h2 id="section-error">Held-out error per joint</h2>',
        f"<p class=\"note\">Model '{html.escape(first.label)}'. NRMS: RMS over the standard deviation of the "
        "measured torque; R^2: share of its variance explained; RMS / noise: 1 is as good as the sensor allows.</p>",
        _metrics_table(figures, first.n),
        '<h2 id="section-methods">Methods side by side</h2>',
        _methods_table(results),
        _figure_html(by_key["methods"]),
        f'<h2 id="section-torque">{html.escape(by_key["torque"].title)}</h2>',
        _figure_html(by_key["torque"]),
        f'<h2 id="section-residual">{html.escape(by_key["residual"].title)}</h2>',
        _figure_html(by_key["residual"]),
        f'<h2 id="section-friction">{html.escape(by_key["friction"].title)}</h2>',
        _figure_html(by_key["friction"]),
        '<h2 id="section-conditions">Condition numbers</h2>',
        '<p class="note">Of the noise-weighted regressor each model was identified from (lower is better '
        "conditioned; the URDF baseline estimated no rigid-body parameter).</p>",
        html_table(["", "condition number"], cond_rows, table_id="conditions"),
    ]
    for section_title, fragment in sections:
        anchor = "".join(ch if ch.isalnum() else "-" for ch in section_title.lower()).strip("-")
        parts += [f'<h2 id="section-{html.escape(anchor)}">{html.escape(section_title)}</h2>', fragment]
    parts += [
        '<h2 id="section-parameters">Base parameters</h2>',
        f"<p class=\"note\">Model '{html.escape(first.label)}' ({html.escape(first.model.method)}): identified "
        "parameters with their standard deviation from the identification's covariance; std (%) relative to "
        "|value| (large: poorly excited by the data).</p>",
        _parameter_table(first),
        '<h2 id="section-consistent">Physically consistent link parameters</h2>',
        _consistent_section(results),
    ]
    if notes:
        parts += [
            '<h2 id="section-notes">Notes</h2>',
            "<ul>" + "".join(f"<li>{html.escape(x)}</li>" for x in notes) + "</ul>",
        ]
    parts += [
        f'<script type="application/json" id="dynid-figures">{payload}</script>',
        "</body>",
        "</html>",
    ]
    return Report(
        html="\n".join(parts) + "\n", figures=tuple(figs), pdf=None if pdf_buf is None else pdf_buf.getvalue()
    )


def json_ready(value: Any) -> Any:
    """A JSON-ready copy: arrays to lists, paths to text, non-finite floats to None (JSON has no NaN).

    Parameters
    ----------
    value : Any
        Figures (dicts, lists, numbers, arrays).
    """
    if isinstance(value, Mapping):
        return {str(k): json_ready(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [json_ready(v) for v in value]
    if isinstance(value, np.ndarray):
        return json_ready(value.tolist())
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value
