"""Text shared by the studies' Markdown: numbers (missing ones as a dash), "v ± e", tables."""

from __future__ import annotations

import math


def fmt(v, spec: str = "", missing: str = "–") -> str:
    """``format(v, spec)``; ``missing`` for None or a non-finite float; ``str(v)`` where the spec does not apply."""
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return missing
    if not spec:
        return str(v)
    try:
        return format(v, spec)
    except (TypeError, ValueError):
        return str(v)


def md_table(rows: list[dict], columns: list[tuple[str, str, str]]) -> str:
    """Markdown table: columns are (key, header, format spec or '' for str)."""
    lines = ["| " + " | ".join(h for _, h, _ in columns) + " |", "|" + "|".join("---" for _ in columns) + "|"]
    for r in rows:
        lines.append("| " + " | ".join(fmt(r.get(key), spec) for key, _, spec in columns) + " |")
    return "\n".join(lines)


def pm(v, e, spec=".3f") -> str:
    """'v ± e' with None/NaN shown as '–'."""
    if v is None or not math.isfinite(v):
        return "–"
    if e is None or not math.isfinite(e):
        return format(v, spec)
    return f"{format(v, spec)} ± {format(e, spec)}"
