"""Pan clips: a hand-held two-camera rig panning across a real image pair, made from the pair's photographs.

Each camera's frame is a window cut from its photograph (``cv2.getRectSubPix``, bilinear): both windows
move together, as two cameras on one rig do, sliding ``slide_px`` to the right over the clip (eased in
and out: a pan starts and stops smoothly) and swaying as a hand does (:data:`SWAY_PX`, a few Hz). Where
the windows sit is chosen once from the pair's background homography (SIFT + RANSAC,
``crossing.background_homography``), so that at mid-pan the two views overlap by about
:data:`OVERLAP_SHARE` of their width and see the same rows. The scene never moves and every frame of
a view is the same photograph, so what changes from frame to frame is only where the rig looks: the
clip a moving rig's alignment should follow exactly. Deterministic: the same pair and settings give
the same clip.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from sena_warp.errors import InputError

from .crossing import background_homography, write_clip

SIZE = (1280, 720)  # (width, height) of each camera's frame
SECONDS = 5.0
FPS = 30
SWAY_PX = ((2.0, 2.3), (6.0, 0.8))  # the hand's sway: (amplitude px, frequency Hz) across and down
OVERLAP_SHARE = 0.4  # the views overlap by about this share of their width at mid-pan ...
OVERLAP_RANGE = (0.2, 0.7)  # ... and by a share within this range, or the pair cannot make a pan
PAN_CRF = 18  # a good phone's quality: the encoder's blocks are part of what a stitch meets


@dataclass(frozen=True)
class PanClip:
    """The clip's files and where each frame's window sits: ``corners_left`` / ``corners_right`` (F, 2)
    float64 (x, y) of each window's top-left corner in its photograph; ``overlap_share``: the views'
    overlap at mid-pan, a share of the width."""

    left: Path
    right: Path
    corners_left: np.ndarray
    corners_right: np.ndarray
    overlap_share: float


def rig_path(frames: int, slide_px: float, fps: float = FPS) -> np.ndarray:
    """(F, 2) float64 (x, y) offsets of the rig's windows from their first position: ``slide_px`` to the
    right, eased (half a cosine), plus the hand's sway (:data:`SWAY_PX`), 0 on the first frame."""
    t = np.arange(frames) / fps
    share = 0.5 * (1.0 - np.cos(np.pi * np.arange(frames) / max(frames - 1, 1)))
    (across, f_across), (down, f_down) = SWAY_PX
    return np.stack([slide_px * share + across * np.sin(2 * np.pi * f_across * t),
                     down * np.sin(2 * np.pi * f_down * t)], axis=1)


def _apply(homography: np.ndarray, pts: np.ndarray) -> np.ndarray:
    return cv2.perspectiveTransform(np.asarray(pts, np.float64).reshape(-1, 1, 2), homography).reshape(-1, 2)


def window_corners(homography: np.ndarray, shape_left: tuple[int, int], shape_right: tuple[int, int],
                   path: np.ndarray, size: tuple[int, int] = SIZE) -> tuple[np.ndarray, np.ndarray, float]:
    """The windows' first top-left corners (x, y) in the left and the right photograph (whole pixels) and
    the overlap share at mid-pan: inside both photographs all along ``path`` (:func:`rig_path`), the
    right window showing the same rows and overlapping the left one by the share nearest
    :data:`OVERLAP_SHARE`. ``homography``: left photograph -> right; ``shape_*``: (rows, cols).
    InputError when the pair leaves no such placement."""
    width, height = size
    low, high = path.min(axis=0), path.max(axis=0)
    mid = path[len(path) // 2]

    def span(shape: tuple[int, int]) -> tuple[range, range]:
        xs = range(int(np.ceil(-low[0])), int(np.floor(shape[1] - width - high[0])) + 1)
        ys = range(int(np.ceil(-low[1])), int(np.floor(shape[0] - height - high[1])) + 1)
        return xs, ys

    xs_l, ys_l = span(shape_left)
    xs_r, ys_r = span(shape_right)
    best = None
    for x in xs_l[::4]:
        for y in ys_l[::4]:
            centre = np.array([x + width / 2.0, y + height / 2.0]) + mid
            seen = _apply(homography, centre)[0]  # where the right photograph shows the left view's centre
            y_r = int(round(seen[1] - height / 2.0 - mid[1]))
            # The right window's centre (1 - OVERLAP_SHARE) widths right of that point, or as near as fits.
            ideal = int(round(seen[0] + (1 - OVERLAP_SHARE) * width - width / 2.0 - mid[0]))
            x_r = min(max(ideal, xs_r.start), xs_r.stop - 1)
            share = 1.0 - abs(x_r + width / 2.0 + mid[0] - seen[0]) / width
            if y_r not in ys_r or x_r not in xs_r or not OVERLAP_RANGE[0] <= share <= OVERLAP_RANGE[1]:
                continue
            score = (round(abs(share - OVERLAP_SHARE) / 0.05), abs(y - (shape_left[0] - height) / 2.0))
            if best is None or score < best[0]:
                best = (score, np.array([x, y], np.float64), np.array([x_r, y_r], np.float64), share)
    if best is None:
        raise InputError(f"pan: no {width}x{height} windows of this pair slide {path[-1, 0] - path[0, 0]:.0f} px "
                         f"inside both photographs with an overlap of {OVERLAP_RANGE[0]}-{OVERLAP_RANGE[1]}")
    return best[1], best[2], float(best[3])


def make_pan(img_left: np.ndarray, img_right: np.ndarray, folder: Path, slide_px: float,
             seconds: float = SECONDS, size: tuple[int, int] = SIZE, fps: int = FPS) -> PanClip:
    """Write ``left.mp4`` / ``right.mp4`` (``size``, ``fps``, ``seconds`` long, libx264 crf :data:`PAN_CRF`)
    into ``folder``: the rig panning ``slide_px`` across the pair ``img_left`` / ``img_right`` (BGR
    photographs of the left and the right view); returns where every frame's windows sit."""
    frames = int(round(seconds * fps))
    path = rig_path(frames, slide_px, fps)
    homography = background_homography(img_left, img_right)
    first_left, first_right, share = window_corners(homography, img_left.shape[:2], img_right.shape[:2], path, size)
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    corners = {"left": first_left + path, "right": first_right + path}
    paths = {"left": folder / "left.mp4", "right": folder / "right.mp4"}
    centre = np.array([(size[0] - 1) / 2.0, (size[1] - 1) / 2.0])
    for side, img in (("left", img_left), ("right", img_right)):
        write_clip(paths[side], (cv2.getRectSubPix(img, size, tuple(map(float, corner + centre)))
                                 for corner in corners[side]), fps, PAN_CRF)
    return PanClip(paths["left"], paths["right"], corners["left"], corners["right"], share)
