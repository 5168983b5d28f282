"""Render a :class:`~i2ris_calib.report.document.Document` to HTML and to Markdown.

HTML is self-contained: CSS inline, figures as base64 PNG data URIs, no script,
no external resource. Markdown links figures as PNG files in a folder beside it.
The page template and stylesheet (``report/templates/``) are passed in as text by
the io layer, so this module never opens files.

Markdown fragments written by other stages (diagnosis.md) are rendered to HTML
with markdown-it-py (CommonMark, raw HTML disabled: a fragment cannot inject
script), the parser that rich already depends on.
"""

from __future__ import annotations

import base64
import html
import re
from string import Template

from markdown_it import MarkdownIt

from i2ris_calib.report.document import (
    Code,
    DocBlock,
    Document,
    Figure,
    MarkdownFragment,
    Note,
    Paragraph,
    Section,
    Table,
    Verdict,
)

NOTE_LABELS = {"missing": "Not available", "warn": "Warning", "info": "Note"}
VERDICT_LABELS = {"ok": "OK", "warn": "CHECK", "info": "INFO"}


def data_uri(png: bytes) -> str:
    """``data:image/png;base64,...`` URI of PNG bytes."""
    return "data:image/png;base64," + base64.b64encode(png).decode("ascii")


def png_size(png: bytes) -> tuple[int, int]:
    """(width, height) in pixels from a PNG's IHDR chunk."""
    if png[:8] != b"\x89PNG\r\n\x1a\n" or len(png) < 24:
        raise ValueError("not a PNG image")
    return int.from_bytes(png[16:20], "big"), int.from_bytes(png[20:24], "big")


# ---------------------------------------------------------------- HTML


def render_html(doc: Document, template: str, css: str, version: str) -> str:
    """The report as one HTML page.

    Parameters
    ----------
    doc : Document
        What to render.
    template : str
        ``string.Template`` text with ``$title $subtitle $css $toc $body $version``.
    css : str
        Stylesheet inlined into the page.
    version : str
        Package version, shown in the footer and the generator meta tag.
    """
    e = html.escape
    body = "\n".join(_html_section(s, 2) for s in doc.sections)
    return Template(template).substitute(
        title=e(doc.title),
        subtitle=e(doc.subtitle),
        css=css,
        toc=_html_toc(doc.sections),
        body=body,
        version=e(version),
    )


def _html_toc(sections: tuple[Section, ...]) -> str:
    if not sections:
        return ""
    items = []
    for s in sections:
        sub = _html_toc(s.subsections)
        items.append(f'<li><a href="#{s.anchor}">{html.escape(s.title)}</a>{sub}</li>')
    return "<ol>" + "".join(items) + "</ol>"


def _html_section(sec: Section, level: int) -> str:
    h = min(level, 6)
    parts = [f'<section id="{sec.anchor}">', f"<h{h}>{html.escape(sec.title)}</h{h}>"]
    parts += [_html_block(b) for b in sec.blocks]
    parts += [_html_section(s, level + 1) for s in sec.subsections]
    parts.append("</section>")
    return "\n".join(parts)


def _html_block(b: DocBlock) -> str:
    e = html.escape
    if isinstance(b, Paragraph):
        return f"<p>{e(b.text)}</p>"
    if isinstance(b, Note):
        label = NOTE_LABELS.get(b.kind, "Note")
        return f'<p class="note {e(b.kind)}"><strong>{label}:</strong> {e(b.text)}</p>'
    if isinstance(b, Verdict):
        label = VERDICT_LABELS.get(b.status, "INFO")
        return f'<p class="verdict {e(b.status)}"><span class="mark">{label}</span> {e(b.text)}</p>'
    if isinstance(b, Table):
        return _html_table(b)
    if isinstance(b, Figure):
        w, h = png_size(b.png)
        return (
            f'<figure id="fig-{e(b.name)}"><img src="{data_uri(b.png)}" width="{w}" height="{h}" '
            f'alt="{e(_alt_text(b))}"><figcaption>{e(b.caption)}</figcaption></figure>'
        )
    if isinstance(b, Code):
        pre = f"<pre><code>{e(b.text)}</code></pre>"
        return f"<details><summary>{e(b.summary)}</summary>{pre}</details>" if b.summary else pre
    if isinstance(b, MarkdownFragment):
        body = f'<div class="fragment">{fragment_html(b)}</div>'
        return f"<details><summary>{e(b.summary)}</summary>{body}</details>" if b.summary else body
    raise TypeError(f"unknown block {type(b).__name__}")


def _html_table(t: Table) -> str:
    e = html.escape
    head = []
    if t.group_header:
        cells = "".join(
            f'<th colspan="{n}">{e(label)}</th>' if n > 1 else f"<th>{e(label)}</th>"
            for label, n in t.group_header
        )
        head.append(f'<tr class="group">{cells}</tr>')
    head.append("<tr>" + "".join(f"<th>{e(c)}</th>" for c in t.header) + "</tr>")
    right = column_alignment(t)
    body = "\n".join(
        "<tr>"
        + "".join(
            f"<td>{e(c)}</td>" if r else f'<td class="text">{e(c)}</td>'
            for c, r in zip(row, right, strict=True)
        )
        + "</tr>"
        for row in t.rows
    )
    caption = f"<caption>{e(t.caption)}</caption>" if t.caption else ""
    notes = (
        '<p class="footnotes">' + "<br>".join(e(n) for n in t.footnotes) + "</p>"
        if t.footnotes
        else ""
    )
    return (
        f'<div class="table-wrap"><table>{caption}<thead>{"".join(head)}</thead>'
        f"<tbody>\n{body}\n</tbody></table>{notes}</div>"
    )


_NUMBER = re.compile(r"^[-+]?(\d[\d.,eE+-]*|—)\*?( \(.*\))?$")  # "*" = not converged


def column_alignment(t: Table) -> list[bool]:
    """True per column to align right: ``t.align`` when given, else all cells numeric-looking."""
    if t.align:
        return [a == "r" for a in t.align]
    return [bool(t.rows) and all(_NUMBER.match(r[j]) for r in t.rows) for j in range(len(t.header))]


FRAGMENT_TOP_LEVEL = 4  # a fragment sits under an h3 (axis) subsection


def fragment_html(frag: MarkdownFragment) -> str:
    """HTML of a Markdown fragment, its top heading level made h4, images inlined.

    Raw HTML in the fragment is escaped, not passed through.
    """
    md = MarkdownIt("commonmark", {"html": False}).enable("table")
    tokens = md.parse(frag.text)
    levels = [int(t.tag[1]) for t in tokens if t.type == "heading_open"]
    shift = FRAGMENT_TOP_LEVEL - min(levels) if levels else 0
    for tok in tokens:
        if tok.type in ("heading_open", "heading_close"):
            tok.tag = f"h{max(1, min(6, int(tok.tag[1]) + shift))}"
        for child in tok.children or ():
            if child.type == "image":
                src = str(child.attrGet("src") or "")
                if src in frag.images:
                    child.attrSet("src", data_uri(frag.images[src][1]))
    return md.renderer.render(tokens, md.options, {})


# ---------------------------------------------------------------- Markdown


def render_markdown(doc: Document, figure_dir: str = "figures") -> tuple[str, dict[str, bytes]]:
    """The report as Markdown plus the PNG files it links.

    Parameters
    ----------
    doc : Document
        What to render.
    figure_dir : str
        Folder (relative to the Markdown file) holding the figures.

    Returns
    -------
    text : str
        Markdown (GitHub-flavoured tables).
    files : dict
        Relative path (``figures/<name>.png``) -> PNG bytes, to write beside it.
    """
    files: dict[str, bytes] = {}
    lines = [f"# {doc.title}", "", f"_{doc.subtitle}_", ""]
    lines += _md_toc(doc.sections, 0)
    lines.append("")
    for s in doc.sections:
        lines += _md_section(s, 2, figure_dir, files)
    return "\n".join(lines).rstrip() + "\n", files


def _md_toc(sections: tuple[Section, ...], depth: int) -> list[str]:
    out = []
    for s in sections:
        out.append(f"{'  ' * depth}- [{s.title}](#{s.anchor})")
        if depth == 0:
            out += _md_toc(s.subsections, depth + 1)
    return out


def _md_section(sec: Section, level: int, fdir: str, files: dict[str, bytes]) -> list[str]:
    out = [f'<a id="{sec.anchor}"></a>', "", f"{'#' * min(level, 6)} {sec.title}", ""]
    for b in sec.blocks:
        out += _md_block(b, fdir, files) + [""]
    for s in sec.subsections:
        out += _md_section(s, level + 1, fdir, files)
    return out


def _figure_file(name: str, png: bytes, fdir: str, files: dict[str, bytes]) -> str:
    """Register ``png`` under a unique ``fdir/name.png`` and return that path."""
    path, i = f"{fdir}/{name}.png", 2
    while path in files and files[path] != png:
        path, i = f"{fdir}/{name}_{i}.png", i + 1
    files[path] = png
    return path


def _md_block(b: DocBlock, fdir: str, files: dict[str, bytes]) -> list[str]:
    if isinstance(b, Paragraph):
        return [_md_text(b.text)]
    if isinstance(b, Note):
        return [f"> **{NOTE_LABELS.get(b.kind, 'Note')}:** {_md_text(b.text)}"]
    if isinstance(b, Verdict):
        return [f"- **{VERDICT_LABELS.get(b.status, 'INFO')}** {_md_text(b.text)}"]
    if isinstance(b, Table):
        return _md_table(b)
    if isinstance(b, Figure):
        path = _figure_file(b.name, b.png, fdir, files)
        alt = _md_inline(_alt_text(b)).replace("[", "(").replace("]", ")")
        return [f"![{alt}]({path})", "", f"_{_md_inline(b.caption)}_" if b.caption else ""]
    if isinstance(b, Code):
        if b.md_note:
            return [_md_text(b.md_note)]
        fence = "```"
        while fence in b.text:
            fence += "`"
        head = [f"**{b.summary}**", ""] if b.summary else []
        return head + [fence, b.text, fence]
    if isinstance(b, MarkdownFragment):
        body = fragment_markdown(b, fdir, files)
        if b.summary:
            return [f"<details><summary>{html.escape(b.summary)}</summary>", "", body, "",
                    "</details>"]  # fmt: skip
        return [body]
    raise TypeError(f"unknown block {type(b).__name__}")


def _alt_text(fig: Figure) -> str:
    """Short alternative text: the caption up to its first colon (the figure's subject)."""
    head = fig.caption.split(":", 1)[0].strip()
    return head[:80] if head else fig.name


def _md_text(text: str) -> str:
    """Plain text made inert in Markdown: no HTML tags, no line breaks."""
    return text.replace("\n", " ").replace("<", "\\<")


def _md_inline(text: str) -> str:
    """Plain text for captions (rendered in italics): emphasis markers escaped too."""
    return _md_text(text).replace("|", "\\|").replace("_", "\\_").replace("*", "\\*")


def _md_table(t: Table) -> list[str]:
    header = list(t.header)
    if t.group_header:
        labels = [label for label, n in t.group_header for _ in range(n)]
        header = [f"{g} {h}".strip() for g, h in zip(labels, header, strict=True)]
    cell = lambda s: _md_text(s).replace("|", "\\|").replace("*", "\\*")  # noqa: E731
    numeric = column_alignment(t)
    out = ["| " + " | ".join(cell(h) for h in header) + " |"]
    out.append("|" + "|".join("---:" if num else "---" for num in numeric) + "|")
    out += ["| " + " | ".join(cell(c) for c in row) + " |" for row in t.rows]
    if t.caption:
        out += ["", f"_{_md_inline(t.caption)}_"]
    if t.footnotes:
        out += [""] + [_md_text(n) + "  " for n in t.footnotes[:-1]] + [_md_text(t.footnotes[-1])]
    return out


def fragment_markdown(frag: MarkdownFragment, fdir: str, files: dict[str, bytes]) -> str:
    """The fragment with its top heading level made ``####`` and image links re-pointed."""
    text = frag.text
    for rel, (name, png) in frag.images.items():
        text = text.replace(f"]({rel})", f"]({_figure_file(name, png, fdir, files)})")
    lines = text.splitlines()
    fenced = _fenced_lines(lines)
    heading = re.compile(r"^(#{1,6}) ")
    levels = [
        len(m.group(1))
        for ln, f in zip(lines, fenced, strict=True)
        if not f
        for m in [heading.match(ln)]
        if m
    ]
    shift = FRAGMENT_TOP_LEVEL - min(levels) if levels else 0
    out = []
    for line, in_fence in zip(lines, fenced, strict=True):
        m = None if in_fence else heading.match(line)
        if m:
            level = max(1, min(6, len(m.group(1)) + shift))
            line = "#" * level + line[len(m.group(1)) :]
        out.append(line)
    return "\n".join(out).strip()


def _fenced_lines(lines: list[str]) -> list[bool]:
    """True for each line inside (or delimiting) a fenced code block."""
    flags, fenced = [], False
    for line in lines:
        fence = line.lstrip().startswith(("```", "~~~"))
        if fence:
            fenced = not fenced
        flags.append(fenced or fence)
    return flags
