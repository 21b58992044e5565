"""A moving rig's maps frame by frame (``video/moving.py``) and ``--rig auto`` deciding the plan (``video/stitch.py``).

On the bundled clips: a new key taken over without a jump; the office's fixed rig judged static and
composited exactly as ``--rig static`` composites it (lossless encodes compared plane for plane); the
hand-held rooftop judged moving from its first frame; and a made-up clip whose rig stands still for a
second and a half, then pans, switched to moving within a second of the pan.
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from sena_warp.cli import main
from sena_warp.config import Config
from sena_warp.evaluation.crossing import write_clip
from sena_warp.evaluation.rig_decisions import RECORDINGS, decisions
from sena_warp.video.estimate import estimate_pair
from sena_warp.video.loop import VideoOptions
from sena_warp.video.maps import edge_home, plane_maps, sampled_mask, target_offset, with_home
from sena_warp.video.moving import MovingRig
from sena_warp.video.stitch import fixed_canvas, stitch_videos
from helpers import decoded_frames

CFG = Config(device="cpu", video_estimate_pairs=2)
LOSSLESS = CFG.replace(video_crf=0)  # decoding gives the composited planes exactly: comparable bit for bit


@pytest.fixture(scope="module")
def clips(bundled_dir) -> Path:
    return bundled_dir / "video"


def test_a_new_key_takes_over_without_a_jump(clips):
    left, right = decoded_frames(clips / "rooftop_left.mp4"), decoded_frames(clips / "rooftop_right.mp4")
    first = estimate_pair(left[0], right[0], CFG, "auto")
    later = estimate_pair(left[30], right[30], CFG, "auto")
    src_is_left = first.rig.source == "a"
    shapes = (left[0].y.shape, right[0].y.shape) if src_is_left else (right[0].y.shape, left[0].y.shape)
    x0, y0, width, height = fixed_canvas(first, shapes, False)
    offset = target_offset(first.map_tgt_input) - np.array([x0, y0], np.float64)
    pick = (lambda i: (left[i].y, right[i].y)) if src_is_left else (lambda i: (right[i].y, left[i].y))
    shapes_src_tgt = (pick(0)[0].shape, pick(0)[1].shape)
    estimated = plane_maps(later, (height, width), offset)
    # The rooftop's overlap spans 83 % of the target: each key's home is at the overlap's edge (with_home).
    key, new = (with_home(plane_maps(first, (height, width), offset), shapes_src_tgt, CFG),
                with_home(estimated, shapes_src_tgt, CFG))
    rig = MovingRig(key, offset, shapes_src_tgt, CFG)
    gains = (1.0, 0.0, 1.0, 0.0)
    maps = [rig.frame_maps(*pick(i), gains) for i in range(25, 31)]
    earlier, before = maps[-2], maps[-1]
    rig.rekey(new)
    after = rig.frame_maps(*pick(31), gains)
    shown = sampled_mask(before.map_src_luma, pick(0)[0].shape)
    # The two keys differ by pixels (measured: 11.9 px at the 99th percentile where the source is shown) ...
    keys_apart = np.abs(new.map_src_luma - key.map_src_luma)[shown]
    assert np.percentile(keys_apart, 99) > 5.0
    # ... but the map moves from one frame to the next no more than the alignment moves it between two
    # frames of the hand-held rig (measured: 1.64 px at the 99th percentile, 1.94 the frame before).
    step = np.abs(after.map_src_luma - before.map_src_luma)[shown]
    usual = np.abs(before.map_src_luma - earlier.map_src_luma)[shown]
    assert np.percentile(step, 99) < 1.5 * np.percentile(usual, 99) < 0.5 * np.percentile(keys_apart, 99)
    # Its seam's home moves towards the new key's, at most video_seam_speed_px a frame ...
    home = new.seam_luma.positions
    assert not np.allclose(home, estimated.seam_luma.positions)
    assert np.abs(after.seam_luma.positions - before.seam_luma.positions).max() <= CFG.video_seam_speed_px + 1e-3
    # ... and reaches it once it could have at that speed (and after video_blend_frames at least).
    frames = max(CFG.video_blend_frames,
                 int(np.ceil(np.abs(before.seam_luma.positions - home).max() / CFG.video_seam_speed_px)))
    for i in range(frames):
        settled = rig.frame_maps(*pick(min(32 + i, 59)), gains)
    assert np.allclose(settled.seam_luma.positions, home)


def test_a_stereo_rigs_seam_home_runs_inside_the_overlaps_target_side_edge():
    overlap = np.array([[0, -1]] + [[300, 330]] * 3 + [[32, 600]] * 40 + [[40, 600]] * 20, np.int32)
    home = edge_home(overlap, np.full(len(overlap), 100.0, np.float32), 3.0, 2.0)
    # 3 px inside the edge where the overlap is whole; lines cut short by a slanted border (300-330, under
    # half the median width) and lines without any go on from the others ...
    np.testing.assert_allclose(home[:41], 35.0)
    # ... and where the edge steps by 8 px the home rises 2 px a line ahead of it, never nearer the edge.
    np.testing.assert_allclose(home[40:46], [35.0, 37.0, 39.0, 41.0, 43.0, 43.0])
    assert (home[44:] >= 43.0).all() and np.abs(np.diff(home)).max() <= 2.0
    # A line whose overlap is narrower than the margin keeps inside it.
    assert edge_home(np.array([[10, 11]] * 4, np.int32), np.zeros(4, np.float32), 3.0, 2.0).max() == 11.0


def test_auto_composites_a_fixed_rig_exactly_as_static(clips, tmp_path, capfd):
    runs = {}
    for rig in ("auto", "static"):
        cfg = LOSSLESS.replace(video_rig=rig)
        out = tmp_path / f"{rig}.mp4"
        runs[rig] = stitch_videos(clips / "office_cam1.mp4", clips / "office_cam2.mp4", out, cfg,
                                  VideoOptions.from_config(cfg))
        runs[rig]["frames"] = decoded_frames(out)
    decisions = runs["auto"]["stitch"]["rig"]["decisions"]
    assert [(d["mode"], d["from_s"]) for d in decisions] == [("static", 0.0)]
    assert runs["static"]["stitch"]["rig"]["decisions"] == []
    assert len(runs["auto"]["frames"]) == len(runs["static"]["frames"]) == 48
    for a, b in zip(runs["auto"]["frames"], runs["static"]["frames"]):
        assert np.array_equal(a.y, b.y) and np.array_equal(a.u, b.u) and np.array_equal(a.v, b.v)


def test_auto_finds_the_hand_held_rooftop_moving_and_says_so(clips, tmp_path, capfd):
    out, report_path = tmp_path / "r.mp4", tmp_path / "r.json"
    capfd.readouterr()
    rc = main(["video", str(clips / "rooftop_left.mp4"), str(clips / "rooftop_right.mp4"), "-o", str(out),
               "--report", str(report_path), "--device", "cpu"])
    err = capfd.readouterr().err
    assert rc == 0
    said = [line for line in err.splitlines() if "rig: " in line]
    assert len(said) == 1 and "rig: moving (" in said[0] and "view drifted" in said[0]
    rig = json.loads(report_path.read_text())["stitch"]["rig"]
    assert rig["mode"] == "auto" and [d["mode"] for d in rig["decisions"]] == ["moving"]
    assert rig["decisions"][0]["from_s"] == 0.0 and rig["alignment"]["frames"] == 60


def standing_then_panning(picture: np.ndarray, folder: Path, size=(320, 180), frames=75, still=45, speed=6.0):
    """``left.mp4`` / ``right.mp4``: two windows of one picture (they overlap by half), still for ``still``
    frames, then both sliding right by ``speed`` px a frame (a rig that pans)."""
    width, height = size
    x0 = np.array([0.0 if i < still else speed * (i - still) for i in range(frames)])
    for name, start in (("left", 20.0), ("right", 20.0 + width / 2)):
        write_clip(folder / f"{name}.mp4", (cv2.getRectSubPix(picture, size, (start + x + (width - 1) / 2,
                                                                               40 + (height - 1) / 2))
                                            for x in x0))
    return folder / "left.mp4", folder / "right.mp4"


def test_auto_switches_a_rig_that_starts_panning_to_moving(udisd_pair, tmp_path):
    picture = cv2.resize(udisd_pair[0], (1024, 512), interpolation=cv2.INTER_CUBIC)
    left, right = standing_then_panning(picture, tmp_path)
    cfg = CFG.replace(video_estimate_workers=0)
    report = stitch_videos(left, right, tmp_path / "out.mp4", cfg, VideoOptions.from_config(cfg))
    decisions = report["stitch"]["rig"]["decisions"]
    assert [d["mode"] for d in decisions] == ["static", "moving"]
    assert decisions[0]["from_s"] == 0.0
    # The pan starts at frame 45 (1.5 s): watched over 1 s windows every 0.2 s, its first window past 1.5 %
    # a second ends within a second of it (measured: 1.6 s, the right view drifting 5.6 % a second).
    assert 1.5 < decisions[1]["from_s"] <= 2.5
    assert report["stitch"]["rig"]["alignment"]["frames"] == 75 - round(decisions[1]["from_s"] * 30)


@pytest.mark.shared
def test_auto_picks_moving_on_every_hand_held_recording_and_static_on_every_fixed_one(shared_dir):
    """The watch over whole recordings (benchmarks/rig_decisions.py): one decision each, never a switch.
    Measured first-second drifts: fixed rigs 0.00-0.26 % of the width a second, hand-held 0.55-26.8."""
    for name, (left, right, rig) in RECORDINGS.items():
        found, _ = decisions(shared_dir / "videos" / name / left, shared_dir / "videos" / name / right, CFG)
        assert [d.mode for d in found] == [rig], (name, found)
