"""The pan clips (``sena_warp.evaluation.pans``): windows that slide as the rig does, cut where they say.

A small pan is made from the bundled UDIS-D pair: every decoded frame must be the window of its
photograph at the corner the clip reports (the encoder's loss aside), the rig's path must start at
rest and slide as far as asked, and the two views must overlap by a share in the allowed range.
"""

from __future__ import annotations

import av
import cv2
import numpy as np
import pytest

from sena_warp.errors import InputError
from sena_warp.evaluation.crossing import background_homography
from sena_warp.evaluation.pans import OVERLAP_RANGE, SWAY_PX, make_pan, rig_path, window_corners

SIZE = (256, 144)


def decoded(path) -> list[np.ndarray]:
    with av.open(str(path)) as container:
        return [frame.to_ndarray(format="bgr24") for frame in container.decode(video=0)]


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    mse = float(np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2))
    return 10.0 * np.log10(255.0**2 / max(mse, 1e-12))


def test_rig_path_starts_at_rest_and_slides_as_far_as_asked():
    path = rig_path(150, 400.0)
    assert path[0].tolist() == [0.0, 0.0]
    (across, _), (down, _) = SWAY_PX
    assert abs(path[-1, 0] - 400.0) <= across and np.abs(path[:, 1]).max() <= down
    steps = np.diff(path[:, 0])
    assert steps.max() < 2.5 * 400.0 / 150  # eased: never faster than a constant pan by much more than 2x


def test_a_pan_cuts_each_frame_where_it_says(udisd_pair, tmp_path):
    img_right, img_left = udisd_pair  # b is the left view
    clip = make_pan(img_left, img_right, tmp_path, slide_px=60.0, seconds=1.0, size=SIZE, fps=10)
    assert OVERLAP_RANGE[0] <= clip.overlap_share <= OVERLAP_RANGE[1]
    centre = np.array([(SIZE[0] - 1) / 2.0, (SIZE[1] - 1) / 2.0])
    for path, img, corners in ((clip.left, img_left, clip.corners_left), (clip.right, img_right, clip.corners_right)):
        frames = decoded(path)
        assert len(frames) == 10 and frames[0].shape == (SIZE[1], SIZE[0], 3)
        for frame, corner in zip(frames, corners):
            window = cv2.getRectSubPix(img, SIZE, tuple(map(float, corner + centre)))
            assert psnr(frame, window) > 30.0  # measured 35.7-38.8 dB (crf 18); a window 1 px off: 18-22 dB
        assert np.allclose(corners - corners[0], rig_path(10, 60.0, 10))  # both windows move as one rig


def test_a_pair_too_small_for_the_slide_is_refused(udisd_pair):
    img_right, img_left = udisd_pair
    homography = background_homography(img_left, img_right)
    with pytest.raises(InputError, match="pan: no 256x144 windows"):
        window_corners(homography, img_left.shape[:2], img_right.shape[:2], rig_path(10, 400.0, 10), SIZE)
