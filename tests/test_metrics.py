import cv2
import numpy as np
import pytest

from sena_warp.imageio import read_image
from sena_warp.metrics import overlap_mask, overlap_psnr_ssim, psnr, similarity_deviation, ssim


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


def test_similarity_deviation():
    rot = np.array([[[np.cos(0.3) * 2, -np.sin(0.3) * 2, 5], [np.sin(0.3) * 2, np.cos(0.3) * 2, 1]]])
    shear = np.array([[[1.0, 0.5, 0], [0.0, 1.0, 0]]])
    dev = similarity_deviation(np.concatenate([rot, shear]))
    assert dev[0] == pytest.approx(0.0, abs=1e-12)
    assert dev[1] > 0.5
