"""The die and its load as text: ``--die X,Y,Z`` and ``--load W@X,Y,Z`` read, a preset's die written back.

One reader of both texts for the command-line options (``dicetrace.commands.options``) and the explorer's
``die`` and ``load`` parameters (``dicetrace.explore.view``); a bottom-layer module (it imports nothing of
dicetrace), so the explorer need not import the commands.
"""

from __future__ import annotations

import math


def fmt_num(v: float) -> str:
    """Compact number for names and tables (10 significant digits)."""
    return f"{float(v):.10g}"


class BodyTextError(ValueError):
    """A ``--die`` or ``--load`` text that is no box or load; ``option`` names it (``"--die"``, ``"--load"``)."""

    def __init__(self, option: str, message: str):
        super().__init__(f"{option} {message}")
        self.option, self.message = option, message


def _numbers(option: str, text: str, count: int, what: str) -> tuple[float, ...]:
    parts = [t.strip() for t in text.split(",")]
    try:
        values = tuple(float(t) for t in parts)
    except ValueError:
        values = ()
    if len(values) != count or not all(math.isfinite(v) for v in values):
        raise BodyTextError(option, f"needs {what}, got {text!r}")
    return values


def parse_body(die: str | None, load: str | None) -> dict:
    """The preset fields that ``--die X,Y,Z`` (sides, cm) and ``--load W@X,Y,Z`` set ({} when neither is given), or
    a :class:`BodyTextError` naming the option.  The values themselves are checked with the preset (``Preset.body``).
    The one reader of both texts: the commands' options and the explorer's ``die`` and ``load`` parameters."""
    out: dict = {}
    if die is not None:
        sides = _numbers("--die", die, 3, "three sides in cm, X,Y,Z (the cube: 2,2,2)")
        if min(sides) <= 0:
            raise BodyTextError("--die", f"needs three sides > 0 cm, got {die!r}")
        out["half_extents_cm"] = tuple(0.5 * v for v in sides)
    if load is not None:
        share, sep, where = load.partition("@")
        if not sep:
            raise BodyTextError("--load", f"needs W@X,Y,Z (a share of the mass at a body-frame point, cm), got {load!r}")
        w = _numbers("--load", share, 1, "a share W of the mass in [0, 1) before the @")[0]
        if not 0.0 <= w < 1.0:
            raise BodyTextError("--load", f"needs a share W of the mass in [0, 1) before the @, got {share.strip()!r}")
        out["load_fraction"] = w
        out["load_cm"] = _numbers("--load", where, 3, "the load's place X,Y,Z (cm, body frame) after the @")
    return out


def plain_body(preset):
    """``preset`` with its body written one way: a cube of its ``half_side_cm`` as ``half_extents_cm=None``, a load of
    share 0 at the centre.  ``--die 2,2,2`` and no ``--die`` are then one scan (one definition to resume)."""
    h = preset.half_extents_cm
    changes = {}
    if h is not None and all(v == preset.half_side_cm for v in h):
        changes["half_extents_cm"] = None
    if preset.load_fraction == 0 and any(v != 0 for v in preset.load_cm):
        changes["load_cm"] = (0.0, 0.0, 0.0)
    return preset.with_(**changes) if changes else preset


def die_text(preset) -> str:
    """The die of ``preset`` in words, as its options give it: ``cube 2 × 2 × 2 cm`` or ``box 2 × 2 × 3 cm``, and
    ``, load 0.3 of its mass at (-0.9, 0, 0) cm`` for a loaded die (what a scan's refusal and the explorer show)."""
    body = preset.body
    sides = " × ".join(fmt_num(2 * v) for v in body.half_extents_cm)
    text = f"{'cube' if len(set(body.half_extents_cm)) == 1 else 'box'} {sides} cm"
    if body.load_fraction:
        text += (f", load {fmt_num(body.load_fraction)} of its mass at "
                 f"({', '.join(fmt_num(v) for v in body.load_cm)}) cm")
    return text


def die_options(preset) -> str:
    """The options that give ``preset``'s die: ``--die X,Y,Z`` and, for a loaded die, ``--load W@X,Y,Z``."""
    body = preset.body
    text = "--die " + ",".join(fmt_num(2 * v) for v in body.half_extents_cm)
    if body.load_fraction:
        text += f" --load {fmt_num(body.load_fraction)}@" + ",".join(fmt_num(v) for v in body.load_cm)
    return text
