"""Short text and HTML displays of results (``__repr__``, ``_repr_html_``).

Every result a notebook shows (datasets, models, fits, diagnoses, compensations) is
displayed by these helpers: one line of at most :data:`MAX_REPR` characters for
``repr``, a heading and a small table for Jupyter. They only format numbers already
computed (a display never evaluates a model). No ``i2ris_calib`` import: any layer
may use them.
"""

from __future__ import annotations

import html
import math
from collections.abc import Iterable, Sequence

#: Longest ``repr`` of a result (characters); longer ones end with "...".
MAX_REPR = 200


def num(x: object, digits: int = 4) -> str:
    """``x`` with ``digits`` significant digits (``"nan"``, ``"inf"`` as such)."""
    try:
        f = float(x)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return str(x)
    if math.isnan(f):
        return "nan"
    return f"{f:.{digits}g}"


def clip(text: str, limit: int = MAX_REPR) -> str:
    """``text`` cut to ``limit`` characters, ending with ``...>`` when cut (the closing
    ``>`` kept for a ``<...>`` repr)."""
    if len(text) <= limit:
        return text
    tail = "...>" if text.endswith(">") else "..."
    return text[: limit - len(tail)] + tail


def name_values(pairs: Iterable[tuple[str, object]], prefix: str, suffix: str = ">") -> str:
    """``prefix`` followed by ``name=value`` pairs, cut to :data:`MAX_REPR` at a pair
    boundary (``...`` marks the rest)."""
    out = prefix
    items = [f"{k}={num(v)}" for k, v in pairs]
    for i, item in enumerate(items):
        sep = "" if i == 0 else ", "
        if len(out) + len(sep) + len(item) + len(suffix) + 5 > MAX_REPR:
            out += ", ..." if i else "..."
            break
        out += sep + item
    return out + suffix


def table(header: Sequence[str], rows: Iterable[Sequence[object]], title: str = "") -> str:
    """An HTML table (cells escaped; floats with 6 significant digits) under an
    optional bold ``title`` (HTML, not escaped: the caller escapes its parts)."""

    def cell(x: object) -> str:
        if isinstance(x, float):
            return num(x, 6)
        return html.escape(str(x))

    head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{cell(x)}</td>" for x in r) + "</tr>" for r in rows)
    top = f"<p>{title}</p>" if title else ""
    return f"{top}<table><tr>{head}</tr>{body}</table>"


def esc(x: object) -> str:
    """HTML-escaped ``str(x)``."""
    return html.escape(str(x))
