"""Figures of a validation: each function draws one joint (or one table of bars) on an ``ax`` it is given.

The functions never create windows nor call ``plt.show()``: the report (:mod:`dynid.validation.report`)
lays them out one joint per panel with :func:`joint_grid` (the torque beside its residual, one joint per
row, with :func:`pair_grid`) and embeds them as PNG.  Use them the same way in a notebook::

    fig, axes = joint_grid(6)
    for j, ax in enumerate(axes):
        plot_torque(ax, result.t, result.tau[:, j], {"full": result.tau_pred[:, j]}, joint=j + 1)

    fig, pairs = pair_grid(6)             # the torque beside its residual, one joint per row
    for j, (left, right) in enumerate(pairs):
        plot_torque(left, result.t, result.tau[:, j], {"full": result.tau_pred[:, j]}, joint=j + 1)
        plot_prediction_error(right, result.t, result.tau[:, j], {"full": result.tau_pred[:, j]}, joint=j + 1)

Figures are plain :class:`matplotlib.figure.Figure` objects, never pyplot's: no window, no global state,
no display needed, whatever backend is configured.
"""

from __future__ import annotations

import base64
import io
from collections.abc import Mapping, Sequence

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from numpy.typing import ArrayLike

__all__ = [
    "COLORS",
    "MAX_POINTS",
    "figure_png",
    "fixed_margins",
    "joint_grid",
    "pair_grid",
    "plot_friction",
    "plot_method_rms",
    "plot_prediction_error",
    "plot_residuals",
    "plot_torque",
    "png_base64",
    "thin",
    "tidy_grid",
]

COLORS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2", "#17becf")
"""Colours of the models, in order (the measured torque is black)."""
MAX_POINTS = 4000
"""Most points drawn per line (longer signals are strided: a figure, not the data)."""


def thin(n: int, limit: int = MAX_POINTS) -> slice:
    """A stride that keeps at most ``limit`` of ``n`` samples.

    Parameters
    ----------
    n : int
        Samples.
    limit : int
        Most samples kept.
    """
    return slice(None, None, max(1, int(np.ceil(n / limit))))


def fixed_margins(
    fig: Figure,
    nrows: int,
    ncols: int,
    *,
    left: float = 0.85,
    right: float = 0.2,
    top: float = 0.65,
    bottom: float = 0.5,
    hspace: float = 0.45,
    wspace: float = 0.9,
) -> None:
    """Place a figure's grid of panels with margins and gaps given in inches (no layout engine).

    A fixed placement instead of matplotlib's constrained layout, which measures every tick label at each
    draw (about half of a validation report's time); the margins are the constrained layout's on dynid's
    report figures, to a few hundredths of an inch.

    Parameters
    ----------
    fig : Figure
        The figure, its panels made (``fig.subplots``).
    nrows, ncols : int
        The grid of panels.
    left, right, top, bottom : float
        Margins (inches) from the figure's edges to the grid.
    hspace, wspace : float
        Gaps (inches) between rows and between columns of panels.
    """
    w, h = fig.get_size_inches()
    avail_h = max(h - top - bottom, 0.1)
    avail_w = max(w - left - right, 0.1)
    ax_h = max((avail_h - (nrows - 1) * hspace) / nrows, 0.05)
    ax_w = max((avail_w - (ncols - 1) * wspace) / ncols, 0.05)
    fig.subplots_adjust(
        left=left / w, right=1 - right / w, bottom=bottom / h, top=1 - top / h,
        hspace=hspace / ax_h, wspace=wspace / ax_w,
    )  # fmt: skip


def joint_grid(
    n: int,
    *,
    ncols: int | None = None,
    height: float = 2.3,
    width: float = 11.0,
    sharex: bool = True,
    fixed: dict | None = None,
) -> tuple[Figure, list[Axes]]:
    """A figure with one panel per joint, in rows of ``ncols``.

    Parameters
    ----------
    n : int
        Joints.
    ncols : int, optional
        Panels per row (default 2, 1 for a single joint).
    height : float
        Height of a row (inches).
    width : float
        Width of the figure (inches).
    sharex : bool
        Share the x axis between panels.
    fixed : dict, optional
        Margins for :func:`fixed_margins` (inches) instead of the constrained layout.

    Returns
    -------
    (Figure, list of Axes)
        The figure and its ``n`` axes, joint 1 first; spare panels are removed.
    """
    ncols = ncols or (1 if n == 1 else 2)
    nrows = int(np.ceil(n / ncols))
    fig = Figure(figsize=(width, height * nrows + 0.6), layout=None if fixed is not None else "constrained")
    axes = fig.subplots(nrows, ncols, sharex=sharex, squeeze=False)
    if fixed is not None:
        fixed_margins(fig, nrows, ncols, **fixed)
    flat = list(axes.ravel())
    for ax in flat[n:]:
        ax.remove()
    for ax in flat[:n]:
        ax.grid(True, alpha=0.3, linewidth=0.6)
    return fig, flat[:n]


def pair_grid(
    n: int,
    *,
    height: float = 2.0,
    width: float = 11.0,
    width_ratios: tuple[float, float] = (3.0, 2.0),
    fixed: dict | None = None,
) -> tuple[Figure, list[tuple[Axes, Axes]]]:
    """A figure with one row per joint and two panels in each: a signal and, beside it, its error.

    Parameters
    ----------
    n : int
        Joints.
    height : float
        Height of a row (inches).
    width : float
        Width of the figure (inches).
    width_ratios : (float, float)
        Widths of the left and right panels, relative.
    fixed : dict, optional
        Margins for :func:`fixed_margins` (inches) instead of the constrained layout.

    Returns
    -------
    (Figure, list of (Axes, Axes))
        The figure and each joint's (left, right) panels, joint 1 first; every panel shares the time axis.
        Call :func:`tidy_grid` on the left and on the right panels (``ncols=1``) after drawing.
    """
    fig = Figure(figsize=(width, height * n + 0.6), layout=None if fixed is not None else "constrained")
    axes = fig.subplots(n, 2, sharex=True, squeeze=False, gridspec_kw={"width_ratios": list(width_ratios)})
    if fixed is not None:
        fixed_margins(fig, n, 2, **fixed)
    for ax in axes.ravel():
        ax.grid(True, alpha=0.3, linewidth=0.6)
    return fig, [(axes[j, 0], axes[j, 1]) for j in range(n)]


def tidy_grid(axes: Sequence[Axes], ncols: int | None = None) -> None:
    """After drawing: x labels on the lowest panel of each column only, its tick labels shown.

    Parameters
    ----------
    axes : sequence of Axes
        The panels of :func:`joint_grid`, joint 1 first.
    ncols : int, optional
        Panels per row, as given to :func:`joint_grid`.
    """
    n = len(axes)
    ncols = ncols or (1 if n == 1 else 2)
    for k, ax in enumerate(axes):
        if k + ncols < n:
            ax.set_xlabel("")
        else:
            ax.tick_params(labelbottom=True)


def plot_torque(
    ax: Axes,
    t: ArrayLike,
    tau: ArrayLike,
    predictions: Mapping[str, ArrayLike],
    *,
    joint: int,
    unit: str = "N m",
) -> Axes:
    """Measured against predicted torque of one joint over time.

    Parameters
    ----------
    ax : Axes
        Where to draw.
    t : array_like, shape (m,)
        Time (s).
    tau : array_like, shape (m,)
        Measured torque as compared.
    predictions : mapping of str to array_like, shape (m,)
        Predicted torque of each model, by label.
    joint : int
        Joint number (from 1), for the title.
    unit : str
        Torque unit.

    Returns
    -------
    Axes
    """
    t, tau = np.asarray(t, float), np.asarray(tau, float)
    s = thin(t.size)
    ax.plot(t[s], tau[s], color="black", linewidth=2.4, alpha=0.35, label="measured")
    for k, (label, pred) in enumerate(predictions.items()):
        ax.plot(
            t[s],
            np.asarray(pred, float)[s],
            color=COLORS[k % len(COLORS)],
            linewidth=0.9,
            label=label,
            alpha=0.9,
        )
    ax.set_title(f"joint {joint}", fontsize=10, loc="left")
    ax.set_xlabel("time (s)")
    ax.set_ylabel(f"torque ({unit})")
    return ax


def plot_prediction_error(
    ax: Axes,
    t: ArrayLike,
    tau: ArrayLike,
    predictions: Mapping[str, ArrayLike],
    *,
    joint: int,
    noise: float | None = None,
    unit: str = "N m",
) -> Axes:
    """Measured minus predicted torque of one joint over time, model by model: what :func:`plot_torque`
    cannot show when the lines lie on each other.

    Parameters
    ----------
    ax : Axes
        Where to draw.
    t : array_like, shape (m,)
        Time (s).
    tau : array_like, shape (m,)
        Measured torque as compared.
    predictions : mapping of str to array_like, shape (m,)
        Predicted torque of each model, by label (the colours of :func:`plot_torque`, in this order).
    joint : int
        Joint number (from 1), for the title.
    noise : float, optional
        Noise floor (standard deviation), drawn as a +-1 sigma band.
    unit : str
        Torque unit.

    Returns
    -------
    Axes
    """
    t, tau = np.asarray(t, float), np.asarray(tau, float)
    s = thin(t.size)
    items = list(predictions.items())
    rms = []
    # the first model (the one validated) last, on top of the others
    for k in reversed(range(len(items))):
        label, pred = items[k]
        error = tau - np.asarray(pred, float)
        rms.append((k, label, float(np.sqrt(np.mean(error**2))) if error.size else float("nan")))
        ax.plot(
            t[s],
            error[s],
            color=COLORS[k % len(COLORS)],
            linewidth=0.9 if k == 0 else 0.7,
            alpha=0.95 if k == 0 else 0.75,
            label=label,
            zorder=3 if k == 0 else 2,
        )
    if noise is not None and np.isfinite(noise):
        ax.axhspan(
            -noise, noise, color="0.5", alpha=0.22, linewidth=0, label="noise floor (+-1 std)", zorder=1
        )
    ax.axhline(0.0, color="black", linewidth=0.5)
    first = min(rms, key=lambda item: item[0]) if rms else None
    title = f"joint {joint}: measured - predicted"
    if first is not None:
        title += f" (rms {first[2]:.3g} {unit}, {first[1]})"
    ax.set_title(title, fontsize=9, loc="left")
    ax.set_xlabel("time (s)")
    ax.set_ylabel(f"residual ({unit})")
    return ax


def plot_residuals(
    ax: Axes,
    t: ArrayLike,
    before: ArrayLike,
    after: ArrayLike | None,
    *,
    joint: int,
    noise: float | None = None,
    unit: str = "N m",
) -> Axes:
    """Residual of one joint before and after the GMM layer, against the noise floor.

    Parameters
    ----------
    ax : Axes
        Where to draw.
    t : array_like, shape (m,)
        Time (s).
    before : array_like, shape (m,)
        Residual of the link and friction layers.
    after : array_like, shape (m,), optional
        Residual of the whole model (None: the model has no GMM layer).
    joint : int
        Joint number (from 1).
    noise : float, optional
        Noise floor (standard deviation) drawn as a +-1 sigma band.
    unit : str
        Torque unit.

    Returns
    -------
    Axes
    """
    t, before = np.asarray(t, float), np.asarray(before, float)
    s = thin(t.size)
    rms_b = float(np.sqrt(np.mean(before**2)))
    ax.plot(t[s], before[s], color=COLORS[1], linewidth=0.8, alpha=0.7, label="before GMM")
    title = f"joint {joint}: rms {rms_b:.3g}"
    if after is not None:
        after = np.asarray(after, float)
        rms_a = float(np.sqrt(np.mean(after**2)))
        ax.plot(t[s], after[s], color=COLORS[0], linewidth=0.8, label="after GMM")
        title += f" before, {rms_a:.3g} after GMM"
    if noise is not None and np.isfinite(noise):
        ax.axhspan(-noise, noise, color=COLORS[2], alpha=0.25, linewidth=0, label="noise floor (+-1 std)")
        title += f"; noise {noise:.3g} {unit}"
    ax.axhline(0.0, color="black", linewidth=0.5)
    ax.set_title(title, fontsize=9, loc="left")
    ax.set_xlabel("time (s)")
    ax.set_ylabel(f"residual ({unit})")
    return ax


def plot_friction(
    ax: Axes,
    dq: ArrayLike,
    friction: ArrayLike,
    curves: Mapping[str, tuple[ArrayLike, ArrayLike]],
    *,
    joint: int,
    unit: str = "N m",
    speed_unit: str = "rad/s",
    max_points: int = 3000,
) -> Axes:
    """Friction torque against velocity (the paper's figure 6): the data and the fitted models.

    Parameters
    ----------
    ax : Axes
        Where to draw.
    dq : array_like, shape (m,)
        Joint velocity.
    friction : array_like, shape (m,)
        Friction torque the data show (measured torque minus the rigid-body prediction).
    curves : mapping of str to (v, F)
        Each model's friction law sampled on velocities ``v``.
    joint : int
        Joint number (from 1).
    unit, speed_unit : str
        Units of the axes.
    max_points : int
        Most data points drawn.

    Returns
    -------
    Axes
    """
    dq, friction = np.asarray(dq, float), np.asarray(friction, float)
    s = thin(dq.size, max_points)
    ax.scatter(dq[s], friction[s], s=3, color="0.45", alpha=0.35, linewidths=0, label="data", rasterized=True)
    lo, hi = np.percentile(friction, [0.5, 99.5]) if friction.size else (0.0, 1.0)
    span = max(hi - lo, 1e-12)
    for k, (label, (v, f)) in enumerate(curves.items()):
        f = np.asarray(f, float)
        ax.plot(np.asarray(v, float), f, color=COLORS[k % len(COLORS)], linewidth=1.6, label=label)
        if f.size:  # show the curves too, but never let one far off squash the data
            lo = max(min(lo, float(f.min())), lo - span)
            hi = min(max(hi, float(f.max())), hi + span)
    ax.axhline(0.0, color="black", linewidth=0.5)
    ax.axvline(0.0, color="black", linewidth=0.5)
    pad = 0.08 * max(hi - lo, 1e-12)
    ax.set_ylim(lo - pad, hi + pad)
    ax.set_title(f"joint {joint}", fontsize=10, loc="left")
    ax.set_xlabel(f"velocity ({speed_unit})")
    ax.set_ylabel(f"friction ({unit})")
    return ax


def plot_method_rms(
    ax: Axes,
    labels: Sequence[str],
    rms: ArrayLike,
    *,
    noise: ArrayLike | None = None,
    unit: str = "N m",
    log: bool = True,
) -> Axes:
    """Held-out RMS per joint of several models, side by side, with the noise floor.

    Parameters
    ----------
    ax : Axes
        Where to draw.
    labels : sequence of str
        Model names.
    rms : array_like, shape (k, n)
        RMS per model and joint.
    noise : array_like, shape (n,), optional
        Noise floor per joint (drawn as a short black bar).
    unit : str
        Torque unit.
    log : bool
        Logarithmic y axis (joints differ by orders of magnitude).

    Returns
    -------
    Axes
    """
    rms = np.atleast_2d(np.asarray(rms, float))
    k, n = rms.shape
    width = 0.8 / max(k, 1)
    x = np.arange(1, n + 1)
    for i, label in enumerate(labels):
        ax.bar(x + (i - (k - 1) / 2) * width, rms[i], width=width, color=COLORS[i % len(COLORS)], label=label)
    if noise is not None:
        noise = np.asarray(noise, float)
        ax.hlines(noise, x - 0.45, x + 0.45, colors="black", linewidth=2.0, label="noise floor")
    ax.set_xticks(x, [f"joint {j}" for j in x])
    ax.set_ylabel(f"held-out RMS ({unit})")
    if log:
        ax.set_yscale("log")
    ax.grid(True, axis="y", alpha=0.3, which="both", linewidth=0.6)
    ax.set_axisbelow(True)
    return ax


def figure_png(fig: Figure, *, dpi: int = 110) -> bytes:
    """The figure as PNG bytes.

    Parameters
    ----------
    fig : Figure
        The figure.
    dpi : int
        Resolution.
    """
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    return buf.getvalue()


def png_base64(png: bytes) -> str:
    """``data:image/png;base64,...`` URI of PNG bytes (for an ``<img src>``).

    Parameters
    ----------
    png : bytes
        PNG file content.
    """
    return "data:image/png;base64," + base64.b64encode(png).decode("ascii")
