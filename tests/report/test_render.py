"""HTML and Markdown renderers: self-contained, escaped, twins carry the same content."""

from __future__ import annotations

import base64
import re

from runfolder import tiny_png

from i2ris_calib.report.document import (
    Code,
    Document,
    Figure,
    MarkdownFragment,
    Note,
    Paragraph,
    Section,
    Table,
)
from i2ris_calib.report.render import (
    fragment_html,
    fragment_markdown,
    png_size,
    render_html,
    render_markdown,
)

TEMPLATE = (
    "<html><head><title>$title</title><style>$css</style></head><body><h1>$title</h1>"
    "<p>$subtitle</p><nav>$toc</nav>$body<footer>$version</footer></body></html>"
)
RED, BLUE = tiny_png(8, 6, (255, 0, 0)), tiny_png(10, 5, (0, 0, 255))


def _doc() -> Document:
    table = Table(
        ("model", "RMSE (deg)", "MAE (deg)"),
        (("EGPI", "0.141", "0.200"), ("G|PI", "0.849", "1.2")),
        "cap",
        (("", 1), ("yaw+", 2)),
    )
    frag = MarkdownFragment(
        "# Step\n\n![before](plots/a.png)\n\n<b>raw</b>\n", {"plots/a.png": ("diag_a", BLUE)}
    )
    return Document(
        "Report <x>",
        "sub & title",
        (
            Section("one", "One", (Paragraph("a < b"), Note("track/angles.csv: not found"), table)),
            Section(
                "two",
                "Two",
                (Figure("fig_red", RED, "red square"),),
                (Section("two-a", "Two A", (Code('{"k": 1}', "config"), frag)),),
            ),
        ),
    )


def test_html_is_self_contained_and_inlines_every_figure():
    page = render_html(_doc(), TEMPLATE, "body{}", "9.9")
    # No reference leaves the page: every src is a data URI, every href an in-page anchor.
    for attr, url in re.findall(r'\b(src|href)="([^"]*)"', page):
        assert url.startswith("data:image/png;base64,") if attr == "src" else url.startswith("#")
    srcs = re.findall(r'src="data:image/png;base64,([^"]+)"', page)
    assert [base64.b64decode(s) for s in srcs] == [RED, BLUE]
    assert 'width="8" height="6"' in page
    assert "Report &lt;x&gt;" in page and "a &lt; b" in page and "sub &amp; title" in page
    assert "&lt;b&gt;raw&lt;/b&gt;" in page and "<b>raw</b>" not in page  # fragment HTML escaped
    assert '<th colspan="2">yaw+</th>' in page
    assert '<a href="#two-a">Two A</a>' in page and '<section id="two-a">' in page


def test_markdown_twin_links_every_figure_and_keeps_tables_rectangular():
    text, files = render_markdown(_doc(), "figures")
    assert files == {"figures/fig_red.png": RED, "figures/diag_a.png": BLUE}
    for path in files:
        assert f"]({path})" in text
    table_lines = [ln for ln in text.splitlines() if ln.startswith("|")]
    assert table_lines[0] == "| model | yaw+ RMSE (deg) | yaw+ MAE (deg) |"
    assert table_lines[1] == "|---|---:|---:|"
    # Escaped pipe keeps 3 columns.
    assert all(len(re.split(r"(?<!\\)\|", ln)) == 5 for ln in table_lines)
    assert "> **Not available:** track/angles.csv: not found" in text
    assert '```\n{"k": 1}\n```' in text
    assert "#### Step" in text  # fragment heading demoted under the h3 subsection


def test_markdown_figure_names_are_unique():
    doc = Document("t", "s", (Section("a", "A", (Figure("f", RED, "x"), Figure("f", BLUE, "y"))),))
    _, files = render_markdown(doc)
    assert files == {"figures/f.png": RED, "figures/f_2.png": BLUE}


def test_fragment_html_demotes_headings_and_inlines_only_known_images():
    frag = MarkdownFragment(
        "## R\n\n![a](a.png) ![b](b.png)\n\n<script>x()</script>", {"a.png": ("n", RED)}
    )
    out = fragment_html(frag)
    assert "<h4>R</h4>" in out  # top level of the fragment becomes h4
    assert "data:image/png;base64," + base64.b64encode(RED).decode() in out
    assert 'src="b.png"' in out  # unknown image left as is (the builder lists it as missing)
    assert "<script>" not in out


def test_fragment_heading_levels_keep_their_relative_depth():
    frag = MarkdownFragment("## A\n\n### B\n", {})
    assert fragment_markdown(frag, "figures", {}).splitlines() == ["#### A", "", "##### B"]
    assert "<h4>A</h4>" in fragment_html(frag) and "<h5>B</h5>" in fragment_html(frag)


def test_fragment_markdown_leaves_code_blocks_alone():
    frag = MarkdownFragment("# H\n```\n# not a heading\n```\n![p](p.png)", {"p.png": ("x", RED)})
    files: dict[str, bytes] = {}
    out = fragment_markdown(frag, "figures", files)
    assert out.splitlines() == ["#### H", "```", "# not a heading", "```", "![p](figures/x.png)"]
    assert files == {"figures/x.png": RED}


def test_png_size():
    assert png_size(tiny_png(13, 7)) == (13, 7)


def test_explicit_alignment_overrides_the_numeric_guess():
    t = Table(("parameter", "unit"), (("kappa", "1"),), align=("l", "l"))
    text, _ = render_markdown(Document("t", "s", (Section("a", "A", (t,)),)))
    assert "|---|---|" in text
    page = render_html(Document("t", "s", (Section("a", "A", (t,)),)), TEMPLATE, "", "1")
    assert '<td class="text">1</td>' in page


def test_markdown_table_cells_cannot_start_emphasis_or_html():
    t = Table(("key", "value"), (("clock", "t = a*1e-6) * t_cam <b>"),))
    text, _ = render_markdown(Document("t", "s", (Section("a", "A", (t,)),)))
    assert "| clock | t = a\\*1e-6) \\* t_cam \\<b> |" in text


def test_a_fragment_with_a_summary_is_folded_in_both_formats():
    doc = Document(
        "t", "s", (Section("a", "A", (MarkdownFragment("# x\n\nbody", {}, "open me"),)),)
    )
    page = render_html(doc, TEMPLATE, "body{}", "9.9")
    assert '<details><summary>open me</summary><div class="fragment">' in page
    md, _ = render_markdown(doc, "figures")
    assert "<details><summary>open me</summary>" in md and "</details>" in md
    assert md.index("<details>") < md.index("body") < md.index("</details>")
