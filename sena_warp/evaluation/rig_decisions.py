"""``--rig auto``'s watch over whole recordings: which rig each shared recording was shot with, and
what the watch decides on it (``benchmarks/rig_decisions.py``, ``tests/test_video_moving.py``)."""

from __future__ import annotations

import time
from pathlib import Path

from ..config import Config
from ..video.reader import FrameReader
from ..video.rig_motion import RigDecision, RigMotion

RECORDINGS = {  # name: (left, right, the rig as recorded)
    "office_static": ("cam1.mp4", "cam2.mp4", "static"),
    "lecture_hall_static": ("left.mp4", "right.mp4", "static"),
    "futsal_night_static": ("cam1.mp4", "cam2.mp4", "static"),
    "cafe_person_close": ("left.avi", "right.avi", "static"),
    "rooftop_handheld": ("left.mp4", "right.mp4", "moving"),
    "house_handheld_stereo": ("left.mp4", "right.mp4", "moving"),
    "window_phones_drift": ("left.mp4", "right.mp4", "moving"),
}


def decisions(left: Path, right: Path, cfg: Config) -> tuple[list[RigDecision], float]:
    """Every decision of the watch over two videos, and the mean seconds it took per frame pair."""
    watch, spent, frames = RigMotion(cfg), 0.0, 0
    with FrameReader(left) as reader_l, FrameReader(right) as reader_r:
        for frame_l, frame_r in zip(reader_l, reader_r):
            t0 = time.perf_counter()
            watch.observe(float(frame_l.time_s), frame_l.y, frame_r.y)
            spent += time.perf_counter() - t0
            frames += 1
    return watch.decisions, spent / max(frames, 1)
