"""Debug pictures of intermediate results (the ``stitch_verbose`` idea of STYLE.md).

Pictures are BGR uint8 ``(H, W, 3)`` images meant for people; nothing in the pipeline reads them.
"""

from __future__ import annotations

import cv2
import numpy as np

from .features import Matches

# Drawing style only (not pipeline tunables): line and marker sizes in output pixels.
LINE_THICKNESS = 1
POINT_RADIUS = 3
HUE_STEPS = 180  # OpenCV's 8-bit hue range


def _match_colours(n: int) -> np.ndarray:
    """n distinct saturated BGR colours (uint8 (n, 3)), hue cycling with the golden ratio."""
    if n == 0:
        return np.zeros((0, 3), np.uint8)  # cvtColor refuses an empty image
    golden = (np.sqrt(5.0) - 1.0) / 2.0
    hues = (np.arange(n) * golden % 1.0 * HUE_STEPS).astype(np.uint8)
    hsv = np.stack([hues, np.full(n, 255, np.uint8), np.full(n, 255, np.uint8)], axis=1)
    return cv2.cvtColor(hsv[None], cv2.COLOR_HSV2BGR)[0]


def draw_matches(img_a: np.ndarray, img_b: np.ndarray, matches: Matches) -> np.ndarray:
    """Image a and image b side by side (a left, b right, tops aligned), one coloured line per match.

    ``img_a``/``img_b``: BGR uint8 (H, W, 3), sizes may differ (the shorter one is padded with
    black below). ``matches.pts_a``/``pts_b`` are ``(x, y)`` pixels of a and b. Returns BGR uint8
    (max(H_a, H_b), W_a + W_b, 3).
    """
    height = max(img_a.shape[0], img_b.shape[0])
    canvas = np.zeros((height, img_a.shape[1] + img_b.shape[1], 3), np.uint8)
    canvas[: img_a.shape[0], : img_a.shape[1]] = img_a
    canvas[: img_b.shape[0], img_a.shape[1]:] = img_b
    pts_b_canvas = matches.pts_b + np.array([img_a.shape[1], 0.0])
    for pa, pb, colour in zip(matches.pts_a, pts_b_canvas, _match_colours(len(matches))):
        colour = tuple(int(c) for c in colour)
        pa, pb = tuple(int(round(v)) for v in pa), tuple(int(round(v)) for v in pb)
        cv2.line(canvas, pa, pb, colour, LINE_THICKNESS, cv2.LINE_AA)
        cv2.circle(canvas, pa, POINT_RADIUS, colour, LINE_THICKNESS, cv2.LINE_AA)
        cv2.circle(canvas, pb, POINT_RADIUS, colour, LINE_THICKNESS, cv2.LINE_AA)
    return canvas
