"""The pieces every dynid HTML report is made of: page, style, tables, numbers, figures, the file check.

Both reports (the validation report, :mod:`dynid.validation.report`, and the gap diagnosis',
:mod:`dynid.diagnosis.report`) are one self-contained file built from these, so they look alike and
show numbers alike:

>>> body = [heading("Results", "section-results"), html_table(["joint", "RMS (N m)"], [["1", 0.0123]])]
>>> text = html_page("Validation of M on V", body)

* :func:`format_number`: ``digits`` significant digits; ``-`` for a missing value, integers in full;
* :func:`html_table`: the first columns text, the others numbers, each number with its exact value
  in a ``data-value`` attribute, so a program can read the report;
* :func:`figure_html`: a PNG embedded as base64 with its caption;
* :func:`json_script`: figures embedded as JSON for a program to read back;
* :func:`check_report_path`: where a report may be written, checked before any work.
"""

from __future__ import annotations

import html
import math
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from dynid._io import dumps_json
from dynid.exceptions import UsageError

__all__ = [
    "CSS",
    "check_report_path",
    "figure_html",
    "format_number",
    "heading",
    "html_page",
    "html_table",
    "json_script",
    "table_cell",
]

CSS = """
body { font-family: -apple-system, "Segoe UI", Helvetica, Arial, sans-serif; margin: 2em auto; max-width: 1150px;
       color: #222; line-height: 1.4; padding: 0 1em; }
h1 { font-size: 1.6em; margin-bottom: 0.2em; }
h2 { font-size: 1.25em; margin-top: 1.8em; border-bottom: 1px solid #ccc; padding-bottom: 0.2em; }
h3 { font-size: 1.05em; margin: 0.4em 0; }
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
.verdict { font-size: 1.15em; padding: 0.6em 1em; background: #f6f8fa; border-left: 4px solid #1f77b4; }
code { background: #f5f5f5; padding: 0 0.2em; }
"""
"""The one style sheet of dynid's reports."""


def format_number(value: Any, digits: int = 4) -> str:
    """A number as a report shows it: ``digits`` significant digits, ``-`` for a missing value.

    Integers (not floats that happen to be whole) are shown in full.

    Parameters
    ----------
    value : float, int or None
        The number; None and NaN are missing.
    digits : int
        Significant digits.
    """
    if value is None:
        return "-"
    if isinstance(value, int | np.integer) and not isinstance(value, bool | np.bool_):
        return str(int(value))
    v = float(value)
    if math.isnan(v):
        return "-"
    if math.isinf(v):
        return "inf" if v > 0 else "-inf"
    return f"{v:.{digits}g}"


def table_cell(
    value: Any,
    *,
    key: str | None = None,
    joint: int | None = None,
    text: bool = False,
    digits: int = 4,
) -> str:
    """One ``<td>``: text (escaped) or a number with its exact value in ``data-value``.

    Parameters
    ----------
    value : Any
        The number (or None), or the text.
    key : str, optional
        The figure's name in the report's JSON, as ``data-key``.
    joint : int, optional
        The joint (1-based), as ``data-joint``.
    text : bool
        Show ``value`` as text (also done for any string).
    digits : int
        Significant digits of a number.
    """
    if text or isinstance(value, str):
        return f'<td class="text">{html.escape(str(value))}</td>'
    attrs = []
    if key is not None:
        attrs.append(f'data-key="{html.escape(key)}"')
    if joint is not None:
        attrs.append(f'data-joint="{joint}"')
    if value is not None and not (isinstance(value, float | np.floating) and math.isnan(value)):
        attrs.append(f'data-value="{float(value)!r}"')
    shown = format_number(value, digits)
    return f"<td {' '.join(attrs)}>{shown}</td>" if attrs else f"<td>{shown}</td>"


def html_table(
    headers: Sequence[str] | None,
    rows: Sequence[Sequence[Any]],
    *,
    table_id: str | None = None,
    text_columns: int = 1,
    digits: int = 4,
) -> str:
    """An HTML table; the first ``text_columns`` columns are text, the others numbers.

    A cell may also be given ready-made as a string starting with ``<td`` (see :func:`table_cell`).
    A string in a number column is shown as text.

    Parameters
    ----------
    headers : sequence of str or None
        Column titles; None for a table without a header row.
    rows : sequence of sequence
        Cells.
    table_id : str, optional
        The table's ``id``.
    text_columns : int
        Leading columns shown as text.
    digits : int
        Significant digits of the numbers.
    """
    head = ""
    if headers is not None:
        titles = "".join(
            f'<th class="text">{html.escape(h)}</th>' if k < text_columns else f"<th>{html.escape(h)}</th>"
            for k, h in enumerate(headers)
        )
        head = f"<thead><tr>{titles}</tr></thead>"
    body = []
    for row in rows:
        cells = []
        for k, value in enumerate(row):
            if isinstance(value, str) and value.startswith("<td"):
                cells.append(value)
            else:
                cells.append(table_cell(value, text=k < text_columns, digits=digits))
        body.append("<tr>" + "".join(cells) + "</tr>")
    ident = f' id="{html.escape(table_id)}"' if table_id else ""
    return f"<table{ident}>{head}<tbody>{''.join(body)}</tbody></table>"


def heading(title: str, anchor: str | None = None, *, level: int = 2) -> str:
    """A section heading, with ``id`` ``anchor`` if given.

    Parameters
    ----------
    title : str
        The text (escaped here).
    anchor : str, optional
        The heading's ``id``.
    level : int
        2 for a section, 3 for a subsection.
    """
    ident = f' id="{html.escape(anchor)}"' if anchor else ""
    return f"<h{level}{ident}>{html.escape(title)}</h{level}>"


def figure_html(
    png: bytes, *, title: str, caption: str, figure_id: str | None = None, show_title: bool = False
) -> str:
    """A PNG embedded as base64 in a ``<figure>`` with its caption.

    Parameters
    ----------
    png : bytes
        The image.
    title : str
        Its title: the image's ``alt`` text, and a heading above it if ``show_title``.
    caption : str
        What it shows.
    figure_id : str, optional
        The figure's ``id``.
    show_title : bool
        Put the title above the image as an ``<h3>``.
    """
    from dynid.validation.plots import png_base64

    ident = f' id="{html.escape(figure_id)}"' if figure_id else ""
    top = heading(title, level=3) if show_title else ""
    return (
        f'<figure{ident}>{top}<img src="{png_base64(png)}" alt="{html.escape(title)}">'
        f"<figcaption>{html.escape(caption)}</figcaption></figure>"
    )


def json_script(value: Any, element_id: str) -> str:
    """``value`` as strict JSON in ``<script type="application/json">``, for a program to read back.

    Parameters
    ----------
    value : Any
        The figures (cleaned by :func:`dynid._io.to_jsonable`: NaN becomes null).
    element_id : str
        The script element's ``id``.
    """
    payload = dumps_json(value, indent=1).rstrip("\n").replace("</", "<\\/")
    return f'<script type="application/json" id="{html.escape(element_id)}">{payload}</script>'


def html_page(title: str, body: Sequence[str]) -> str:
    """A whole HTML document: the title as ``<title>`` and ``<h1>``, the style, then ``body``.

    Parameters
    ----------
    title : str
        The report's title (escaped here).
    body : sequence of str
        HTML fragments after the ``<h1>``, in order (escaped by the caller).
    """
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en">',
        "<head>",
        '<meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        f"<title>{html.escape(title)}</title>",
        f"<style>{CSS}</style>",
        "</head>",
        "<body>",
        f"<h1>{html.escape(title)}</h1>",
        *body,
        "</body>",
        "</html>",
    ]
    return "\n".join(parts) + "\n"


def check_report_path(path: str | os.PathLike[str], *, pdf: bool = True) -> Path:
    """Check that a report can be written at ``path`` (``.html``/``.htm``, or ``.pdf``; existing folder).

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
