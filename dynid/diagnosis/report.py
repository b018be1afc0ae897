"""The gap diagnosis as a self-contained HTML report (figures embedded as base64 PNG).

>>> write_diagnosis_report(result, "gap.html")

Sections: the verdict in plain words; the decomposition of the held-out error per joint (noise floor,
parametric, attributed, unexplained) and the closure; the gap map as pictures (excess over the noise
floor per bin with bootstrap intervals, one joint per panel); the residual before and after the
accepted effects (one joint per panel); the candidate ranking; the parameter-change test; the global
flags (whiteness, delay, cogging).
"""

from __future__ import annotations

import html
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from dynid._io import write_text
from dynid.validation.html_page import check_report_path, figure_html, format_number, html_page, html_table

__all__ = ["diagnosis_figures", "refit_rows", "render_diagnosis_html", "write_diagnosis_report"]



def _delay_word(d: dict[str, Any]) -> str:
    """The delay flag in a word or three, saying why a large correlation is not flagged."""
    if d["flag"]:
        return "yes"
    thr = d.get("threshold")
    if thr is None or abs(d["rho"]) <= thr or d["lag_ms"] == 0:
        return "no"
    if d.get("at_edge"):
        return "no (peak on the window's edge)"
    if d.get("rise", thr + 1.0) <= thr:
        return "no (flat across the lags)"
    return "no"

def _table(headers: list[str], rows: list[list[Any]], text_columns: int = 1) -> str:
    return html_table(headers, rows, text_columns=text_columns, digits=3)


REVERSAL_TEXT = (
    "The stiction row (near zero speed) and the row within 50 ms of a velocity reversal can stand far above 1 "
    "with no effect behind them: there Coulomb friction changes sign, a step of twice its level, which the model "
    "places by the estimated velocity and the low-pass filter smooths, so the predicted and the measured step "
    "rarely line up to the millisecond and each reversal leaves a short spike in the residual.  Few samples "
    "fall in those bins, so the spikes dominate them.  The samples near zero speed are left out of the error "
    "figures and the excess test for that reason; effects that act at reversals (Stribeck friction, backlash) "
    "are tested as candidates (the ranking below), and the verdict rests on those tests, not on these bars."
)
"""What the gap map's stiction and reversal rows mean when no effect is behind them (its caption)."""
WHITENESS_TEXT = (
    "White: whether the residual is uncorrelated from one sample to the next (a Ljung-Box test on 20 lags of "
    "the residual decimated to about 50 Hz; 'no' where p < 0.05).  A residual compared after a low-pass filter, "
    "from a model whose parameters were fitted, is correlated in time even with no unmodelled effect, and on a "
    "run of thousands of samples the p-value of that correlation is tiny (1e-10 or less is common): it says "
    "the residual is not white, not how large it is or what causes it.  The verdict does not use it: it rests "
    "on the held-out excess test (whose block statistics allow for the correlation) and on the candidates' "
    "tests.  The delay and cogging flags are screens in the same way: each points at a candidate (a delay, "
    "cogging) that the ranking tests on the held-out data.  A delay is flagged only where the curve peaks "
    "inside the window and rises above its zero-lag value by more than the threshold: a curve flat across "
    "the lags (a parameter error on a slow torque) or climbing to the window's edge is no delay."
)
"""What the global flags mean for the verdict (the text under their table)."""

LABEL_PT = 8.0
"""Smallest text in the figures (pt): at the 110 dpi of their PNG, scaled to a 1280 px page, about 11 px."""
GAP_ROW_IN = 0.14
"""Height of one gap-map bar (inches): a LABEL_PT label and some space."""
_PALETTE = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2", "#17becf")


def _gap_bars(joint_map: dict[str, list[dict[str, Any]]]) -> tuple[list[str], list, list, list, list[str]]:
    """One joint's gap-map bars: ``(labels, excess, low, high, colors)``, bins without an estimate left out."""
    labels, est, lo, hi, colors = [], [], [], [], []
    for k, (kind, rows) in enumerate(joint_map.items()):
        for r in rows:
            if r.get("excess") is None:
                continue
            labels.append(f"{kind}: {r['label']}"[:38])
            est.append(r["excess"])
            lo.append(r["low"] if r.get("low") is not None else r["excess"])
            hi.append(r["high"] if r.get("high") is not None else r["excess"])
            colors.append(_PALETTE[k % len(_PALETTE)])
    return labels, est, lo, hi, colors


def _log_ticks(axis) -> None:
    """Plain-numbered major ticks on a log axis, few enough that their labels never touch.

    1, 2 and 5 per decade over up to 1.5 decades, 1 and 3 up to 2.5, one per decade (or per few decades)
    beyond: at most about six.  Minor ticks stay unlabelled: matplotlib labels them in scientific notation on a
    short range, and 1, 2, 5 per decade on a long one run into each other ("100200", "20005000").
    """
    from matplotlib.ticker import FormatStrFormatter, LogLocator, NullFormatter

    lo, hi = sorted(axis.get_view_interval())
    decades = math.log10(hi / lo) if lo > 0 and hi > lo else 0.0
    subs = (1.0, 2.0, 5.0) if decades <= 1.5 else (1.0, 3.0) if decades <= 2.5 else (1.0,)
    axis.set_major_locator(LogLocator(base=10, subs=subs, numticks=6))
    axis.set_major_formatter(FormatStrFormatter("%g"))
    axis.set_minor_locator(LogLocator(base=10, subs=np.arange(2.0, 10.0), numticks=12))
    axis.set_minor_formatter(NullFormatter())


def _gap_panel(ax, joint_map: dict[str, list[dict[str, Any]]]) -> None:
    """One joint's gap map on ``ax``: excess per bin (log scale) with its interval, labels at LABEL_PT."""
    labels, est, lo, hi, colors = _gap_bars(joint_map)
    y = np.arange(len(labels))
    est_a = np.maximum(np.array(est, dtype=float), 1e-3)
    err = np.vstack([est_a - np.minimum(lo, est_a), np.maximum(hi, est_a) - est_a])
    ax.barh(y, est_a, xerr=err, color=colors, alpha=0.8, error_kw={"linewidth": 0.8})
    ax.axvline(1.0, color="k", linewidth=1.0, linestyle="--")
    ax.set_xscale("log")
    _log_ticks(ax.xaxis)
    ax.set_yticks(y, labels, fontsize=LABEL_PT)
    ax.invert_yaxis()
    ax.set_xlabel("excess: mean(r^2) / noise variance (-)")


def diagnosis_figures(result) -> list[tuple[str, str, bytes]]:
    """The report's figures: ``(title, caption, png)`` each, one joint per panel.

    Parameters
    ----------
    result : Diagnosis
        What :func:`dynid.diagnosis.core.diagnose` returned.
    """
    from matplotlib.figure import Figure

    from dynid.validation.plots import figure_png, joint_grid, thin, tidy_grid

    out = []
    names = result.joint_names
    n = len(names)
    gmap = result.gap_map
    # 1. Gap map: excess per bin with its interval; each row tall enough for its labels at LABEL_PT.
    rows = max((len(_gap_bars(gmap["joints"][j])[0]) for j in range(n)), default=0)
    fig, axes = joint_grid(n, height=max(3.6, GAP_ROW_IN * rows + 1.0), sharex=False)
    for j, ax in enumerate(axes):
        _gap_panel(ax, gmap["joints"][j])
        ax.set_title(f"joint {j + 1} ({names[j]})", fontsize=9)
    tidy_grid(axes)
    out.append(
        (
            "Gap map",
            "Held-out residual of the re-identified model: mean squared residual over the noise variance in each "
            "bin (1, dashed: at the noise floor), 90 % moving-block bootstrap intervals; frequency bands against "
            "the filtered noise spectrum.  " + REVERSAL_TEXT,
            figure_png(fig),
        )
    )
    # 2. Decomposition per joint.
    dec = result.decomposition
    fig, axes = joint_grid(n, height=2.4, sharex=False)
    for j, ax in enumerate(axes):
        vals = [dec["mse_model"][j], dec["mse_refit"][j], dec["mse_after"][j], dec["noise"][j]]
        ax.bar(
            ["model", "re-identified", "with effects", "noise floor"],
            vals,
            color=["#7f7f7f", "#1f77b4", "#2ca02c", "#000000"],
        )
        ax.set_ylabel("MSE (N^2 m^2)")
        ax.set_title(f"joint {j + 1} ({names[j]})", fontsize=9)
        ax.tick_params(axis="x", labelsize=LABEL_PT)
    out.append(
        (
            "Held-out error per joint",
            "Mean squared torque error on the held-out data (filtered like the model's data, samples near zero "
            "speed left out): the model as given, "
            "its base parameters identified again, with the accepted effects added, and the measured noise floor.",
            figure_png(fig),
        )
    )
    # 3. Residual before / after over time.
    t = result.residuals["t"]
    before, after = result.residuals["before"], result.residuals["after"]
    sd = result.residuals["noise_std"]
    s = thin(len(t))
    fig, axes = joint_grid(n, height=2.0)
    for j, ax in enumerate(axes):
        ax.plot(t[s], before[s, j], color="#d62728", linewidth=0.6, label="re-identified model")
        if result.accepted:
            ax.plot(t[s], after[s, j], color="#2ca02c", linewidth=0.6, label="with accepted effects")
        ax.axhspan(-2 * sd[j], 2 * sd[j], color="k", alpha=0.08, label="+-2 noise std")
        ax.set_ylabel(f"r_{j + 1} (N m)")
        ax.set_xlabel("time (s)")
        ax.set_title(f"joint {j + 1} ({names[j]})", fontsize=9)
    axes[0].legend(fontsize=LABEL_PT, loc="upper right")
    tidy_grid(axes)
    out.append(
        (
            "Held-out residual",
            "Torque residual over time before and after adding the accepted effects; the grey band is +-2 "
            "standard deviations of the noise floor.  Short spikes at velocity reversals are usually Coulomb "
            "friction's "
            "sign change placed a few milliseconds off (see the gap map); the samples near zero speed are left "
            "out of the error figures and the excess test.",
            figure_png(fig),
        )
    )
    # 4. The training residual over the period (the lack-of-fit check).
    lof = result.lack_of_fit
    if lof and lof.get("curve", {}).get("phase_s"):
        curve = lof["curve"]
        phase = np.asarray(curve["phase_s"], dtype=float)
        fig, axes = joint_grid(n, height=2.0)
        for j, ax in enumerate(axes):
            mean = np.asarray(curve["mean"][j], dtype=float)
            band = np.asarray(curve["band"][j], dtype=float)
            ax.fill_between(phase, -band, band, color="k", alpha=0.1, linewidth=0, label="+-2 noise std of the mean")
            lead = lof["lead_joint"][j]
            ax.plot(phase, mean, color="#d62728" if lead else "#1f77b4", linewidth=0.8, label="mean over the periods")
            ax.set_xlabel("time into the period (s)")
            ax.set_ylabel(f"r_{j + 1} (N m)")
            ax.set_title(
                f"joint {j + 1} ({names[j]}): misfit {lof['misfit'][j]:.2g}, p = {lof['p_raw'][j]:.2g}"
                + (" (lead)" if lead else ""),
                fontsize=9,
            )
        axes[0].legend(fontsize=LABEL_PT, loc="upper right")
        tidy_grid(axes)
        out.append(
            (
                "Training residual over the period",
                f"The training refit's residual averaged over the training run's {lof['periods']:.3g} periods, phase "
                "by phase (the joint's moving samples).  Noise averages out across the periods; what the state "
                "determines repeats and stays.  The grey band is two noise stds of such a mean (the noise "
                "measured by the spread across the periods); a curve that leaves it on long stretches is "
                "something the model lacks.  Misfit: its mean square less the noise's share, in noise variances "
                f"(a lead at {lof['lead_misfit']:g} or more with p < alpha, red).",
                figure_png(fig),
            )
        )
    # 5. Delay and cogging flags as curves.
    fig, axes = joint_grid(n, height=2.0, sharex=False)
    for j, ax in enumerate(axes):
        d = gmap["flags"]["delay"][j]
        curve = d.get("curve")
        if curve:
            ax.plot(curve["lag_ms"], curve["rho"], color="#1f77b4")
            if d.get("threshold"):
                ax.axhline(d["threshold"], color="k", linestyle="--", linewidth=0.8)
                ax.axhline(-d["threshold"], color="k", linestyle="--", linewidth=0.8)
        ax.set_xlabel("lag (ms)")
        ax.set_ylabel("correlation (-)")
        ax.set_title(f"joint {j + 1}: residual vs predicted torque", fontsize=9)
    tidy_grid(axes)
    out.append(
        (
            "Residual-torque cross-correlation",
            "Correlation of the residual with the predicted torque shifted by +-50 ms; a peak beyond the dashed "
            "threshold at a non-zero lag, and above the zero-lag value by as much, points to a delay.",
            figure_png(fig),
        )
    )
    fig, axes = joint_grid(n, height=2.0, sharex=False)
    for j, ax in enumerate(axes):
        c = gmap["flags"]["cogging"][j]
        spec = c.get("spectrum")
        if spec:
            ax.semilogy(spec["N"], np.maximum(spec["power"], 1e-30), color="#9467bd", linewidth=0.8)
        ax.set_xlabel("angular frequency N (cycles per 2 pi rad)")
        ax.set_ylabel("power (N^2 m^2)")
        ax.set_title(f"joint {j + 1}: angle-domain spectrum", fontsize=9)
    tidy_grid(axes)
    out.append(
        (
            "Angle-domain spectrum of the residual",
            "Power of the residual at harmonics of the joint angle; a sharp peak at N points to cogging or a "
            "gear ripple with N periods per revolution.",
            figure_png(fig),
        )
    )
    del Figure
    return out


def refit_rows(refit: dict[str, Any], joint_names: list[str] | tuple[str, ...]) -> list[list[Any]]:
    """One row per joint: held-out RMS before and after the accepted effects and their ratio.

    Parameters
    ----------
    refit : dict
        ``rms_before`` and ``rms_after`` (N m per joint), as ``dynid diagnose --out`` records them.
    joint_names : sequence of str
        The joints' names.

    Returns
    -------
    list of list
        ``[joint, before (N m), after (N m), after / before]`` per joint (the ratio None where the
        model's own error is zero or not finite).
    """
    before = np.asarray(refit["rms_before"], dtype=np.float64)
    after = np.asarray(refit["rms_after"], dtype=np.float64)
    rows: list[list[Any]] = []
    for j, name in enumerate(joint_names):
        ok = np.isfinite(before[j]) and np.isfinite(after[j]) and before[j] > 0
        rows.append(
            [f"{j + 1} ({name})", float(before[j]), float(after[j]), after[j] / before[j] if ok else None]
        )
    return rows


def _refit_html(refit: dict[str, Any], joint_names) -> str:
    rows = refit_rows(refit, joint_names)
    b = np.asarray(refit["rms_before"], dtype=np.float64)
    a = np.asarray(refit["rms_after"], dtype=np.float64)
    better = sum(1 for r in rows if r[3] is not None and r[3] < 1)
    effects = ", ".join(refit.get("effects", []))
    where = f" ({html.escape(str(refit['path']))})" if refit.get("path") else ""
    return (
        "<h2>The model with the accepted effects</h2>"
        f"<p>Refitted on the training data with {html.escape(effects)} added as model terms{where}. "
        f"Held-out RMS per joint before and after (the same held-out data as above); lower on {better} of "
        f"{len(rows)} joints, mean {format_number(float(np.mean(b)), 3)} to {format_number(float(np.mean(a)), 3)} N m.</p>"
        + _table(["joint", "before (N m)", "after (N m)", "after / before"], rows)
    )


def _stiction_row(joint_map: dict[str, list[dict[str, Any]]]) -> dict[str, Any] | None:
    """The gap map's row of the samples near zero speed (None if it has none)."""
    rows = joint_map.get("speed", [])
    return next((r for r in rows if str(r.get("label", "")).startswith("stiction")), None)


def _left_out_html(result, dec: dict[str, Any]) -> str:
    """Which held-out samples the error figures leave out, why, and how they relate to a validation report's.

    The diagnosis scores each joint on the samples where it moves (faster than ``stick_fraction`` of its top
    speed); a validation report's RMS counts every sample, so for the same model it is larger by what the
    samples near zero speed add.
    """
    from dynid.diagnosis.settings import DiagnosisSettings

    n = len(result.joint_names)
    frac = float(result.settings.get("stick_fraction", DiagnosisSettings().stick_fraction))
    total = result.settings.get("samples_heldout")
    rms = np.sqrt(np.maximum(np.asarray(dec["mse_model"], dtype=float), 0.0))
    shares, spikes = [], []
    for j in range(n):
        row = _stiction_row(result.gap_map["joints"][j])
        # The gap map's stiction row is the 2 % of the top speed: the left-out samples at the default only.
        if row is None or not total or not math.isclose(frac, 0.02):
            continue
        shares.append(100.0 * row["count"] / total)
        if row.get("excess") is not None:
            spikes.append(f"joint {j + 1} {format_number(row['excess'], 2)}")
    share = (
        f" ({format_number(min(shares), 2)}-{format_number(max(shares), 2)} % of the held-out samples, by joint)"
        if shares
        else ""
    )
    there = (
        "; on them the re-identified model's mean squared residual is, in noise variances, "
        + ", ".join(spikes)
        + " (the gap map's stiction row)"
        if spikes
        else ""
    )
    figures = ", ".join(f"joint {j + 1} {format_number(float(rms[j]), 4)}" for j in range(n))
    text = (
        f"Samples left out: where a joint moves slower than {100 * frac:g} % of its top speed{share}. Coulomb "
        "friction changes sign there (sticking, reversals), a step the model places a few milliseconds off, "
        f"which leaves short spikes that say nothing of an unmodelled effect{there}. The model as given has, "
        f"as RMS on the samples kept, {figures} N m: a validation report's RMS counts every sample and is "
        "larger for the same model by what the samples near zero speed add."
    )
    return f"<p>{html.escape(text)}</p>"


def _floor_free_html(doc: dict[str, Any], joint_names) -> list[str]:
    """The two checks that do not rest on the floor, per joint: the runs' agreement on the parameters and the
    training run's misfit across its periods."""
    con, lof = doc.get("consistency"), doc.get("lack_of_fit")
    if not con and not lof:
        return []
    headers, columns = ["joint"], []
    if con:
        headers += ["disagreement: cost (-)", "p", "lead"]
        columns.append(
            lambda j: [con["cost"][j], con["p_raw"][j], "yes" if con["lead_joint"][j] else "no"]
        )
    if lof:
        headers += ["training misfit (noise variances)", "quantised angles (white model)", "p", "lead"]
        columns.append(
            lambda j: [lof["misfit"][j], lof["state_estimation"][j], lof["p_raw"][j], "yes" if lof["lead_joint"][j] else "no"]
        )
    rows = [[f"{j + 1} ({joint_names[j]})", *[v for col in columns for v in col(j)]] for j in range(len(joint_names))]
    text = []
    if con:
        text.append(
            f"Disagreement: the training loss the coefficients refitted with the held-out run add, over the training "
            f"residual's variance; a lead where it reaches {con['lead_cost']:g} with p < alpha."
        )
    if lof:
        text.append(
            f"Training misfit: how much of the training refit's residual repeats across the training run's "
            f"{lof['periods']:.3g} periods beyond noise; a lead where, less {lof['quantisation_factor']:g} times what the "
            f"white model of the quantised angles gives, it "
            f"reaches {lof['lead_misfit']:g} with p < alpha."
        )
    return [
        "<h3>Checks that do not rest on the floor</h3>",
        _table(headers, rows, text_columns=1),
        "<p>" + html.escape(" ".join(text)) + "</p>",
    ]


def render_diagnosis_html(
    result,
    *,
    title: str = "dynid gap diagnosis",
    context: dict[str, Any] | None = None,
    refit: dict[str, Any] | None = None,
    settle: dict[str, Any] | None = None,
) -> str:
    """The report as one HTML string.

    Parameters
    ----------
    result : Diagnosis
        The diagnosis.
    title : str
        Page title.
    context : dict, optional
        Extra facts shown in a table (model file, data files, robot).
    refit : dict, optional
        The model refitted with the accepted effects (``dynid diagnose --out``): ``rms_before``,
        ``rms_after`` (N m per joint, held out), ``effects`` and ``path``; shown as a per-joint table.
    settle : dict, optional
        The recording that would settle an undecided or provisional verdict (``dynid diagnose``):
        ``reason`` and the ``commands`` that record and diagnose it.
    """
    doc = result.to_dict()
    dec = doc["decomposition"]
    n = len(result.joint_names)
    parts = [f'<p class="verdict">Verdict: <strong>{html.escape(", ".join(result.verdict))}</strong></p>']
    parts.append(
        "<ul>" + "".join(f"<li>{html.escape(line)}</li>" for line in result.summary().splitlines()) + "</ul>"
    )
    if context:
        parts.append(html_table(None, [[k, str(v)] for k, v in context.items()], text_columns=2))
    if refit and refit.get("written"):
        parts.append(_refit_html(refit, result.joint_names))
    if settle and settle.get("commands"):
        commands = html.escape("\n".join(settle["commands"]))
        parts.append(
            "<h2>The recording that would decide</h2>"
            f"<p>{html.escape(str(settle.get('reason', '')))}</p>"
            f'<pre style="white-space: pre-wrap; overflow-wrap: anywhere">{commands}</pre>'
        )
    parts.append("<h2>Where the held-out error lies</h2>")
    rows = []
    for j in range(n):
        rows.append(
            [
                f"{j + 1} ({result.joint_names[j]})",
                dec["mse_model"][j],
                dec["noise"][j],
                dec["parametric"][j],
                dec["attributed"][j],
                dec["unexplained"][j],
                doc["excess"]["ratio"][j],
                doc["excess"]["estimation"][j],
                dec["closure"][j],
            ]
        )
    parts.append(
        _table(
            [
                "joint",
                "MSE model (N^2 m^2)",
                "noise floor",
                "parametric",
                "attributed",
                "unexplained",
                "excess (re-identified / noise)",
                "of it from parameter uncertainty",
                "closure",
            ],
            rows,
        )
    )
    parts.append(
        f"<p>Noise floor: {html.escape(result.noise.detail)}. Closure overall: {format_number(dec['closure_overall'], 3)}. "
        "MSE on the filtered held-out torque, samples near zero speed left out (sticking). Excess: the "
        "re-identified model's MSE over the noise variance (in noise variances: the square of an RMS / noise); "
        "less its share from parameter uncertainty it is what the excess test ran on, the figure the summary "
        "gives.</p>"
    )
    parts.append(_left_out_html(result, dec))
    rem = doc.get("remainder")
    if rem is not None:
        parts.append("<h3>What a state model still predicts (a check that does not rest on the floor)</h3>")
        parts.append(
            _table(
                ["joint", "share of the residual predicted", "gain (floor variances)", "p (Holm)", "predictable"],
                [
                    [
                        f"{j + 1} ({result.joint_names[j]})",
                        rem["share"][j],
                        rem["gain"][j],
                        rem["p_joint"][j],
                        "yes" if rem["predictable_joint"][j] else "no",
                    ]
                    for j in range(n)
                ],
                text_columns=1,
            )
        )
        parts.append(
            f"<p>{html.escape(rem['model'])}; each held-out fold is predicted by trees that never saw it. A share "
            "at or below zero: the trees learnt nothing that holds on data they did not see.</p>"
        )
    parts.extend(_floor_free_html(doc, result.joint_names))
    for title_f, caption, png in diagnosis_figures(result):
        parts.append(figure_html(png, title=title_f, caption=caption, show_title=True))
    parts.append("<h2>Which effect: candidate ranking</h2>")
    rows = []
    for r in doc["ranking"][:20]:
        joint = r["joint"]
        joint = "+".join(map(str, joint)) if isinstance(joint, list) else joint
        rows.append(
            [
                r["effect"],
                "-" if joint is None else joint,
                "yes" if r["accepted"] else "no",
                "yes" if r["significant"] else "no",
                r["gain"],
                r["closure"],
                r["p_value"],
                ", ".join(r["confounded_with"]) or "-",
            ]
        )
    parts.append(
        _table(
            [
                "effect",
                "joint",
                "accepted",
                "significant",
                "gain (noise var.)",
                "closure",
                "p (adjusted)",
                "not separable from",
            ],
            rows,
            text_columns=4,
        )
    )
    parts.append("<h2>Parameter change</h2>")
    par = doc["parametric"]
    parts.append(f"<p>{html.escape(par.get('text', ''))}</p>")
    parts.append(
        _table(
            ["hypothesis", "free parameters", "chi^2", "dof", "BIC"],
            [[h["name"], h["k"], h["chi2"], h["dof"], h["bic"]] for h in par.get("hypotheses", [])[:8]],
        )
    )
    parts.append("<h2>Global flags</h2>")
    flags = doc["gap_map"]["flags"]
    rows = []
    for j in range(n):
        w, d, c = flags["whiteness"][j], flags["delay"][j], flags["cogging"][j]
        rows.append(
            [
                f"{j + 1}",
                w["p_value"],
                "yes" if w["white"] else "no",
                d["lag_ms"],
                d["rho"],
                _delay_word(d),
                c.get("peak_ratio"),
                c.get("peak"),
                "yes" if c.get("flag") else "no",
            ]
        )
    parts.append(
        _table(
            [
                "joint",
                "Ljung-Box p",
                "white",
                "xcorr peak lag (ms)",
                "xcorr",
                "delay flag",
                "angle peak N",
                "peak / median",
                "cogging flag",
            ],
            rows,
        )
    )
    parts.append(f"<p>{html.escape(WHITENESS_TEXT)}</p>")
    if result.notes:
        parts.append(
            "<h2>Notes</h2><ul>" + "".join(f"<li>{html.escape(x)}</li>" for x in result.notes) + "</ul>"
        )
    return html_page(title, parts)


def write_diagnosis_report(
    result,
    path: str | os.PathLike[str],
    *,
    title: str = "dynid gap diagnosis",
    context: dict[str, Any] | None = None,
    refit: dict[str, Any] | None = None,
    settle: dict[str, Any] | None = None,
) -> Path:
    """Write the HTML report atomically (a temporary file renamed into place).

    Parameters
    ----------
    result : Diagnosis
        The diagnosis.
    path : str or path-like
        The ``.html`` file; its folder must exist.
    title : str
        Page title.
    context : dict, optional
        Extra facts shown in a table.
    refit : dict, optional
        The model refitted with the accepted effects (see :func:`render_diagnosis_html`).
    settle : dict, optional
        The recording that would settle the verdict (see :func:`render_diagnosis_html`).

    Returns
    -------
    Path
    """
    path = check_report_path(path, pdf=False)
    return write_text(
        path, render_diagnosis_html(result, title=title, context=context, refit=refit, settle=settle)
    )
