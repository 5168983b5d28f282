"""A small document model rendered twice: to self-contained HTML and to Markdown.

The report is built once as a tree of :class:`Section` objects holding blocks
(paragraphs, notes, tables, figures, code, Markdown fragments); the two
renderers in :mod:`i2ris_calib.report.render` turn the same tree into
``report.html`` and ``report.md``, so the twins cannot drift apart.
"""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True)
class Paragraph:
    """Plain text (no markup); rendered escaped."""

    text: str


@dataclass(frozen=True)
class Note:
    """A highlighted remark, e.g. a missing stage output.

    ``kind`` is ``"missing"`` (stage output absent), ``"warn"`` or ``"info"``.
    """

    text: str
    kind: str = "missing"


@dataclass(frozen=True)
class Verdict:
    """A one-line judgement of a stage: ``status`` ``"ok"``, ``"warn"`` or ``"info"``.

    Rendered as a marked line (HTML: a coloured label; Markdown: a bold label)."""

    text: str
    status: str = "info"


@dataclass(frozen=True)
class Table:
    """A text table: ``header`` of k strings, ``rows`` of k strings each.

    ``group_header`` optionally spans columns above the header: a tuple of
    ``(label, n_columns)`` pairs whose widths add up to k (HTML only; in Markdown
    the group label is prefixed to the header cells). ``align`` optionally gives
    ``"l"`` or ``"r"`` per column; by default numeric-looking columns align right.
    ``footnotes`` are lines printed under the table (e.g. ``"[1] v_f: ..."``, for
    cells that carry a ``[1]`` marker instead of a long text).
    """

    header: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]
    caption: str = ""
    group_header: tuple[tuple[str, int], ...] = ()
    align: tuple[str, ...] = ()
    footnotes: tuple[str, ...] = ()


@dataclass(frozen=True)
class Figure:
    """A PNG figure: ``name`` is the file stem used in the Markdown twin."""

    name: str
    png: bytes
    caption: str


@dataclass(frozen=True)
class Code:
    """Preformatted text (JSON, TOML) shown verbatim; collapsed under ``summary`` in HTML.

    ``md_note``, when given, replaces the text in the Markdown twin (e.g. a pointer to
    the raw file, so the Markdown stays short)."""

    text: str
    summary: str = ""
    md_note: str = ""


@dataclass(frozen=True)
class MarkdownFragment:
    """A Markdown fragment written by another stage (e.g. diagnosis.md).

    ``images`` maps every image link target used in ``text`` (as written in the
    fragment) to ``(figure_name, png_bytes)``: HTML inlines the bytes, Markdown
    rewrites the link to the copied figure file.
    """

    text: str
    images: dict[str, tuple[str, bytes]] = field(default_factory=dict)
    summary: str = ""
    """When set, the fragment is folded behind this one-line summary (HTML and Markdown
    ``<details>``): evidence a reader opens on demand."""


DocBlock = Paragraph | Note | Verdict | Table | Figure | Code | MarkdownFragment


@dataclass(frozen=True)
class Section:
    """A titled section; ``anchor`` is its HTML id (unique in the report)."""

    anchor: str
    title: str
    blocks: tuple[DocBlock, ...] = ()
    subsections: tuple[Section, ...] = ()


@dataclass(frozen=True)
class Document:
    """The whole report: a title, a subtitle line and top-level sections."""

    title: str
    subtitle: str
    sections: tuple[Section, ...]

    def figures(self) -> list[Figure]:
        """Every figure in document order (including fragment images)."""
        out: list[Figure] = []

        def walk(sec: Section) -> None:
            for b in sec.blocks:
                if isinstance(b, Figure):
                    out.append(b)
                elif isinstance(b, MarkdownFragment):
                    out.extend(Figure(n, p, "") for n, p in b.images.values())
            for s in sec.subsections:
                walk(s)

        for s in self.sections:
            walk(s)
        return out
