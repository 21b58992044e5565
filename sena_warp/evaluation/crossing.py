"""The crossing clip: a textured object moving across the overlap of a real image pair.

A static two-camera clip made from one image pair (background, the same every frame) with a square
object, a patch cut from another image, pasted into both views: it moves at a constant speed along
a row of the right view from outside its left edge (seen by the left camera only) across the overlap
to beyond it (seen by the right camera only). Its disparity is the background's plus
``extra_disparity_px``: in the left view it sits at the background's correspondence of its
right-view position (a homography fitted by SIFT + RANSAC to the pair, independent of SENA) shifted by
that much in x, so it is nearer than the background and a warp aligned to the background
cannot align it. Every frame knows the object's points (a grid over the patch, corners included) in
both views exactly: the ground truth of :class:`~sena_warp.evaluation.video_figures.VideoFigures`'
duplicated / lost figure.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterable
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path

import cv2
import numpy as np

from sena_warp.errors import InputError
from sena_warp.video.writer import VideoWriter

OBJECT_PX = 48  # side of the square object
EXTRA_DISPARITY_PX = 12.0  # the object's disparity minus the background's (it is nearer)
FRAMES = 60
FPS = 30
GRID = 6  # object points per side (a GRID x GRID lattice from corner to corner, 1 px inside)
CLIP_CRF = 10  # near-lossless clips: the figure is about the seam, not the encoder
SIFT_RATIO = 0.75
HOMOGRAPHY_PX = 3.0


@dataclass(frozen=True)
class CrossingClip:
    """The clip's files and ground truth: ``centres_left`` / ``centres_right`` (F, 2) float64 (x, y)
    of the object's centre in each view per frame; ``offsets`` (K, 2) the object's points about its
    centre (the same in both views: the object is pasted unscaled)."""

    left: Path
    right: Path
    centres_left: np.ndarray
    centres_right: np.ndarray
    offsets: np.ndarray
    size_px: int
    extra_disparity_px: float

    def points(self, index: int, source: str) -> tuple[np.ndarray, np.ndarray] | None:
        """The object's points in frame ``index``: (in the source view, in the target view), (K, 2)
        input-frame (x, y); ``source`` is "left" or "right". A :data:`video_figures.Truth`."""
        if not 0 <= index < len(self.centres_left):
            return None
        left = self.centres_left[index] + self.offsets
        right = self.centres_right[index] + self.offsets
        return (left, right) if source == "left" else (right, left)


def background_homography(img_left: np.ndarray, img_right: np.ndarray) -> np.ndarray:
    """3x3 homography (left pixels -> right pixels) of the background: SIFT, ratio test, RANSAC."""
    sift = cv2.SIFT_create()
    grey = [cv2.cvtColor(img, cv2.COLOR_BGR2GRAY) for img in (img_left, img_right)]
    (kp_l, des_l), (kp_r, des_r) = (sift.detectAndCompute(g, None) for g in grey)
    pairs = cv2.BFMatcher().knnMatch(des_l, des_r, k=2)
    good = [m for m, n in (p for p in pairs if len(p) == 2) if m.distance < SIFT_RATIO * n.distance]
    if len(good) < 12:
        raise InputError(f"crossing clip: only {len(good)} SIFT matches between the views")
    pts_l = np.float64([kp_l[m.queryIdx].pt for m in good])
    pts_r = np.float64([kp_r[m.trainIdx].pt for m in good])
    homography, _ = cv2.findHomography(pts_l, pts_r, cv2.RANSAC, HOMOGRAPHY_PX)
    return homography


def _apply(homography: np.ndarray, pts: np.ndarray) -> np.ndarray:
    return cv2.perspectiveTransform(np.asarray(pts, np.float64).reshape(-1, 1, 2), homography).reshape(-1, 2)


def paste(frame: np.ndarray, patch: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """``frame`` with ``patch`` (S, S, 3) pasted opaque with its centre at sub-pixel ``centre`` (x, y)."""
    size = patch.shape[0]
    shift = np.asarray(centre, np.float64) - (size - 1) / 2.0
    move = np.float64([[1, 0, shift[0]], [0, 1, shift[1]]])
    height, width = frame.shape[:2]
    placed = cv2.warpAffine(patch.astype(np.float32), move, (width, height), flags=cv2.INTER_LINEAR)
    mask = cv2.warpAffine(np.ones(patch.shape[:2], np.float32), move, (width, height), flags=cv2.INTER_LINEAR)
    mixed = mask[:, :, None] * placed + (1.0 - mask[:, :, None]) * frame.astype(np.float32)
    return np.clip(np.rint(mixed), 0, 255).astype(np.uint8)


def write_clip(path: Path, frames_bgr: Iterable[np.ndarray], fps: int = FPS, crf: int = CLIP_CRF) -> None:
    """An H.264 clip of BGR frames (H, W, 3) uint8 with even sides, at ``crf`` (near-lossless by default)."""
    frames_bgr = iter(frames_bgr)
    first = next(frames_bgr)
    height, width = first.shape[:2]
    with VideoWriter(path, width, height, Fraction(fps), "libx264", crf, "veryfast") as writer:
        for index, frame in enumerate(itertools.chain([first], frames_bgr)):
            i420 = cv2.cvtColor(frame, cv2.COLOR_BGR2YUV_I420)
            chroma = i420[height:].reshape(2, height // 2, width // 2)
            writer.write(i420[:height], chroma[0], chroma[1], index)


def make_crossing_clip(img_left: np.ndarray, img_right: np.ndarray, texture_img: np.ndarray, folder: Path,
                       size_px: int = OBJECT_PX, extra_disparity_px: float = EXTRA_DISPARITY_PX,
                       frames: int = FRAMES, row: float | None = None) -> CrossingClip:
    """Write ``left.mp4`` / ``right.mp4`` into ``folder`` and return the clip with its ground truth.

    ``img_left`` / ``img_right``: the pair's BGR views (the left camera's and the right one's, same
    size, even sides); ``texture_img``: where the object's patch is cut (its centre). ``row``: the
    right-view row of the object's centre (default: the middle). The object's right-view x goes from
    one object size left of the view to one object size right of where the left view's border
    crosses that row.
    """
    height, width = img_right.shape[:2]
    if img_left.shape != img_right.shape or height % 2 or width % 2:
        raise InputError("crossing clip: the views must have one even-sided size")
    homography = background_homography(img_left, img_right)
    row = height / 2.0 if row is None else float(row)
    # Where the left view's right border lands on that row of the right view: the overlap's end.
    border = _apply(homography, np.array([[width - 1.0, y] for y in np.linspace(0, height - 1, 64)]))
    overlap_end = float(np.interp(row, border[:, 1], border[:, 0])) if np.all(np.diff(border[:, 1]) > 0) \
        else float(np.median(border[:, 0]))
    xs = np.linspace(-float(size_px), overlap_end + size_px, frames)
    centres_right = np.stack([xs, np.full(frames, row)], axis=1)
    centres_left = _apply(np.linalg.inv(homography), centres_right) + np.array([extra_disparity_px, 0.0])
    th, tw = texture_img.shape[:2]
    patch = texture_img[th // 2 - size_px // 2: th // 2 - size_px // 2 + size_px,
                        tw // 2 - size_px // 2: tw // 2 - size_px // 2 + size_px]
    grid = np.linspace(-(size_px - 1) / 2.0 + 1.0, (size_px - 1) / 2.0 - 1.0, GRID)
    offsets = np.stack(np.meshgrid(grid, grid), axis=-1).reshape(-1, 2)
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    paths = {"left": folder / "left.mp4", "right": folder / "right.mp4"}
    for side, background, centres in (("left", img_left, centres_left), ("right", img_right, centres_right)):
        write_clip(paths[side], (paste(background, patch, centre) for centre in centres))
    return CrossingClip(paths["left"], paths["right"], centres_left, centres_right, offsets, size_px,
                        extra_disparity_px)
