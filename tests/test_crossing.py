"""The crossing clip and its figures (``sena_warp.evaluation.crossing``): a figure nearer than the
background walking across a static rig's overlap is shown whole and once in every frame.

The figures are checked on made-up canvases first (what a seam through two copies does), then the
clip on the bundled office recording (its left camera is ``office_cam2.mp4``): a 100 x 200 px figure
40 px nearer than the wall behind it, walking 8 px a frame from the left camera's side to the
right's, a 150 px one 60 px nearer walking back, and a 150 px one at the wall's depth walking back at
6 px a frame (its stripes change its cells every frame for as long as it takes to pass).
"""

from __future__ import annotations

import numpy as np
import pytest

from sena_warp.affine import apply_affine
from sena_warp.config import Config
from sena_warp.evaluation.crossing import (BLOCK_PX, CrossingFigures, Walk, background_affines, make_crossing_clip,
                                           shown_figure, walk_affines)
from sena_warp.video.estimate import spaced_span
from sena_warp.video.loop import VideoOptions
from sena_warp.video.stitch import stitch_videos

CFG = Config(device="cpu")  # the static rig's defaults
CANVAS = (300, 400)  # (H, W) of the made-up canvases
FIGURE = np.ones((100, 40), bool)
BLOCKS = FIGURE.size // BLOCK_PX**2  # what the figures count
COLUMN = 100 // BLOCK_PX  # blocks in a column of the figure
OFFSET_TGT = np.array([150.0, 0.0])  # the target's pixel (0, 0) on the made-up canvas


def made_up(parallax: float, seam_x: float) -> tuple:
    """A made-up canvas: the source map the identity, the target's shifted by ``OFFSET_TGT``; the
    figure at canvas x 200 in the target and ``parallax`` further right in the source; the seam a
    hard cut at ``seam_x``. The arguments of ``shown_figure``."""
    rows, cols = np.mgrid[0:CANVAS[0], 0:CANVAS[1]].astype(np.float32)
    map_src = np.dstack([cols, rows]).astype(np.float32)
    map_tgt = np.dstack([cols - OFFSET_TGT[0], rows - OFFSET_TGT[1]]).astype(np.float32)
    valid = (cols < 300, cols >= OFFSET_TGT[0])  # the overlap: 150 <= x < 300
    alpha = (cols < seam_x).astype(np.float32)
    to_tgt = np.float64([[1, 0, 200 - OFFSET_TGT[0]], [0, 1, 100]])
    to_src = np.float64([[1, 0, 200 + parallax], [0, 1, 100]])
    return (map_src, map_tgt), valid, alpha, (to_src, to_tgt), FIGURE


def test_a_seam_clear_of_both_copies_shows_the_figure_whole_from_one_view():
    left_of_both = shown_figure(*made_up(30.0, 190.0))
    assert left_of_both.whole and not left_of_both.doubled and left_of_both.source_share == 0.0
    assert left_of_both.truth == BLOCKS and left_of_both.apart_px == pytest.approx(30.0, abs=0.5)
    right_of_both = shown_figure(*made_up(30.0, 280.0))
    assert right_of_both.whole and right_of_both.source_share == 1.0


def test_a_seam_between_the_copies_of_a_near_figure_loses_a_strip_and_tears_it():
    # Between the left edges of the copies (x 200 and 230): the target shows the figure right of
    # the seam, the source nothing of it: a strip of 15 px is lost.
    cut = shown_figure(*made_up(30.0, 215.0))
    assert not cut.whole and cut.shown == pytest.approx(BLOCKS * (1 - 15 / 40), abs=COLUMN) and cut.pieces == 1
    # Through both: each view shows its side, with the 30 px between the copies lost: two pieces.
    torn = shown_figure(*made_up(30.0, 235.0))
    assert not torn.whole and torn.pieces == 2 and torn.shown == pytest.approx(BLOCKS * (1 - 30 / 40), abs=COLUMN)
    # Between the copies of a figure nearer than its width: it vanishes.
    gone = shown_figure(*made_up(50.0, 245.0))
    assert gone.shown == 0 and gone.pieces == 0


def test_a_seam_through_a_figure_farther_than_the_background_doubles_it():
    doubled = shown_figure(*made_up(-20.0, 200.0))
    assert doubled.doubled and doubled.twice == pytest.approx(BLOCKS * 20 / 40, abs=COLUMN) and doubled.pieces == 2


def test_a_seam_through_a_figure_at_the_background_s_depth_leaves_it_whole():
    through = shown_figure(*made_up(0.0, 220.0))
    assert through.whole and through.pieces == 1 and 0.0 < through.source_share < 1.0


def test_the_walk_starts_and_ends_where_one_view_alone_sees_the_figure():
    # A background shifted 300 px between the views: the left view ends at right-view x 339.
    rng = np.random.default_rng(0)
    pts_right = rng.uniform([0, 0], [340, 480], (200, 2))
    pts_left = pts_right + [300.0, 0.0]
    walk = Walk(parallax_px=25, width_px=100, speed_px=5)
    to_left, to_right, overlap_end = walk_affines(pts_left, pts_right, (480, 640), walk)
    assert overlap_end == pytest.approx(339.0)
    xs = to_right[:, 0, 2]
    assert xs[0] + 100 + 25 < 0 and xs[-1] > overlap_end and np.allclose(np.diff(xs), 5.0)
    assert np.allclose(to_left[:, 0, 2], xs + 300 + 25) and np.allclose(to_left[:, :, :2], np.eye(2))
    back = walk_affines(pts_left, pts_right, (480, 640), Walk(25, 100, 5, "left"))[1]
    assert np.allclose(back[::-1], to_right)


def test_the_background_behind_the_figure_is_its_nearest_matches_affine():
    # Two depths: the left half shifted 300 px, the right half 280 px (nearer walls shift more).
    rng = np.random.default_rng(1)
    pts_right = rng.uniform([0, 100], [640, 300], (400, 2))
    pts_left = pts_right + np.where(pts_right[:, :1] < 320, 300.0, 280.0) * [1.0, 0.0]
    at = np.float64([[60.0, 200.0], [580.0, 200.0]])
    affines = background_affines(pts_left, pts_right, at[:, 0], (100, 300), 40.0)
    shifts = [apply_affine(affine, point[None])[0] - point for affine, point in zip(affines, at)]
    assert np.allclose(shifts, [[300.0, 0.0], [280.0, 0.0]], atol=0.5)


WALKS = {"near, walking right": Walk(parallax_px=40, width_px=100, speed_px=8, direction="right"),
         "nearer and wide, walking left": Walk(parallax_px=60, width_px=150, speed_px=8, direction="left"),
         "wide at a medium speed, walking left": Walk(parallax_px=0, width_px=150, speed_px=6, direction="left")}


@pytest.fixture(scope="module", params=list(WALKS))
def crossing(request, bundled_dir, tmp_path_factory):
    video = bundled_dir / "video"
    folder = tmp_path_factory.mktemp("crossing")
    clip = make_crossing_clip(video / "office_cam2.mp4", video / "office_cam1.mp4", folder, WALKS[request.param],
                              spaced_span(CFG))
    observer = CrossingFigures(clip)
    report = stitch_videos(clip.left, clip.right, folder / "out.mp4", CFG, VideoOptions.from_config(CFG),
                           observer=observer)
    return clip, report, observer.figures()


def test_the_clip_is_a_crossing_at_a_parallax_the_warp_does_not_remove(crossing):
    clip, report, figures = crossing
    assert report["frames_out"] == clip.frames and report["stitch"]["rig"]["source"] == "left"
    assert figures["frames_counted"] == clip.frames - clip.lead_frames
    # The copies, where the canvas has both, lie about the parallax apart: the warp, fitted to the
    # background, does not align the figure.
    in_overlap = clip.in_overlap()
    apart = np.array([f["apart_px"] for f in figures["per_frame"] if in_overlap[f["frame"]] and f["apart_px"]])
    assert len(apart) >= 10 and np.all(np.abs(apart - clip.walk.parallax_px) < 12)


def test_the_crossing_figure_is_whole_and_shown_once_in_every_frame(crossing):
    # The seam keeps off the figure's two copies and the strip between them (video/frame_objects.py);
    # with the seam's band alone it cut through the near one in 18 frames and the wide one in 24. The
    # wide one at 6 px a frame was in two pieces in 3 frames while the views' spread learnt its
    # stripes at the full rate (video_seam_spread_learn 1).
    _, report, figures = crossing
    assert figures["frames_not_whole"] == [] and figures["frames_doubled"] == []
    # Shown from one view at a time: the source's share is 0 or 100 % in nearly every frame.
    shares = [f["source_pct"] for f in figures["per_frame"]]
    assert sum(0.0 < share < 100.0 for share in shares) <= 2


def test_the_object_band_moves_with_the_frame_s_own_transfers(crossing):
    """The object band comes down with the seam's band, and where its route moves the seam's band the
    band's cells go up with the frame's seam: each frame still moves its planes up and its output down
    once, one small download and one small upload (``kernels/transfer.py``); a plan goes up only with
    new maps (the first, a drift's blend)."""
    _, report, _ = crossing
    transfers = report["stitch"]["transfers"]
    assert transfers["per_frame_min"] == transfers["per_frame_max"] == {"upload": 2, "download": 2, "sync": 2}
    # No drift on this clip: one map set, whose plan's uploads (both passes' maps and static seam, the
    # bands' lines and first cells) are all; the band moving round the figure adds none.
    assert report["stitch"]["drift"]["applied"] == []
    assert transfers["total"]["upload"]["plan"] <= 12
