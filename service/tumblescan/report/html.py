"""One self-contained HTML page per report: a title, sections of HTML, plotly's JavaScript
inlined from the installed package (so the file works offline) and a footer."""

from __future__ import annotations

import base64
import html
from collections.abc import Iterable, Sequence
from typing import Any

CSS = """
body { font-family: system-ui, sans-serif; margin: 1.5em auto; max-width: 1100px; color: #222; }
table { border-collapse: collapse; margin: 0.5em 0 1em; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.6em; text-align: left; font-variant-numeric: tabular-nums; }
th { background: #f3f3f3; }
.warn { color: #a40; } .ok { color: #070; } .bad { color: #b00; font-weight: bold; }
footer { margin-top: 2em; color: #777; font-size: 0.85em; }
.note { color: #555; font-size: 0.9em; }
figure { margin: 0.5em 0; } figure img { max-width: 100%; image-rendering: pixelated; }
.strip { display: flex; flex-wrap: wrap; gap: 6px; } .strip figure { width: 24%; margin: 0; }
"""

FOOTER = "Tumblescan report; 1-sigma from the covariance of the maximum-likelihood fit."


def page(title: str, sections: Iterable[str], *, footer: str = FOOTER, with_plotly: bool = True) -> str:
    """The whole document: ``sections`` are HTML fragments placed in order under the title."""
    script = ""
    if with_plotly:
        import plotly.offline

        script = f'<script type="text/javascript">{plotly.offline.get_plotlyjs()}</script>'
    body = "\n".join([f"<h1>{html.escape(title)}</h1>", *sections])
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>{html.escape(title)}</title>
<style>{CSS}</style>
{script}
</head><body>
{body}
<footer>{html.escape(footer)}</footer>
</body></html>
"""


def figure_html(fig: Any, div_id: str) -> str:
    """A plotly figure as a ``<div>`` (the page carries the script once)."""
    return str(fig.to_html(full_html=False, include_plotlyjs=False, div_id=div_id, config={"displaylogo": False}))


def image_html(png: bytes, caption: str = "", *, alt: str = "") -> str:
    """A PNG embedded as a data URI, with an optional caption."""
    data = base64.b64encode(png).decode("ascii")
    cap = f"<figcaption class='note'>{html.escape(caption)}</figcaption>" if caption else ""
    return f"<figure><img src='data:image/png;base64,{data}' alt='{html.escape(alt or caption)}'>{cap}</figure>"


def value_text(v: Any, digits: int = 6) -> str:
    """A number or vector as text; None as 'n/a'."""
    if v is None:
        return "n/a"
    if isinstance(v, list | tuple):
        return "[" + ", ".join(f"{x:.{digits}f}" for x in v) + "]"
    return f"{v:.{digits}f}" if isinstance(v, float) else str(v)


def sigmas_text(v: Iterable[float], scale: float = 1.0) -> str:
    """Sigmas ``v`` times ``scale`` with 2 significant digits (``[5.7e-05, 0.00014]``): fixed
    decimals print a sub-millimetre sigma of a dense fit's centre as 0.000."""
    return "[" + ", ".join(f"{scale * x:.2g}" for x in v) + "]"


def table_html(header: Sequence[str], rows: Iterable[Sequence[Any]], *, css_class: str = "") -> str:
    """A plain table; cells are escaped text (pass pre-formatted strings for numbers)."""
    head = "".join(f"<th>{html.escape(str(h))}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in row) + "</tr>" for row in rows)
    cls = f" class='{html.escape(css_class)}'" if css_class else ""
    return f"<table{cls}><tr>{head}</tr>{body}</table>"
