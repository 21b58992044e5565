"""``video/device_frame.py`` on real frames: both frame kernels give the same planes, frame after frame.

CUDA composites with the per-pixel kernel, the CPU with the row-run kernel and its runs
(``kernels/composite.py``). Here both run on the CPU over a whole clip as ``sena-warp video`` makes it
(plans made when the maps change, runs found once a plan has served a frame, the per-frame seam and
gains): every output plane must be the same, byte for byte.
"""

from __future__ import annotations

from itertools import islice
from pathlib import Path

import numpy as np
import pytest

from sena_warp.composite import FrameState, composite, composite_image, coverage
from sena_warp.config import Config
from sena_warp.video import device_frame
from sena_warp.video.reader import FrameReader
from sena_warp.video.stitch import SenaFrameCompositor

CFG = Config(device="cpu", video_estimate_pairs=1)


def composited(left: Path, right: Path, cfg: Config, frames: int) -> tuple[list[tuple[np.ndarray, ...]], list[bool]]:
    """The first ``frames`` output frames' (y, u, v) as the frame loop makes them, and per frame whether
    its Y plan had its runs."""
    compositor = SenaFrameCompositor.from_videos(left, right, 0.0, cfg, "auto")
    out, runs = [], []
    try:
        with FrameReader(left) as reader_l, FrameReader(right) as reader_r:
            for frame_l, frame_r in islice(zip(reader_l, reader_r), frames):
                compositor.update(frame_l, frame_r)
                out.append(compositor.composite_yuv(frame_l.y, frame_l.u, frame_l.v, frame_r.y, frame_r.u, frame_r.v))
                runs.append(compositor.last_frame[0].luma.runs is not None)
    finally:
        compositor.close()
    return out, runs


def per_pixel(monkeypatch) -> None:
    """Every pass composited by the per-pixel kernel, as on CUDA."""
    def forced(frame, plan, seam, gains, cfg, _per_pixel=None):
        composite(frame, plan, seam, gains, cfg, per_pixel=True)

    monkeypatch.setattr(device_frame, "composite", forced)


def assert_same_planes(left: Path, right: Path, cfg: Config, frames: int, monkeypatch) -> list[bool]:
    rows, runs = composited(left, right, cfg, frames)
    with monkeypatch.context() as patch:
        per_pixel(patch)
        pixels, _ = composited(left, right, cfg, frames)
    assert len(rows) == len(pixels) == frames
    for index, (a, b) in enumerate(zip(rows, pixels)):
        for plane_a, plane_b in zip(a, b):
            np.testing.assert_array_equal(plane_a, plane_b, err_msg=f"frame {index}")
    return runs


@pytest.mark.parametrize("rig", ["static", "moving"])
def test_both_frame_kernels_give_the_same_planes_on_the_bundled_clip(bundled_dir, rig, monkeypatch):
    """The rooftop clip: a static rig whose drift checks move the maps, and a moving rig aligned every
    frame (a plan every frame)."""
    clips = bundled_dir / "video"
    cfg = CFG.replace(video_rig=rig, video_reestimate_s=0.5, video_estimate_workers=0)
    runs = assert_same_planes(clips / "rooftop_left.mp4", clips / "rooftop_right.mp4", cfg, 60, monkeypatch)
    if rig == "static":
        assert sum(runs) > 20  # the row-run kernel took its runs on many frames
    else:  # each plan serves one frame: its runs are never found, the per-pixel kernel composites it
        assert not any(runs)


@pytest.mark.shared
def test_both_frame_kernels_give_the_same_planes_on_a_recording(shared_dir, monkeypatch):
    """The shared office recording (its target's border blend on the Y plane), 100 frames."""
    folder = shared_dir / "videos" / "office_static"
    runs = assert_same_planes(folder / "cam1.mp4", folder / "cam2.mp4", CFG, 100, monkeypatch)
    assert sum(runs) > 50  # a plan has its runs from its second frame on (a drift move makes new plans)


def sample_positions(words: np.ndarray, width: int, channels: int) -> np.ndarray:
    """(n, 2) input (x, y) that plan ``words`` of an image ``width`` px wide with ``channels`` sample
    (``kernels/composite.py``: bits 2-12 x, 13-23 y in 1/1024 px, 24+ the top-left tap's element offset)."""
    pixel = (words >> 24) // channels
    fx, fy = (words >> 2) & 0x7FF, (words >> 13) & 0x7FF
    return np.stack([pixel % width + fx / 1024.0, pixel // width + fy / 1024.0], axis=1)


@pytest.mark.parametrize("corner", [(3.3, -2.7), (-5.0, 4.25), (12.0, 0.0), (0.0, 0.0)])
def test_a_windows_plan_composites_what_the_plan_of_its_own_maps_does(bundled_dir, corner):
    """A moving rig's steady window: its plan made in one kernel on the canvas's maps (``composite.window_plan``)
    against the plan of the window's maps made on the host (``maps.windowed_plane_maps``), on the bundled
    rooftop's first estimate and frame, for windows shifted by fractions of a pixel and whole ones."""
    clips = bundled_dir / "video"
    compositor = SenaFrameCompositor.from_videos(clips / "rooftop_left.mp4", clips / "rooftop_right.mp4", 0.0, CFG,
                                                 "auto")
    compositor.close()
    with FrameReader(clips / "rooftop_left.mp4") as reader_l, FrameReader(clips / "rooftop_right.mp4") as reader_r:
        frame_l, frame_r = next(iter(reader_l)), next(iter(reader_r))
    planes_src, planes_tgt = compositor.source_target((frame_l.y, frame_l.u, frame_l.v), (frame_r.y, frame_r.u, frame_r.v))
    maps, shapes = compositor.maps, (planes_src[0].shape, planes_tgt[0].shape)
    window = device_frame.OutputWindow(np.array(corner), maps.shape, compositor.offset_tgt)
    made = device_frame.frame_plan(maps, shapes, CFG, window=window)
    reference = device_frame.frame_plan(made.shown_maps(), shapes, CFG)
    state = FrameState(made.luma.layout.positions + np.float32(2.0), (np.ones(1), np.zeros(1), np.ones(1), np.zeros(1)))
    uv = state.__class__(made.chroma.layout.positions, (np.ones(2), np.zeros(2), np.ones(2), np.zeros(2)))
    for name, planes, frame_state in (("luma", (planes_src[0], planes_tgt[0]), state),
                                      ("chroma", tuple(np.dstack(p[1:]) for p in (planes_src, planes_tgt)), uv)):
        plan, plain = getattr(made, name), getattr(reference, name)
        # The same seam, coverage and kind of every pixel; sample positions within one step of 1/1024 px.
        np.testing.assert_array_equal(plan.layout.positions, plain.layout.positions)
        np.testing.assert_array_equal(coverage(plan), coverage(plain))
        words, plain_words = plan.words.numpy(), plain.words.numpy()
        np.testing.assert_array_equal(words & 3, plain_words & 3)
        sampled = (words & 3) != 0
        channels = planes[0].shape[2] if planes[0].ndim == 3 else 1
        shapes_of = {1: planes[0].shape, 2: planes[1].shape, 3: planes[0].shape}
        for kind, shape in shapes_of.items():
            at = sampled & ((words & 3) == kind)
            np.testing.assert_allclose(sample_positions(words[at], shape[1], channels),
                                       sample_positions(plain_words[at], shape[1], channels), atol=1.5 / 1024)
        out, out_plain = (composite_image(*planes, p, frame_state, CFG).astype(np.int16) for p in (plan, plain))
        assert np.abs(out - out_plain).max() <= 1, name
