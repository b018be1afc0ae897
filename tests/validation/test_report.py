"""Tests of the HTML report, its figures and the PDF."""

from __future__ import annotations

import base64
import json
import math
import re
import struct
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest
from matplotlib.figure import Figure

from dynid.cli import main
from dynid.data.files import load_dataset
from dynid.exceptions import UsageError
from dynid.identify.model import load_model
from dynid.validation import plots
from dynid.validation.report import (
    NEAR_ZERO_SPEED,
    _near_zero_speed_note,
    check_report_path,
    format_number,
    gmm_changed,
    held_at_bound,
    render_report,
)
from dynid.validation.validate import nominal_model, validate
from tests.validation.cases import simulated_case

VOID = {"meta", "img", "br", "hr", "link", "input", "col", "source", "area", "base", "wbr"}
FIGURES = ("methods", "torque", "friction")
"""The figures of every report; ``residual`` (before and after the GMM layer) only where the mixture changed the
prediction."""


class Document(HTMLParser):
    """Checks that tags nest and close; collects images, cells with numbers, ids and the embedded JSON."""

    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.stack: list[str] = []
        self.errors: list[str] = []
        self.seen: list[str] = []
        self.images: list[str] = []
        self.ids: set[str] = set()
        self.cells: list[dict] = []
        self.scripts: dict[str, str] = {}
        self._cell: dict | None = None
        self._script: str | None = None
        self.doctype = None

    def handle_decl(self, decl):
        self.doctype = decl

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        self.seen.append(tag)
        if "id" in attrs:
            if attrs["id"] in self.ids:
                self.errors.append(f"duplicate id {attrs['id']}")
            self.ids.add(attrs["id"])
        if tag == "img":
            self.images.append(attrs.get("src", ""))
        if tag == "td" and "data-key" in attrs:
            self._cell = {**attrs, "text": ""}
        if tag == "script":
            self._script = attrs.get("id", "")
            self.scripts[self._script] = ""
        if tag not in VOID:
            self.stack.append(tag)

    def handle_endtag(self, tag):
        if tag in VOID:
            return
        if not self.stack or self.stack[-1] != tag:
            self.errors.append(f"</{tag}> closes <{self.stack[-1] if self.stack else None}>")
            return
        self.stack.pop()
        if tag == "td" and self._cell is not None:
            self.cells.append(self._cell)
            self._cell = None
        if tag == "script":
            self._script = None

    def handle_data(self, data):
        if self._cell is not None:
            self._cell["text"] += data
        if self._script is not None:
            self.scripts[self._script] += data


def parse(text: str) -> Document:
    doc = Document()
    doc.feed(text)
    doc.close()
    assert doc.doctype and doc.doctype.lower() == "doctype html"
    assert not doc.errors, doc.errors[:5]
    assert not doc.stack, f"unclosed tags: {doc.stack}"
    assert doc.seen[:3] == ["html", "head", "meta"]
    assert {"title", "body", "h1", "table", "figure"} <= set(doc.seen)
    return doc


def png_size(uri: str) -> tuple[int, int]:
    prefix = "data:image/png;base64,"
    assert uri.startswith(prefix)
    png = base64.b64decode(uri[len(prefix) :], validate=True)
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    return struct.unpack(">II", png[16:24])


def value_at(figures: dict, key: str, joint: str | None):
    node = figures
    for part in key.split("."):
        node = node[int(part)] if isinstance(node, list) else node[part]
    return node if joint is None else node[int(joint) - 1]


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    return simulated_case(tmp_path_factory.getbasetemp())


@pytest.fixture(scope="module")
def command_outputs(case, tmp_path_factory):
    """``dynid validate`` with a report, run once."""
    out = tmp_path_factory.mktemp("report")
    argv = ["validate", "--model", str(case.full), "--compare", str(case.ols), "--data", str(case.heldout)]
    argv += ["--report", str(out / "R.html"), "--json", str(out / "F.json")]
    assert main(argv) == 0
    return (out / "R.html").read_text(encoding="utf-8"), json.loads((out / "F.json").read_text()), out


def _figures_of(case) -> tuple[str, ...]:
    """The figures a report of the case's full model has: ``residual`` only if its mixture changed something."""
    full = validate(load_model(case.full), load_dataset(case.heldout))
    return FIGURES + (("residual",) if gmm_changed([full]) is not None else ())


def test_report_is_valid_html_with_every_figure_embedded(command_outputs, case):
    text, _, out = command_outputs
    doc = parse(text)
    expected = _figures_of(case)
    assert len(doc.images) == len(expected)
    for uri in doc.images:
        width, height = png_size(uri)
        assert width >= 800 and height >= 300
    assert {f"figure-{key}" for key in expected} <= doc.ids
    for section in (
        "error",
        "methods",
        "torque",
        "residual",
        "friction",
        "conditions",
        "parameters",
        "consistent",
    ):
        assert f"section-{section}" in doc.ids, section
    # self-contained: nothing fetched from elsewhere
    assert not re.search(r"""(src|href)=["'](https?:|//|file:)""", text)
    assert sorted(p.name for p in out.iterdir()) == ["F.json", "R.html"]  # no temporary file left


def test_report_numbers_equal_the_json(command_outputs):
    text, figures, _ = command_outputs
    doc = parse(text)
    embedded = json.loads(doc.scripts["dynid-figures"])
    assert embedded == figures
    keys = {cell["data-key"] for cell in doc.cells}
    assert {"rms", "nrms", "r2", "max_error", "noise_floor", "rms_mean", "models.1.rms"} <= keys
    checked = 0
    for cell in doc.cells:
        expected = value_at(figures, cell["data-key"], cell.get("data-joint"))
        if expected is None:
            assert "data-value" not in cell and cell["text"] == "-"
            continue
        assert float(cell["data-value"]) == expected  # exact: repr round-trips a float
        assert cell["text"] == format_number(expected)
        checked += 1
    n = len(figures["rms"])
    assert checked >= 6 * n + 2 + 2 * (n + 3) - 2  # the metrics and methods tables, nothing skipped silently


def test_report_shows_the_physically_consistent_links(command_outputs):
    text, figures, _ = command_outputs
    assert figures["method"] == "consistent"
    table = re.search(r'<table id="consistent">(.*?)</table>', text, flags=re.S)
    assert table is not None
    rows = re.findall(r"<tr><td class=\"text\">link (\d)</td>", table.group(1))
    assert rows == [str(j) for j in range(1, 7)]
    masses = [
        float(v)
        for v in re.findall(r'<tr><td class="text">link \d</td><td data-value="([^"]+)"', table.group(1))
    ]
    assert all(m > 0 for m in masses)


def test_report_without_gmm_or_consistent_fit_says_so(case, tmp_path):
    ols = validate(load_model(case.ols), load_dataset(case.heldout), label="OLS")
    report = render_report([ols])
    doc = parse(report.html)
    assert len(doc.images) == len(FIGURES)
    assert "no model here has a GMM layer" in report.html
    assert "No model here carries physically consistent link parameters" in report.html
    # the RMS without the samples near zero speed, the gap diagnosis's figure for this model, is named
    moving = np.abs(ols.dq) >= NEAR_ZERO_SPEED * np.abs(ols.dq).max(axis=0)
    rms = np.sqrt(np.sum(np.where(moving, ols.residual**2, 0.0), axis=0) / moving.sum(axis=0))
    assert f"the RMS of &#x27;OLS&#x27; is joint 1 {format_number(rms[0])}, " in report.html
    path = report.write(tmp_path / "ols.html")
    assert path.read_text(encoding="utf-8") == report.html


def test_pdf_report(case, tmp_path):
    result = validate(load_model(case.full), load_dataset(case.heldout))
    report = render_report([result], pdf=True)
    path = report.write(tmp_path / "R.pdf")
    data = path.read_bytes()
    assert data.startswith(b"%PDF") and data.rstrip().endswith(b"%%EOF")
    # a table page, then the figures
    assert len(re.findall(rb"/Type\s*/Page\b", data)) == 1 + len(report.figures) == 1 + len(_figures_of(case))


@pytest.mark.parametrize(
    ("name", "message"),
    [
        ("missing/R.html", r"the folder '.*missing' of the report does not exist; create it"),
        ("R.png", r"has the extension '.png'; give a file name ending in .html or .htm or .pdf"),
    ],
)
def test_report_path_errors(tmp_path, name, message):
    with pytest.raises(UsageError, match=message):
        check_report_path(tmp_path / name)


def test_html_report_cannot_be_written_as_pdf_unless_rendered_so(case, tmp_path):
    report = render_report([validate(load_model(case.ols), load_dataset(case.heldout))])
    with pytest.raises(
        UsageError, match=r"has the extension '\.pdf'; give a file name ending in \.html or \.htm\."
    ):
        report.write(tmp_path / "R.pdf")
    assert not list(tmp_path.iterdir())


def test_the_error_figure_without_the_samples_near_zero_speed_is_named():
    """The RMS counts every sample; the note names the samples near zero speed, why they spike (Coulomb friction's
    sign change) and the RMS without them (the gap diagnosis's figure)."""
    from types import SimpleNamespace

    t = np.linspace(0.0, 10.0, 1001)
    dq = np.column_stack([np.sin(t), 2.0 * np.cos(t)])
    residual = np.full_like(dq, 0.1)
    still = np.abs(dq) < NEAR_ZERO_SPEED * np.abs(dq).max(axis=0)
    assert still.any(axis=0).all()
    residual[still] = 5.0  # a spike at every velocity reversal
    result = SimpleNamespace(residual=residual, dq=dq, n=2, label="fit")
    note = _near_zero_speed_note(result)
    # every sample: far above 0.1; without the samples near zero speed: exactly 0.1
    assert np.all(np.sqrt(np.mean(residual**2, axis=0)) > 0.5)
    assert "the RMS of &#x27;fit&#x27; is joint 1 0.1, joint 2 0.1 N m" in note
    share = 100.0 * still.mean(axis=0)
    assert f"({format_number(share.min(), 2)}-{format_number(share.max(), 2)} % of the samples here" in note
    assert "Coulomb friction changes sign" in note and "dynid diagnose" in note
    assert _near_zero_speed_note(SimpleNamespace(residual=np.zeros((0, 2)), dq=np.zeros((0, 2)), n=2)) == ""


def test_format_number():
    assert format_number(0.000123456) == "0.0001235"
    assert format_number(None) == format_number(math.nan) == "-"
    assert format_number(math.inf) == "inf"
    assert format_number(12345.678) == "1.235e+04"


# ---------------------------------------------------------------------------- plot functions
@pytest.fixture
def no_show(monkeypatch):
    import matplotlib.pyplot as plt

    def show(*args, **kwargs):
        raise AssertionError("plot functions must never call plt.show()")

    monkeypatch.setattr(plt, "show", show)


def test_plot_functions_draw_on_the_axes_they_are_given(no_show):
    t = np.linspace(0, 2, 500)
    tau = np.sin(t)
    fig = Figure()
    ax = fig.subplots()
    assert plots.plot_torque(ax, t, tau, {"a": tau + 0.1, "b": tau - 0.1}, joint=2) is ax
    assert ax.get_xlabel() == "time (s)" and ax.get_ylabel() == "torque (N m)"
    assert [line.get_label() for line in ax.get_lines()] == ["measured", "a", "b"]
    assert ax.get_title(loc="left") == "joint 2"

    ax = Figure().subplots()
    plots.plot_residuals(ax, t, tau, 0.5 * tau, joint=1, noise=0.1)
    assert ax.get_ylabel() == "residual (N m)"
    assert "noise 0.1 N m" in ax.get_title(loc="left")

    ax = Figure().subplots()
    v = np.linspace(-1, 1, 50)
    plots.plot_friction(ax, t - 1, np.sign(t - 1), {"seed": (v, np.sign(v))}, joint=3)
    assert ax.get_xlabel() == "velocity (rad/s)" and ax.get_ylabel() == "friction (N m)"

    ax = Figure().subplots()
    plots.plot_method_rms(ax, ["a", "b"], [[1.0, 2.0], [0.5, 0.1]], noise=[0.05, 0.05])
    assert ax.get_ylabel() == "held-out RMS (N m)" and ax.get_yscale() == "log"
    assert len(ax.patches) == 4


def test_joint_grid_has_one_panel_per_joint():
    fig, axes = plots.joint_grid(7)
    assert len(axes) == 7 and len(fig.axes) == 7
    for ax in axes:
        ax.set_xlabel("time (s)")
    plots.tidy_grid(axes)
    # x labels only where no panel sits below: joints 6 and 7
    assert [ax.get_xlabel() for ax in axes] == [""] * 5 + ["time (s)"] * 2
    png = plots.figure_png(fig)
    assert png[:4] == b"\x89PNG"
    assert plots.thin(10_000, 4000) == slice(None, None, 3)


def test_report_figures_written_as_png_files(case, tmp_path):
    """The figures a person looks at: written as files so they can be opened (and were, while writing)."""
    result = validate(load_model(case.full), load_dataset(case.heldout), label="full")
    report = render_report([result])
    for fig in report.figures:
        (tmp_path / f"{fig.key}.png").write_bytes(fig.png)
    assert sorted(p.stem for p in Path(tmp_path).glob("*.png")) == sorted(_figures_of(case))


# ---------------------------------------------------------------------------- what the figures say
@pytest.fixture(scope="module")
def bump_case(ur5):
    """A UR5 with a smooth position-dependent torque the physical layers cannot take: a mixture that helps."""
    from dynid.identify.columns import column_set
    from dynid.identify.model import identify
    from dynid.sim.synthetic import random_fourier, synthetic_dataset, true_parameters

    rng = np.random.default_rng(5)
    cols = column_set(ur5)
    x = true_parameters(cols, rng)

    def bump(q, dq):
        return 1.5 * np.sin(2.0 * q)

    traj = random_fourier(
        ur5, rng, periods=2
    )  # held out: another record of the same motion (the mixture's range)
    train, heldout = (
        synthetic_dataset(cols, x, traj, rate=100, rng=rng, noise=0.02, extra=bump) for _ in range(2)
    )
    model = identify(ur5, train, method="ols", friction="linear", gmm=3, rounds=0)
    assert model.gmr.active_.any(), "the mixture should take the sin(2 q) torque"
    return model, train, heldout


def test_a_residual_panel_sits_beside_every_torque_panel(no_show):
    t = np.linspace(0, 2, 500)
    tau = np.sin(t)
    fig, pairs = plots.pair_grid(3)
    assert len(pairs) == 3 and len(fig.axes) == 6
    for j, (left, right) in enumerate(pairs):
        plots.plot_torque(left, t, tau, {"a": tau + 0.1, "b": tau - 0.2}, joint=j + 1)
        assert (
            plots.plot_prediction_error(
                right, t, tau, {"a": tau + 0.1, "b": tau - 0.2}, joint=j + 1, noise=0.05
            )
            is right
        )
        # the residual beside the torque: same row, to its right, the same time axis
        assert right.get_position().y0 == pytest.approx(left.get_position().y0)
        assert right.get_position().x0 > left.get_position().x1
        assert right.get_shared_x_axes().joined(left, right)
    ax = pairs[0][1]
    lines = {
        line.get_label(): line.get_ydata() for line in ax.get_lines() if not line.get_label().startswith("_")
    }
    np.testing.assert_allclose(lines["a"], -0.1)  # measured minus predicted
    np.testing.assert_allclose(lines["b"], 0.2)
    assert ax.get_ylabel() == "residual (N m)"
    assert ax.get_title(loc="left") == "joint 1: measured - predicted (rms 0.1 N m, a)"


def test_the_gmm_figure_only_where_the_mixture_changed_the_prediction(bump_case, case):
    import copy
    from dataclasses import replace

    model, _, heldout = bump_case
    changed = validate(model, heldout, label="with GMM")
    report = render_report([changed])
    assert [f.key for f in report.figures] == ["methods", "torque", "residual", "friction"]
    assert "figure-residual" in parse(report.html).ids
    # the same model with a mixture that corrects no joint: its residual after the layer is the one before
    gmr = copy.deepcopy(model.gmr)
    gmr.active_ = np.zeros_like(gmr.active_)
    idle = validate(replace(model, gmr=gmr), heldout, label="idle GMM")
    assert gmm_changed([idle]) is None and gmm_changed([idle, changed]) is changed
    report = render_report([idle])
    assert [f.key for f in report.figures] == list(FIGURES)
    doc = parse(report.html)
    assert "figure-residual" not in doc.ids and "section-residual" in doc.ids
    assert "The GMM layer of &#x27;idle GMM&#x27; changed nothing on these data" in report.html


def test_the_condition_caption_names_only_rows_that_are_there(bump_case, ur5):
    model, train, heldout = bump_case
    alone = render_report([validate(model, heldout, label="fit")]).html
    caption = re.search(r'<h2 id="section-conditions">.*?<p class="note">(.*?)</p>', alone, flags=re.S).group(
        1
    )
    assert "URDF" not in caption and "baseline" not in caption
    baseline = validate(nominal_model(ur5, train), heldout, label="URDF")
    both = render_report([validate(model, heldout, label="fit"), baseline]).html
    caption = re.search(r'<h2 id="section-conditions">.*?<p class="note">(.*?)</p>', both, flags=re.S).group(
        1
    )
    assert "&#x27;URDF&#x27; estimated no rigid-body parameter" in caption
    table = re.search(r'<table id="conditions">(.*?)</table>', both, flags=re.S).group(1)
    assert re.search(r'<td class="text">URDF</td><td>-</td>', table)


def test_parameters_held_at_a_bound_are_shown_so(bump_case):
    from dataclasses import replace

    model, _, heldout = bump_case
    names = list(model.columns.names)
    k = names.index("fv3")
    params = model.params.copy()
    params[k] = 1e-6 * model.std[k]  # where an interior-point fit stops: just inside the bound 0
    held = replace(model, params=params, info={**model.info, "bounds": {"physical": True, "active": ["fc2"]}})
    # the fit's own: the bounded solve leaves armatures the data push below 0 at ~1e-11, not exactly at 0
    before = {names[i] for i in np.flatnonzero(held_at_bound(model))}
    assert before and all(model.params[names.index(b)] < 1e-9 for b in before)
    assert not before & {"fc2", "fv3"}
    at = held_at_bound(held)
    assert {names[i] for i in np.flatnonzero(at)} == before | {"fc2", "fv3"}
    near = params.copy()
    near[k] = 0.01 * model.std[k]  # a hundredth of a standard deviation from it: the data's value
    assert not held_at_bound(replace(held, params=near))[k]
    text = render_report([validate(held, heldout, label="held")]).html
    table = re.search(r'<table id="parameters">(.*?)</table>', text, flags=re.S).group(1)
    for name in ("fc2", "fv3"):
        row = re.search(rf'<tr><td class="text">{name}</td>.*?</tr>', table).group(0)
        assert row.endswith('<td class="at-bound" style="white-space: nowrap">at bound</td></tr>')
    assert re.search(r"Held at their lower bound \(0\) by the physical constraints: (ia\d, )*fc2, fv3;", text)
    assert text.count(">at bound<") == len(before) + 2
    # the model as fitted: the parameters its bounds hold are the ones shown so
    text = render_report([validate(model, heldout, label="fit")]).html
    assert text.count(">at bound<") == len(before)
