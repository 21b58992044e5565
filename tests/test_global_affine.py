"""Step 1: global affine A_glob by RANSAC on real matches and on hand-made point sets."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from sena_warp.affine import apply_affine
from sena_warp.config import Config
from sena_warp.errors import MatchError
from sena_warp.features import match_images
from sena_warp.global_affine import check_views_alike, fit_global_affine, near_model, overlap_correlation
from helpers import read_pair

CFG = Config()


def sift_matches(img_a: np.ndarray, img_b: np.ndarray, ratio: float = CFG.sift_ratio) -> tuple[np.ndarray, np.ndarray]:
    """SIFT + Lowe ratio matches (pts_a, pts_b), float64 (N, 2) (x, y): real matches for the tests."""
    sift = cv2.SIFT_create()
    kp_a, desc_a = sift.detectAndCompute(cv2.cvtColor(img_a, cv2.COLOR_BGR2GRAY), None)
    kp_b, desc_b = sift.detectAndCompute(cv2.cvtColor(img_b, cv2.COLOR_BGR2GRAY), None)
    pairs = cv2.BFMatcher(cv2.NORM_L2).knnMatch(desc_a, desc_b, k=2)
    good = [p[0] for p in pairs if len(p) == 2 and p[0].distance < ratio * p[1].distance]
    pts_a = np.array([kp_a[m.queryIdx].pt for m in good], dtype=np.float64)
    pts_b = np.array([kp_b[m.trainIdx].pt for m in good], dtype=np.float64)
    return pts_a, pts_b


def test_graf_sift_affine_agrees_with_ground_truth_homography_where_its_inliers_are(bundled_dir):
    img_a, img_b = read_pair(bundled_dir / "graf_gt")
    h_a_to_b = np.loadtxt(bundled_dir / "graf_gt" / "H_a_to_b.txt")
    pts_a, pts_b = sift_matches(img_a, img_b)
    glob = fit_global_affine(pts_a, pts_b, CFG)
    # Measured: 520 SIFT matches, 128 affine inliers.
    assert glob.n_matches == len(pts_a) == glob.inliers.size
    assert glob.n_inliers == int(glob.inliers.sum()) >= 100
    # graf1 -> graf3 is a strong homography: no affine fits the whole image (the least-squares
    # affine of H over all of a misses H at a's centre by 10 px, the RANSAC one by 23 px, because
    # its inliers sit in one part of the wall). Where the inliers are, the affine is the local
    # linearisation of H: measured 2.7 px at their centroid, 4.9 px median over them (SIFT
    # localisation + perspective curvature across the inlier patch).
    inl_a = pts_a[glob.inliers]
    def err(p):
        return np.linalg.norm(
            apply_affine(glob.affine_src_to_tgt, p) - cv2.perspectiveTransform(p[None], h_a_to_b)[0], axis=1
        )
    assert err(inl_a.mean(axis=0, keepdims=True))[0] < 5.0
    assert np.median(err(inl_a)) < 7.0


def test_graf_affine_from_project_features_maps_the_centre_like_the_homography(bundled_dir):
    img_a, img_b = read_pair(bundled_dir / "graf_gt")
    h_a_to_b = np.loadtxt(bundled_dir / "graf_gt" / "H_a_to_b.txt")
    matches = match_images(img_a, img_b, CFG)
    glob = fit_global_affine(matches.pts_a, matches.pts_b, CFG)
    # Measured with XFeat: 1414 matches, 235 inliers spread over the middle of the wall, and A_glob
    # maps a's centre 1.3 px from H's mapping (median 1.4 px over the inliers). 3 px is the RANSAC
    # threshold: a model that misses H by more at the centre has its inliers elsewhere.
    assert glob.n_inliers >= 200
    centre_a = np.array([[(img_a.shape[1] - 1) / 2, (img_a.shape[0] - 1) / 2]])
    centre_h = cv2.perspectiveTransform(centre_a[None], h_a_to_b)[0]
    assert np.linalg.norm(apply_affine(glob.affine_src_to_tgt, centre_a) - centre_h) < 3.0


def test_known_affine_on_a_real_image_is_recovered(bundled_dir):
    img_a, _ = read_pair(bundled_dir / "udisd_test_000001")
    affine_true = np.array([[0.93, 0.12, 40.0], [-0.08, 1.02, 25.0]])
    height, width = img_a.shape[:2]
    img_b = cv2.warpAffine(img_a, affine_true, (width + 80, height + 80), flags=cv2.INTER_LINEAR)
    pts_a, pts_b = sift_matches(img_a, img_b)
    glob = fit_global_affine(pts_a, pts_b, CFG)
    assert glob.model == "affine"  # a shear: the similarity cannot explain it
    assert glob.n_inliers > 0.8 * glob.n_matches
    probes = np.array([[width / 2, height / 2], [0, 0], [width - 1, height - 1], [0, height - 1]])
    err = np.linalg.norm(apply_affine(glob.affine_src_to_tgt, probes) - apply_affine(affine_true, probes), axis=1)
    assert err.max() < 0.2  # measured 0.03 px: 1989 of 1992 matches are exact up to interpolation


def test_tie_goes_to_the_similarity_and_shear_to_the_affine():
    rng = np.random.default_rng(3)
    pts_src = rng.uniform(0, 500, size=(80, 2))
    angle = np.deg2rad(5.0)
    similarity = 1.1 * np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    pts_tgt = pts_src @ similarity.T + [30.0, -12.0] + rng.normal(0, 0.3, size=pts_src.shape)
    glob = fit_global_affine(pts_src, pts_tgt, CFG)
    assert glob.model == "similarity" and glob.n_inliers == 80
    shear = np.array([[1.0, 0.25], [0.0, 1.0]])
    glob = fit_global_affine(pts_src, pts_src @ shear.T + 5.0, CFG)
    assert glob.model == "affine" and glob.n_inliers == 80


def test_too_few_matches_is_a_match_error_naming_the_counts():
    pts = np.random.default_rng(0).uniform(0, 100, size=(CFG.min_inliers - 1, 2))
    with pytest.raises(MatchError, match=rf"only {CFG.min_inliers - 1} matches.*--features sift"):
        fit_global_affine(pts, pts + 1.0, CFG)


def test_random_matches_are_a_match_error_naming_the_counts():
    rng = np.random.default_rng(1)
    pts_src = rng.uniform(0, 1000, size=(300, 2))
    pts_tgt = rng.uniform(0, 1000, size=(300, 2))
    with pytest.raises(MatchError, match=r"only \d+ of 300 matches agree.*overlap"):
        fit_global_affine(pts_src, pts_tgt, CFG)


def _working_matches(img_a, img_b):
    from sena_warp.rig import detect_rig, matches_to_working

    matches = match_images(img_a, img_b, Config())
    rig = detect_rig(matches.pts_a, matches.pts_b, img_a.shape, "auto")
    return matches_to_working(matches.pts_a, matches.pts_b, rig)


def test_by_support_a_near_tie_is_decided_by_the_inliers(bundled_dir):
    """The bundled pair: as many matches lie within fit_match_px of the similarity as of the full affine
    (1917 vs 1918), a tie: the inliers decide, as in the paper (590 vs 516: the affine), on the image
    and on a grey copy of it alike."""
    img_a, img_b = read_pair(bundled_dir / "udisd_test_000001")
    grey_a = cv2.cvtColor(cv2.cvtColor(img_a, cv2.COLOR_BGR2GRAY), cv2.COLOR_GRAY2BGR)
    for first in (img_a, grey_a):
        pts_src, pts_tgt = _working_matches(first, img_b)
        assert fit_global_affine(pts_src, pts_tgt, Config()).model == "affine"
        assert fit_global_affine(pts_src, pts_tgt, Config(global_model_choice="inliers")).model == "affine"


@pytest.mark.shared
def test_by_support_spw_2_keeps_the_model_most_of_the_scene_lies_near(shared_dir):
    """spw_2 (parallax): the full affine fits one plane with 200 inliers but has 880 matches within
    50 px; the similarity 156 and 1261. The lattice follows every match within fit_match_px, so the
    similarity is the model it can correct: by support it is kept, by inliers the affine."""
    cfg = Config()
    pts_src, pts_tgt = _working_matches(*read_pair(shared_dir / "pairs" / "spw_2"))
    by_inliers = fit_global_affine(pts_src, pts_tgt, cfg.replace(global_model_choice="inliers"))
    by_support = fit_global_affine(pts_src, pts_tgt, cfg)
    assert (by_inliers.model, by_support.model) == ("affine", "similarity")
    near = [int(near_model(g.affine_src_to_tgt, pts_src, pts_tgt, cfg.fit_match_px).sum()) for g in (by_inliers, by_support)]
    assert near[1] > 1.3 * near[0] and by_inliers.n_inliers > by_support.n_inliers


def test_the_views_of_a_real_pair_correlate_where_a_glob_aligns_them_and_noise_does_not(bundled_dir):
    """The bundled pairs align to an overlap correlation far above the 0.2 floor (every shared pair: 0.47 or
    more, docs/evaluation.md); two noise images, whose 24-30 matches agree on an identity by chance, to 0."""
    cfg = Config(device="cpu")
    for name in ("udisd_test_000001", "graf_gt"):
        img_a, img_b = read_pair(bundled_dir / name)
        matches = match_images(img_a, img_b, cfg)
        glob = fit_global_affine(matches.pts_a, matches.pts_b, cfg)
        assert overlap_correlation(img_a, img_b, glob.affine_src_to_tgt) > 0.4
        check_views_alike(img_a, img_b, glob, cfg)
    noise_a, noise_b = (np.random.default_rng(seed).integers(0, 256, (512, 512, 3), dtype=np.uint8) for seed in (1, 2))
    identity = fit_global_affine(np.array([[10.0, 10], [400, 30], [30, 400]]), np.array([[10.0, 10], [400, 30], [30, 400]]),
                                 Config(min_inliers=3))
    assert abs(overlap_correlation(noise_a, noise_b, identity.affine_src_to_tgt)) < 0.05
    with pytest.raises(MatchError, match="align views that do not look alike .overlap correlation 0.0"):
        check_views_alike(noise_a, noise_b, identity, cfg)
    flat = np.full((512, 512, 3), 90, np.uint8)
    assert overlap_correlation(flat, noise_b, identity.affine_src_to_tgt) is None  # nothing to compare: not refused
