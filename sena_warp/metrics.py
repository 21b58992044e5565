"""Quality figures of SENA.md "Measuring": overlap alignment (UDIS-D protocol) and shape.

All images here are already on the canvas: the warped source and the placed target, each with a
validity mask of the same (H, W) shape.
"""

from __future__ import annotations

import cv2
import numpy as np

OVERLAP_ERODE_PX = 2  # UDIS-D protocol: both masks eroded by 2 px before comparing
SSIM_SIGMA_PX = 1.5  # Wang et al. 2004 Gaussian window
SSIM_C1 = (0.01 * 255) ** 2
SSIM_C2 = (0.03 * 255) ** 2


def overlap_mask(valid_src_canvas: np.ndarray, valid_tgt_canvas: np.ndarray) -> np.ndarray:
    """Pixels where both images are valid, each mask eroded by ``OVERLAP_ERODE_PX``; (H, W) bool."""
    kernel = np.ones((2 * OVERLAP_ERODE_PX + 1, 2 * OVERLAP_ERODE_PX + 1), np.uint8)
    a = cv2.erode(valid_src_canvas.astype(np.uint8), kernel)
    b = cv2.erode(valid_tgt_canvas.astype(np.uint8), kernel)
    return (a > 0) & (b > 0)


def psnr(img_a: np.ndarray, img_b: np.ndarray, mask: np.ndarray) -> float:
    """PSNR in dB of two uint8 images over ``mask`` (all channels); inf when identical, nan when empty."""
    if not mask.any():
        return float("nan")
    diff = img_a[mask].astype(np.float64) - img_b[mask].astype(np.float64)
    mse = float(np.mean(diff * diff))
    return float("inf") if mse == 0.0 else 10.0 * np.log10(255.0**2 / mse)


def ssim(img_a: np.ndarray, img_b: np.ndarray, mask: np.ndarray) -> float:
    """Mean SSIM (grey, Gaussian window sigma 1.5) over ``mask``; nan when empty.

    Pixels outside the mask are filled from the other image before filtering, so a window that
    straddles the overlap's border is not penalised for the uncovered part.
    """
    if not mask.any():
        return float("nan")
    a = _grey(img_a)
    b = _grey(img_b)
    a = np.where(mask, a, b)

    def blur(x: np.ndarray) -> np.ndarray:
        return cv2.GaussianBlur(x, (0, 0), SSIM_SIGMA_PX)

    mu_a, mu_b = blur(a), blur(b)
    var_a = blur(a * a) - mu_a * mu_a
    var_b = blur(b * b) - mu_b * mu_b
    cov = blur(a * b) - mu_a * mu_b
    num = (2 * mu_a * mu_b + SSIM_C1) * (2 * cov + SSIM_C2)
    den = (mu_a * mu_a + mu_b * mu_b + SSIM_C1) * (var_a + var_b + SSIM_C2)
    return float(np.mean((num / den)[mask]))


def overlap_psnr_ssim(
    warped_src_canvas: np.ndarray,
    valid_src_canvas: np.ndarray,
    placed_tgt_canvas: np.ndarray,
    valid_tgt_canvas: np.ndarray,
) -> tuple[float, float]:
    """UDIS-D alignment figures: PSNR (dB) and SSIM of the two images over their eroded overlap."""
    mask = overlap_mask(valid_src_canvas, valid_tgt_canvas)
    return psnr(warped_src_canvas, placed_tgt_canvas, mask), ssim(warped_src_canvas, placed_tgt_canvas, mask)


def similarity_deviation(affines_src_to_tgt: np.ndarray) -> np.ndarray:
    """Per affine, how far its linear part is from a similarity: singular-value ratio s_max / s_min - 1.

    0 for a rotation+uniform scale; grows with shear and anisotropic scale. Input (J, 2, 3).
    """
    sv = np.linalg.svd(np.asarray(affines_src_to_tgt, np.float64)[:, :, :2], compute_uv=False)
    return sv[:, 0] / np.maximum(sv[:, 1], 1e-12) - 1.0


def _grey(img: np.ndarray) -> np.ndarray:
    if img.ndim == 3 and img.shape[2] == 3:
        img = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    elif img.ndim == 3:
        img = img[:, :, 0]
    return img.astype(np.float32)
