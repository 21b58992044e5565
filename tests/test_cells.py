"""Step 2: grid cells over the overlap (count, windows, centroids, bounding boxes, dropping)."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import read_pair
from test_global_affine import sift_matches

from sena_warp.canvas import Canvas
from sena_warp.cells import grid_cells
from sena_warp.config import Config
from sena_warp.global_affine import fit_global_affine
from sena_warp.overlap import Overlap, convex_polygon_mask, plan_overlap

CFG = Config(grid_x=2, grid_y=2)  # the hand-made cases below are laid out for a 2 x 2 grid


def _overlap_from_polygon(polygon_tgt: np.ndarray, canvas: Canvas) -> Overlap:
    polygon_canvas = canvas.tgt_to_canvas(polygon_tgt)
    return Overlap(
        canvas=canvas,
        polygon_tgt=polygon_tgt,
        polygon_canvas=polygon_canvas,
        mask_canvas=convex_polygon_mask(polygon_canvas, canvas.shape),
        corners_src_canvas=polygon_canvas[:4],
    )


def test_rectangle_overlap_gives_four_known_cells():
    affine = np.array([[1.0, 0.0, -300.0], [0.0, 1.0, 20.0]])  # overlap: target x 0..339, y 20..479
    overlap = plan_overlap((480, 640), (480, 640), affine, CFG)
    cells = grid_cells(overlap, CFG)
    assert [c.grid_index for c in cells] == [(0, 0), (0, 1), (1, 0), (1, 1)]
    assert [c.window_canvas for c in cells] == [
        (300, 20, 470, 250), (470, 20, 640, 250), (300, 250, 470, 480), (470, 250, 640, 480)
    ]
    first = cells[0]
    assert first.n_pixels == 170 * 230 and first.mask_window.shape == (230, 170)
    np.testing.assert_allclose(first.centroid_tgt, [84.5, 134.5])
    np.testing.assert_allclose(first.bbox_tgt, [0, 20, 169, 249])
    assert first.diag_px == pytest.approx(np.hypot(169, 229))
    np.testing.assert_allclose(cells[3].centroid_tgt, [254.5, 364.5])
    assert sum(c.n_pixels for c in cells) == overlap.mask_canvas.sum()


def test_cells_outside_a_triangular_overlap_are_dropped():
    canvas = Canvas(width=150, height=130, offset_tgt=(20.0, 10.0))
    triangle_tgt = np.array([[0.0, 0.0], [100.0, 0.0], [0.0, 100.0]])
    overlap = _overlap_from_polygon(triangle_tgt, canvas)
    cells = grid_cells(overlap, CFG.replace(grid_x=3, grid_y=3))
    # Grid edges 0, 34, 67, 101 in target x and y: the three cells beyond x + y = 100 are empty.
    assert [c.grid_index for c in cells] == [(0, 0), (0, 1), (0, 2), (1, 0), (1, 1), (2, 0)]
    np.testing.assert_allclose(cells[0].centroid_tgt, [16.5, 16.5])
    np.testing.assert_allclose(cells[0].bbox_tgt, [0, 0, 33, 33])
    # The corner cell (1, 1) is cut by the hypotenuse: its box shrinks to its own pixels.
    corner = cells[4]
    assert corner.bbox_tgt[2] + corner.bbox_tgt[1] <= 100 and corner.n_pixels < 33 * 33
    # Cell centroids weighted by pixel counts give the centroid of the whole overlap mask.
    ys, xs = np.nonzero(overlap.mask_canvas)
    centre_tgt = canvas.canvas_to_tgt(np.array([[xs.mean(), ys.mean()]]))[0]
    weighted = sum(c.n_pixels * c.centroid_tgt for c in cells) / sum(c.n_pixels for c in cells)
    np.testing.assert_allclose(weighted, centre_tgt, atol=1e-9)


def test_empty_overlap_has_no_cells():
    canvas = Canvas(width=40, height=30, offset_tgt=(0.0, 0.0))
    assert grid_cells(_overlap_from_polygon(np.zeros((0, 2)), canvas), CFG) == []


def test_real_pair_cells_tile_the_overlap(bundled_dir):
    img_a, img_b = read_pair(bundled_dir / "udisd_test_000001")
    glob = fit_global_affine(*sift_matches(img_a, img_b), CFG)
    overlap = plan_overlap(img_a.shape, img_b.shape, glob.affine_src_to_tgt, CFG)
    cells = grid_cells(overlap, CFG)
    assert len(cells) == CFG.grid_x * CFG.grid_y
    assert sum(c.n_pixels for c in cells) == overlap.mask_canvas.sum()
    for cell in cells:
        x, y = np.round(overlap.canvas.tgt_to_canvas(cell.centroid_tgt[None])[0]).astype(int)
        assert overlap.mask_canvas[y, x]
        assert 0 <= cell.bbox_tgt[0] <= cell.centroid_tgt[0] <= cell.bbox_tgt[2] <= img_b.shape[1] - 1
