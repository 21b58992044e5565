"""Step 2: Sutherland-Hodgman clipping, overlap polygon and mask, canvas planning and refusals."""

from __future__ import annotations

import tracemalloc

import cv2
import numpy as np
import pytest

from sena_warp.config import Config
from sena_warp.errors import GeometryError
from sena_warp.overlap import clip_polygon, convex_polygon_mask, plan_overlap, polygon_area, rectangle_corners

CFG = Config()
SQUARE_10 = np.array([[0, 0], [10, 0], [10, 10], [0, 10]], dtype=np.float64)


def _inside_convex(pts: np.ndarray, polygon: np.ndarray, tol: float = 1e-9) -> bool:
    """All points inside (or on) a convex polygon, either orientation."""
    edges = np.roll(polygon, -1, axis=0) - polygon
    rel = pts[:, None, :] - polygon[None, :, :]
    cross = edges[None, :, 0] * rel[..., 1] - edges[None, :, 1] * rel[..., 0]
    return bool(np.all(cross >= -tol) or np.all(cross <= tol))


@pytest.mark.parametrize("reverse_clip", [False, True])
def test_square_clipped_by_shifted_square(reverse_clip):
    clip = SQUARE_10 + 5.0
    result = clip_polygon(SQUARE_10, clip[::-1] if reverse_clip else clip)
    assert polygon_area(result) == pytest.approx(25.0)
    assert sorted(map(tuple, result)) == [(5, 5), (5, 10), (10, 5), (10, 10)]


def test_triangle_clipped_by_square_loses_its_corner():
    triangle = np.array([[0, 0], [20, 0], [0, 20]], dtype=np.float64)
    clip = SQUARE_10 + 5.0  # [5, 15]^2; x + y > 20 cuts off a right triangle of legs 10
    assert polygon_area(clip_polygon(triangle, clip)) == pytest.approx(100.0 - 50.0)
    assert polygon_area(clip_polygon(triangle[::-1], clip)) == pytest.approx(50.0)


def test_disjoint_polygons_give_an_empty_result():
    result = clip_polygon(SQUARE_10, SQUARE_10 + [30.0, 0.0])
    assert result.shape == (0, 2) and polygon_area(result) == 0.0


def test_containment_returns_the_inner_polygon():
    inner = SQUARE_10 * 0.2 + 3.0
    np.testing.assert_allclose(clip_polygon(inner, SQUARE_10), inner)
    assert polygon_area(clip_polygon(SQUARE_10, inner)) == pytest.approx(polygon_area(inner))


def test_random_convex_pairs_match_opencv_and_stay_inside_both():
    rng = np.random.default_rng(11)
    for _ in range(200):
        subject = cv2.convexHull(rng.uniform(0, 100, size=(6, 2)).astype(np.float32))[:, 0].astype(np.float64)
        clip = cv2.convexHull(rng.uniform(20, 120, size=(5, 2)).astype(np.float32))[:, 0].astype(np.float64)
        result = clip_polygon(subject, clip)
        area_cv, _ = cv2.intersectConvexConvex(subject.astype(np.float32), clip.astype(np.float32))
        assert polygon_area(result) == pytest.approx(max(area_cv, 0.0), abs=1e-3)
        assert polygon_area(result) <= min(polygon_area(subject), polygon_area(clip)) + 1e-9
        if len(result):
            assert _inside_convex(result, subject, 1e-6) and _inside_convex(result, clip, 1e-6)


def test_mask_counts_pixel_centres_inside_the_polygon():
    mask = convex_polygon_mask(np.array([[2.0, 1.0], [2.0, 6.0], [9.0, 6.0], [9.0, 1.0]]), (10, 12))
    expected = np.zeros((10, 12), dtype=bool)
    expected[1:7, 2:10] = True  # centres on the edges are inside
    np.testing.assert_array_equal(mask, expected)
    triangle = np.array([[0.0, 0.0], [200.0, 0.0], [0.0, 100.0]])
    # Pick's theorem: lattice points in or on a lattice polygon = area + boundary points / 2 + 1;
    # the boundary holds 200 + 100 + gcd(200, 100) = 400 lattice points.
    assert convex_polygon_mask(triangle, (120, 220)).sum() == polygon_area(triangle) + 400 / 2 + 1


def test_translation_gives_the_expected_canvas_polygon_and_mask():
    affine = np.array([[1.0, 0.0, -300.0], [0.0, 1.0, 20.0]])  # source 300 px left, 20 px down
    overlap = plan_overlap((480, 640, 3), (480, 640), affine, CFG)
    canvas = overlap.canvas
    assert (canvas.width, canvas.height, canvas.offset_tgt) == (940, 500, (300.0, 0.0))
    assert polygon_area(overlap.polygon_tgt) == pytest.approx(339.0 * 459.0)
    np.testing.assert_allclose(overlap.polygon_canvas, overlap.polygon_tgt + [300.0, 0.0])
    expected = np.zeros(canvas.shape, dtype=bool)
    expected[20:480, 300:640] = True
    np.testing.assert_array_equal(overlap.mask_canvas, expected)
    np.testing.assert_allclose(overlap.corners_src_canvas, rectangle_corners(640, 480) + [0.0, 20.0])


def test_sizes_may_differ_and_the_canvas_covers_both():
    affine = np.array([[0.8, -0.1, -200.0], [0.1, 0.8, -40.0]])
    overlap = plan_overlap((600, 800), (400, 500), affine, CFG)
    canvas = overlap.canvas
    corners_tgt_canvas = canvas.tgt_to_canvas(rectangle_corners(500, 400))
    for pts in (corners_tgt_canvas, overlap.corners_src_canvas):
        assert pts.min() >= 0 and (pts[:, 0].max() <= canvas.width - 1) and (pts[:, 1].max() <= canvas.height - 1)
    assert canvas.offset_tgt == tuple(float(int(v)) for v in canvas.offset_tgt)  # target pasted unresampled
    assert overlap.mask_canvas.sum() == pytest.approx(polygon_area(overlap.polygon_tgt), rel=0.02)


def test_huge_canvas_is_refused_before_anything_canvas_sized_is_allocated():
    affine = np.array([[40.0, 0.0, 0.0], [0.0, 40.0, 0.0]])  # a 25561 x 19161 canvas: 490 MB of bool mask
    tracemalloc.start()
    try:
        with pytest.raises(GeometryError, match=r"25561 x 19161 px canvas.*limit 4\.0x"):
            plan_overlap((480, 640), (480, 640), affine, CFG)
        _, peak_bytes = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak_bytes < 1_000_000


@pytest.mark.parametrize(
    "affine, message",
    [
        (np.array([[-1.0, 0.0, 600.0], [0.0, 1.0, 0.0]]), "mirrors"),
        (np.array([[0.1, 0.0, 10.0], [0.0, 0.1, 10.0]]), "shrinks"),
        (np.array([[1.0, 0.0, 1500.0], [0.0, 1.0, 0.0]]), "no overlap"),
    ],
)
def test_implausible_models_are_geometry_errors(affine, message):
    with pytest.raises(GeometryError, match=message):
        plan_overlap((480, 640), (480, 640), affine, CFG)
