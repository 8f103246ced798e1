"""A campaign report's Markdown as one self-contained HTML page (figures inlined)."""

from __future__ import annotations

import base64
import html
import re
from pathlib import Path

_CSS = """body{font-family:system-ui,sans-serif;max-width:1000px;margin:2em auto;padding:0 1em;
color:#222}table{border-collapse:collapse;margin:1em 0;font-size:.9em}th,td{border:1px solid
#ccc;padding:.25em .6em}th{background:#f3f3f3}td.r,th.r{text-align:right}figure{margin:1em 0}
img{max-width:100%}figcaption{font-style:italic;color:#555}code{background:#f3f3f3;padding:0
.2em}"""


def _inline(text: str, folder: Path) -> str:
    """The report's inline markdown (code, links, italics) as HTML; files linked from the
    report are embedded as ``data:`` URIs."""
    parts = re.split(r"(`[^`]*`)", text)
    out = []
    for part in parts:
        if part.startswith("`") and part.endswith("`") and len(part) > 1:
            out.append(f"<code>{html.escape(part[1:-1])}</code>")
            continue
        part = html.escape(part, quote=False)

        def link(m: re.Match) -> str:
            target = folder / html.unescape(m.group(2))
            href = html.unescape(m.group(2))
            if target.is_file():
                kind = "text/csv" if target.suffix == ".csv" else "application/octet-stream"
                href = f"data:{kind};base64," + base64.b64encode(target.read_bytes()).decode()
                return (f'<a href="{href}" download="{html.escape(target.name)}">'
                        f"{m.group(1)}</a>")
            return f'<a href="{html.escape(href)}">{m.group(1)}</a>'

        part = re.sub(r"\[([^\]]+)\]\(([^)\s]+)\)", link, part)
        part = re.sub(r"\*\*([^*]+)\*\*", r"<strong>\1</strong>", part)
        part = re.sub(r"(?<![\w*])\*([^*]+)\*(?![\w*])", r"<em>\1</em>", part)
        out.append(part)
    return "".join(out)


def _table_html(rows: list[str], folder: Path) -> list[str]:
    def cells(line: str) -> list[str]:
        return [c.strip() for c in line.strip().strip("|").split("|")]

    head, align, body = cells(rows[0]), cells(rows[1]), [cells(r) for r in rows[2:]]
    right = [a.endswith(":") for a in align]

    def tr(tag: str, cs: list[str]) -> str:
        return "<tr>" + "".join(
            f'<{tag}{" class=r" if i < len(right) and right[i] else ""}>'
            f"{_inline(c, folder)}</{tag}>" for i, c in enumerate(cs)) + "</tr>"

    return ["<table>", "<thead>", tr("th", head), "</thead>", "<tbody>",
            *(tr("td", r) for r in body), "</tbody>", "</table>"]


def markdown_html(md: str, folder: Path, title: str) -> str:
    """The report's markdown (headings, paragraphs, pipe tables, images with a caption line)
    as one self-contained HTML page: every image embedded as a base64 ``data:`` URI, the
    per-run CSV as a download link of the same kind; no external file, script or style."""
    lines = md.splitlines()
    body: list[str] = []
    para: list[str] = []

    def flush() -> None:
        if para:
            body.append(f"<p>{_inline(' '.join(para), folder)}</p>")
            para.clear()

    i = 0
    while i < len(lines):
        line = lines[i]
        img = re.fullmatch(r"!\[(.*)\]\(([^)\s]+)\)", line.strip())
        heading = re.match(r"(#{1,6}) (.*)", line)
        if heading:
            flush()
            n = len(heading.group(1))
            body.append(f"<h{n}>{_inline(heading.group(2), folder)}</h{n}>")
        elif line.startswith("|"):
            flush()
            rows = []
            while i < len(lines) and lines[i].startswith("|"):
                rows.append(lines[i])
                i += 1
            body += _table_html(rows, folder)
            continue
        elif img:
            flush()
            png = folder / img.group(2)
            alt = html.escape(img.group(1))
            src = ("data:image/png;base64," + base64.b64encode(png.read_bytes()).decode()
                   if png.is_file() else html.escape(img.group(2)))
            caption = ""
            j = i + 1
            while j < len(lines) and not lines[j].strip():
                j += 1
            if j < len(lines) and lines[j].strip() == f"*{img.group(1)}*":
                caption = f"<figcaption>{alt}</figcaption>"
                i = j
            body.append(f'<figure><img src="{src}" alt="{alt}">{caption}</figure>')
        elif not line.strip():
            flush()
        else:
            para.append(line.strip())
        i += 1
    flush()
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            f"<title>{html.escape(title)}</title><style>{_CSS}</style></head><body>\n"
            + "\n".join(body) + "\n</body></html>\n")
