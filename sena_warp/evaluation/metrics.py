"""Quality measures on arrays (``docs/evaluation.md``): overlap alignment (UDIS-D protocol), seam, shape.

Alignment: images already on one frame (the warped source and the placed target, each with a
validity mask of the same (H, W) shape). Seam: the canvas maps and anchors of steps 6-9 (working
frame). Shape: a warp given as a *forward* function that takes (N, 2) float64 source (x, y) pixels
to (N, 2) output (x, y) pixels (NaN where it is undefined), so that SENA, the global models and
OpenCV's stitcher are measured the same way.
"""

from __future__ import annotations

from typing import Callable

import cv2
import numpy as np

from sena_warp.affine import similarity_deviation
from sena_warp.bilinear import sample_bilinear

OVERLAP_ERODE_PX = 2  # UDIS-D protocol: both masks eroded by 2 px before comparing
SSIM_SIGMA_PX = 1.5  # Wang et al. 2004 Gaussian window
SSIM_REACH_SIGMAS = 4  # OpenCV's Gaussian kernel for float images reaches 4 sigma from its centre
SSIM_C1 = (0.01 * 255) ** 2
SSIM_C2 = (0.03 * 255) ** 2
JACOBIAN_STEP_PX = 2.0  # central-difference step of a forward warp's Jacobian
LONG_LINE_FRACTION = 0.10  # a "long line": a detected segment at least this x the image's long side
MAX_LINES = 30  # the longest this many long lines are measured
LINE_SAMPLES = 33  # points per line mapped through a warp
NEWTON_STEPS = 5  # anchor_residuals_px: Newton steps to invert the map (converges in 2-3 on smooth maps)
ANCHOR_JACOBIAN_STEP_PX = 0.5  # half-step of anchor_residuals_px's central differences of the map

Forward = Callable[[np.ndarray], np.ndarray]


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
    # Integers all the way: exact, and 6 bytes a sample where float64 copies took 32.
    diff = img_a[mask].astype(np.int16) - img_b[mask]
    mse = float(np.square(diff, dtype=np.int32).sum(dtype=np.int64)) / diff.size
    return float("inf") if mse == 0.0 else 10.0 * np.log10(255.0**2 / mse)


def ssim(img_a: np.ndarray, img_b: np.ndarray, mask: np.ndarray) -> float:
    """Mean SSIM (grey, Gaussian window sigma 1.5) over ``mask``; nan when empty.

    Pixels outside the mask are filled from the other image before filtering, so a window that
    straddles the overlap's border is not penalised for the uncovered part. Only the mask's bounding
    box (and the window's reach around it) is filtered: the same figure as over the whole canvas.
    """
    if not mask.any():
        return float("nan")
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    reach = int(np.ceil(SSIM_REACH_SIGMAS * SSIM_SIGMA_PX))
    box = (slice(max(rows[0] - reach, 0), rows[-1] + reach + 1), slice(max(cols[0] - reach, 0), cols[-1] + reach + 1))
    mask = mask[box]
    a = _grey(img_a[box])
    b = _grey(img_b[box])
    a = np.where(mask, a, b)

    def blur(x: np.ndarray) -> np.ndarray:
        return cv2.GaussianBlur(x, (0, 0), SSIM_SIGMA_PX)

    # In place where it can be, in the usual order of operations: the same figure, fewer float images alive.
    mu_a, mu_b = blur(a), blur(b)
    var_a = blur(a * a)
    var_a -= mu_a * mu_a
    var_b = blur(b * b)
    var_b -= mu_b * mu_b
    cov = blur(a * b)
    cov -= mu_a * mu_b
    del a, b
    num = 2 * mu_a * mu_b + SSIM_C1
    num *= 2 * cov + SSIM_C2
    den = mu_a * mu_a + mu_b * mu_b + SSIM_C1
    den *= var_a + var_b + SSIM_C2
    num /= den
    return float(np.mean(num[mask]))


def overlap_psnr_ssim(
    warped_src_canvas: np.ndarray,
    valid_src_canvas: np.ndarray,
    placed_tgt_canvas: np.ndarray,
    valid_tgt_canvas: np.ndarray,
) -> tuple[float, float]:
    """UDIS-D alignment figures: PSNR (dB) and SSIM of the two images over their eroded overlap."""
    mask = overlap_mask(valid_src_canvas, valid_tgt_canvas)
    return psnr(warped_src_canvas, placed_tgt_canvas, mask), ssim(warped_src_canvas, placed_tgt_canvas, mask)


def anchor_residuals_px(
    map_src_canvas_before: np.ndarray,
    map_src_canvas_after: np.ndarray,
    anchors_src_canvas: np.ndarray,
    anchors_tgt_canvas: np.ndarray,
) -> np.ndarray:
    """(K,) float64 canvas distance between where each source anchor lands after reconstruction and
    its target anchor.

    The source anchor's scene point is ``p = before(anchor_src)`` (a source-image position); where it
    lands is the canvas point u with ``after(u) = p``, found by Newton steps from the target anchor
    with a central-difference Jacobian of ``after`` (docs/method.md step 6: invert maps numerically).
    NaN where the maps are not defined, the Newton steps leave the canvas (anchors on its border),
    or the Jacobian is singular.
    """
    p_src = sample_bilinear(map_src_canvas_before, np.asarray(anchors_src_canvas, np.float64))
    u = np.asarray(anchors_tgt_canvas, np.float64).copy()
    step = np.array([ANCHOR_JACOBIAN_STEP_PX, 0.0]), np.array([0.0, ANCHOR_JACOBIAN_STEP_PX])
    for _ in range(NEWTON_STEPS):
        jac = np.stack(
            [sample_bilinear(map_src_canvas_after, u + h) - sample_bilinear(map_src_canvas_after, u - h) for h in step], axis=-1
        ) / (2 * ANCHOR_JACOBIAN_STEP_PX)
        residual = sample_bilinear(map_src_canvas_after, u) - p_src
        ok = np.isfinite(jac).all(axis=(1, 2)) & np.isfinite(residual).all(axis=1)
        ok[ok] = np.linalg.matrix_rank(jac[ok]) == 2
        delta = np.full_like(u, np.nan)
        delta[ok] = np.linalg.solve(jac[ok], residual[ok][..., None])[..., 0]
        u = u - delta
    return np.hypot(*(u - anchors_tgt_canvas).T)


def transition_mad(
    out_src: np.ndarray, out_tgt: np.ndarray, valid: np.ndarray, seam_x: np.ndarray, width: float
) -> float:
    """Mean |src - tgt| (grey levels, over channels) inside the transition band |x - seam_x[y]| <= width/2.

    out_src, out_tgt: (H, W) or (H, W, C) images remapped onto the canvas; valid: (H, W) bool where
    both are defined; seam_x: (H,) seam x per row. NaN when the band holds no valid pixel.
    """
    cols = np.arange(valid.shape[1])[None, :]
    seam_x = np.asarray(seam_x, np.float64)[:, None]
    band = valid & (cols >= seam_x - 0.5 * width) & (cols <= seam_x + 0.5 * width)  # no canvas-sized floats
    if not band.any():
        return float("nan")
    # Only the band's pixels: a whole-canvas float64 difference costs 24 bytes a pixel. uint8 images
    # differ exactly in int16 (2 bytes a sample, not 8: the feather's band is the whole overlap), and
    # the mean of integers sums exactly in float64, so the figure is the same as in float64.
    src, tgt = out_src[band], out_tgt[band]
    diff = src.astype(np.int16 if src.dtype == np.uint8 and tgt.dtype == np.uint8 else np.float64)
    diff -= tgt
    np.abs(diff, out=diff)
    return float(diff.mean())


def forward_jacobians(forward: Forward, pts_src: np.ndarray, step_px: float = JACOBIAN_STEP_PX) -> np.ndarray:
    """(N, 2, 2) Jacobians d(output)/d(source) of ``forward`` at (N, 2) source points, central differences."""
    pts_src = np.asarray(pts_src, np.float64).reshape(-1, 2)
    columns = []
    for axis in (0, 1):
        delta = np.zeros(2)
        delta[axis] = step_px
        columns.append((forward(pts_src + delta) - forward(pts_src - delta)) / (2.0 * step_px))
    return np.stack(columns, axis=2)


def forward_anisotropy(forward: Forward, pts_src: np.ndarray, step_px: float = JACOBIAN_STEP_PX) -> np.ndarray:
    """Per source point, how far the warp is locally from a similarity (``similarity_deviation`` of its
    Jacobian): 0 for rotation + uniform scale, growing with shear and stretch; NaN where undefined."""
    jac = forward_jacobians(forward, pts_src, step_px)
    ok = np.all(np.isfinite(jac), axis=(1, 2))
    out = np.full(len(jac), np.nan)
    if ok.any():
        out[ok] = similarity_deviation(np.concatenate([jac[ok], np.zeros((int(ok.sum()), 2, 1))], axis=2))
    return out


def long_segments(img: np.ndarray, min_fraction: float = LONG_LINE_FRACTION, max_count: int = MAX_LINES) -> np.ndarray:
    """The longest straight segments of an image (LSD), at least ``min_fraction`` of its long side.

    Returns (K, 2, 2) float64: K segments, each two (x, y) end points, longest first (K <= max_count).
    """
    found = cv2.createLineSegmentDetector().detect(_grey(img).astype(np.uint8))[0]
    if found is None:
        return np.zeros((0, 2, 2))
    segments = found.reshape(-1, 2, 2).astype(np.float64)
    lengths = np.linalg.norm(segments[:, 1] - segments[:, 0], axis=1)
    order = np.argsort(-lengths)
    keep = order[lengths[order] >= min_fraction * max(img.shape[:2])][:max_count]
    return segments[keep]


def line_bend_pct(forward: Forward, segments_src: np.ndarray, samples: int = LINE_SAMPLES) -> np.ndarray:
    """Per segment (K, 2, 2) of the source: how far its image under the warp is from straight.

    The largest distance of a mapped point from the chord between the mapped end points, in percent
    of the chord's length (scale-free, so warps of any output scale compare); 0 for any affine or
    homography; NaN where the warp is undefined on the segment.
    """
    t = np.linspace(0.0, 1.0, samples)[None, :, None]
    segments_src = np.asarray(segments_src, np.float64).reshape(-1, 2, 2)
    pts = segments_src[:, :1] + t * (segments_src[:, 1:] - segments_src[:, :1])  # (K, samples, 2)
    mapped = forward(pts.reshape(-1, 2)).reshape(pts.shape)
    chord = mapped[:, -1] - mapped[:, 0]
    length = np.linalg.norm(chord, axis=1)
    rel = mapped - mapped[:, :1]
    off_chord = np.abs(rel[:, :, 0] * chord[:, None, 1] - rel[:, :, 1] * chord[:, None, 0]) / length[:, None]
    with np.errstate(invalid="ignore"):
        return 100.0 * off_chord.max(axis=1) / length


def _grey(img: np.ndarray) -> np.ndarray:
    if img.ndim == 3 and img.shape[2] == 3:
        img = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    elif img.ndim == 3:
        img = img[:, :, 0]
    return img.astype(np.float32)
