"""naturalness: the seam step, vectorised, against its per-row definition on a real pair."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from sena_warp.evaluation import naturalness as nat


def seam_step_per_row(pano, src, tgt, valid_src, valid_tgt, seam_x) -> tuple[float, int]:
    """The seam step row by row as the module docstring defines it (a plain loop), and how many
    rows the views' disagreement left out."""
    height, width = pano.shape
    offsets = np.arange(nat.STEP_NEAR_PX, nat.STEP_FAR_PX + 1)
    steps = np.full(height, np.nan)
    disagree = 0
    for y in range(height):
        if not np.isfinite(seam_x[y]):
            continue
        left, right = np.floor(seam_x[y] - offsets).astype(int), np.ceil(seam_x[y] + offsets).astype(int)
        if left.min() < 0 or right.max() >= width:
            continue
        strips = np.r_[left, right]
        if not (valid_src[y, strips].all() and valid_tgt[y, strips].all()):
            continue
        step_src, step_tgt, step_pano = (img[y, left].mean() - img[y, right].mean() for img in (src, tgt, pano))
        if abs(step_src - step_tgt) > nat.STEP_AGREE_GREY:
            disagree += 1
            continue
        steps[y] = step_pano - 0.5 * (step_src + step_tgt)
    known = np.isfinite(steps)
    window = np.ones(nat.STEP_ROWS)
    total = np.convolve(np.where(known, steps, 0.0), window, "same")
    count = np.convolve(known.astype(np.float64), window, "same")
    kept = known & (count >= nat.STEP_ROWS / 2)
    return float(np.mean(np.abs(total[kept] / count[kept]))), disagree


def test_seam_step_equals_its_per_row_definition_on_a_real_pair(udisd_pair):
    """The bundled pair, a aligned onto b by one homography (SIFT, RANSAC), so the views agree but
    where parallax or a's border is; a random-walk seam and a 5-level step on the target side: the
    vectorised step is the per-row one, to the last digit."""
    img_a, img_b = udisd_pair
    grey_a, src = (cv2.cvtColor(img, cv2.COLOR_BGR2GRAY) for img in (img_a, img_b))
    sift = cv2.SIFT_create()
    (kp_a, des_a), (kp_b, des_b) = sift.detectAndCompute(grey_a, None), sift.detectAndCompute(src, None)
    matches = cv2.BFMatcher(cv2.NORM_L2, crossCheck=True).match(des_a, des_b)
    pts_a = np.float32([kp_a[m.queryIdx].pt for m in matches])
    pts_b = np.float32([kp_b[m.trainIdx].pt for m in matches])
    h_a_to_b, _ = cv2.findHomography(pts_a, pts_b, cv2.RANSAC, 3.0)
    height, width = src.shape
    tgt = cv2.warpPerspective(grey_a, h_a_to_b, (width, height), flags=cv2.INTER_LINEAR).astype(np.float32)
    valid_tgt = cv2.warpPerspective(np.ones_like(grey_a), h_a_to_b, (width, height), flags=cv2.INTER_NEAREST) > 0
    valid_src = np.ones(src.shape, bool)
    src = src.astype(np.float32)
    rng = np.random.default_rng(3)
    for trial in range(4):
        seam_x = np.clip(width / 2 + np.cumsum(rng.normal(0.0, 1.5, height)), 5.0, width - 5.0)
        seam_x[rng.integers(0, height, 3)] = np.nan  # lines the seam does not cross
        cols = np.arange(width)[None, :]
        pano = np.where(cols < np.nan_to_num(seam_x, nan=width / 2)[:, None], src, tgt + 5.0)
        expected, disagree = seam_step_per_row(pano, src, tgt, valid_src, valid_tgt, seam_x)
        assert 0 < disagree < height / 2, trial  # the filter leaves some rows out, not most
        assert nat.seam_step(pano, src, tgt, valid_src, valid_tgt, seam_x) == expected, trial


def test_border_step_is_the_exposure_step_across_the_targets_border(udisd_pair):
    """A real image as the source everywhere and, inside rows 100-399 right of a seam, as the target
    too, 8 grey levels brighter: the border step is that 8 (the scene's own change across the border
    cancels), and 0 without the step; columns where the source is shown on both sides do not count."""
    grey = cv2.cvtColor(udisd_pair[1], cv2.COLOR_BGR2GRAY).astype(np.float32)
    height, width = grey.shape
    rows, cols = np.mgrid[0:height, 0:width]
    weight_tgt = ((rows >= 100) & (rows < 400) & (cols > 200)).astype(np.float32)
    valid_src = np.ones(grey.shape, bool)
    for step in (8.0, 0.0):
        pano = grey + step * weight_tgt
        assert nat.border_step(pano, grey, valid_src, weight_tgt, (99.5, 399.5)) == pytest.approx(step, abs=1e-3)
    pano = grey + 8.0 * weight_tgt
    weight_tgt[:, :] = 0.0
    assert np.isnan(nat.border_step(pano, grey, valid_src, weight_tgt, (99.5, 399.5)))
