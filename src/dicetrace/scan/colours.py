"""The outcome colours every picture of a scan uses: the PNG and Rerun maps, and the explorer's map.

Colours are the writeup's: face 1 blue, 2 green, 3 red, 4 magenta, 5 yellow, 6 black;
0 (undefined) grey, -1 (did not settle) white.
"""

from __future__ import annotations

import numpy as np

#: RGB (0-255) of each outcome label -1..6.
OUTCOME_RGB: dict[int, tuple[int, int, int]] = {
    -1: (255, 255, 255),
    0: (128, 128, 128),
    1: (0, 0, 255),
    2: (0, 128, 0),
    3: (255, 0, 0),
    4: (255, 0, 255),
    5: (255, 255, 0),
    6: (0, 0, 0),
}
OUTCOME_NAMES = {-1: "did not settle", 0: "undefined", 1: "1", 2: "2", 3: "3", 4: "4", 5: "5", 6: "6"}


def outcome_rgb_table() -> np.ndarray:
    """(8, 3) uint8: the colour of outcome -1..6 at row outcome + 1."""
    t = np.zeros((8, 3), dtype=np.uint8)
    for k, rgb in OUTCOME_RGB.items():
        t[k + 1] = rgb
    return t
