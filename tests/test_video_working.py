"""A video's estimate at a working resolution (``video/working.py``): the positions' conventions, and on
the bundled rooftop clips an estimate made on frames half as large, scaled up, against the estimate
at full resolution."""

from __future__ import annotations

from dataclasses import replace
from itertools import islice

import cv2
import numpy as np
import pytest

from sena_warp.config import Config
from sena_warp.features import match_images
from sena_warp.kernels.runtime import resolve_config
from sena_warp.video.estimate import estimate_pair
from sena_warp.video.reader import FrameReader
from sena_warp.video.maps import at_positions
from sena_warp.video.working import prior_to_small, to_full, to_small, working_scale

CFG = resolve_config(Config(device="cpu"))


def test_working_scale_shrinks_only_frames_above_the_side():
    assert working_scale(((1080, 1920), (1080, 1920)), 1024) == 1.875
    assert working_scale(((720, 1280, 3), (1080, 1920, 3)), 1024) == 1.875  # the larger frame decides
    assert working_scale(((480, 640), (480, 640)), 1024) == 1.0


def test_pixel_centres_map_between_resolutions():
    pts = np.array([[0.0, 0.0], [1919.0, 1079.0], [100.25, 7.5]])
    scale = np.array([1.875, 1.875])
    assert np.allclose(to_full(to_small(pts, scale), scale), pts)
    # Full pixels 0 and 1 straddle working pixel 0's centre at scale 2: -0.25 and 0.25.
    assert np.allclose(to_small(np.array([0.0, 1.0]), 2.0), [-0.25, 0.25])


def test_at_positions_is_linear_and_keeps_unknown_lines_unknown():
    values = np.array([0.0, 10.0, np.nan, 30.0])
    out = at_positions(values, np.array([-1.0, 0.5, 1.0, 1.5, 3.0, 9.0]))
    assert np.allclose(out[[0, 1, 2, 4, 5]], [0.0, 5.0, 10.0, 30.0, 30.0])
    assert np.isnan(out[3])  # one of its taps is unknown
    grid = np.arange(12.0).reshape(2, 6)
    assert np.allclose(at_positions(grid, np.array([2.5]), axis=1)[:, 0], [2.5, 8.5])


def test_a_prior_seam_is_carried_to_the_smaller_target():
    prior = np.full(1080, 900.0)
    prior[:100] = np.nan
    small = prior_to_small(prior, 2.0)
    assert len(small) == 540
    assert np.allclose(small[60:], (900.5 / 2) - 0.5) and np.isnan(small[:49]).all()
    assert prior_to_small(None, 2.0) is None


@pytest.fixture(scope="module", params=[False, True], ids=["horizontal", "turned"])
def rooftop_pair(bundled_dir, request):
    """Frame 10 of the rooftop clips (270x480 px, portrait) made twice as large, then estimated at half
    that: frames above the working side, as 4K ones are above the default 1920 px. Turned by 90
    degrees, the left camera is on top: a vertical rig, whose working frame is transposed."""
    def doubled(plane: np.ndarray) -> np.ndarray:
        plane = np.ascontiguousarray(plane.T) if request.param else plane
        return cv2.resize(plane, (2 * plane.shape[1], 2 * plane.shape[0]), interpolation=cv2.INTER_CUBIC)

    frames = []
    for name in ("rooftop_left", "rooftop_right"):
        with FrameReader(bundled_dir / "video" / f"{name}.mp4") as reader:
            frame = list(islice(reader, 11))[-1]
        frames.append(replace(frame, y=doubled(frame.y), u=doubled(frame.u), v=doubled(frame.v)))
    return tuple(frames)


def residuals_px(maps, pair, cfg: Config) -> np.ndarray:
    """|M_s(a match's target point on the canvas) - its source point| (full source pixels, input frame)
    over the pair's matches at full resolution that land on the canvas: how well the stitch aligns them."""
    matches = match_images(pair[0].to_bgr(), pair[1].to_bgr(), cfg)
    pts_src, pts_tgt = maps.rig.pick(matches.pts_a, matches.pts_b)
    canvas = (pts_tgt - maps.map_tgt_input[0, 0]).astype(np.float32)  # the target is pasted at offset -map_tgt[0, 0]
    sampled = cv2.remap(maps.map_src_input, canvas[:, :1], canvas[:, 1:], cv2.INTER_LINEAR,
                        borderMode=cv2.BORDER_CONSTANT, borderValue=np.nan)[:, 0]
    return np.linalg.norm(sampled - pts_src, axis=1)[np.isfinite(sampled).all(1)]


def test_an_estimate_at_half_the_size_aligns_as_the_full_one_does(rooftop_pair):
    """The doubled rooftop frames estimated at a long side of 480 and scaled up, against the estimate at
    full resolution, XFeat at 480 px in both (as at 1080p, where XFeat works at 1024 px either way): the
    canvas is as large, the target sits unwarped at a whole-pixel offset, the seam (where the alpha
    crosses 0.5) and the lf fade are on the full canvas, and the matches line up as closely."""
    cfg = CFG.replace(xfeat_max_side=480)
    full = estimate_pair(*rooftop_pair, cfg.replace(video_estimate_max_side=960), "auto")
    half = estimate_pair(*rooftop_pair, cfg.replace(video_estimate_max_side=480), "auto")
    assert "scale_up" in half.seconds and "scale_up" not in full.seconds
    assert half.rig.vertical == full.rig.vertical
    assert abs(half.alpha_input.shape[0] - full.alpha_input.shape[0]) <= 0.05 * full.alpha_input.shape[0]
    assert abs(half.alpha_input.shape[1] - full.alpha_input.shape[1]) <= 0.05 * full.alpha_input.shape[1]
    offset = -half.map_tgt_input[0, 0]
    rows, cols = half.map_tgt_input.shape[:2]
    assert np.array_equal(offset, np.round(offset))
    assert np.array_equal(half.map_tgt_input[rows - 1, cols - 1], [cols - 1 - offset[0], rows - 1 - offset[1]])
    lines = cols if half.rig.vertical else rows
    assert half.map_src_input.shape == (rows, cols, 2) and len(half.seam_input.positions) == lines
    assert len(half.seam.maps.seam_x_canvas) == lines
    alpha = half.alpha_input.T if half.rig.vertical else half.alpha_input  # one line per row
    for line in range(0, lines, 97):
        crossing = np.argmax(alpha[line] < 0.5)
        if alpha[line, 0] >= 0.5 and crossing > 0:
            assert abs(crossing - half.seam_input.positions[line]) <= 2
    assert half.seam_input.lf_px == pytest.approx(full.seam_input.lf_px, rel=0.05)  # a fade of the same reach
    assert half.seam_input.transition_px == full.seam_input.transition_px  # composited at full resolution
    res_full, res_half = residuals_px(full, rooftop_pair, cfg), residuals_px(half, rooftop_pair, cfg)
    assert len(res_half) > 0.9 * len(res_full) > 100
    assert np.median(res_half) < 1.1 * np.median(res_full) + 0.2
    assert (res_half < 3).mean() > 0.9 * (res_full < 3).mean()
