"""Self-contained HTML reports: figures embedded as base64 PNG (matplotlib, Agg), tables,
the command line, library versions and a timestamp - one file that opens anywhere, offline.

Figures are built with :class:`matplotlib.figure.Figure` (no pyplot, no global backend
switch); :meth:`Report.figure` renders them with the Agg canvas.
"""

from __future__ import annotations

import base64
import csv
import datetime as _dt
import html
import io
import math
from pathlib import Path

_CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Roboto,sans-serif;max-width:1200px;margin:2em auto;padding:0 1em;
color:#222;line-height:1.45}
h1{font-size:1.6em;border-bottom:2px solid #446;padding-bottom:.2em}h2{font-size:1.25em;margin-top:1.8em;color:#335}
table{border-collapse:collapse;margin:.6em 0 1.2em 0;font-size:.86em}caption{text-align:left;font-weight:600;
padding:.3em 0}th,td{border:1px solid #bbb;padding:.2em .45em;text-align:right}th{background:#eef}
td.t,th.t{text-align:left}tr:nth-child(even) td{background:#fafafa}figure{margin:1em 0}figcaption{font-size:.9em;
color:#444}img{max-width:100%}code,pre{background:#f4f4f4;padding:.1em .3em}pre{padding:.6em;overflow-x:auto;
white-space:pre-wrap}.note{color:#555;font-size:.92em}.result{font-size:1.08em;font-weight:600;border-left:4px solid #2a6;padding-left:.6em}.scroll{overflow-x:auto;max-width:100%}
"""


def fmt(value, digits: int = 3) -> str:
    """A table cell: numbers with ``digits`` significant digits, None/NaN as an en dash."""
    if value is None:
        return "\u2013"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "\u2013"
        if value == 0:
            return "0"
        if abs(value) >= 10 ** digits or abs(value) < 10 ** -(digits + 1):
            return f"{value:.{digits - 1}e}"
        return f"{value:.{digits}g}"
    try:  # numpy scalars
        import numpy as np

        if isinstance(value, np.generic):
            return fmt(value.item(), digits)
    except ImportError:  # pragma: no cover
        pass
    return str(value)


class Report:
    """An HTML report under construction.

    Parameters
    ----------
    title : str
    command : str, optional
        The command line that made it.
    versions : dict, optional
        Library -> version.
    """

    def __init__(self, title: str, command: str | None = None, versions: dict | None = None):
        self.title = title
        self.command = command
        self.versions = dict(versions or {})
        self.created = _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat()
        self._parts: list[str] = []
        self.n_figures = 0
        self.n_tables = 0

    # ------------------------------------------------------------------ content
    def heading(self, text: str, level: int = 2) -> None:
        self._parts.append(f"<h{level}>{html.escape(text)}</h{level}>")

    def paragraph(self, text: str, css_class: str | None = None) -> None:
        cls = f' class="{css_class}"' if css_class else ""
        self._parts.append(f"<p{cls}>{html.escape(text)}</p>")

    def bullets(self, items) -> None:
        self._parts.append("<ul>" + "".join(f"<li>{html.escape(str(i))}</li>" for i in items) + "</ul>")

    def preformatted(self, text: str) -> None:
        self._parts.append(f"<pre>{html.escape(text)}</pre>")

    def table(self, columns, rows, caption: str | None = None, digits: int = 3, text_columns=()) -> None:
        """A table; ``rows`` is a list of sequences (or dicts keyed by ``columns``)."""
        text_columns = set(text_columns) | ({columns[0]} if columns else set())
        out = ['<div class="scroll"><table>']  # a wide table scrolls within the page
        if caption:
            out.append(f"<caption>{html.escape(caption)}</caption>")
        out.append("<tr>" + "".join(
            f'<th class="{"t" if c in text_columns else ""}">{html.escape(str(c))}</th>' for c in columns) + "</tr>")
        for r in rows:
            vals = [r.get(c) for c in columns] if isinstance(r, dict) else list(r)
            out.append("<tr>" + "".join(
                f'<td class="{"t" if c in text_columns else ""}">{html.escape(fmt(v, digits))}</td>'
                for c, v in zip(columns, vals)) + "</tr>")
        out.append("</table></div>")
        self._parts.append("".join(out))
        self.n_tables += 1

    def figure(self, fig, caption: str = "", dpi: int = 110, tight: bool = True) -> None:
        """Embed a matplotlib :class:`~matplotlib.figure.Figure` as a base64 PNG.

        ``tight``: crop the PNG to what the figure draws (``bbox_inches="tight"``, which draws the
        figure twice); False for a figure that sets its own margins (``subplots_adjust``)."""
        from matplotlib.backends.backend_agg import FigureCanvasAgg

        FigureCanvasAgg(fig)
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight" if tight else None)
        data = base64.b64encode(buf.getvalue()).decode("ascii")
        alt = html.escape(caption or f"figure {self.n_figures + 1}")
        self._parts.append(f'<figure><img alt="{alt}" src="data:image/png;base64,{data}">'
                           f"<figcaption>{html.escape(caption)}</figcaption></figure>")
        self.n_figures += 1

    # ------------------------------------------------------------------ output
    def to_html(self) -> str:
        head = [f"<h1>{html.escape(self.title)}</h1>",
                f'<p class="note">Generated {html.escape(self.created)} (UTC).</p>']
        tail = ["<h2>Provenance</h2>"]
        if self.command:
            tail.append(f"<p>Command:</p><pre>{html.escape(self.command)}</pre>")
        if self.versions:
            tail.append("<table><caption>Library versions</caption><tr><th class=\"t\">library</th>"
                        "<th class=\"t\">version</th></tr>" + "".join(
                            f'<tr><td class="t">{html.escape(k)}</td><td class="t">{html.escape(str(v))}</td></tr>'
                            for k, v in self.versions.items()) + "</table>")
        return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
                f"<title>{html.escape(self.title)}</title><style>{_CSS}</style></head><body>\n"
                + "\n".join(head + self._parts + tail) + "\n</body></html>\n")

    def write(self, path) -> Path:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(self.to_html(), encoding="utf-8")
        return path


def write_csv(path, columns, rows) -> Path:
    """A plain CSV table (floats with full precision)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(columns)
        for r in rows:
            vals = [r.get(c) for c in columns] if isinstance(r, dict) else list(r)
            w.writerow(["" if v is None or (isinstance(v, float) and math.isnan(v)) else
                        (repr(float(v)) if isinstance(v, float) else v) for v in vals])
    return path
