"""A self-contained HTML report: one file, figures embedded as PNG data URIs, no scripts.

Used by the mission (``report.html``) and available to any command that wants a page a person can
open without a server. Figures are matplotlib figures (rendered with Agg) or PNG files.

>>> report = Report("Mission")
>>> report.add_text("Outbound drive, mapping and return.")
>>> report.add_table("Figures", [("final distance to operator", "0.31 m")])
>>> html = report.to_html()
"""

from __future__ import annotations

import base64
import html
import io
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from navkit.io.atomic import write_text

__all__ = ["Report"]

_STYLE = """
body { font-family: system-ui, -apple-system, "Segoe UI", sans-serif; margin: 2rem auto;
       max-width: 1200px; padding: 0 1rem; color: #1d2330; background: #fff; }
h1 { margin-bottom: 0.2rem; } .subtitle { color: #5a6275; margin-top: 0; }
h2 { border-bottom: 2px solid #e3e6ee; padding-bottom: 0.3rem; margin-top: 2.2rem; }
figure { margin: 1rem 0; } figure img { max-width: 100%; border: 1px solid #e3e6ee; }
figcaption { color: #5a6275; font-size: 0.92rem; }
table { border-collapse: collapse; margin: 0.8rem 0; font-size: 0.95rem; }
th, td { border: 1px solid #d9dde7; padding: 0.3rem 0.7rem; text-align: left; }
th { background: #f3f5f9; } td.num { text-align: right; font-variant-numeric: tabular-nums; }
.grid { display: grid; grid-template-columns: repeat(auto-fit, minmax(420px, 1fr)); gap: 1rem; }
"""


def _png_data_uri(png: bytes) -> str:
    return "data:image/png;base64," + base64.b64encode(png).decode("ascii")


def figure_png(fig: Any, dpi: int = 110) -> bytes:
    """PNG bytes of a matplotlib figure (the figure is closed afterwards)."""
    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")
    plt.close(fig)
    return buf.getvalue()


@dataclass
class _Section:
    title: str
    parts: list[str] = field(default_factory=list)


@dataclass
class Report:
    """Builder of one HTML page made of sections of text, figures and tables."""

    title: str
    subtitle: str = ""
    sections: list[_Section] = field(default_factory=list)

    def section(self, title: str) -> Report:
        """Start a new section; following ``add_*`` calls go into it."""
        self.sections.append(_Section(title))
        return self

    def _current(self) -> _Section:
        if not self.sections:
            self.sections.append(_Section(""))
        return self.sections[-1]

    def add_text(self, text: str) -> Report:
        """A paragraph of plain text (escaped)."""
        self._current().parts.append(f"<p>{html.escape(text)}</p>")
        return self

    def add_figure(self, figure: Any, caption: str = "", alt: str = "") -> Report:
        """A matplotlib figure, PNG bytes, or a path to a PNG file, embedded in the page."""
        if isinstance(figure, (bytes, bytearray)):
            png = bytes(figure)
        elif isinstance(figure, (str, os.PathLike)):
            png = Path(figure).read_bytes()
        else:
            png = figure_png(figure)
        alt_text = html.escape(alt or caption or "figure")
        cap = f"<figcaption>{html.escape(caption)}</figcaption>" if caption else ""
        self._current().parts.append(
            f'<figure><img src="{_png_data_uri(png)}" alt="{alt_text}">{cap}</figure>'
        )
        return self

    def add_table(
        self,
        caption: str,
        rows: list[tuple[Any, ...]] | list[list[Any]],
        header: tuple[str, ...] | None = None,
    ) -> Report:
        """A table; numbers are right-aligned and shown with 4 significant digits."""

        def cell(v: Any, tag: str = "td") -> str:
            if isinstance(v, float):
                return f'<{tag} class="num">{v:.4g}</{tag}>'
            if isinstance(v, int) and not isinstance(v, bool):
                return f'<{tag} class="num">{v}</{tag}>'
            return f"<{tag}>{html.escape(str(v))}</{tag}>"

        head = "<tr>" + "".join(cell(h, "th") for h in header) + "</tr>" if header else ""
        body = "".join("<tr>" + "".join(cell(v) for v in row) + "</tr>" for row in rows)
        cap = f"<caption>{html.escape(caption)}</caption>" if caption else ""
        self._current().parts.append(f"<table>{cap}{head}{body}</table>")
        return self

    def to_html(self) -> str:
        """The whole page as a string."""
        sections = []
        for s in self.sections:
            title = f"<h2>{html.escape(s.title)}</h2>" if s.title else ""
            sections.append(f"<section>{title}{''.join(s.parts)}</section>")
        subtitle = f'<p class="subtitle">{html.escape(self.subtitle)}</p>' if self.subtitle else ""
        return (
            '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
            f'<meta name="viewport" content="width=device-width, initial-scale=1">'
            f"<title>{html.escape(self.title)}</title><style>{_STYLE}</style>"
            '<link rel="icon" href="data:,"></head>'
            f"<body><h1>{html.escape(self.title)}</h1>{subtitle}{''.join(sections)}</body></html>\n"
        )

    def write(self, path: str | os.PathLike[str]) -> Path:
        """Write the page atomically; returns the path."""
        write_text(path, self.to_html())
        return Path(path)
