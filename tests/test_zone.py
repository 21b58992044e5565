"""Step 7, adequate zone: Algorithm 1, the cluster score, the zone and its fallback, on hand-made cases."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sena_warp.config import Config
from sena_warp.errors import GeometryError
from sena_warp.zone import (
    adequate_zone,
    cluster_classes,
    cluster_score,
    disparity_classes,
    patch_values,
    textured,
)

NAN = float("nan")


def test_algorithm1_paper_example_drops_singletons():
    means = np.array([0.0, 1.0, 1.5, 9.0, 9.5, 10.0, 30.0])
    assert cluster_classes(means, 2.0) == [[0, 1, 2], [3, 4, 5]]


def test_algorithm1_compares_with_previous_class_not_cluster_start():
    # 0 -> 2 -> 4 -> 6: each step is 2 <= v although the ends differ by 6 (Algorithm 1 line 4).
    assert cluster_classes(np.array([0.0, 2.0, 4.0, 6.0]), 2.0) == [[0, 1, 2, 3]]
    assert cluster_classes(np.array([0.0, 2.1, 4.2]), 2.0) == []


def test_algorithm1_empty_class_breaks_the_cluster():
    means = np.array([0.0, 1.0, NAN, 1.5, 2.0, NAN, 3.0])
    assert cluster_classes(means, 2.0) == [[0, 1], [3, 4]]


@settings(max_examples=200, deadline=None)
@given(
    st.lists(st.one_of(st.floats(-50, 50), st.just(NAN)), min_size=0, max_size=30),
    st.floats(0.1, 10.0),
)
def test_algorithm1_invariants(values, jump):
    means = np.array(values, dtype=np.float64)
    clusters = cluster_classes(means, jump)
    seen = [c for cluster in clusters for c in cluster]
    assert len(seen) == len(set(seen))  # every class in at most one cluster
    for cluster in clusters:
        assert len(cluster) >= 2
        assert cluster == list(range(cluster[0], cluster[-1] + 1))  # contiguous
        assert not np.isnan(means[cluster]).any()
        assert np.all(np.abs(np.diff(means[cluster])) <= jump)
    # maximal: a non-empty class next to a cluster within v would have been joined
    for cluster in clusters:
        nxt = cluster[-1] + 1
        if nxt < len(means) and not np.isnan(means[nxt]):
            assert abs(means[nxt] - means[cluster[-1]]) > jump


def test_cluster_score_hand_computed():
    # sigma = std([1, 3]) = 1, mu_c = 2, |mu_c - mu_g| = 3: w = 40 / (1 + 0.5 * 3 + 1.5) = 10.
    assert cluster_score(40, np.array([1.0, 3.0]), 5.0, 0.5, 1.5) == pytest.approx(10.0)


def test_tight_populous_cluster_beats_loose_one():
    global_mean = np.mean([0.0, 0.1, 5.0, 6.5, 8.0])  # 3.92
    tight = cluster_score(100, np.array([0.0, 0.1]), global_mean, 1.0, 1e-3)
    loose = cluster_score(30, np.array([5.0, 6.5, 8.0]), global_mean, 1.0, 1e-3)
    assert tight == pytest.approx(100 / (0.05 + 3.87 + 1e-3))
    assert loose == pytest.approx(30 / (np.std([5.0, 6.5, 8.0]) + 2.58 + 1e-3))
    assert tight > loose


def test_disparity_classes_bins_and_means():
    x = np.array([100.0, 119.9, 120.0, 150.0, 299.0, 400.0])
    d = np.array([1.0, 3.0, 5.0, 7.0, 9.0, 11.0])
    classes = disparity_classes(x, d, 100.0, 300.0, 10)
    assert classes.class_of_point.tolist() == [0, 0, 1, 2, 9, 9]
    assert classes.counts.tolist() == [2, 1, 1, 0, 0, 0, 0, 0, 0, 2]
    np.testing.assert_allclose(classes.means_px[[0, 1, 2, 9]], [2.0, 5.0, 7.0, 10.0])
    assert np.isnan(classes.means_px[3:9]).all()


def test_patch_values_outside_canvas_are_nan_and_flat_is_detected():
    grey = np.zeros((20, 30), np.float32)
    grey[:, 15:] = np.tile(np.array([0.0, 100.0], np.float32), 8)[: 15]
    pts = np.array([[5.0, 5.0], [22.0, 10.0], [0.0, 0.0]])
    patches = patch_values(grey, pts, 3)
    assert patches.shape == (3, 9)
    assert np.isnan(patches[2]).sum() == 5  # top-left corner: one row and one column outside
    assert textured(grey, pts, Config(flat_patch_px=3, flat_min_std=4.0)).tolist() == [False, True, False]


def _scene(rng, disparity_by_class, points_per_class, flat_box=None):
    """Canvas 200 x 400 with the overlap over columns [100, 300) and 10 classes of 20 px."""
    grey_tgt = rng.uniform(0, 255, (200, 400)).astype(np.float32)
    if flat_box is not None:
        y0, y1, x0, x1 = flat_box
        grey_tgt[y0:y1, x0:x1] = 128.0
    grey_src = rng.uniform(0, 255, (200, 400)).astype(np.float32)
    mask = np.zeros((200, 400), bool)
    mask[:, 100:300] = True
    pts_tgt, pts_src = [], []
    for k, (d, n) in enumerate(zip(disparity_by_class, points_per_class)):
        x = rng.uniform(100 + 20 * k + 2, 100 + 20 * k + 18, n)
        y = rng.uniform(20, 180, n)
        pts_tgt.append(np.column_stack([x, y]))
        pts_src.append(np.column_stack([x + d + rng.normal(0, 0.2, n), y]))
    return np.vstack(pts_src), np.vstack(pts_tgt), mask, grey_src, grey_tgt


def test_adequate_zone_picks_the_dominant_cluster():
    rng = np.random.default_rng(7)
    disparities = [0.0, 0.5, 0.2, 0.4, 10.0, 11.0, 30.0, 35.0, 40.0, 45.0]
    counts = [30, 30, 30, 30, 3, 3, 5, 5, 5, 5]
    pts_src, pts_tgt, mask, grey_src, grey_tgt = _scene(rng, disparities, counts)
    zone = adequate_zone(pts_src, pts_tgt, mask, grey_src, grey_tgt, Config(zone_classes=10))
    assert not zone.fallback
    assert [c.classes for c in zone.clusters] == [(0, 1, 2, 3), (4, 5)]
    assert zone.chosen == 0
    assert (zone.x0, zone.x1) == pytest.approx((100.0, 180.0))
    assert sorted(zone.point_indices.tolist()) == list(range(120))


def test_flat_points_are_dropped_before_clustering():
    rng = np.random.default_rng(8)
    disparities = [0.0, 0.5, 0.2, 0.4, 10.0, 11.0, 30.0, 35.0, 40.0, 45.0]
    counts = [30, 30, 30, 30, 3, 3, 5, 5, 5, 5]
    pts_src, pts_tgt, mask, grey_src, grey_tgt = _scene(rng, disparities, counts, flat_box=(0, 16, 120, 140))
    # 40 wild matches (disparity 50) in class 1, inside a flat target area: they must not count
    # (with them class 1's mean would be ~29 and break the run of classes 0..3).
    wild_tgt = np.column_stack([rng.uniform(124, 136, 40), rng.uniform(4, 12, 40)])
    wild_src = wild_tgt + [50.0, 0.0]
    cfg = Config(zone_classes=10)
    zone = adequate_zone(
        np.vstack([pts_src, wild_src]), np.vstack([pts_tgt, wild_tgt]), mask, grey_src, grey_tgt, cfg
    )
    assert [c.classes for c in zone.clusters] == [(0, 1, 2, 3), (4, 5)]
    assert sorted(zone.point_indices.tolist()) == list(range(120))


def test_unconverged_forward_points_are_dropped_without_a_cast_warning():
    """forward_points gives NaN for a source point it cannot place; step 7 drops it, explicitly."""
    rng = np.random.default_rng(7)
    disparities = [0.0, 0.5, 0.2, 0.4, 10.0, 11.0, 30.0, 35.0, 40.0, 45.0]
    pts_src, pts_tgt, mask, grey_src, grey_tgt = _scene(rng, disparities, [30, 30, 30, 30, 3, 3, 5, 5, 5, 5])
    pts_src[[3, 50]] = np.nan  # two of the dominant cluster's points did not converge
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # numpy's "invalid value encountered in cast" would raise here
        zone = adequate_zone(pts_src, pts_tgt, mask, grey_src, grey_tgt, Config(zone_classes=10))
    assert (zone.x0, zone.x1) == pytest.approx((100.0, 180.0))
    assert sorted(zone.point_indices.tolist()) == sorted(set(range(120)) - {3, 50})
    assert np.isnan(patch_values(grey_src, pts_src[[3]], 7)).all()


def test_no_cluster_falls_back_to_whole_overlap():
    rng = np.random.default_rng(9)
    disparities = [0.0, 5.0, 10.0, 15.0, 20.0, 25.0, 30.0, 35.0, 40.0, 45.0]
    pts_src, pts_tgt, mask, grey_src, grey_tgt = _scene(rng, disparities, [10] * 10)
    zone = adequate_zone(pts_src, pts_tgt, mask, grey_src, grey_tgt, Config(zone_classes=10))
    assert zone.fallback and zone.chosen == -1 and zone.clusters == ()
    assert (zone.x0, zone.x1) == (100.0, 300.0)
    assert len(zone.point_indices) == 100


def test_empty_overlap_is_a_geometry_error():
    grey = np.zeros((10, 10), np.float32)
    with pytest.raises(GeometryError):
        adequate_zone(np.zeros((0, 2)), np.zeros((0, 2)), np.zeros((10, 10), bool), grey, grey, Config())
