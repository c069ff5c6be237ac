"""Self-contained HTML reports: headings, text, tables and embedded PNG figures.

A :class:`Report` collects blocks and writes one HTML file with every figure
embedded as a base64 PNG (``data:`` URI), so the page can be mailed or archived
alone. A small script in the page counts the figures the browser decoded
(``naturalWidth > 0``) and writes the count into ``<body data-figures-loaded>``,
which the headless-browser test reads from the rendered DOM.
"""

from __future__ import annotations

import base64
import html
import io
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from matplotlib.figure import Figure

_STYLE = """
body { font-family: system-ui, sans-serif; max-width: 1100px; margin: 2em auto;
       padding: 0 1em; color: #222; line-height: 1.45; }
h1 { border-bottom: 2px solid #444; padding-bottom: .2em; }
h2 { margin-top: 2em; border-bottom: 1px solid #bbb; }
table { border-collapse: collapse; margin: 1em 0; font-size: 0.9em; }
th, td { border: 1px solid #ccc; padding: .25em .6em; text-align: right; }
th { background: #f0f0f0; }
td:first-child, th:first-child { text-align: left; }
figure { margin: 1.2em 0; }
figure img { max-width: 100%; border: 1px solid #ddd; }
figcaption { font-size: .9em; color: #555; }
.banner { background: #fff3cd; border: 2px solid #d39e00; padding: .6em 1em;
          font-weight: bold; margin: 1em 0; }
.pass { color: #196c2e; font-weight: bold; }
.warn { color: #9a6700; font-weight: bold; }
.fail { color: #b42318; font-weight: bold; }
pre { background: #f6f6f6; padding: .6em; overflow-x: auto; font-size: .85em; }
"""

_SCRIPT = """
window.addEventListener('load', function () {
  var imgs = Array.prototype.slice.call(document.querySelectorAll('figure img'));
  var ok = imgs.filter(function (im) { return im.complete && im.naturalWidth > 0; });
  document.body.setAttribute('data-figures-total', String(imgs.length));
  document.body.setAttribute('data-figures-loaded', String(ok.length));
  var s = document.getElementById('figure-status');
  if (s) { s.textContent = ok.length + ' of ' + imgs.length + ' figures loaded'; }
});
"""


def png_data_uri(png: bytes) -> str:
    """A ``data:image/png;base64,...`` URI of PNG bytes."""
    return "data:image/png;base64," + base64.b64encode(png).decode("ascii")


def figure_png(fig: Figure, *, dpi: int = 110) -> bytes:
    """PNG bytes of a matplotlib figure (the figure is closed)."""
    from mincam_render.analysis.plots import plt

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    plt.close(fig)
    return buf.getvalue()


class Report:
    """An HTML page built block by block (text is escaped; figures are embedded).

    Args:
        title: page title and first heading.
        banner: optional warning shown on top in a highlighted box (e.g. that the
            data are SURROGATE, not measured).
    """

    def __init__(self, title: str, *, banner: str | None = None) -> None:
        self.title = title
        self.banner = banner
        self._blocks: list[str] = []
        self.num_figures = 0

    def heading(self, text: str, level: int = 2) -> None:
        """A section heading (level 2-4)."""
        level = min(4, max(2, int(level)))
        self._blocks.append(f"<h{level}>{html.escape(text)}</h{level}>")

    def paragraph(self, text: str, *, css_class: str | None = None) -> None:
        """A paragraph of plain text."""
        cls = f' class="{html.escape(css_class)}"' if css_class else ""
        self._blocks.append(f"<p{cls}>{html.escape(text)}</p>")

    def bullets(self, items: list[str]) -> None:
        """A bulleted list of plain-text items."""
        lis = "".join(f"<li>{html.escape(str(i))}</li>" for i in items)
        self._blocks.append(f"<ul>{lis}</ul>")

    def preformatted(self, text: str) -> None:
        """Monospaced text (tables pasted as text, commands)."""
        self._blocks.append(f"<pre>{html.escape(text)}</pre>")

    def table(
        self,
        columns: list[str],
        rows: list[list[Any]],
        *,
        caption: str | None = None,
        cell_classes: list[list[str | None]] | None = None,
    ) -> None:
        """A table; ``cell_classes[i][j]`` optionally styles a cell (``pass``/``warn``/``fail``)."""
        head = "".join(f"<th>{html.escape(str(c))}</th>" for c in columns)
        body = []
        for i, row in enumerate(rows):
            cells = []
            for j, v in enumerate(row):
                cls = cell_classes[i][j] if cell_classes and cell_classes[i][j] else None
                attr = f' class="{html.escape(cls)}"' if cls else ""
                cells.append(f"<td{attr}>{html.escape(str(v))}</td>")
            body.append("<tr>" + "".join(cells) + "</tr>")
        cap = f"<caption>{html.escape(caption)}</caption>" if caption else ""
        self._blocks.append(
            f"<table>{cap}<thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody></table>"
        )

    def figure_png(self, png: bytes, caption: str) -> None:
        """Embed PNG bytes with a caption."""
        self.num_figures += 1
        alt = html.escape(caption, quote=True)
        self._blocks.append(
            f'<figure><img src="{png_data_uri(png)}" alt="{alt}">'
            f"<figcaption>Figure {self.num_figures}. {html.escape(caption)}</figcaption></figure>"
        )

    def figure(self, fig: Figure, caption: str) -> None:
        """Embed a matplotlib figure (closed afterwards)."""
        self.figure_png(figure_png(fig), caption)

    def figure_file(self, path: str | os.PathLike, caption: str) -> None:
        """Embed a PNG file."""
        self.figure_png(Path(path).read_bytes(), caption)

    def html(self) -> str:
        """The whole page as a string."""
        banner = f'<div class="banner">{html.escape(self.banner)}</div>' if self.banner else ""
        return (
            '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
            f"<title>{html.escape(self.title)}</title><style>{_STYLE}</style>"
            f"<script>{_SCRIPT}</script></head>"
            f'<body data-figures-loaded="pending"><h1>{html.escape(self.title)}</h1>{banner}'
            + "\n".join(self._blocks)
            + f'<p id="figure-status">{self.num_figures} figures</p>'
            + (banner if banner else "")
            + "</body></html>\n"
        )

    def write(self, path: str | os.PathLike) -> Path:
        """Write the page atomically; returns the path."""
        from mincam_render.data.dataset import atomic_write_bytes

        return atomic_write_bytes(path, self.html().encode("utf-8"))
