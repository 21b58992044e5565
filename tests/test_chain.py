"""Step 8, keypoint chain: brightness test, nearest-next walk, unique x, directional validation, edges."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from sena_warp.chain import (
    brightness_consistent,
    extend_to_edges,
    keypoint_chain,
    validate_directions,
    walk_chain,
)
from sena_warp.config import Config
from sena_warp.errors import GeometryError
from sena_warp.imageio import read_image
from sena_warp.zone import Zone


def test_brightness_consistent_compares_patch_means():
    grey_src = np.full((40, 40), 100.0, np.float32)
    grey_tgt = np.full((40, 40), 100.0, np.float32)
    grey_tgt[:, 20:] = 130.0  # 30 grey levels brighter on the right
    grey_tgt[30:, :] = np.nan  # not covered
    pts_src = np.array([[10.0, 10.0], [10.0, 10.0], [10.0, 10.0]])
    pts_tgt = np.array([[10.0, 10.0], [30.0, 10.0], [10.0, 29.0]])
    cfg = Config(brightness_max_diff=25.0, flat_patch_px=5)
    assert brightness_consistent(grey_src, grey_tgt, pts_src, pts_tgt, cfg).tolist() == [True, False, False]
    assert brightness_consistent(grey_src, grey_tgt, pts_src, pts_tgt, cfg.replace(brightness_max_diff=30.0)).tolist() == [
        True,
        True,
        False,
    ]


def test_walk_takes_nearest_point_further_down_with_unique_x():
    pts_tgt = np.array(
        [
            [52.0, 20.0],  # 0: B
            [50.0, 10.0],  # 1: A, the top-most: start
            [50.2, 15.0],  # 2: nearest below A but same integer x as A: skipped
            [55.0, 30.0],  # 3: C
            [120.0, 25.0],  # 4: far distractor, passed by the walk (above D when the walk is at C)
            [53.0, 40.0],  # 5: D
            [70.0, 31.0],  # 6: below C but farther from C (15.0) than D (10.2)
        ]
    )
    pts_src = pts_tgt + [3.0, 0.0]
    assert walk_chain(pts_src, pts_tgt).tolist() == [1, 0, 3, 5]


def test_walk_skips_repeated_source_x():
    pts_tgt = np.array([[10.0, 0.0], [20.0, 5.0], [30.0, 12.0]])
    pts_src = np.array([[10.0, 0.0], [10.4, 5.0], [31.0, 12.0]])  # point 1 reuses source x 10
    assert walk_chain(pts_src, pts_tgt).tolist() == [0, 2]
    assert walk_chain(np.zeros((0, 2)), np.zeros((0, 2))).tolist() == []


def test_directional_validation_rejects_opposite_x_steps():
    tgt = np.array([[10.0, 0.0], [20.0, 10.0], [15.0, 20.0], [25.0, 30.0], [30.0, 40.0]])
    src = np.array([[12.0, 1.0], [22.0, 11.0], [24.0, 21.0], [27.0, 31.0], [33.0, 30.5]])
    # step 1->2: tgt goes left (20 -> 15), src goes right (22 -> 24): rejected; step 1->3 is then
    # checked against anchor 1 (right in both: kept); step 3->4 goes up in the source: rejected.
    assert validate_directions(src, tgt).tolist() == [True, True, False, True, False]


def test_extend_to_edges_uses_overlap_column_and_keeps_residual():
    mask = np.zeros((100, 60), bool)
    mask[5:95, 10:50] = True
    mask[:8, 30:] = False  # column 40 starts at row 8
    tgt = np.array([[20.0, 30.0], [40.2, 60.0]])
    src = np.array([[22.0, 32.0], [41.0, 61.5]])
    src_ext, tgt_ext, is_edge = extend_to_edges(src, tgt, mask)
    assert is_edge.tolist() == [True, False, False, True]
    np.testing.assert_allclose(tgt_ext, [[20.0, 5.0], [20.0, 30.0], [40.2, 60.0], [40.2, 94.0]])
    np.testing.assert_allclose(src_ext, [[22.0, 7.0], [22.0, 32.0], [41.0, 61.5], [41.0, 95.5]])
    on_edge = np.array([[20.0, 5.0], [40.0, 94.0]])
    assert extend_to_edges(on_edge, on_edge, mask)[2].tolist() == [False, False]


def test_keypoint_chain_on_real_image_with_known_shift(bundled_dir):
    """Target = a real image; warped source = the same image 7 px right, 3 px down (a pure shift)."""
    grey = cv2.cvtColor(read_image(bundled_dir / "udisd_test_000001" / "a.jpg"), cv2.COLOR_BGR2GRAY)
    grey_tgt = grey.astype(np.float32)
    grey_src = np.full_like(grey_tgt, np.nan)
    grey_src[3:, 7:] = grey_tgt[:-3, :-7]
    corners = cv2.goodFeaturesToTrack(grey, 400, 0.01, 5).reshape(-1, 2).astype(np.float64)
    inside = (corners[:, 0] > 150) & (corners[:, 0] < 350) & (corners[:, 1] > 15) & (corners[:, 1] < 495)
    pts_tgt = corners[inside]
    pts_src = pts_tgt + [7.0, 3.0]
    # the top-most match sees a source 60 grey levels brighter (exposure flare): it must not start the chain
    bad = int(np.argmin(pts_tgt[:, 1]))
    bx, by = np.rint(pts_src[bad]).astype(int)
    grey_src[by - 5 : by + 6, bx - 5 : bx + 6] += 60.0
    mask = np.zeros(grey.shape, bool)
    mask[10:500, 100:400] = True
    zone = Zone(150.0, 350.0, np.arange(len(pts_tgt)), (), -1, True)
    anchors_src, anchors_tgt = keypoint_chain(zone, pts_src, pts_tgt, grey_src, grey_tgt, mask, Config())
    # edge extensions first and last, on the overlap's top and bottom rows
    assert anchors_tgt[0, 1] == 10.0 and anchors_tgt[-1, 1] == 499.0
    inner_tgt = anchors_tgt[1:-1]
    assert len(inner_tgt) >= 5
    assert np.all(np.diff(anchors_tgt[:, 1]) > 0)
    x_int = np.rint(inner_tgt[:, 0])
    assert len(np.unique(x_int)) == len(x_int)
    np.testing.assert_allclose(anchors_src - anchors_tgt, np.tile([7.0, 3.0], (len(anchors_tgt), 1)))
    # every inner anchor is one of the matches, and the flared one is not among them
    assert all(np.any(np.all(pts_tgt == a, axis=1)) for a in inner_tgt)
    assert not np.any(np.all(inner_tgt == pts_tgt[bad], axis=1))


def test_keypoint_chain_without_consistent_brightness_is_a_geometry_error():
    grey_src = np.zeros((50, 50), np.float32)
    grey_tgt = np.full((50, 50), 200.0, np.float32)
    pts = np.array([[20.0, 20.0], [25.0, 30.0]])
    zone = Zone(0.0, 50.0, np.arange(2), (), -1, True)
    with pytest.raises(GeometryError, match="brightness_max_diff"):
        keypoint_chain(zone, pts, pts, grey_src, grey_tgt, np.ones((50, 50), bool), Config())
