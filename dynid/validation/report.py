"""The validation report: one self-contained HTML file (figures inside as base64 PNG), optionally a PDF.

>>> report = render_report([validate(model, data)], figures=result.figures())
>>> report.write("R.html")                      # opens offline in any browser
>>> report.write("R.pdf")                       # the same figures and tables through PdfPages

What it shows, for the first model (the one validated) and the others (compared on the same data):

* the held-out error per joint (RMS, normalised RMS, R^2, largest error) against the measured noise
  floor, and the methods side by side (table and bar chart);
* measured against predicted torque, one joint per row, with the residual (measured minus predicted)
  beside it against the noise floor;
* the residual before and after the GMM layer, when the mixture changed the prediction (else a sentence
  saying so);
* friction torque against velocity with each model's friction law over the data (the paper's figure 6);
* condition numbers, the base parameters with their relative standard deviation (``at bound`` for a
  parameter the physical constraints hold at its bound), and the physically
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
from dynid.identify.model import AT_BOUND_STD
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
    "AT_BOUND_STD",
    "Report",
    "ReportFigure",
    "check_report_path",
    "format_number",
    "gmm_changed",
    "held_at_bound",
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


def gmm_changed(results: Sequence[ValidationResult]) -> ValidationResult | None:
    """The first result whose GMM layer changed its prediction on the held-out data, or None.

    Parameters
    ----------
    results : sequence of ValidationResult
        The results of a report.
    """
    for r in results:
        if not r.has_gmm or not r.residual.size:
            continue
        scale = float(np.max(np.abs(r.tau))) or 1.0
        if np.max(np.abs(r.residual - r.residual_before_gmm)) > 1e-9 * scale:  # more than rounding
            return r
    return None


def _gmm_sentence(results: Sequence[ValidationResult]) -> str:
    """Why a report has no before/after GMM figure, as an HTML paragraph."""
    with_gmm = [r for r in results if r.model.gmr is not None]
    if not with_gmm:
        text = (
            "There is no before/after figure: no model here has a GMM layer. Each model's residual is beside its "
            "measured and predicted torque above."
        )
    else:
        r = with_gmm[0]
        why = r.model.gmr.fallback_ if r.model.gmr.fallback_ else "no joint's correction is active"
        text = (
            f"The GMM layer of '{r.label}' changed nothing on these data ({why}), so its residual after the "
            "layer is the one before it: shown once, beside the measured and predicted torque above."
        )
    return f'<p class="note">{html.escape(text)}</p>'


def _render_figures(results: Sequence[ValidationResult], pdf_pages: Any | None) -> list[ReportFigure]:
    from dynid.validation.plots import (
        figure_png,
        fixed_margins,
        joint_grid,
        pair_grid,
        plot_friction,
        plot_method_rms,
        plot_prediction_error,
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

    fig = Figure(figsize=(11, 3.6))
    ax = fig.subplots()
    # the legend right of the panel, as wide as its longest label (8 pt: about 0.07 inch a character)
    longest = max(len("noise floor"), *(len(r.label) for r in results))
    fixed_margins(fig, 1, 1, right=max(1.9, 0.75 + 0.07 * longest), bottom=0.45)
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

    # measured vs predicted, the residual beside
    fig, pairs = pair_grid(n, fixed={"bottom": 0.85, "hspace": 0.35, "wspace": 0.85})
    predictions = {r.label: r.tau_pred for r in results}
    for j, (left, right) in enumerate(pairs):
        plot_torque(left, first.t, first.tau[:, j], {k: v[:, j] for k, v in predictions.items()}, joint=j + 1)
        plot_prediction_error(
            right,
            first.t,
            first.tau[:, j],
            {k: v[:, j] for k, v in predictions.items()},
            joint=j + 1,
            noise=float(first.noise.std[j]),
        )
    tidy_grid([a for a, _ in pairs], ncols=1)
    tidy_grid([b for _, b in pairs], ncols=1)
    # one legend for both columns, below the panels (inside one it hides the data)
    handles, labels = pairs[0][0].get_legend_handles_labels()
    for handle, label in zip(*pairs[0][1].get_legend_handles_labels(), strict=True):
        if label not in labels:  # the noise band
            handles.append(handle)
            labels.append(label)
    fig.legend(handles, labels, loc="lower center", ncols=len(labels), fontsize=8, frameon=False)
    emit(
        "torque",
        "Measured and predicted joint torque",
        f"Held-out data ({first.data}); the measured torque is {first.reference}, as compared. Left: measured "
        "(grey) and each model's prediction; right: measured minus predicted, model by model, against the band "
        "of +-1 noise standard deviation (the title gives the RMS of the first model). Short spikes at velocity "
        "reversals are usually Coulomb friction's sign change placed a few milliseconds off (see 'Samples near zero "
        "speed' under the held-out error).",
        fig,
    )

    # residual before / after GMM: only where the mixture changed the prediction
    with_gmm = gmm_changed(results)
    if with_gmm is not None:
        fig, axes = joint_grid(n, fixed={"bottom": 0.85, "hspace": 0.35, "wspace": 0.85})
        for j, ax in enumerate(axes):
            plot_residuals(
                ax,
                with_gmm.t,
                with_gmm.residual_before_gmm[:, j],
                with_gmm.residual[:, j],
                joint=j + 1,
                noise=float(with_gmm.noise.std[j]),
            )
        handles, labels = axes[0].get_legend_handles_labels()
        fig.legend(handles, labels, loc="lower center", ncols=len(labels), fontsize=8, frameon=False)
        tidy_grid(axes)
        emit(
            "residual",
            "Residual before and after the GMM layer",
            f"Residual of '{with_gmm.label}' before (link and friction layers) and after the GMM layer; the band "
            "is +-1 noise standard deviation.",
            fig,
        )

    # friction against velocity
    fig, axes = joint_grid(n, sharex=False, height=2.6, fixed={"hspace": 0.75, "wspace": 0.85})
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


NEAR_ZERO_SPEED = 0.02
"""Share of a joint's top speed below which the gap diagnosis leaves its samples out (its default
``stick_fraction``): the samples the moving-only RMS of :func:`_near_zero_speed_note` leaves out."""


def _near_zero_speed_note(result: ValidationResult) -> str:
    """What the samples near zero speed add to the RMS, and the RMS without them (the gap diagnosis's figure).

    Coulomb friction changes sign at a velocity reversal; the step the model places by the estimated
    velocity and the filtered measured one rarely line up, which leaves short spikes in the residual there.
    The gap diagnosis scores a joint only where it moves faster than :data:`NEAR_ZERO_SPEED` of its top
    speed, so its error figure for this model is the RMS without those samples, given here.
    """
    r, dq = result.residual, result.dq
    if r.size == 0 or dq.shape != r.shape:
        return ""
    top = np.max(np.abs(dq), axis=0)
    moving = np.abs(dq) >= NEAR_ZERO_SPEED * np.maximum(top, 1e-12)
    kept = np.maximum(moving.sum(axis=0), 1)
    rms = np.sqrt(np.sum(np.where(moving, r**2, 0.0), axis=0) / kept)
    share = 100.0 * (1.0 - moving.mean(axis=0))
    figures = ", ".join(f"joint {j + 1} {format_number(float(rms[j]))}" for j in range(result.n))
    text = (
        f"Samples near zero speed: the RMS and the largest error count every sample. Where a joint moves slower "
        f"than {100 * NEAR_ZERO_SPEED:g} % of its top speed ({format_number(float(share.min()), 2)}-"
        f"{format_number(float(share.max()), 2)} % of the samples here, by joint) Coulomb friction changes sign, a "
        "step of twice its level that the model places by the estimated velocity and the filter smooths; the "
        "predicted and the measured step rarely line up to the millisecond, so each velocity reversal leaves a "
        "short spike in the residual. The gap diagnosis (dynid diagnose) leaves those samples out; without them "
        f"the RMS of '{result.label}' is {figures} N m, the diagnosis's figure for this model (its 'MSE model' "
        "as RMS, up to the diagnosis's even thinning of the samples)."
    )
    return f'<p class="note">{html.escape(text)}</p>'


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



def held_at_bound(model: Any) -> np.ndarray:
    """Which layer-1 parameters the identification held at their bound: (p,) bool.

    Those the model file lists as active (``info["bounds"]["active"]``), and, for a physically bounded fit
    (armature, Coulomb and viscous friction ``>= 0``), those closer to the bound than :data:`AT_BOUND_STD` of
    their standard deviation: an interior-point fit (the consistent projection's barrier) stops just inside
    a bound, where the value is the bound's and not the data's.

    Parameters
    ----------
    model : IdentifiedModel
        The model.
    """
    from dynid.identify.estimators import physical_lower_bounds

    cols = model.columns
    bounds = model.info.get("bounds") or {}
    active = set(bounds.get("active") or [])
    held = np.array([name in active for name in cols.names], dtype=bool)
    if bounds.get("physical"):
        lower = physical_lower_bounds(cols)
        finite = np.isfinite(lower)
        gap = np.where(finite, np.asarray(model.params, float) - np.where(finite, lower, 0.0), np.inf)
        held |= finite & (gap <= AT_BOUND_STD * model.std)
    return held


def _parameter_table(result: ValidationResult) -> tuple[str, list[str]]:
    """The parameter table and the names of the parameters held at their bound."""
    m = result.model
    held = held_at_bound(m)
    rows = []
    for name, expr, kind, v, s, pct, at in zip(
        m.columns.names,
        m.columns.expressions,
        m.columns.kinds,
        m.params,
        m.std,
        m.std_percent,
        held,
        strict=True,
    ):
        shown = '<td class="at-bound" style="white-space: nowrap">at bound</td>' if at else float(pct)
        rows.append([name, kind, expr, float(v), float(s), shown])
    table = html_table(
        ["name", "kind", "expression", "value (SI)", "std", "std (%)"],
        rows,
        table_id="parameters",
        text_columns=3,
    )
    return table, [name for name, at in zip(m.columns.names, held, strict=True) if at]


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


def _bound_note(held: Sequence[str]) -> str:
    """A sentence naming the parameters held at their bound (empty when there are none)."""
    if not held:
        return ""
    names = ", ".join(held)
    return html.escape(
        f" Held at their lower bound (0) by the physical constraints: {names}; the data would put "
        f"{'it' if len(held) == 1 else 'them'} at or below it, so the value is the bound's and a relative "
        "standard deviation means nothing there ('at bound')."
    )


def _conditions_note(
    results: Sequence[ValidationResult], conditions: Sequence[tuple[str, float | None]]
) -> str:
    """The caption of the condition numbers: what they are, and why a row has none (only rows that are there)."""
    text = "Of the noise-weighted regressor each model was identified from (lower is better conditioned)"
    none = [r.label for r in results if not np.isfinite(r.model.cond)]
    if none:
        quoted = ", ".join(f"'{label}'" for label in none)
        text += (
            f"; {quoted} estimated no rigid-body parameter (the robot description's are used), so "
            f"{'it has' if len(none) == 1 else 'they have'} none"
        )
    if conditions:
        text += "; the rows after the models are the motion's own, as named"
    return f'<p class="note">{html.escape(text)}.</p>'


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
    parameter_table, held = _parameter_table(first)

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
        _near_zero_speed_note(first),
        heading("Methods side by side", "section-methods"),
        _methods_table(results),
        _figure_html(by_key["methods"]),
        heading(by_key["torque"].title, "section-torque"),
        _figure_html(by_key["torque"]),
        heading("Residual before and after the GMM layer", "section-residual"),
        _figure_html(by_key["residual"]) if "residual" in by_key else _gmm_sentence(results),
        heading(by_key["friction"].title, "section-friction"),
        _figure_html(by_key["friction"]),
        heading("Condition numbers", "section-conditions"),
        _conditions_note(results, conditions),
        html_table(["", "condition number"], cond_rows, table_id="conditions"),
    ]
    for section_title, fragment in sections:
        anchor = "".join(ch if ch.isalnum() else "-" for ch in section_title.lower()).strip("-")
        parts += [heading(section_title, f"section-{anchor}"), fragment]
    parts += [
        heading("Base parameters", "section-parameters"),
        f"<p class=\"note\">Model '{html.escape(first.label)}' ({html.escape(first.model.method)}): identified "
        "parameters with their standard deviation from the identification's covariance; std (%) relative to "
        f"|value| (large: poorly excited by the data).{_bound_note(held)}</p>",
        parameter_table,
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
