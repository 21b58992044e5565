import cv2
import numpy as np
import pytest

from sena_warp.affine import apply_affine
from sena_warp.imageio import read_image
from sena_warp.evaluation.metrics import (forward_anisotropy, line_bend_pct, long_segments, overlap_mask, overlap_psnr_ssim,
                                           psnr, ssim, transition_mad)


@pytest.fixture(scope="module")
def photo(bundled_dir):
    return read_image(bundled_dir / "udisd_test_000001" / "a.jpg")


def test_psnr_matches_closed_form_for_uniform_error(photo):
    mask = np.ones(photo.shape[:2], bool)
    shifted = np.clip(photo.astype(np.int16) + 4, 0, 255).astype(np.uint8)
    exact = (shifted.astype(np.float64) - photo) ** 2
    expected = 10 * np.log10(255.0**2 / exact.mean())
    assert psnr(photo, shifted, mask) == pytest.approx(expected, abs=1e-9)
    assert psnr(photo, photo, mask) == float("inf")


def test_ssim_is_one_for_identical_and_drops_with_blur(photo):
    mask = np.ones(photo.shape[:2], bool)
    assert ssim(photo, photo, mask) == pytest.approx(1.0, abs=1e-6)
    blurred = cv2.GaussianBlur(photo, (0, 0), 3.0)
    assert 0.2 < ssim(photo, blurred, mask) < 0.9


def test_misalignment_lowers_both_figures(photo):
    h, w = photo.shape[:2]
    valid = np.ones((h, w), bool)
    shifted = np.roll(photo, 3, axis=1)
    p0, s0 = overlap_psnr_ssim(photo, valid, photo, valid)
    p1, s1 = overlap_psnr_ssim(photo, valid, shifted, valid)
    assert p0 == float("inf") and s0 == pytest.approx(1.0, abs=1e-6)
    assert p1 < 25 and s1 < 0.8


def test_overlap_mask_erodes_both_sides():
    a = np.zeros((20, 20), bool)
    b = np.zeros((20, 20), bool)
    a[:, :14] = True
    b[:, 8:] = True
    m = overlap_mask(a, b)
    # Shared columns 8..13 lose 2 px at each mask's own border; the canvas edge is no mask border.
    assert np.flatnonzero(m.any(axis=0)).tolist() == [10, 11]
    assert m[:, 10].all()


def affine_forward(matrix):
    return lambda pts: apply_affine(matrix, pts)


def test_forward_anisotropy_is_zero_for_a_similarity_and_known_for_a_stretch():
    pts = np.array([[10.0, 20.0], [300.0, 40.0], [55.0, 400.0]])
    rotation = affine_forward([[np.cos(0.4) * 1.5, -np.sin(0.4) * 1.5, 7], [np.sin(0.4) * 1.5, np.cos(0.4) * 1.5, -3]])
    np.testing.assert_allclose(forward_anisotropy(rotation, pts), 0.0, atol=1e-9)
    np.testing.assert_allclose(forward_anisotropy(affine_forward([[2.0, 0, 0], [0, 1.0, 0]]), pts), 1.0, atol=1e-9)
    undefined = forward_anisotropy(lambda p: np.where(p[:, :1] > 100, np.nan, p), pts)
    assert undefined[0] == 0.0 and np.isnan(undefined[1]) and undefined[2] == 0.0  # x > 100: undefined


def test_line_bend_is_zero_for_projective_maps_and_exact_for_a_parabola():
    segments = np.array([[[100.0, 50.0], [300.0, 50.0]], [[20.0, 10.0], [40.0, 200.0]]])
    homography = np.array([[1.0, 0.1, 3], [0.05, 1.0, 2], [1e-4, 2e-4, 1.0]])

    def projective(pts):
        q = np.c_[pts, np.ones(len(pts))] @ homography.T
        return q[:, :2] / q[:, 2:]

    np.testing.assert_allclose(line_bend_pct(projective, segments), 0.0, atol=1e-9)
    k = 1e-3  # y += k (x - 200)^2 bends the first segment (x 100..300) by k * 100^2 = 10 px over 200 px: 5 %
    bend = line_bend_pct(lambda p: np.c_[p[:, 0], p[:, 1] + k * (p[:, 0] - 200.0) ** 2], segments[:1])
    assert bend[0] == pytest.approx(5.0, rel=1e-3)


def test_long_segments_finds_a_drawn_line_longest_first():
    img = np.full((200, 300, 3), 40, np.uint8)
    cv2.line(img, (20, 30), (280, 60), (230, 230, 230), 3)
    cv2.line(img, (50, 150), (120, 150), (230, 230, 230), 3)
    found = long_segments(img, min_fraction=0.1)
    lengths = np.linalg.norm(found[:, 1] - found[:, 0], axis=1)
    assert len(found) >= 2 and np.all(np.diff(lengths) <= 0) and lengths[0] > 240
    assert len(long_segments(img, min_fraction=0.5)) >= 1 and len(long_segments(img, min_fraction=0.95)) == 0
    assert long_segments(np.zeros((50, 50, 3), np.uint8)).shape == (0, 2, 2)


def test_transition_mad_counts_only_the_band():
    valid = np.ones((4, 10), bool)
    src = np.zeros((4, 10))
    tgt = np.zeros((4, 10))
    tgt[:, 4:7] = 6.0  # inside |x - 5| <= 1
    tgt[:, 0] = 100.0  # outside the band
    assert transition_mad(src, tgt, valid, np.full(4, 5.0), 2.0) == pytest.approx(6.0)
    assert np.isnan(transition_mad(src, tgt, np.zeros((4, 10), bool), np.full(4, 5.0), 2.0))


def test_transition_mad_of_uint8_images_is_the_float64_figure():
    # uint8 images are differenced in int16 (memory: the feather's band is the whole overlap); the
    # figure must be the float64 one to the bit, over a narrow band and over the whole width.
    rng = np.random.default_rng(7)
    src, tgt = (rng.integers(0, 256, (120, 160, 3), dtype=np.uint8) for _ in range(2))
    valid = rng.random((120, 160)) > 0.2
    seam_x = rng.uniform(0, 160, 120)
    for width in (24.0, 160.0):
        cols = np.arange(160)[None, :]
        band = valid & (np.abs(cols - seam_x[:, None]) <= width / 2)
        expected = float(np.abs(src[band].astype(np.float64) - tgt[band].astype(np.float64)).mean())
        assert transition_mad(src, tgt, valid, seam_x, width) == expected
