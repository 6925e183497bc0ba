"""Text shared by the studies' Markdown: numbers (missing ones as a dash), "v ± e", tables."""

from __future__ import annotations

import math

#: The least convergence certificate (agreement with the map integrated 10x tighter) for which the report calls
#: a map converged; a map above its chaos floor but below this gives statistics only.
CONVERGED_MIN = 0.99


def verdict_word(converged: bool, certificate: float) -> str:
    """"converged", "statistics only" (certified against its floor, certificate below :data:`CONVERGED_MIN`) or
    "not converged"."""
    if not converged:
        return "not converged"
    return "converged" if certificate >= CONVERGED_MIN else "statistics only"


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


def compared(a: float, b: float, words: tuple[str, str, str], *, err: float | None = None,
             rel: float = 0.0) -> str:
    """The word of ``words`` = (more, less, same) that says how ``a`` stands against ``b``: ``same`` when they differ
    by no more than ``2·err`` (two standard errors of the difference) or by no more than ``rel`` of the larger."""
    tie = max(2.0 * err if err is not None and math.isfinite(err) else 0.0, rel * max(abs(a), abs(b)))
    if abs(a - b) <= tie:
        return words[2]
    return words[0] if a > b else words[1]


def pm(v, e, spec=".3f") -> str:
    """'v ± e' with None/NaN shown as '–'."""
    if v is None or not math.isfinite(v):
        return "–"
    if e is None or not math.isfinite(e):
        return format(v, spec)
    return f"{format(v, spec)} ± {format(e, spec)}"


def grows(r: dict) -> bool:
    """Whether a run's tolerance loosens over the throw (a ``tol_growth`` above 0; rows without one: no)."""
    g = r.get("tol_growth")
    return g is not None and math.isfinite(g) and g > 0


def tol_text(r: dict) -> str:
    """A run's tolerance as text: ``1e-07``, or ``2e-08 growing 10/s`` when it loosens over the throw; '' for none."""
    tol = r.get("tol")
    if tol is None or not math.isfinite(tol):
        return ""
    return f"{tol:g}" + (f" growing {r['tol_growth']:g}/s" if grows(r) else "")
