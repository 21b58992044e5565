"""Sparse XFeat on onnxruntime: the shipped model, and each post-processing step on known answers."""

from __future__ import annotations

import numpy as np
import pytest

from sena_warp.config import Config
from sena_warp.errors import InputError
from sena_warp.imageio import read_image
from sena_warp.xfeat import (CELL, OUTPUT_NAMES, detect_xfeat, keypoint_heatmap, nms_peaks, sample_map,
                             top_k_indices, working_size, xfeat_session)


def test_model_loads_from_installed_package():
    session = xfeat_session(0, False)
    assert session is xfeat_session(0, False)  # cached: loaded once per process
    assert [i.name for i in session.get_inputs()] == ["image"]
    assert tuple(o.name for o in session.get_outputs()) == OUTPUT_NAMES
    h, w = 64, 96
    feats, logits, reliability = session.run(list(OUTPUT_NAMES),
                                             {"image": np.random.default_rng(0).random((1, 3, h, w), np.float32)})
    assert feats.shape == (1, 64, h // CELL, w // CELL)
    assert logits.shape == (1, 65, h // CELL, w // CELL)
    assert reliability.shape == (1, 1, h // CELL, w // CELL)
    assert 0.0 <= reliability.min() and reliability.max() <= 1.0  # after the sigmoid


def test_working_size_multiples_of_32_and_long_side_cap():
    assert working_size((640, 800), 1024) == (800, 640)  # already fits: unchanged
    assert working_size((1440, 2160), 1024) == (1024, 672)  # 2160 -> 1024, 1440 * 1024/2160 = 682 -> 672
    assert working_size((100, 100), 1024) == (96, 96)  # never upscaled, rounded down
    with pytest.raises(InputError):
        working_size((20, 400), 1024)


def test_heatmap_softmax_drops_dustbin_and_pixel_shuffles():
    h, w = 2, 3
    logits = np.zeros((65, h, w), np.float32)
    logits[8 * 5 + 2, 1, 2] = 20.0  # cell (row 1, col 2), offset dy=5, dx=2
    logits[64, 0, 0] = 20.0  # dustbin wins in cell (0, 0)
    heat = keypoint_heatmap(logits)
    assert heat.shape == (h * CELL, w * CELL)
    assert np.unravel_index(np.argmax(heat), heat.shape) == (1 * CELL + 5, 2 * CELL + 2)
    assert heat[CELL + 5, 2 * CELL + 2] == pytest.approx(1.0, abs=1e-6)
    assert heat[:CELL, :CELL].max() < 1e-6  # dustbin took the mass; it is not in the heatmap
    uniform = 1.0 / 65.0
    assert heat[:CELL, CELL:2 * CELL] == pytest.approx(np.full((CELL, CELL), uniform))


def test_nms_keeps_local_maxima_above_threshold_in_row_major_order():
    heat = np.zeros((20, 20), np.float32)
    heat[5, 5] = 0.9
    heat[6, 7] = 0.5  # within the 5x5 window of (5, 5): suppressed
    heat[5, 12] = 0.4  # 7 px away: kept
    heat[15, 3] = 0.04  # below the threshold
    heat[15, 15] = 0.3
    peaks = nms_peaks(heat, 5, 0.05)
    np.testing.assert_array_equal(peaks, [[5, 5], [12, 5], [15, 15]])  # (x, y)
    assert len(nms_peaks(heat, 5, 0.95)) == 0


def test_top_k_best_first_and_stable_on_ties():
    scores = np.array([0.1, 0.7, 0.3, 0.7, 0.9], np.float32)
    np.testing.assert_array_equal(top_k_indices(scores, 3), [4, 1, 3])
    assert len(top_k_indices(scores, 10)) == 5


def test_sample_map_follows_xfeat_grid_convention():
    rng = np.random.default_rng(1)
    h, w = 6, 8
    work_h, work_w = h * CELL, w * CELL
    cols, rows = np.meshgrid(np.arange(w), np.arange(h))
    ramp = np.stack([cols + 10.0 * rows, np.ones((h, w))]).astype(np.float32)  # linear in the map column/row
    # Two cells from the border, so that every bicubic tap lies inside the map.
    margin = 2 * CELL
    pts_work = np.column_stack([rng.uniform(margin, work_w - 1 - margin, 50),
                                rng.uniform(margin, work_h - 1 - margin, 50)])
    u = pts_work[:, 0] * w / (work_w - 1) - 0.5
    v = pts_work[:, 1] * h / (work_h - 1) - 0.5
    bilinear = sample_map(ramp, pts_work, (work_h, work_w), "bilinear")
    np.testing.assert_allclose(bilinear[:, 0], u + 10.0 * v, rtol=1e-5)
    bicubic = sample_map(ramp, pts_work, (work_h, work_w), "bicubic")
    np.testing.assert_allclose(bicubic[:, 1], 1.0, rtol=1e-5)  # weights sum to one inside the map
    # At a point that falls exactly on a map sample, the cubic kernel returns that sample.
    on_sample = np.array([[(3 + 0.5) * (work_w - 1) / w, (2 + 0.5) * (work_h - 1) / h]])
    assert sample_map(ramp, on_sample, (work_h, work_w), "bicubic")[0, 0] == pytest.approx(3 + 20.0, abs=1e-4)
    # Zeros outside the map (grid_sample padding): the corner pixel's sample is damped.
    corner = sample_map(np.ones((1, h, w), np.float32), np.zeros((1, 2)), (work_h, work_w), "bilinear")
    assert corner[0, 0] == pytest.approx(0.25)


def test_detect_on_real_image(bundled_dir):
    img = read_image(bundled_dir / "graf_gt" / "a.png")
    cfg = Config()
    pts, desc, scores = detect_xfeat(img, cfg)
    assert 1000 <= len(pts) <= cfg.xfeat_top_k
    assert pts.dtype == np.float64 and desc.shape == (len(pts), 64) and desc.dtype == np.float32
    np.testing.assert_allclose(np.linalg.norm(desc, axis=1), 1.0, atol=1e-5)
    assert np.all(np.diff(scores) <= 0) and scores[-1] > 0
    assert pts[:, 0].min() >= 0 and pts[:, 0].max() <= img.shape[1] - 1
    assert pts[:, 1].min() >= 0 and pts[:, 1].max() <= img.shape[0] - 1


def test_detect_maps_points_back_to_input_pixels(bundled_dir):
    """At a reduced working resolution the keypoints still land on the same scene points."""
    img = read_image(bundled_dir / "graf_gt" / "a.png")
    pts_full, _, _ = detect_xfeat(img, Config())
    pts_small, _, _ = detect_xfeat(img, Config(xfeat_max_side=512))
    assert pts_small[:, 0].max() > 0.9 * img.shape[1]  # spread over the whole input, not the 512 px image
    # The strongest corners at 512 px: the nearest full-resolution keypoint is close by.
    dist = np.linalg.norm(pts_small[:200, None, :] - pts_full[None, :, :], axis=2).min(axis=1)
    assert np.median(dist) < 2.0
