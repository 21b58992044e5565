"""Is the rig moving (``video/rig_motion.py``)? Known moves of a real picture, and the bundled clips.

A view's still-part move is read off a picture shifted by a known amount, also where most of it is
covered by something moving (a person at the lens); the decisions are checked on views drifting at
known speeds (a fixed rig's creep, a hand-held rig's drift, a rig put down) and on the bundled clips
of a fixed office rig and a hand-held rooftop rig.
"""

from __future__ import annotations

import av
import cv2
import numpy as np
import pytest

from sena_warp.config import Config
from sena_warp.video.rig_motion import RigMotion, still_move, thumbnail

CFG = Config(device="cpu")
FPS = 30.0


@pytest.fixture(scope="module")
def grey(udisd_pair) -> np.ndarray:
    return cv2.cvtColor(udisd_pair[0], cv2.COLOR_BGR2GRAY)


def shifted(grey: np.ndarray, dx: float, dy: float, size: int = 384) -> np.ndarray:
    """A ``size`` square view of ``grey`` whose content moved by (dx, dy) px (bilinear)."""
    move = np.float32([[1, 0, dx], [0, 1, dy]])
    return cv2.warpAffine(grey, move, grey.shape[::-1], flags=cv2.INTER_LINEAR)[64:64 + size, 64:64 + size]


@pytest.mark.parametrize("dx, dy", [(0.0, 0.0), (1.5, -0.5), (-6.0, 3.0), (25.0, 10.0)])
def test_still_move_reads_a_known_shift(grey, dx, dy):
    move = still_move(shifted(grey, 0, 0), shifted(grey, dx, dy))
    assert move is not None and np.allclose(move, (dx, dy), atol=0.15)


def test_still_move_is_the_background_when_a_near_object_moves(grey):
    # Three quarters of the view is a textured object moving 8 px; the background (a quarter) stays.
    before, after = shifted(grey, 0, 0), shifted(grey, 0, 0)
    patch = np.ascontiguousarray(np.fliplr(grey[:288, :384]))
    before[96:, :] = patch
    after[96:, :] = shifted(np.pad(patch, 64, mode="reflect"), 8.0, 0.0, 384)[:288]
    move = still_move(before, after)
    assert move is not None and np.hypot(*move) < 0.2


def test_a_flat_view_says_nothing():
    assert still_move(np.full((180, 320), 90, np.uint8), np.full((180, 320), 91, np.uint8)) is None


def drifting(grey, seconds: float, speed_px_s: tuple[float, float], start_s: float = 0.0, start=(0.0, 0.0)):
    """(time, left view, right view) per frame, both views drifting at ``speed_px_s`` (left, right) px a second."""
    for i in range(int(round(seconds * FPS))):
        t = start_s + i / FPS
        yield t, shifted(grey, start[0] + speed_px_s[0] * (t - start_s), 0.0), \
            shifted(grey, start[1] + speed_px_s[1] * (t - start_s), 0.0)


def decisions(cfg, frames) -> RigMotion:
    motion = RigMotion(cfg)
    for t, left, right in frames:
        motion.observe(t, left, right)
    return motion


def test_a_creeping_fixed_rig_is_static_and_a_drifting_hand_held_one_moving(grey):
    width = 384
    creep = decisions(CFG, drifting(grey, 2.0, (0.002 * width, 0.0)))  # 0.2 %/s: a fixed mount's creep
    assert [d.mode for d in creep.decisions] == ["static"] and creep.decisions[0].time_s == pytest.approx(1.0, abs=0.05)
    assert creep.drifts[0] == pytest.approx(0.002, abs=0.0005)
    held = decisions(CFG, drifting(grey, 2.0, (0.0, 0.006 * width)))  # 0.6 %/s: hands held still
    assert [d.mode for d in held.decisions] == ["moving"] and "right view drifted" in held.decisions[0].reason
    assert held.drifts[1] == pytest.approx(0.006, abs=0.0005)


def test_a_static_rig_that_starts_moving_switches_and_back_when_put_down(grey):
    width = 384
    frames = list(drifting(grey, 1.5, (0.0, 0.0)))  # still: static at 1 s
    frames += list(drifting(grey, 1.5, (0.03 * width, 0.0), start_s=1.5))  # 3 %/s: moving
    moved = 0.03 * width * (3.0 - 1.5 - 1 / FPS)
    frames += list(drifting(grey, 4.0, (0.0, 0.0), start_s=3.0, start=(moved, 0.0)))  # put down
    motion = decisions(CFG, frames)
    modes = [(d.mode, round(d.time_s, 1)) for d in motion.decisions]
    assert [m for m, _ in modes] == ["static", "moving", "static"]
    assert 1.5 < modes[1][1] <= 2.2  # within a window of the move's start
    assert modes[2][1] >= 3.0 + CFG.video_rig_still_s  # still for video_rig_still_s, windows after the move


def test_a_fixed_rig_creeping_faster_later_stays_static(grey):
    width = 384
    frames = list(drifting(grey, 1.2, (0.0, 0.0)))
    frames += list(drifting(grey, 3.0, (0.008 * width, 0.0), start_s=1.2))  # 0.8 %/s later: the pitch's worst
    assert [d.mode for d in decisions(CFG, frames).decisions] == ["static"]


def clip_frames(left, right):
    with av.open(str(left)) as a, av.open(str(right)) as b:
        for i, (fa, fb) in enumerate(zip(a.decode(video=0), b.decode(video=0))):
            yield i / float(a.streams.video[0].average_rate), fa.to_ndarray(format="gray"), fb.to_ndarray(format="gray")


@pytest.mark.parametrize("left, right, mode", [("office_cam1.mp4", "office_cam2.mp4", "static"),
                                               ("rooftop_left.mp4", "rooftop_right.mp4", "moving")])
def test_the_bundled_clips(bundled_dir, left, right, mode):
    motion = decisions(CFG, clip_frames(bundled_dir / "video" / left, bundled_dir / "video" / right))
    assert [d.mode for d in motion.decisions] == [mode]


def test_thumbnails_are_at_most_320_wide():
    thumb, scale = thumbnail(np.zeros((720, 1280), np.uint8))
    assert thumb.shape == (180, 320) and scale == 4.0
    thumb, scale = thumbnail(np.zeros((480, 270), np.uint8))
    assert thumb.shape == (480, 270) and scale == 1.0
