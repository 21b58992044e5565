"""``video/drift.py`` and ``maps.drifted_maps``: a static rig's drift check on the bundled pair, the maps
moved by the cameras' moves, and a static rig that creeps (the shared pitch's case): its maps follow
the camera that moved, a fixed rig's do not move."""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np
import pytest

from sena_warp.config import Config
from sena_warp.evaluation.crossing import write_clip
from sena_warp.evaluation.video_figures import VideoFigures
from sena_warp.composite import SeamLayout
from sena_warp.video.drift import (MAX_SHARE, MAX_STEP_SHARE, MIN_RESPONSE, DriftWatch, hann_window, overlap_boxes,
                                   thumbnail, view_shift)
from sena_warp.video.maps import PlaneMaps, chroma_positions, chroma_seam, drifted_maps, target_map
from sena_warp.video.loop import VideoOptions
from sena_warp.video.stitch import stitch_videos
from helpers import read_pair

CFG = Config(device="cpu")  # the static rig's defaults
FPS = 30
STILL, MOVING, SETTLED = 30, 60, 40  # frames before, during and after the left camera's move
DRIFT_PX = 12.0  # how far the left camera's view moves (down): 3 px between two checks, a creep


def shifted(img: np.ndarray, dx: float, dy: float) -> np.ndarray:
    return cv2.warpAffine(img, np.float64([[1, 0, dx], [0, 1, dy]]), img.shape[1::-1], flags=cv2.INTER_LINEAR,
                          borderMode=cv2.BORDER_REFLECT)


@pytest.fixture(scope="module")
def grey_view(bundled_dir) -> np.ndarray:
    _, img_b = read_pair(bundled_dir / "udisd_test_000001")
    return cv2.cvtColor(img_b, cv2.COLOR_BGR2GRAY)


def test_a_moved_view_is_measured_and_a_person_walking_through_a_fixed_one_is_not(grey_view):
    reference, scale = thumbnail(grey_view)
    window = hann_window(reference)
    assert reference.shape[1] == 320 and reference.dtype == np.float32
    same, response = view_shift(reference, thumbnail(grey_view)[0], scale, window)
    assert np.abs(same).max() < 0.1 and response > 0.9
    moved, response = view_shift(reference, thumbnail(shifted(grey_view, 12.0, -5.0))[0], scale, window)
    assert np.abs(moved - [12.0, -5.0]).max() < 1.0 and response > MIN_RESPONSE
    walker = grey_view.copy()
    walker[100:260, 200:280] = np.random.default_rng(0).integers(0, 256, (160, 80), dtype=np.uint8)
    assert np.abs(view_shift(reference, thumbnail(walker)[0], scale, window)[0]).max() < 1.0


def test_the_watch_gives_both_cameras_moves_and_none_for_a_view_it_cannot_compare(grey_view):
    whole = (0, 0, grey_view.shape[1], grey_view.shape[0])
    watch = DriftWatch(grey_view, grey_view, (whole, whole))
    source, target = watch.shifts(shifted(grey_view, 4.0, 0.0), shifted(grey_view, 0.0, -3.0))
    assert np.abs(source - [4.0, 0.0]).max() < 1.0 and np.abs(target - [0.0, -3.0]).max() < 1.0
    elsewhere = np.random.default_rng(1).integers(0, 256, grey_view.shape, dtype=np.uint8)  # nothing in common
    assert watch.shifts(grey_view, elsewhere) is None
    far = MAX_SHARE * grey_view.shape[1] + 6.0  # a rig that moved, not one that drifted
    assert watch.shifts(grey_view, shifted(grey_view, far, 0.0)) is None


def test_a_fast_move_is_not_followed_until_the_view_holds_still_again(grey_view):
    whole = (0, 0, grey_view.shape[1], grey_view.shape[0])
    watch = DriftWatch(grey_view, grey_view, (whole, whole))
    jump = MAX_STEP_SHARE * grey_view.shape[1] + 3.0  # within MAX_SHARE, but all at once
    assert jump < MAX_SHARE * grey_view.shape[1]
    bumped = shifted(grey_view, jump, 0.0)
    assert watch.shifts(grey_view, bumped) is None  # a pan, or a bump
    _, target = watch.shifts(grey_view, bumped)  # the next check: it stayed there
    assert abs(target[0] - jump) < 1.0


def test_the_watch_compares_the_part_of_each_view_the_overlap_shows(grey_view):
    # Only the box moves: the rest of the view stays. The watch over the box sees the move; one over
    # the whole view would see a mix.
    box = (200, 100, 420, 300)
    moved = grey_view.copy()
    moved[100:300, 200:420] = shifted(grey_view, 4.0, 0.0)[100:300, 200:420]
    source, _ = DriftWatch(grey_view, grey_view, (box, box)).shifts(moved, grey_view)
    assert np.abs(source - [4.0, 0.0]).max() < 1.0


def test_overlap_boxes_are_the_parts_of_the_views_the_overlap_samples():
    maps = shifted_by_20_5((40, 60))
    source_box, target_box = overlap_boxes(maps, (50, 70), (40, 50))
    # Both sampled where canvas x < 50 (the target's width) and the source x + 20 <= 69 (canvas x <= 49);
    # canvas y + 5 <= 49 all over: the source box is x 20-69, y 5-44, the target's x 0-49, y 0-39, both
    # widened by a tenth.
    assert source_box == (15, 1, 70, 49) and target_box == (0, 0, 50, 40)


def shifted_by_20_5(shape: tuple[int, int]) -> PlaneMaps:
    """Maps of ``shape`` where the source shows canvas (x, y) at (x + 20, y + 5), the target at (x, y)."""
    ys, xs = np.mgrid[0:shape[0], 0:shape[1]].astype(np.float32)
    map_src = np.stack([xs + 20.0, ys + 5.0], axis=-1)
    seam = SeamLayout(np.full(shape[0], 30.0, np.float32), True, 10.0, 8.0, 1.5, 0.0)
    alpha = np.full(shape, 0.5, np.float32)
    map_tgt = target_map(shape, np.array([0.0, 0.0]))
    return PlaneMaps(map_src, map_tgt, alpha, chroma_positions(map_src), chroma_positions(map_tgt),
                     alpha[::2, ::2].copy(), seam, chroma_seam(seam), np.full(shape[0], 30.0, np.float32), 100, None)


def test_drifted_maps_move_the_source_map_by_both_cameras_moves():
    # A map where the source shows canvas (x, y) at (x + 20, y + 5): after the target's content moved by
    # (3, 2) and the source's by (-1, 4), canvas q shows what was at q - (3, 2), now in the source at
    # (q - (3, 2)) + (20, 5) + (-1, 4); the seam stays.
    maps = shifted_by_20_5((40, 60))
    moved = drifted_maps(maps, np.array([-1.0, 4.0]), np.array([3.0, 2.0]))
    np.testing.assert_allclose(moved.map_src_luma[10, 10], [10 - 3 + 20 - 1, 10 - 2 + 5 + 4])
    assert np.isnan(moved.map_src_luma[0:2, :]).all() and np.isnan(moved.map_src_luma[:, 0:3]).all()
    np.testing.assert_allclose(moved.map_src_chroma, chroma_positions(moved.map_src_luma))
    assert moved.seam_luma is maps.seam_luma and moved.map_tgt_luma is maps.map_tgt_luma
    half = drifted_maps(maps, np.zeros(2), np.array([0.4, 0.0]))  # a fraction: on the positions
    np.testing.assert_allclose(half.map_src_luma[10, 10], [10 - 0.4 + 20, 15])


def creeping_clip(bundled_dir, folder, drift_px: float):
    """The bundled pair as a static rig (b left) whose left camera's view moves ``drift_px`` down
    between frames STILL and STILL + MOVING."""
    img_a, img_b = read_pair(bundled_dir / "udisd_test_000001")
    moves = np.concatenate([np.zeros(STILL), np.linspace(0.0, drift_px, MOVING), np.full(SETTLED, drift_px)])
    write_clip(folder / "left.mp4", (shifted(img_b, 0.0, dy) for dy in moves), FPS)
    write_clip(folder / "right.mp4", (img_a for _ in moves), FPS)
    return folder / "left.mp4", folder / "right.mp4"


def stitched(left, right, out, cfg: Config) -> tuple[dict, list[float]]:
    observer = VideoFigures(cfg)
    report = stitch_videos(left, right, out, cfg, VideoOptions.from_config(cfg), observer=observer)
    misalignment = observer.figures()["per_frame"]["misalignment_px"]
    return report, [m for m in misalignment[-SETTLED // 2:] if m is not None]


def test_a_creeping_static_rig_has_its_maps_moved_and_stays_aligned(bundled_dir, tmp_path):
    left, right = creeping_clip(bundled_dir, tmp_path, DRIFT_PX)
    report, late = stitched(left, right, tmp_path / "out.mp4", CFG)
    applied = report["stitch"]["drift"]["applied"]
    assert applied and STILL / FPS < applied[0]["time_s"] <= (STILL + MOVING) / FPS + CFG.video_drift_check_s
    # The left camera (the source) moved DRIFT_PX down: its content moved that much in its view.
    # (It follows to within video_drift_px: a smaller change does not move the maps.)
    assert abs(applied[-1]["source_px"][1] - DRIFT_PX) <= CFG.video_drift_px
    assert np.abs(applied[-1]["target_px"]).max() < 1.0
    assert report["stitch"]["reestimations"]["attempted"] == 0  # no new estimate: the maps moved
    fixed, late_fixed = stitched(left, right, tmp_path / "fixed.mp4", CFG.replace(video_drift_check_s=0.0))
    assert fixed["stitch"]["drift"]["checks"] == 0
    # Maps made before the move leave the views about the drift apart at the seam; moved ones align them.
    assert np.median(late_fixed) > 0.8 * DRIFT_PX
    assert np.median(late) < 0.4 * np.median(late_fixed)  # measured: 3.5 against 12 px


def test_a_fixed_rig_keeps_its_maps(bundled_dir, tmp_path):
    left, right = creeping_clip(bundled_dir, tmp_path, 0.0)
    report = stitch_videos(left, right, tmp_path / "out.mp4", CFG, VideoOptions.from_config(CFG))
    drift = report["stitch"]["drift"]
    assert drift["checks"] >= 5 and drift["applied"] == [] and drift["unclear"] == 0
    assert report["stitch"]["jitter"]["seam_jitter_px_max"] == 0.0


def test_on_an_output_scaled_from_the_canvas_a_drift_moves_the_maps_by_the_scaled_move():
    # The output at half the canvas: output (x, y) samples the source at canvas (2x + 0.5, 2y + 0.5) + (20, 5).
    ys, xs = np.mgrid[0:20, 0:30].astype(np.float32)
    maps = shifted_by_20_5((20, 30))
    maps = replace(maps, map_src_luma=np.stack([2 * xs + 20.5, 2 * ys + 5.5], axis=-1))
    # The target's content moved (4, 2) input px: 2 and 1 output px; the source's own move is in its px.
    moved = drifted_maps(maps, np.array([-1.0, 4.0]), np.array([4.0, 2.0]), (0.5, 0.5))
    np.testing.assert_allclose(moved.map_src_luma[10, 10], [2 * 8 + 20.5 - 1, 2 * 9 + 5.5 + 4])
    part = drifted_maps(maps, np.zeros(2), np.array([0.4, 0.0]), (0.5, 0.5))  # 0.2 output px: on the positions
    np.testing.assert_allclose(part.map_src_luma[10, 10], [2 * 10 + 20.5 - 0.4, 2 * 10 + 5.5])
