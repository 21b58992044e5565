"""Property tests (hypothesis) of the pure geometry: polygon clipping (step 2), Algorithm 1 (step 7), the
keypoint chain (step 8). tests/test_zone.py holds the basic Algorithm-1 invariants; here is what they
leave open: the clusters are exactly the runs of steps <= v, and they depend only on those steps.
"""

from __future__ import annotations

import cv2
import numpy as np
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from sena_warp.chain import keypoint_chain, validate_directions, walk_chain
from sena_warp.config import Config
from sena_warp.overlap import clip_polygon, polygon_area
from sena_warp.zone import Zone, cluster_classes

SETTINGS = settings(max_examples=60, deadline=None)
NAN = float("nan")

# --- polygon clipping ----------------------------------------------------------------------------


@st.composite
def convex_polygons(draw, max_abs=200):
    """Counter-clockwise or clockwise convex polygon (K >= 3, K, 2) float64 with area >= 1 px^2."""
    coords = draw(st.lists(st.tuples(st.integers(-max_abs, max_abs), st.integers(-max_abs, max_abs)),
                           min_size=3, max_size=12))
    hull = cv2.convexHull(np.array(coords, np.float32)).reshape(-1, 2).astype(np.float64)
    assume(len(hull) >= 3 and polygon_area(hull) >= 1.0)
    return hull[::-1] if draw(st.booleans()) else hull


def _inside_convex(pts, polygon, tol):
    """(N,) bool: points lie in the convex polygon (either orientation), within ``tol`` px of its edges."""
    (ax, ay), (bx, by) = polygon[1] - polygon[0], polygon[2] - polygon[1]
    sign = 1.0 if ax * by - ay * bx > 0 else -1.0
    inside = np.ones(len(pts), bool)
    for i in range(len(polygon)):
        start, end = polygon[i], polygon[(i + 1) % len(polygon)]
        edge = end - start
        dist = sign * (edge[0] * (pts[:, 1] - start[1]) - edge[1] * (pts[:, 0] - start[0])) / np.hypot(*edge)
        inside &= dist >= -tol
    return inside


def _tol(*polygons):
    return 1e-9 * max(1.0, max(np.abs(p).max() for p in polygons)) ** 2


@SETTINGS
@given(convex_polygons(), convex_polygons())
def test_clip_result_lies_in_both_and_is_no_larger(subject, clip):
    result = clip_polygon(subject, clip)
    area = polygon_area(result)
    assert area <= min(polygon_area(subject), polygon_area(clip)) + _tol(subject, clip)
    if len(result):
        assert _inside_convex(result, subject, 1e-6).all()
        assert _inside_convex(result, clip, 1e-6).all()


@SETTINGS
@given(convex_polygons())
def test_clip_by_itself_keeps_the_area(polygon):
    assert np.isclose(polygon_area(clip_polygon(polygon, polygon)), polygon_area(polygon), rtol=1e-9)
    assert np.isclose(polygon_area(clip_polygon(polygon, polygon[::-1])), polygon_area(polygon), rtol=1e-9)


@SETTINGS
@given(convex_polygons(), convex_polygons(), st.tuples(st.integers(-500, 500), st.integers(-500, 500)))
def test_clip_area_is_commutative_and_translation_invariant(subject, clip, shift):
    area = polygon_area(clip_polygon(subject, clip))
    tol = _tol(subject, clip) * 10
    assert abs(polygon_area(clip_polygon(clip, subject)) - area) <= tol
    shift = np.array(shift, np.float64)
    assert abs(polygon_area(clip_polygon(subject + shift, clip + shift)) - area) <= 100 * tol


@SETTINGS
@given(st.lists(st.floats(5, 150), min_size=5, max_size=16), convex_polygons(max_abs=120))
def test_non_convex_subject_clipped_by_convex_stays_inside_the_clip(radii, clip):
    """A star-shaped (possibly non-convex) subject, as a projected quadrilateral never is but may be."""
    angles = np.linspace(0, 2 * np.pi, len(radii), endpoint=False)
    subject = np.c_[np.cos(angles), np.sin(angles)] * np.array(radii)[:, None]
    result = clip_polygon(subject, clip)
    assert polygon_area(result) <= min(polygon_area(subject), polygon_area(clip)) + _tol(subject, clip)
    if len(result):
        assert _inside_convex(result, clip, 1e-6).all()


# --- Algorithm 1 (zone clustering) ----------------------------------------------------------------

class_means = st.lists(st.one_of(st.integers(-40, 40).map(float), st.just(NAN)), min_size=0, max_size=25)


@SETTINGS
@given(class_means, st.integers(0, 8).map(float))
def test_clusters_are_exactly_the_runs_of_small_steps(values, jump):
    means = np.array(values, np.float64)
    clusters = cluster_classes(means, jump)
    assert [c for cluster in clusters for c in cluster] == sorted(c for cluster in clusters for c in cluster)
    cluster_of = {c: k for k, cluster in enumerate(clusters) for c in cluster}
    joined = [not np.isnan(means[i:i + 2]).any() and abs(means[i + 1] - means[i]) <= jump
              for i in range(len(means) - 1)]
    for i, step_ok in enumerate(joined):
        # two neighbouring classes share a cluster exactly when the step between them is <= v
        assert (i in cluster_of and cluster_of.get(i) == cluster_of.get(i + 1)) == step_ok
    for i in range(len(means)):
        # a class is clustered exactly when it joins a neighbour (so every run of >= 2 classes is kept)
        assert (i in cluster_of) == ((i > 0 and joined[i - 1]) or (i < len(joined) and joined[i]))


@SETTINGS
@given(class_means, st.integers(0, 8).map(float), st.integers(-1000, 1000).map(float), st.sampled_from([0.25, 2.0, 8.0]))
def test_clusters_depend_only_on_the_steps(values, jump, offset, scale):
    """Adding one disparity to every class, or scaling means and v together, keeps the clusters (exact
    in binary floating point for these integers and powers of two)."""
    means = np.array(values, np.float64)
    clusters = cluster_classes(means, jump)
    assert cluster_classes(means + offset, jump) == clusters
    assert cluster_classes(means * scale, jump * scale) == clusters


# --- keypoint chain ---------------------------------------------------------------------------------

@st.composite
def matched_points(draw, max_n=30):
    """(pts_src, pts_tgt) float64 (N, 2) canvas points: target inside [20, 180]^2, source = target +
    a shared shift + per-point parallax of a few px, so both frames roughly agree."""
    n = draw(st.integers(1, max_n))
    coord = st.floats(20, 180, allow_nan=False)
    pts_tgt = np.array(draw(st.lists(st.tuples(coord, coord), min_size=n, max_size=n)), np.float64)
    jitter = np.array(draw(st.lists(st.tuples(st.floats(-6, 6), st.floats(-6, 6)), min_size=n, max_size=n)))
    shift = np.array(draw(st.tuples(st.floats(-10, 10), st.floats(-10, 10))))
    return pts_tgt + shift + jitter, pts_tgt


@SETTINGS
@given(matched_points())
def test_walk_goes_down_with_unique_x_to_the_nearest_free_point(pts):
    pts_src, pts_tgt = pts
    order = walk_chain(pts_src, pts_tgt)
    assert len(order) >= 1 and len(set(order.tolist())) == len(order)
    assert order[0] == np.argmin(pts_tgt[:, 1])
    assert np.all(np.diff(pts_tgt[order, 1]) > 0)
    for frame in (pts_tgt, pts_src):
        x_round = np.rint(frame[order, 0])
        assert len(np.unique(x_round)) == len(order)
    x_tgt, x_src = np.rint(pts_tgt[:, 0]), np.rint(pts_src[:, 0])
    for k in range(len(order)):
        here, used = order[k], order[:k + 1]
        free = ((pts_tgt[:, 1] > pts_tgt[here, 1]) & ~np.isin(x_tgt, x_tgt[used]) & ~np.isin(x_src, x_src[used]))
        if k + 1 == len(order):
            assert not free.any()  # the walk stops only when no point is left below
        else:
            dist = np.hypot(*(pts_tgt[free] - pts_tgt[here]).T)
            assert np.hypot(*(pts_tgt[order[k + 1]] - pts_tgt[here])) <= dist.min()


@SETTINGS
@given(matched_points())
def test_directional_validation_keeps_only_agreeing_downward_steps(pts):
    pts_src, pts_tgt = pts
    order = walk_chain(pts_src, pts_tgt)
    keep = validate_directions(pts_src[order], pts_tgt[order])
    assert keep[0]
    kept = order[keep]
    step_src, step_tgt = np.diff(pts_src[kept], axis=0), np.diff(pts_tgt[kept], axis=0)
    assert np.all(step_src[:, 0] * step_tgt[:, 0] >= 0)
    assert np.all(step_src[:, 1] > 0) and np.all(step_tgt[:, 1] > 0)
    # a rejected anchor really disagrees with the last anchor kept before it
    last = 0
    for i in range(1, len(order)):
        d_src = pts_src[order[i]] - pts_src[order[last]]
        d_tgt = pts_tgt[order[i]] - pts_tgt[order[last]]
        assert keep[i] == (d_src[0] * d_tgt[0] >= 0 and d_src[1] > 0)
        last = i if keep[i] else last


@SETTINGS
@given(matched_points(), st.integers(0, 60), st.integers(140, 199))
def test_keypoint_chain_anchors(pts, mask_top, mask_bottom):
    """Anchors go strictly down, have unique x (but the edge extensions), agree in x-direction between
    source and target, and each is an input match or an edge extension of the first/last one."""
    pts_src, pts_tgt = pts
    cfg = Config()
    grey = np.full((200, 200), 100.0, np.float32)  # uniform: every pair passes the brightness test
    mask = np.zeros((200, 200), bool)
    mask[mask_top:mask_bottom + 1, 10:190] = True
    zone = Zone(0.0, 200.0, np.arange(len(pts_tgt)), (), -1, True)
    anchors_src, anchors_tgt = keypoint_chain(zone, pts_src, pts_tgt, grey, grey, mask, cfg)
    assert anchors_src.shape == anchors_tgt.shape and anchors_tgt.shape[1] == 2
    assert np.all(np.diff(anchors_tgt[:, 1]) > 0) and np.all(np.diff(anchors_src[:, 1]) > 0)
    steps_src, steps_tgt = np.diff(anchors_src, axis=0), np.diff(anchors_tgt, axis=0)
    assert np.all(steps_src[:, 0] * steps_tgt[:, 0] >= 0)
    is_match = np.array([np.any(np.all(pts_tgt == t, axis=1) & np.all(pts_src == s, axis=1))
                         for s, t in zip(anchors_src, anchors_tgt)])
    assert is_match[1:-1].all()
    for end, neighbour, edge_y in ((0, 1, mask_top), (-1, -2, mask_bottom)):
        if not is_match[end]:
            assert len(anchors_tgt) >= 2 and is_match[neighbour]
            assert anchors_tgt[end, 1] == edge_y and anchors_tgt[end, 0] == anchors_tgt[neighbour, 0]
            # the extension shifts, it does not stretch: the source keeps its anchor's residual
            np.testing.assert_allclose(anchors_src[end] - anchors_tgt[end],
                                       anchors_src[neighbour] - anchors_tgt[neighbour], atol=1e-9)
    inner_x = np.rint(anchors_tgt[is_match, 0])
    assert len(np.unique(inner_x)) == len(inner_x)
