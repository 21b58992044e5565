"""A moving rig's steady canvas (``video/steady.py``) and its window, composited through its own maps.

On the bundled hand-held rooftop clip: the output's path shakes less than the target camera's while
following its pan within the lag bound; a stitch shows the canvas through that window with black
areas that change by well under 1 % of the output a frame, and ``--crop`` gives up the margin on
every side so the rectangle shown never changes.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from sena_warp.config import Config
from sena_warp.evaluation.video_figures import VideoFigures, second_difference
from sena_warp.video.loop import VideoOptions
from sena_warp.video.maps import sampled_mask
from sena_warp.video.steady import SteadyCanvas, margin_px, steady_crop
from sena_warp.video.stitch import stitch_videos
from helpers import decoded_frames

CFG = Config(device="cpu", video_estimate_pairs=2)


@pytest.fixture(scope="module")
def rooftop(bundled_dir):
    return bundled_dir / "video" / "rooftop_left.mp4", bundled_dir / "video" / "rooftop_right.mp4"


class WindowCheck:
    """An observer comparing each output frame with the canvas shown at its window, on the target's own
    part (the target is sampled once either way): the largest |difference| per frame (grey levels)."""

    def __init__(self, figures: VideoFigures):
        self.figures = figures
        self.largest: list[float] = []

    def __call__(self, frame) -> None:
        self.figures(frame)
        canvas, out = frame.canvas()[0].astype(np.float32), frame.planes_out[0].astype(np.float32)
        x, y, width, height = frame.window
        rows, cols = np.mgrid[0:height, 0:width].astype(np.float32)
        at = (cols + np.float32(x), rows + np.float32(y))
        shown = cv2.remap(canvas, *at, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=np.nan)
        alpha, lf = frame.weights()
        target = (alpha == 0) & (lf == 0) & sampled_mask(frame.maps.map_tgt_luma, frame.planes_tgt[0].shape)
        target = cv2.erode(target.astype(np.uint8), np.ones((5, 5), np.uint8))
        kept = (cv2.remap(target, *at, cv2.INTER_NEAREST) > 0) & np.isfinite(shown)
        self.largest.append(float(np.abs(out - shown)[kept].max()))


def test_the_output_path_shakes_less_than_the_target_and_lags_it_boundedly(rooftop):
    frames = decoded_frames(rooftop[1])
    steady = SteadyCanvas((480, 270), (480, 270), np.ones(2), CFG)
    path, shown = [], []
    for frame in frames:
        steady.follow(frame.y)
        path.append(steady.path)
        shown.append(steady.path + steady.shift)
    path, shown = np.array(path), np.array(shown)
    # The rig turns: its view moves by tens of px over the clip's two seconds.
    assert np.ptp(path[:, 0]) > 40.0
    # The window never lags the camera by more than the bound ...
    assert np.abs(shown - path).max() <= CFG.video_steady_max_px + 1e-9
    # ... and the picture's frame-to-frame shake is a fraction of the camera's (measured: 0.06 against 0.20 px).
    assert second_difference(shown).mean() < 0.5 * second_difference(path).mean()


def test_a_rig_found_static_glides_back_to_the_whole_canvas(rooftop):
    frames = decoded_frames(rooftop[1])
    steady = SteadyCanvas((480, 270), (480, 270), np.ones(2), CFG)
    for frame in frames[:40]:
        steady.follow(frame.y)
    away = steady.window().copy()
    assert np.abs(away).max() > 3.0  # the window sits off the canvas's corner while the rig pans
    windows = [away]
    for _ in range(120):
        steady.hold()
        windows.append(steady.window().copy())
    steps = np.abs(np.diff(np.array(windows), axis=0)).max()
    assert steps < 1.0  # no jump home: it stops, then glides (measured 0.67 px a frame at most, home in 2.5 s)
    assert steady.window_for("static") is None  # ... but home in the end: the output is the canvas again


def steady_run(rooftop, tmp_path, cfg: Config) -> tuple[VideoFigures, dict]:
    figures = VideoFigures(cfg)
    report = stitch_videos(*rooftop, tmp_path / "out.mp4", cfg, VideoOptions.from_config(cfg), observer=figures,
                           overwrite=True)
    return figures, report


def test_a_moving_rig_is_shown_steady_without_flashing_black(rooftop, tmp_path):
    cfg = CFG.replace(video_rig="moving")
    figures = VideoFigures(cfg)
    check = WindowCheck(figures)
    report = stitch_videos(*rooftop, tmp_path / "out.mp4", cfg, VideoOptions.from_config(cfg), observer=check)
    still, _ = steady_run(rooftop, tmp_path, cfg.replace(video_steady_max_px=0.0))
    # The output is the canvas shown at the window, sampled from the inputs once: on the target's part
    # what the canvas shows there, to the rounding (measured: at most 1.25 grey levels a frame).
    assert len(check.largest) == 60 and max(check.largest) <= 2.0
    found, unsteady = figures.figures(), still.figures()
    stitch = report["stitch"]
    assert stitch["rig"]["steady"]["frames"] == found["frames"]
    # The output shakes less than the canvas it is shown from (the target camera's shake; measured: 0.130
    # against 0.184 px a frame with the alignment's Lucas-Kanade window at 11 px, 0.123 at 15).
    assert found["output_shake_px"]["mean"] < 0.8 * unsteady["output_shake_px"]["mean"]
    # Black areas move in and out smoothly: under 1 % of the output a frame (measured: 0.62 %, the band at
    # the edge of an output 270 px wide moving by a pixel or two).
    assert found["uncovered_pct"]["largest_change"] <= 1.0


@pytest.fixture(scope="module")
def static_crop(rooftop, tmp_path_factory) -> dict:
    """The report of a cropped stitch of the rooftop as a fixed rig: the rectangle the crop tests compare with."""
    return steady_run(rooftop, tmp_path_factory.mktemp("static"), CFG.replace(video_rig="static", video_crop=True))[1]


def test_crop_gives_up_the_margin_on_every_side(rooftop, static_crop, tmp_path):
    cfg = CFG.replace(video_rig="moving", video_crop=True)
    _, report = steady_run(rooftop, tmp_path, cfg)
    static = static_crop
    margin = margin_px(cfg)
    canvas = report["stitch"]["canvas"]
    shown = static["stitch"]["canvas"]  # a static rig's crop: the first estimate's whole rectangle
    assert (canvas["width"], canvas["height"]) == (shown["width"] - 2 * margin, shown["height"] - 2 * margin)
    assert steady_crop(0, 0, 3, 100, margin) == (0, 0, 3, 100)  # too narrow to give anything up: kept


def test_crop_under_auto_is_the_whole_rectangle_unmoved(rooftop, static_crop, tmp_path):
    """--rig auto fixes the output's size before it has judged the rig: a cropped output keeps a fixed rig's
    whole rectangle, and no window moves over it (its edges would show black)."""
    cfg = CFG.replace(video_rig="auto", video_crop=True)
    figures, report = steady_run(rooftop, tmp_path, cfg)
    assert margin_px(cfg) == 0 and report["stitch"]["canvas"] == static_crop["stitch"]["canvas"]
    assert report["stitch"]["rig"]["decisions"][0]["mode"] == "moving"  # the rooftop is hand-held
    assert report["stitch"]["rig"]["steady"]["frames"] == 0  # never followed: the window stays on the rectangle
    assert figures.figures()["uncovered_pct"]["largest_change"] <= 1.0  # measured: 0.014 % (the moving maps)
