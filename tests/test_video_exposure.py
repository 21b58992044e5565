"""``video/exposure.py``: the views' gains measured on the overlap of the current maps.

A blend hands the tracker new maps every frame; it measures every ``period_frames``. What it measures
must be the overlap of the maps of that frame, whenever they changed.
"""

from __future__ import annotations

import numpy as np

from sena_warp.config import Config
from sena_warp.video.exposure import ExposureTracker
from test_video_stitch import synthetic_maps

CFG = Config(device="cpu", video_gain_stride_px=2, gain_min_pixels=40)  # enough samples on small planes
PLANES = (40, 60)


def planes(rng: np.random.Generator, level: float) -> tuple[np.ndarray, ...]:
    """(y_src, y_tgt, u_src, u_tgt, v_src, v_tgt) of a textured scene, the source's Y ``level`` brighter
    on its right half (what a moved overlap then sees more or less of)."""
    y = rng.integers(60, 160, size=PLANES).astype(np.uint8)
    y_src = y.copy()
    y_src[:, 30:] = np.clip(y_src[:, 30:].astype(int) + level, 0, 255).astype(np.uint8)
    chroma = np.full((20, 30), 128, np.uint8)
    return y_src, y, chroma, chroma, chroma, chroma


def test_gains_are_measured_on_the_maps_of_the_frame_they_were_set_for():
    rng = np.random.default_rng(5)
    frames = [planes(rng, 30) for _ in range(3)]
    first, moved = synthetic_maps(-20.0, 300), synthetic_maps(-5.0, 300)  # the overlap moves right
    followed = ExposureTracker(first, PLANES, PLANES, 30.0, CFG)
    fresh = ExposureTracker(moved, PLANES, PLANES, 30.0, CFG)
    assert followed.period_frames > 1
    followed.update(first, *frames[0])  # measured on ``first``
    for step in (-15.0, -10.0, -5.0):  # a blend: new maps every frame
        followed.update(synthetic_maps(step, 300), *frames[0])
    assert np.allclose(followed.measure(*frames[1]), fresh.measure(*frames[1]))
    assert not np.allclose(ExposureTracker(first, PLANES, PLANES, 30.0, CFG).measure(*frames[1]),
                           fresh.measure(*frames[1]))
