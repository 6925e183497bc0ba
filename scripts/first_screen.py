"""The README's first picture: the red-sea outcome map beside the red-sea throw recorded in Rerun's viewer.

Composes two committed images, ``docs/red-sea.png`` (``dicetrace scan ... --png``) and ``docs/viewer.png`` (the
viewer's screenshot of ``dicetrace record --slice seed --at 1.65,3.9``), side by side at one height on white,
into ``docs/first-screen.png``.  Run it again whenever either of them changes (a test checks that the committed
picture is what this script makes of them): ``python scripts/first_screen.py``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from PIL import Image

REPO = Path(__file__).resolve().parents[1]
SOURCES = (REPO / "docs" / "red-sea.png", REPO / "docs" / "viewer.png")
OUT = REPO / "docs" / "first-screen.png"
HEIGHT = 540  # px: both images scaled to this height
GAP = 24  # px of white between them


def compose(sources=SOURCES, height: int = HEIGHT, gap: int = GAP) -> Image.Image:
    """The images of ``sources`` scaled to ``height`` (aspect kept), left to right, ``gap`` pixels apart, on white."""
    parts = []
    for path in sources:
        with Image.open(path) as im:
            im = im.convert("RGBA")
            flat = Image.new("RGBA", im.size, "white")
            flat.alpha_composite(im)
            w = round(im.width * height / im.height)
            parts.append(flat.convert("RGB").resize((w, height), Image.Resampling.LANCZOS))
    out = Image.new("RGB", (sum(p.width for p in parts) + gap * (len(parts) - 1), height), "white")
    x = 0
    for p in parts:
        out.paste(p, (x, 0))
        x += p.width + gap
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=OUT)
    args = ap.parse_args()
    compose().save(args.out, optimize=True)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
