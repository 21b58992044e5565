"""The crossing test (``sena_warp.evaluation.crossing``): an object that crosses the seam
of a static rig is shown once in every frame, neither twice nor cut.

The clip: the bundled udisd_test_000001 pair as a fixed background (b is the left view), a 48 px
patch of graf_gt moving along the middle row from the left camera's side across the overlap to the
right camera's, 12 px nearer than the background, 60 frames at 30 fps. Each frame's object points
in both views are known; ``VideoFigures`` maps them to the canvas and judges them from the frame's
seam weights (``naturalness.copy_figures``).
"""

from __future__ import annotations

import numpy as np
import pytest

from sena_warp.config import Config
from sena_warp.evaluation.crossing import EXTRA_DISPARITY_PX, FRAMES, OBJECT_PX, make_crossing_clip
from sena_warp.evaluation.video_figures import VideoFigures
from sena_warp.video.loop import VideoOptions
from sena_warp.video.stitch import stitch_videos
from helpers import read_pair

CFG = Config(device="cpu")  # the static rig's defaults


@pytest.fixture(scope="module")
def crossing(bundled_dir, tmp_path_factory):
    img_a, img_b = read_pair(bundled_dir / "udisd_test_000001")
    texture_img, _ = read_pair(bundled_dir / "graf_gt")
    folder = tmp_path_factory.mktemp("crossing")
    clip = make_crossing_clip(img_b, img_a, texture_img, folder)
    observer = VideoFigures(CFG, truth=clip.points)
    report = stitch_videos(clip.left, clip.right, folder / "out.mp4", CFG, VideoOptions.from_config(CFG),
                           observer=observer)
    return clip, report, observer.figures()["copies"]


def test_the_clip_is_a_crossing_at_a_parallax_the_warp_does_not_remove(crossing):
    clip, report, copies = crossing
    assert report["frames_out"] == FRAMES and report["stitch"]["rig"]["source"] == "left"
    assert report["stitch"]["reestimations"]["attempted"] == 0
    counted = [c for c in copies["per_frame"] if c["points"] > 0]
    assert len(counted) >= 50  # the object is in the overlap in most frames
    whole = [c for c in counted if c["points"] == 36]  # all of its 6 x 6 points
    assert len(whole) >= 40
    # Its two copies on the canvas stay about the extra disparity apart: the warp, fitted to the
    # background, does not align the object (measured 12.5-14.5 px).
    apart = np.array([c["apart_px"] for c in whole])
    assert np.all(apart > EXTRA_DISPARITY_PX - 2) and np.all(apart < EXTRA_DISPARITY_PX + 4)


def test_the_crossing_object_is_shown_once_in_every_frame(crossing):
    # The seam steps round the object (its background model's motion cost), within a band wide
    # enough for the object and its second copy (video_seam_band_ratio). With the band at 0.04 x the
    # diagonal it was cut in frame 26; without the motion cost, in frames 23-28.
    _, report, copies = crossing
    assert copies["frames_duplicated"] == [] and copies["frames_lost"] == []
    assert report["stitch"]["frame_seam"]["motion_px_max"] > OBJECT_PX  # it went round, not through
