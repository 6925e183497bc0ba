"""The scan map ``.rrd``: outcome image, true coordinates with y up, axes, face legend, rounded labels, small."""

from __future__ import annotations

import numpy as np
import pytest

from dicetrace.ics import Grid
from dicetrace.scan import label_grid, read_scan, scan
from dicetrace.scan.map_rrd import CLASS_IDS, MAX_LABELLED, class_ids, nice_ticks, write_scan_rrd
from dicetrace.scan.colours import OUTCOME_RGB

# not square (7 × 5), so that a transposed or flipped image cannot pass
GRID = Grid("seed", ((1.0, 2.0), (3.5, 4.5)), (7, 5))


def _decode(path) -> dict[str, dict]:
    """Entity path → {column: first row's value} of every static chunk of a recording."""
    from rerun.chunk import RrdReader

    out: dict[str, dict] = {}
    for ch in RrdReader(str(path)).stream():
        b = ch.to_record_batch()
        row = out.setdefault(ch.entity_path, {})
        for name in b.schema.names:
            if not name.startswith("rerun."):
                row[name] = b.column(name)[0]
    return out


def _image(entity: dict) -> np.ndarray:
    fmt = entity["SegmentationImage:format"].as_py()[0]
    buf = np.array(entity["SegmentationImage:buffer"].as_py()[0], dtype=np.uint8)
    assert fmt["channel_datatype"] == 6  # u8
    return buf.reshape(fmt["height"], fmt["width"])


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    out = tmp_path_factory.mktemp("map") / "s"
    scan(GRID, out)
    return out


@pytest.fixture(scope="module")
def decoded(folder, tmp_path_factory):
    rrd = tmp_path_factory.mktemp("rrd") / "map.rrd"
    write_scan_rrd(folder, rrd)
    return _decode(rrd)


def _screen(decoded, xy):
    """Where slice point ``xy`` lands in the 2-D view: the transform of /map applied (the view's y points down)."""
    sx, sy, _ = decoded["/map"]["Transform3D:scale"].as_py()[0]
    return np.array([xy[0] * sx, xy[1] * sy])


def test_the_map_has_image_points_axes_legend_and_the_definition(decoded):
    for entity in ("/map/outcome", "/map/cells", "/map/axes/lines", "/map/axes/x_ticks", "/map/axes/y_ticks",
                   "/map/axes/names", "/map/legend/swatches", "/map/legend/frames", "/map/legend/names", "/definition"):
        assert entity in decoded, entity
    assert decoded["/map/axes/names"]["Points2D:labels"].as_py() == ["x", "y"]
    infos = {e["class_id"]: e["class_description"]["info"] for e in decoded["/map"]["AnnotationContext:context"].as_py()[0]}
    for o, c in CLASS_IDS.items():
        r, g, b = OUTCOME_RGB[o]
        assert infos[c]["color"] == (r << 24) | (g << 16) | (b << 8) | 255  # the writeup's face colours
    assert infos[3]["label"] == "face 3" and infos[8]["label"] == "did not settle"


def test_the_legend_names_each_outcome_present_faces_first(decoded, folder):
    present = sorted(set(label_grid(folder).ravel().tolist()), key=lambda o: (o <= 0, o))
    names = decoded["/map/legend/names"]["Points2D:labels"].as_py()
    assert names == [f"face {o}" if o > 0 else {0: "undefined", -1: "did not settle"}[o] for o in present]
    swatches = _image(decoded["/map/legend/swatches"])[::-1, 0]  # top to bottom on screen
    assert swatches[::2].tolist() == [CLASS_IDS[o] for o in present] and not swatches[1::2].any()


def test_orientation_a_known_cell_at_a_known_corner(decoded, folder):
    grid = label_grid(folder)  # [i, j]: i along x, j along y
    img = _image(decoded["/map/outcome"])
    assert img.shape == (5, 7)  # rows along y, columns along x
    np.testing.assert_array_equal(img, class_ids(grid.T))
    # the image's pixel [row, col] covers [col, col + 1] × [row, row + 1] in its own frame, mapped to slice
    # coordinates by its transform and to the screen by /map's
    t = decoded["/map/outcome"]["Transform3D:translation"].as_py()[0]
    s = decoded["/map/outcome"]["Transform3D:scale"].as_py()[0]
    xs, ys = GRID.axes()

    def centre(row, col):
        return np.array([t[0] + (col + 0.5) * s[0], t[1] + (row + 0.5) * s[1]])

    np.testing.assert_allclose(centre(0, 0), (xs[0], ys[0]), atol=1e-6)      # pixel [0, 0] is grid point (x0, y0)
    np.testing.assert_allclose(centre(4, 6), (xs[-1], ys[-1]), atol=1e-6)
    top_left = _screen(decoded, centre(4, 0))  # grid point (x0, y1): smallest x and largest y
    corners = [_screen(decoded, centre(r, c)) for r in (0, 4) for c in (0, 6)]
    assert top_left[0] == min(p[0] for p in corners) and top_left[1] == min(p[1] for p in corners)  # on top
    assert img[4, 0] == class_ids(grid[0, 4])


def test_hover_points_hold_true_coordinates_and_rounded_labels(decoded, folder):
    df = read_scan(folder)
    pos = np.asarray(decoded["/map/cells"]["Points2D:positions"].as_py())
    np.testing.assert_allclose(pos, df[["x", "y"]].to_numpy(), rtol=1e-6)  # y as it is, not negated
    labels = decoded["/map/cells"]["Points2D:labels"].as_py()
    r = df.iloc[12]
    # cells 1/6 by 1/4 wide: 2 decimals tell neighbours apart
    assert labels[12] == f"x={r['x']:.2f}, y={r['y']:.2f}: face {r['outcome']}, {r['steps']} steps"
    assert max(len(s) for s in labels) < 40


def test_ticks_are_round_numbers_in_slice_coordinates(decoded):
    assert decoded["/map/axes/x_ticks"]["Points2D:labels"].as_py() == ["1.00", "1.25", "1.50", "1.75", "2.00"]
    assert decoded["/map/axes/y_ticks"]["Points2D:labels"].as_py() == ["3.50", "3.75", "4.00", "4.25", "4.50"]
    xt = np.asarray(decoded["/map/axes/x_ticks"]["Points2D:positions"].as_py())[:, 0]
    np.testing.assert_allclose(xt, [1.0, 1.25, 1.5, 1.75, 2.0], atol=1e-6)  # each label at its value
    assert nice_ticks(0.0, 0.1)[1] == ["0.00", "0.02", "0.04", "0.06", "0.08", "0.10"]
    assert nice_ticks(1.0, 2.0)[1] == ["1.0", "1.2", "1.4", "1.6", "1.8", "2.0"]
    assert nice_ticks(-10, 90)[1] == ["0", "20", "40", "60", "80"]
    assert nice_ticks(-0.35, 0.05)[1] == ["-0.3", "-0.2", "-0.1", "0.0"]


@pytest.mark.slow
@pytest.mark.long
def test_a_400_square_map_is_well_under_2_mb(tmp_path):
    out = tmp_path / "s"
    scan(Grid("seed", "red-sea", 400), out)
    rrd = tmp_path / "map.rrd"
    write_scan_rrd(out, rrd)
    size = rrd.stat().st_size
    assert size < 1.5e6, f"{size / 1e6:.2f} MB (the scatter of 17-digit labels took 14.6 MB)"
    d = _decode(rrd)
    assert _image(d["/map/outcome"]).shape == (400, 400)
    assert 400 * 400 > MAX_LABELLED and "Points2D:labels" not in d["/map/cells"]  # hover: position and face
    assert len(d["/map/cells"]["Points2D:positions"].as_py()) == 160_000
    grid = label_grid(out)
    assert _image(d["/map/outcome"])[399, 0] == class_ids(grid[0, 399])  # the top-left cell: (x0, y1)


def test_the_readme_states_the_label_limit():
    from pathlib import Path

    readme = " ".join((Path(__file__).resolve().parents[2] / "README.md").read_text().split())
    assert f"on grids of up to {MAX_LABELLED:,} cells also a label" in readme
