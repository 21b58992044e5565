"""A moving rig's alignment every frame (``video/align.py``), on a real picture with known warps.

The views are two crops of the bundled UDIS-D picture on a canvas in the picture's own coordinates,
so the right source map is the identity; the key map is made wrong by a known amount, or the source
view drifts at a known speed, and the alignment must find the identity again: the residual flow at the
target's corners, the lattice fit (also with wrong points among them), the filter's lag, and the two
copies of a point the warp leaves off.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from sena_warp.config import Config
from sena_warp.video.align import (Alignment, CorrectionFit, FrameAlignment, LagBoundedFilter, OverlapGrid, Seam,
                                   TargetPoints, copies_apart, corners_in, reduction, residual_flow, small_plane,
                                   small_to_full)

CFG = Config(device="cpu")
SRC_COLS = (0, 300)  # the source view: these picture columns; the target view ...
TGT_COLS = (180, 480)  # ... these: they overlap on picture columns 180-300
OFFSET = np.array([float(TGT_COLS[0]), 0.0])  # the target's canvas offset: the canvas is the picture
CANVAS = (512, 480)  # (rows, cols)
IDENTITY = np.dstack(np.meshgrid(np.arange(CANVAS[1], dtype=np.float32), np.arange(CANVAS[0], dtype=np.float32)))


@pytest.fixture(scope="module")
def picture(udisd_pair) -> np.ndarray:
    return cv2.cvtColor(udisd_pair[0], cv2.COLOR_BGR2GRAY)


def views(picture: np.ndarray, drift_px: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """(source, target) Y planes; the source's content moved ``drift_px`` to the left (bilinear)."""
    move = np.float32([[1, 0, -drift_px], [0, 1, 0]])
    source = cv2.warpAffine(picture, move, picture.shape[::-1], flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
    return (np.ascontiguousarray(source[:, SRC_COLS[0]:SRC_COLS[1]]),
            np.ascontiguousarray(picture[:, TGT_COLS[0]:TGT_COLS[1]]))


def overlap_error(map_src: np.ndarray, truth: np.ndarray) -> float:
    """The largest |map - truth| over the canvas columns both views show (the overlap)."""
    part = (slice(20, -20), slice(TGT_COLS[0] + 10, SRC_COLS[1] - 10))
    return float(np.abs(map_src[part] - truth[part]).max())


def test_the_filter_settles_on_a_step_follows_a_ramp_and_never_lags_more_than_its_bound():
    steady = LagBoundedFilter(0.5, 1.0)
    values = [float(steady.update(np.array([0.0 if t < 5 else 4.0]))[0]) for t in range(40)]
    assert values[4] == 0.0 and values[5] == pytest.approx(3.0)  # clipped: at most 1.0 behind the measurement
    assert abs(values[-1] - 4.0) < 1e-3
    ramp = LagBoundedFilter(0.5, 1.0)
    lags = [t * 0.8 - float(ramp.update(np.array([t * 0.8]))[0]) for t in range(60)]
    assert max(abs(lag) for lag in lags) <= 1.0 + 1e-9 and abs(lags[-1]) < 1e-3  # no lag on a steady drift
    noisy = LagBoundedFilter(0.5, 10.0)
    noise = np.random.default_rng(1).normal(0.0, 1.0, 400)
    out = np.array([float(noisy.update(np.array([v]))[0]) for v in noise])
    assert out[50:].std() < 0.7 * noise[50:].std()  # measured 0.54 of the noise


def test_the_fit_recovers_a_smooth_correction_and_drops_wrong_points():
    fit = CorrectionFit(CANVAS, CFG)
    rng = np.random.default_rng(0)
    pts = np.column_stack([rng.uniform(180, 300, 300), rng.uniform(0, 511, 300)])
    truth = np.column_stack([2.0 + 0.01 * (pts[:, 1] - 256), -1.5 + 0.005 * (pts[:, 0] - 240)])
    residual = truth.copy()
    wrong = rng.choice(300, 40, replace=False)
    residual[wrong] += rng.uniform(15, 30, (40, 2))  # a near object's points: far off the rest
    lattice, error, weights = fit.fit(pts, residual, np.zeros((*fit.shape, 2)))
    assert (weights[wrong] == 0).all() and (weights > 0).sum() >= 250
    kept = np.setdiff1d(np.arange(300), wrong)
    assert np.median(error[kept]) < 0.05 and error[kept].max() < 0.3


@pytest.mark.parametrize("error_px", [(0.0, 0.0), (2.5, -1.5), (-4.0, 3.0)])
def test_residual_flow_reads_how_far_the_warp_is_off(picture, error_px):
    y_src, y_tgt = views(picture)
    key = (IDENTITY + np.float32(error_px)).astype(np.float32)
    overlap = OverlapGrid(key, OFFSET, y_src.shape, y_tgt.shape, 1)
    points = TargetPoints(CFG).update(y_tgt, overlap.mask)
    flow, kept = residual_flow(y_src, y_tgt, key, overlap, points, (1.0, 0.0, 1.0, 0.0), 1, CFG.video_align_window_px)
    assert kept.mean() > 0.8
    assert np.allclose(np.median(flow[kept], axis=0), -np.array(error_px), atol=0.05)


def test_a_reduced_plane_measures_in_full_canvas_px(picture):
    # The same views twice as large: the alignment works on them halved and must answer in full px.
    y_src, y_tgt = (cv2.resize(v, None, fx=2, fy=2, interpolation=cv2.INTER_CUBIC) for v in views(picture))
    key = (IDENTITY_2X + np.float32([3.0, -2.0])).astype(np.float32)
    factor = reduction((y_src.shape, y_tgt.shape), CFG)
    assert factor == 2  # 600 columns / 360
    small_src, small_tgt = small_plane(y_src, factor), small_plane(y_tgt, factor)
    overlap = OverlapGrid(key, 2 * OFFSET, y_src.shape, small_tgt.shape, factor)
    points = TargetPoints(CFG).update(small_tgt, overlap.mask)
    flow, kept = residual_flow(small_src, small_tgt, key, overlap, points, (1.0, 0.0, 1.0, 0.0), factor,
                               CFG.video_align_window_px)
    assert kept.mean() > 0.8 and np.allclose(np.median(flow[kept], axis=0), [-3.0, 2.0], atol=0.1)
    assert np.allclose(small_to_full(np.array([[0.0, 0.0], [10.0, 4.0]]), 2), [[0.5, 0.5], [20.5, 8.5]])


IDENTITY_2X = np.dstack(np.meshgrid(np.arange(2 * CANVAS[1], dtype=np.float32),
                                    np.arange(2 * CANVAS[0], dtype=np.float32)))


def test_a_wrong_key_map_is_corrected_within_a_few_frames(picture):
    y_src, y_tgt = views(picture)
    key = (IDENTITY + np.float32([3.0, -2.0])).astype(np.float32)
    align = FrameAlignment(key, OFFSET, (y_src.shape, y_tgt.shape), CFG)
    assert overlap_error(align.map_src, IDENTITY) == pytest.approx(3.0)
    errors = []
    for _ in range(20):
        align.step(y_src, y_tgt, (1.0, 0.0, 1.0, 0.0))
        errors.append(overlap_error(align.map_src, IDENTITY))
    # The first frame takes half the measured change, then no less than all of it but
    # video_align_max_lag_px: 1 px off in x and y.
    assert errors[0] == pytest.approx(CFG.video_align_max_lag_px, abs=0.3)  # measured 1.21 (the max over the overlap)
    assert errors[-1] < 0.15  # measured 0.06 px (0.38 at most on the way: the velocity term overshoots a step)


def test_a_drifting_source_is_followed_with_bounded_lag(picture):
    speed = 0.6  # px a frame: two hand-held phones drifting apart, fast
    y_src, y_tgt = views(picture)
    align = FrameAlignment(IDENTITY.copy(), OFFSET, (y_src.shape, y_tgt.shape), CFG)
    lags = []
    for t in range(30):
        y_src, _ = views(picture, speed * t)
        align.step(y_src, y_tgt, (1.0, 0.0, 1.0, 0.0))
        truth = IDENTITY - np.float32([speed * t, 0.0])  # canvas u shows source column u - drift
        lags.append(overlap_error(align.map_src, truth))
    # Measured: 0.99 px at most (the sixth frame: the bound holds it), 0.07-0.13 px over the last ten: the
    # velocity term takes the drift up.
    assert max(lags) <= CFG.video_align_max_lag_px + 0.05 and max(lags[-10:]) < 0.2


def test_copies_of_a_point_the_warp_leaves_off():
    map_src = IDENTITY.copy()
    pts = np.array([[200.0, 100.0], [250.0, 300.0], [260.0, 400.0]])
    targets = pts + np.array([[0.0, 0.0], [6.0, 0.0], [-3.0, 4.0]])  # the source pixels they should show
    alignment = Alignment(np.zeros((2, 2, 2)), pts, targets, np.ones(3), np.zeros(3), 0)
    tgt_copies, src_copies = copies_apart(alignment, map_src, 2.0)
    assert np.allclose(tgt_copies, pts[1:]) and np.allclose(src_copies, targets[1:], atol=1e-3)


@pytest.mark.parametrize("box", [(40, 300, 100, 160), (0, 512, 0, 50), (500, 512, 200, 480), (0, 512, 0, 480)])
def test_corners_in_a_mask_are_the_whole_planes_search_in_it(picture, box):
    """The search on the mask's bounding box finds exactly what OpenCV's search of the whole plane finds
    (boxes inside the plane, along its left edge, its last rows, all of it)."""
    y0, y1, x0, x1 = box
    mask = np.zeros_like(picture)
    mask[y0:y1, x0:x1] = 255
    cv2.circle(mask, ((x0 + x1) // 2, (y0 + y1) // 2), 12, 0, -1)  # an existing point's keep-off disc
    whole = cv2.goodFeaturesToTrack(picture, 120, 0.01, 6, mask=mask).reshape(-1, 2)
    found = corners_in(picture, mask, 120, 6)
    assert len(found) > 5 and np.array_equal(found, whole)
    assert corners_in(picture, np.zeros_like(picture), 120, 6).shape == (0, 2)


@pytest.mark.parametrize("lines_are_rows", [True, False])
@pytest.mark.parametrize("factor", [1, 2])
def test_the_seams_mask_marks_the_pixels_within_reach_of_it(lines_are_rows, factor):
    rng = np.random.default_rng(5)
    seam = Seam(rng.uniform(0, 400, 300).astype(np.float32), lines_are_rows)
    offset = np.array([-20.0, 35.0])
    mask = seam.mask_small((150, 200), offset, factor, 24.0)
    rows, cols = np.mgrid[0:150, 0:200]
    pts = small_to_full(np.stack([cols.ravel(), rows.ravel()], axis=1), factor) + offset
    assert np.array_equal(mask.ravel() == 255, seam.distance(pts) <= 24.0) and 0 < (mask == 255).mean() < 0.5


def test_a_frame_without_points_has_no_copies():
    """A frame whose tracks all failed (a person filling both views) has no points: no copies, no error."""
    alignment = Alignment(np.zeros((2, 2, 2)), np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0), np.zeros(0), 0)
    tgt_copies, src_copies = copies_apart(alignment, IDENTITY.copy(), 2.0)
    assert tgt_copies.shape == (0, 2) and src_copies.shape == (0, 2)
