"""A moving rig's steady canvas (``video/steady.py``) and its window kernel (``kernels/shift.py``).

On the bundled hand-held rooftop clip: the output's path shakes less than the target camera's while
following its pan within the lag bound; a stitch shows the canvas through that window with black
areas that change by well under 1 % of the output a frame, and ``--crop`` gives up the margin on
every side so the rectangle shown never changes.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import warp as wp

from sena_warp.config import Config
from sena_warp.evaluation.video_figures import VideoFigures, second_difference
from sena_warp.kernels import runtime
from sena_warp.kernels.shift import shifted_plane_kernel
from sena_warp.video.loop import VideoOptions
from sena_warp.video.steady import SteadyCanvas, margin_px, steady_crop
from sena_warp.video.stitch import stitch_videos
from helpers import decoded_frames

CFG = Config(device="cpu", video_estimate_pairs=2)


@pytest.fixture(scope="module")
def rooftop(bundled_dir):
    return bundled_dir / "video" / "rooftop_left.mp4", bundled_dir / "video" / "rooftop_right.mp4"


def shifted(plane: np.ndarray, origin: tuple[float, float], shape: tuple[int, int], fill: int) -> np.ndarray:
    """``plane`` (H, W) uint8 seen through ``shifted_plane_kernel`` from ``origin`` (x, y), ``shape`` (H, W)."""
    canvas = wp.array(plane[:, :, None], dtype=wp.uint8, device="cpu")
    out = wp.empty((*shape, 1), dtype=wp.uint8, device="cpu")
    runtime.launch_row_loops(shifted_plane_kernel, *shape, [canvas, wp.vec2(*origin), wp.vec2i(fill, 0), out], "cpu", 2)
    return out.numpy()[:, :, 0]


def test_the_window_copies_whole_pixels_and_interpolates_between_them(bundled_dir):
    grey = cv2.cvtColor(cv2.imread(str(bundled_dir / "graf_gt" / "a.png")), cv2.COLOR_BGR2GRAY)
    # Whole pixels: the canvas itself, the fill where the window leaves it.
    out = shifted(grey, (-7.0, 5.0), (200, 300), 16)
    assert np.array_equal(out[:, 7:], grey[5:205, :293])
    assert (out[:, :7] == 16).all()
    # Sub-pixel: a smooth picture shifted by a fraction is what bilinear sampling gives, within a grey level
    # (the cubic differs from the bilinear by the picture's curvature, small once blurred).
    smooth = cv2.GaussianBlur(grey, (0, 0), 3.0)
    out = shifted(smooth, (10.5, 20.25), (200, 300), 16).astype(np.float64)
    rows, cols = np.mgrid[0:200, 0:300].astype(np.float32)
    bilinear = cv2.remap(smooth.astype(np.float32), cols + 10.5, rows + 20.25, cv2.INTER_LINEAR)
    assert np.abs(out - bilinear).max() <= 1.5
    assert np.abs(out - bilinear).mean() < 0.3


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
    figures, report = steady_run(rooftop, tmp_path, cfg)
    still, _ = steady_run(rooftop, tmp_path, cfg.replace(video_steady_max_px=0.0))
    found, unsteady = figures.figures(), still.figures()
    stitch = report["stitch"]
    assert stitch["rig"]["steady"]["frames"] == found["frames"]
    # The output shakes less than the canvas it is cut from (the target camera's shake; measured: 0.10
    # against 0.18 px a frame).
    assert found["output_shake_px"]["mean"] < 0.7 * unsteady["output_shake_px"]["mean"]
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
