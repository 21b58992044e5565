"""The warps SENA is compared with (docs/evaluation.md): its own global affine alone, a global
homography from SIFT + RANSAC, and OpenCV's stitcher (``cv2.Stitcher``, PANORAMA and SCANS modes).

Each gives what the evaluation measures the same way for every method: the source warped onto a
frame shared with the target (for overlap PSNR/SSIM) and a forward map of each input's pixels into
the output (for the shape figures of ``metrics``). Points are (N, 2) float64 (x, y) pixels.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import cv2
import numpy as np

from sena_warp.affine import as_homogeneous
from sena_warp.config import Config
from sena_warp.errors import GeometryError, MatchError
from sena_warp.features import match_images
from sena_warp.stitch import Warp
from sena_warp.warp_map import source_map_canvas

from .metrics import Forward

HOMOGRAPHY_RANSAC_PX = 3.0  # the SIFT + RANSAC baseline's inlier threshold (docs/evaluation.md)
MIN_HOMOGRAPHY_INLIERS = 8  # fewer RANSAC inliers than this: no usable homography
FULL_WEIGHT_TOL = 1e-4  # a warped image of ones below 1 - this had a bilinear tap outside the source
OPENCV_MODES = {"opencv_panorama": cv2.Stitcher_PANORAMA, "opencv_scans": cv2.Stitcher_SCANS}
# cv2.Stitcher's projection per mode: what composePanorama warps both views with.
OPENCV_WARPERS = {"opencv_panorama": "spherical", "opencv_scans": "affine"}
AFFINE_PROBE_PX = 1000.0  # spacing of the panorama points an affine warper's forward map is fitted through
OPENCV_STATUS = {  # cv2.Stitcher.Status -> what it means for the user
    1: "too few confident matches between the images (ERR_NEED_MORE_IMGS)",
    2: "its homography estimation failed (ERR_HOMOGRAPHY_EST_FAIL)",
    3: "its camera parameter adjustment failed (ERR_CAMERA_PARAMS_ADJUST_FAIL)",
}


def affine_map_canvas(warp: Warp, cfg: Config) -> np.ndarray:
    """The source map of ``A_glob`` alone (zero field) over the warp's working canvas: (H, W, 2) float32
    (x, y); ``cfg.device`` resolved."""
    canvas = warp.overlap.canvas
    return source_map_canvas(canvas, warp.glob.affine_src_to_tgt, np.zeros((*canvas.shape, 2), np.float32), cfg)


def sift_homography(img_src: np.ndarray, img_tgt: np.ndarray, cfg: Config) -> np.ndarray:
    """3x3 homography src -> tgt from OpenCV SIFT matches (ratio test) and RANSAC (3 px); MatchError if none."""
    matches = match_images(img_src, img_tgt, cfg.replace(features="sift"))
    if len(matches) < MIN_HOMOGRAPHY_INLIERS:
        raise MatchError(f"only {len(matches)} SIFT matches, a homography needs {MIN_HOMOGRAPHY_INLIERS}")
    homography, inliers = cv2.findHomography(matches.pts_a, matches.pts_b, cv2.RANSAC, HOMOGRAPHY_RANSAC_PX)
    if homography is None or int(inliers.sum()) < MIN_HOMOGRAPHY_INLIERS:
        raise MatchError(f"no homography with {MIN_HOMOGRAPHY_INLIERS} RANSAC inliers among {len(matches)} SIFT matches")
    return homography


def homography_to_target(img_src: np.ndarray, homography: np.ndarray, shape_tgt: tuple[int, ...]
                         ) -> tuple[np.ndarray, np.ndarray]:
    """The source warped into the target frame by a 3x3 src -> tgt homography: (image, valid (h, w) bool)."""
    size_tgt = (shape_tgt[1], shape_tgt[0])
    warped = cv2.warpPerspective(img_src, homography, size_tgt, flags=cv2.INTER_LINEAR)
    ones = np.ones(img_src.shape[:2], np.float32)
    # Bilinear weights of in-image taps sum to 1: below 1 means a tap fell outside the source.
    valid = cv2.warpPerspective(ones, homography, size_tgt, flags=cv2.INTER_LINEAR) >= 1.0 - FULL_WEIGHT_TOL
    return warped, valid


def homography_forward(homography: np.ndarray) -> Forward:
    """The forward map of a 3x3 homography or a 2x3 affine (``affine.as_homogeneous``)."""
    matrix = as_homogeneous(homography)

    def forward(pts: np.ndarray) -> np.ndarray:
        projected = np.c_[pts, np.ones(len(pts))] @ matrix.T
        return projected[:, :2] / projected[:, 2:]

    return forward


@dataclass(frozen=True)
class OpenCVStitch:
    """A finished ``cv2.Stitcher`` run on (img_a, img_b): its panorama and the camera models it composed with.

    ``cameras[i]`` belongs to input i (a = 0, b = 1), at the stitcher's registration scale
    ``work_scale``; the composition ran at full resolution with ``warper`` (see :func:`opencv_warper`).
    """

    method: str
    panorama: np.ndarray  # (H, W, 3) BGR uint8
    cameras: tuple
    work_scale: float
    seconds: float


def opencv_stitch(img_a: np.ndarray, img_b: np.ndarray, method: str) -> OpenCVStitch:
    """Run OpenCV's stitcher in ``method``'s mode; MatchError/GeometryError with its status when it fails."""
    stitcher = cv2.Stitcher.create(OPENCV_MODES[method])
    t0 = time.perf_counter()
    status, panorama = stitcher.stitch([img_a, img_b])
    seconds = time.perf_counter() - t0
    if status != cv2.Stitcher_OK:
        error = MatchError if status == 1 else GeometryError
        raise error(f"cv2.Stitcher ({method}) failed: {OPENCV_STATUS.get(status, f'status {status}')}")
    if list(stitcher.component()) != [0, 1]:
        raise MatchError(f"cv2.Stitcher ({method}) kept only input(s) {list(stitcher.component())}")
    return OpenCVStitch(method, panorama, tuple(stitcher.cameras()), float(stitcher.workScale()), seconds)


def opencv_warper(stitch: OpenCVStitch) -> tuple[cv2.PyRotationWarper, list[np.ndarray], list[np.ndarray]]:
    """The warper and full-resolution (K, R) per input that ``composePanorama`` used.

    As cv2.Stitcher does at full compositing resolution: the warper's scale is the median focal
    length, camera intrinsics are rescaled from the registration scale to full resolution.
    """
    to_full = np.diag([1.0 / stitch.work_scale, 1.0 / stitch.work_scale, 1.0])
    scale = float(np.median([camera.focal for camera in stitch.cameras])) / stitch.work_scale
    warper = cv2.PyRotationWarper(OPENCV_WARPERS[stitch.method], scale)
    intrinsics = [(to_full @ camera.K()).astype(np.float32) for camera in stitch.cameras]
    rotations = [np.asarray(camera.R, np.float32) for camera in stitch.cameras]
    return warper, intrinsics, rotations


def opencv_forward(stitch: OpenCVStitch, index: int) -> Forward:
    """Forward map of input ``index``'s pixels into the stitcher's panorama frame (its own projection)."""
    warper, intrinsics, rotations = opencv_warper(stitch)
    k, r = intrinsics[index], rotations[index]
    if OPENCV_WARPERS[stitch.method] == "affine":
        # OpenCV's AffineWarper.warpPoint disagrees with its own warp() (tens of px, seen with
        # OpenCV 5.0); warpPointBackward agrees with it, and the map is affine: invert three points.
        pano = np.float32([[0, 0], [AFFINE_PROBE_PX, 0], [0, AFFINE_PROBE_PX]])
        src = np.float32([warper.warpPointBackward((float(x), float(y)), k, r) for x, y in pano])
        return homography_forward(cv2.getAffineTransform(src, pano))

    def forward(pts: np.ndarray) -> np.ndarray:
        return np.array([warper.warpPoint((float(x), float(y)), k, r) for x, y in pts], np.float64).reshape(-1, 2)

    return forward


def opencv_views(stitch: OpenCVStitch, images: tuple[np.ndarray, np.ndarray]
                 ) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]:
    """Both inputs warped into the stitcher's panorama frame on one grid, before its seams and blending.

    Returns ((image_a, valid_a), (image_b, valid_b)): uint8 (H, W, 3) and bool (H, W) on the union of
    the two warped rectangles, so the overlap can be measured as for the other methods.
    """
    warper, intrinsics, rotations = opencv_warper(stitch)
    placed = []
    for img, k, r in zip(images, intrinsics, rotations):
        corner, warped = warper.warp(img, k, r, cv2.INTER_LINEAR, cv2.BORDER_CONSTANT)
        _, mask = warper.warp(np.full(img.shape[:2], 255, np.uint8), k, r, cv2.INTER_NEAREST, cv2.BORDER_CONSTANT)
        placed.append((np.asarray(corner, int), warped, mask > 0))
    x0, y0 = np.min([c for c, _, _ in placed], axis=0)
    x1 = max(c[0] + w.shape[1] for c, w, _ in placed)
    y1 = max(c[1] + w.shape[0] for c, w, _ in placed)
    views = []
    for (cx, cy), warped, mask in placed:
        image = np.zeros((y1 - y0, x1 - x0, 3), np.uint8)
        valid = np.zeros((y1 - y0, x1 - x0), bool)
        rows, cols = slice(cy - y0, cy - y0 + warped.shape[0]), slice(cx - x0, cx - x0 + warped.shape[1])
        image[rows, cols], valid[rows, cols] = warped, mask
        views.append((image, valid))
    return views[0], views[1]
