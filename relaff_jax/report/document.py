"""The report document as a list of blocks, rendered as Markdown and as one HTML page.

Blocks: ``("h", level, text)``, ``("p", text)``, ``("ul", [items])``, ``("table", header,
rows)``, ``("img", relative_path, caption)``; text may hold ``code``, **bold** and *emphasis*.
``render_markdown`` gives ``report.md`` (images as relative links); ``render_html`` gives
``report.html``, one self-contained page with the images base64-embedded.
"""
from __future__ import annotations

import base64
import html as _html
import re
from pathlib import Path


def _inline_html(text: str) -> str:
    s = _html.escape(text, quote=False)
    s = re.sub(r"`([^`]+)`", r"<code>\1</code>", s)
    s = re.sub(r"\*\*([^*]+)\*\*", r"<b>\1</b>", s)
    # *emphasis*: a word-bounded pair of single asterisks (not a product such as 2 * 3)
    return re.sub(r"(?<![\w*])\*(?=\S)([^*]+?)(?<=\S)\*(?![\w*])", r"<i>\1</i>", s)


_NUMERIC = re.compile(r"^[-+−]?(\d|\.\d|(inf|nan)\b)|^[-–—]$|^n/a$", re.IGNORECASE)


def numeric_columns(header: list, rows: list) -> list[bool]:
    """Per column: True when every non-empty cell reads as a number (figures, intervals such as
    ``0.85 [0.80, 0.90]``, a dash), so it is right-aligned; text columns are left-aligned."""
    cols = []
    for j in range(len(header)):
        cells = [str(r[j]).strip().strip("*`") for r in rows if j < len(r) and str(r[j]).strip()]
        cols.append(bool(cells) and all(_NUMERIC.match(c) for c in cells))
    return cols


def render_markdown(blocks: list[tuple]) -> str:
    """Markdown of a block list: ``("h", level, text)``, ``("p", text)``, ``("ul", [items])``,
    ``("table", header, rows)``, ``("img", relative_path, caption)``."""
    lines: list[str] = []
    for b in blocks:
        kind = b[0]
        if kind == "h":
            lines += ["#" * b[1] + " " + b[2], ""]
        elif kind == "p":
            lines += [b[1], ""]
        elif kind == "ul":
            lines += [f"- {x}" for x in b[1]] + [""]
        elif kind == "table":
            header, rows = b[1], b[2]
            lines.append("| " + " | ".join(header) + " |")
            lines.append("|" + "".join("---:|" if num else "---|" for num in numeric_columns(header, rows)))
            lines += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
            lines.append("")
        elif kind == "img":
            lines += [f"![{b[2]}]({b[1]})", "", f"*{b[2]}*", ""]
        else:
            raise ValueError(f"unknown block kind {kind!r}")
    return "\n".join(lines)


_CSS = """body{font-family:-apple-system,Segoe UI,Helvetica,Arial,sans-serif;max-width:1100px;margin:2em auto;
padding:0 1em;color:#222;line-height:1.45}table{border-collapse:collapse;margin:0.6em 0 1.2em;font-size:0.9em}
th,td{border:1px solid #ccc;padding:3px 8px}th{background:#f2f2f2}.num{text-align:right}.txt{text-align:left}img{max-width:100%;border:1px solid #eee}figure{margin:1em 0}figcaption{font-size:0.85em;color:#555}
code{background:#f4f4f4;padding:0 3px}h1,h2,h3{border-bottom:1px solid #eee;padding-bottom:0.2em}"""


def render_html(blocks: list[tuple], base: Path, title: str) -> str:
    """One self-contained HTML page of a block list; images under ``base`` are embedded."""
    body: list[str] = []
    for b in blocks:
        kind = b[0]
        if kind == "h":
            body.append(f"<h{b[1]}>{_inline_html(b[2])}</h{b[1]}>")
        elif kind == "p":
            body.append(f"<p>{_inline_html(b[1])}</p>")
        elif kind == "ul":
            body.append("<ul>" + "".join(f"<li>{_inline_html(x)}</li>" for x in b[1]) + "</ul>")
        elif kind == "table":
            side = ["num" if num else "txt" for num in numeric_columns(b[1], b[2])]
            head = "".join(f'<th class="{k}">{_inline_html(str(c))}</th>' for c, k in zip(b[1], side))
            rows = "".join("<tr>" + "".join(f'<td class="{k}">{_inline_html(str(c))}</td>' for c, k in zip(r, side))
                           + "</tr>" for r in b[2])
            body.append(f"<table><thead><tr>{head}</tr></thead><tbody>{rows}</tbody></table>")
        elif kind == "img":
            data = base64.b64encode((base / b[1]).read_bytes()).decode("ascii")
            body.append(f'<figure><img alt="{_html.escape(b[2])}" src="data:image/png;base64,{data}">'
                        f"<figcaption>{_inline_html(b[2])}</figcaption></figure>")
        else:
            raise ValueError(f"unknown block kind {kind!r}")
    return (f"<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{_html.escape(title)}</title>"
            f"<style>{_CSS}</style></head><body>\n" + "\n".join(body) + "\n</body></html>\n")
