"""The baselines of the evaluation: SIFT + RANSAC homography and OpenCV's stitcher, on the bundled pairs."""

from __future__ import annotations

import numpy as np
import pytest

from sena_warp.config import Config
from sena_warp.errors import MatchError
from sena_warp.evaluation.baselines import (homography_forward, homography_to_target, opencv_forward, opencv_stitch,
                                            opencv_views, sift_homography)
from sena_warp.evaluation.metrics import overlap_psnr_ssim
from sena_warp.features import match_images
from helpers import read_pair

CFG = Config(device="cpu")


@pytest.fixture(scope="module")
def udisd(bundled_dir):
    return read_pair(bundled_dir / "udisd_test_000001")


def test_sift_homography_agrees_with_the_graf_ground_truth(bundled_dir):
    img_a, img_b = read_pair(bundled_dir / "graf_gt")
    truth = np.loadtxt(bundled_dir / "graf_gt" / "H_a_to_b.txt")
    h, w = img_a.shape[:2]
    grid = np.stack(np.meshgrid(np.linspace(100, w - 100, 5), np.linspace(100, h - 100, 5)), -1).reshape(-1, 2)
    error = np.linalg.norm(homography_forward(sift_homography(img_a, img_b, CFG))(grid) - homography_forward(truth)(grid),
                           axis=1)
    assert np.median(error) < 2.0  # graf is planar: the homography is the exact model


def test_homography_to_target_puts_matched_content_on_the_target(udisd):
    img_a, img_b = udisd
    homography = sift_homography(img_a, img_b, CFG)
    warped, valid = homography_to_target(img_a, homography, img_b.shape)
    assert warped.shape == img_b.shape and 0.2 < valid.mean() < 0.95
    psnr, _ = overlap_psnr_ssim(warped, valid, img_b, np.ones(valid.shape, bool))
    shifted = np.roll(img_b, 6, axis=1)  # the same overlap against a target 6 px off: clearly worse
    assert psnr > overlap_psnr_ssim(warped, valid, shifted, np.ones(valid.shape, bool))[0] + 2.0


# Median panorama distance of a SIFT match's two ends, measured 1.4 px (rotation model) and 5.8 px (the
# SCANS affine, with parallax); OpenCV's own AffineWarper.warpPoint would put it at 45 px.
@pytest.mark.parametrize("method, max_gap_px", [("opencv_panorama", 4.0), ("opencv_scans", 10.0)])
def test_opencv_stitch_views_and_forward_maps_agree_on_matched_points(udisd, method, max_gap_px):
    img_a, img_b = udisd
    stitch = opencv_stitch(img_a, img_b, method)
    (view_a, valid_a), (view_b, valid_b) = opencv_views(stitch, udisd)
    # The views are on the stitcher's own panorama grid: the same size as its panorama.
    assert view_a.shape == stitch.panorama.shape and valid_a.shape == valid_b.shape
    assert (valid_a & valid_b).mean() > 0.1 and (valid_a & ~valid_b).any() and (valid_b & ~valid_a).any()
    # A scene point seen in both inputs lands on (nearly) one panorama position from either side.
    matches = match_images(img_a, img_b, CFG.replace(features="sift"))
    gap = np.linalg.norm(opencv_forward(stitch, 0)(matches.pts_a) - opencv_forward(stitch, 1)(matches.pts_b), axis=1)
    assert np.median(gap) < max_gap_px
    assert 12.0 < overlap_psnr_ssim(view_a, valid_a, view_b, valid_b)[0] < 40.0


def test_opencv_stitch_failure_is_a_match_error_naming_the_status(udisd, bundled_dir):
    flat = np.full_like(udisd[0], 128)
    with pytest.raises(MatchError, match="ERR_NEED_MORE_IMGS"):
        opencv_stitch(udisd[0], flat, "opencv_scans")
