"""``video/drift.py``: a static rig's drift check, on the bundled pair, and a static rig that creeps
(the shared pitch's case): its maps follow the camera that moved, a fixed rig's do not move."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from sena_warp.config import Config
from sena_warp.evaluation.crossing import write_clip
from sena_warp.evaluation.video_figures import VideoFigures
from sena_warp.video.drift import DriftWatch, thumbnail, view_shift_px
from sena_warp.video.estimate import estimate_pair
from sena_warp.video.loop import VideoOptions
from sena_warp.video.stitch import stitch_videos
from helpers import decoded_frames, read_pair

# The static rig's defaults, re-estimates on the loop's thread: the same frames every run.
CFG = Config(device="cpu", video_estimate_workers=0)
FPS = 30
STILL, MOVING, SETTLED = 30, 20, 40  # frames before, during and after the left camera's move
DRIFT_PX = 20.0  # how far the left camera's view moves (down)


def shifted(img: np.ndarray, dx: float, dy: float) -> np.ndarray:
    return cv2.warpAffine(img, np.float64([[1, 0, dx], [0, 1, dy]]), img.shape[1::-1], flags=cv2.INTER_LINEAR,
                          borderMode=cv2.BORDER_REFLECT)


@pytest.fixture(scope="module")
def grey_view(bundled_dir) -> np.ndarray:
    _, img_b = read_pair(bundled_dir / "udisd_test_000001")
    return cv2.cvtColor(img_b, cv2.COLOR_BGR2GRAY)


def test_a_moved_view_is_measured_and_a_person_walking_through_a_fixed_one_is_not(grey_view):
    reference, scale = thumbnail(grey_view)
    assert reference.shape[1] == 320 and reference.dtype == np.float32
    assert view_shift_px(reference, thumbnail(grey_view)[0], scale) < 0.1
    moved = thumbnail(shifted(grey_view, 12.0, -5.0))[0]
    assert abs(view_shift_px(reference, moved, scale) - 13.0) < 1.0
    walker = grey_view.copy()
    walker[100:260, 200:280] = np.random.default_rng(0).integers(0, 256, (160, 80), dtype=np.uint8)
    assert view_shift_px(reference, thumbnail(walker)[0], scale) < 1.0


def test_the_watch_reports_the_camera_that_moved_most(grey_view):
    watch = DriftWatch(grey_view, grey_view)
    assert watch.shift_px(grey_view, grey_view) < 0.1
    assert abs(watch.shift_px(grey_view, shifted(grey_view, 0.0, 9.0)) - 9.0) < 1.0
    assert abs(watch.shift_px(shifted(grey_view, 4.0, 0.0), shifted(grey_view, 0.0, 9.0)) - 9.0) < 1.0


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


def test_a_creeping_static_rig_gets_new_maps_and_stays_aligned(bundled_dir, tmp_path):
    left, right = creeping_clip(bundled_dir, tmp_path, DRIFT_PX)
    report, late = stitched(left, right, tmp_path / "out.mp4", CFG)
    drift = report["stitch"]["drift"]
    assert drift["moved"] and all(m["shift_px"] > CFG.video_drift_px for m in drift["moved"])
    assert STILL / FPS < drift["moved"][0]["time_s"] <= (STILL + MOVING) / FPS + CFG.video_drift_check_s
    assert report["stitch"]["reestimations"]["accepted"] >= 1
    fixed, late_fixed = stitched(left, right, tmp_path / "fixed.mp4", CFG.replace(video_drift_check_s=0.0))
    assert fixed["stitch"]["drift"]["checks"] == 0 and fixed["stitch"]["reestimations"]["attempted"] == 0
    # Maps made before the move leave the views about the drift apart at the seam; new ones align them.
    assert np.median(late_fixed) > 8.0
    assert np.median(late) < 0.5 * np.median(late_fixed)


def test_with_a_worker_the_new_maps_land_on_the_frame_the_drift_was_seen_on(bundled_dir, tmp_path, monkeypatch):
    # The loop holds video_estimate_lookahead_s of pairs: the drift check sees the newest, and the
    # estimate made on it is blended in when the loop reaches that frame. The worker here answers at
    # once, with maps made beforehand on the views after the move.
    from sena_warp.video import stitch as video_stitch

    left, right = creeping_clip(bundled_dir, tmp_path, DRIFT_PX)
    after = STILL + MOVING + 5
    maps = estimate_pair(decoded_frames(left)[after], decoded_frames(right)[after], CFG, "auto")
    monkeypatch.setattr(video_stitch, "estimate_pair", lambda *args, **kwargs: maps)
    cfg = CFG.replace(video_estimate_workers=1, video_estimate_lookahead_s=1.0)
    report, late = stitched(left, right, tmp_path / "out.mp4", cfg)
    moved = [m["time_s"] for m in report["stitch"]["drift"]["moved"]]
    applied = report["stitch"]["reestimations"]["applied"]
    assert moved and [a["made_on_s"] for a in applied] == moved
    assert all(a["at_s"] == a["made_on_s"] for a in applied), applied
    # The blend then takes the maps there at most video_seam_speed_px a frame (measured: 12 -> 2 px).
    assert late[-1] < 0.25 * late[0]


def test_a_fixed_rig_keeps_its_maps(bundled_dir, tmp_path):
    left, right = creeping_clip(bundled_dir, tmp_path, 0.0)
    report = stitch_videos(left, right, tmp_path / "out.mp4", CFG, VideoOptions.from_config(CFG))
    drift = report["stitch"]["drift"]
    assert drift["checks"] >= 5 and drift["moved"] == []
    assert report["stitch"]["reestimations"]["attempted"] == 0
