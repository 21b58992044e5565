"""``sena-warp video`` end to end on the bundled 2 s clips: real SENA maps on YUV planes.

Checks what a viewer would notice: frame count, pts at the input rate, audio as long as the video,
frames that are real stitches (the unwarped target appears unchanged on a canvas wider than either
input), a static rig's seam that never moves, re-estimation counts and finite jitter for a moving
rig, pairing by time across frame rates, and one-line CLI errors that leave no output behind.
"""

from __future__ import annotations

import json
import math
from dataclasses import replace
from fractions import Fraction
from pathlib import Path

import cv2
import numpy as np
import pytest

from sena_warp.cli import main
from sena_warp.config import Config
from sena_warp.video.loop import VideoOptions
from sena_warp.errors import GeometryError, VideoError
from sena_warp.video import estimate
from sena_warp.video.estimate import best_first_estimate, first_pairs, rejection_reason
from sena_warp.composite import BorderBlend, SeamLayout
from sena_warp.video.maps import (ArrayLerp, MapsBlend, PlaneMaps, canvas_scale, chroma_positions, chroma_seam,
                                 map_change_px, output_shape, scaled_plane_maps, seam_change_px, windowed_plane_maps, windowed_seam,
                                 seam_on_canvas_lines, seam_per_target_line, target_map)
from sena_warp.video.moving import MovingRig
from sena_warp.video.pairing import pair_times
from sena_warp.video.reader import FrameReader, YuvFrame
from sena_warp.video.stitch import SenaFrameCompositor, stitch_videos
from sena_warp.video.writer import VideoWriter
from helpers import decoded_frames, stream_spans

CFG = Config(device="cpu")
STATIC = CFG.replace(video_rig="static")  # the rooftop's rig is hand-held: --rig auto finds it moving
FAST = CFG.replace(video_estimate_pairs=2)  # fewer first-pair tries where the test is not about them
AWAY_FROM_SEAM_PX = 8  # margin beyond the transition band where the output must be the target alone


@pytest.fixture(scope="module")
def clips(bundled_dir) -> Path:
    return bundled_dir / "video"


class SeamsSeen:
    """An observer of the frame loop keeping every frame's seam as composited (index -> (L,) float32)."""

    def __init__(self):
        self.seams: dict[int, np.ndarray] = {}

    def __call__(self, frame) -> None:
        self.seams[frame.index] = np.asarray(frame.seam).copy()


def target_region_diff(out: YuvFrame, tgt: YuvFrame, report: dict, seam: np.ndarray, cfg: Config) -> float:
    """Mean |output Y - target Y| right of each row's seam transition band, where the output is the target alone.

    For a left-to-right rig (working frame = input frame); ``seam``: the frame's seam per row (``SeamsSeen``).
    """
    canvas = report["stitch"]["canvas"]
    ox, oy = (int(v) for v in canvas["offset_tgt"])
    h, w = tgt.y.shape
    diffs = []
    for row, seam_x in enumerate(seam):
        if not np.isfinite(seam_x) or not oy <= row < oy + h:
            continue
        first_col = int(math.ceil(seam_x)) + cfg.transition_px + AWAY_FROM_SEAM_PX
        last_col = min(ox + w, canvas["width"])
        diffs.append(out.y[row, first_col:last_col].astype(np.int16)
                     - tgt.y[row - oy, first_col - ox:last_col - ox].astype(np.int16))
    pixels = np.abs(np.concatenate(diffs))
    assert pixels.size > 0.2 * tgt.y.size  # a real part of the target, not a sliver
    return float(pixels.mean())


def stitch_counting_openings(clips: Path, out: Path, cfg: Config) -> tuple[dict, list[str], SeamsSeen]:
    """The rooftop clips stitched with ``cfg``: the report, the file of every ``FrameReader`` opened, and
    every frame's seam."""
    opened, seen = [], SeamsSeen()
    real_init = FrameReader.__init__

    def counting_init(self, path, *args, **kwargs):
        opened.append(Path(path).name)
        real_init(self, path, *args, **kwargs)

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(FrameReader, "__init__", counting_init)
        report = stitch_videos(clips / "rooftop_left.mp4", clips / "rooftop_right.mp4", out, cfg,
                               VideoOptions.from_config(cfg), observer=seen)
    return report, opened, seen


@pytest.fixture(scope="module")
def rooftop_static(clips, tmp_path_factory):
    out = tmp_path_factory.mktemp("rooftop") / "static.mp4"
    report, opened, seen = stitch_counting_openings(clips, out, STATIC)
    return out, report, opened, seen


def test_the_first_estimate_takes_its_pairs_from_the_frame_loop(rooftop_static):
    """Each input is opened and decoded once: the pairs screened are the loop's, composited after."""
    out, report, opened, _ = rooftop_static
    assert opened == ["rooftop_left.mp4", "rooftop_right.mp4"]
    assert report["frames_in"] == {"left": 60, "right": 63} and report["frames_out"] == 60
    assert len(report["stitch"]["first_estimate"]["tried"]) == CFG.video_estimate_pairs


def test_pairs_too_large_to_hold_are_decoded_apart_with_the_same_frames(clips, tmp_path):
    """Over ``video_estimate_lookahead_mib`` (21 pairs of 270x480: 7.8 MiB) the estimate opens the
    inputs itself, as at 8K by default, and the video is the same."""
    lossless = STATIC.replace(video_crf=0)  # decoding gives the composited planes exactly: comparable bit for bit
    report, opened, _ = stitch_counting_openings(clips, tmp_path / "apart.mp4",
                                              lossless.replace(video_estimate_lookahead_mib=7))
    assert opened == ["rooftop_left.mp4", "rooftop_right.mp4"] * 2
    stitch_counting_openings(clips, tmp_path / "held.mp4", lossless)
    apart, held = decoded_frames(tmp_path / "apart.mp4"), decoded_frames(tmp_path / "held.mp4")
    assert len(apart) == len(held) == 60
    assert all(np.array_equal(a.y, b.y) and np.array_equal(a.v, b.v) for a, b in zip(apart, held))


FRAME_COUNTS = {"upload": 2, "download": 2, "sync": 2}  # planes and seam up, band and output down, a wait each


def test_each_frame_moves_its_planes_once_each_way_and_waits_only_for_its_downloads(rooftop_static):
    """Per frame (``kernels/transfer.py``, counted on the CPU as on a GPU): the decoded planes go up in
    one block, the seam band's difference and a static rig's object band's come down together and the
    frame's seam goes up (small), the output planes come down in one block, and nothing else waits for
    the device; a new map set's plans add their own uploads, on the frames whose maps changed."""
    _, report, _, _ = rooftop_static
    transfers = report["stitch"]["transfers"]
    assert transfers["frames"] == report["frames_out"] == 60
    assert transfers["per_frame_min"] == transfers["per_frame_max"] == FRAME_COUNTS
    total = transfers["total"]
    plans = total["upload"].pop("plan")
    assert total == {"upload": {"planes": 60, "seam": 60}, "download": {"band": 60, "output": 60},
                     "sync": {"band": 60, "output": 60}}
    made = 1 + len(report["stitch"]["drift"]["applied"])  # the first plan, and a blend after each drift move
    assert plans >= 6 * made  # each pass's maps and static seam, the band's cells


def test_rooftop_frames_pts_audio(rooftop_static):
    out, report, _, _ = rooftop_static
    assert report["frames_out"] == 60 and report["dropped"] == 0 and report["repeated"] == 0
    spans = stream_spans(out)
    n_video, t_video, end_video = spans["video"]
    assert n_video == 60 and t_video[0] == 0
    assert set(np.diff(t_video)) == {Fraction(1, 30)}
    n_audio, t_audio, end_audio = spans["audio"]
    assert n_audio > 0 and abs(float(end_audio - t_audio[0]) - float(end_video)) < 0.1


def test_rooftop_frames_are_real_stitches(clips, rooftop_static):
    out, report, _, seen = rooftop_static
    stitch = report["stitch"]
    assert stitch["rig"]["source"] == "left"  # the right camera is the unwarped target
    assert [a["error"] for a in stitch["first_estimate"]["tried"]] == [None] * CFG.video_estimate_pairs
    assert stitch["first_estimate"]["inliers"] == max(a["inliers"] for a in stitch["first_estimate"]["tried"])
    out_frames, in_r = decoded_frames(out), decoded_frames(clips / "rooftop_right.mp4")
    height, width = out_frames[0].y.shape
    assert (width, height) == (report["output"]["width"], report["output"]["height"])
    assert width > 270 * 1.1 and width % 2 == 0 and height % 2 == 0
    for k in (0, 30, 59):
        own = target_region_diff(out_frames[k], in_r[k], report, seen.seams[k], STATIC)
        assert own < 3.0
        # ... and it is that frame, not a neighbour (the rig moves between frames).
        assert own < target_region_diff(out_frames[k], in_r[k + 3], report, seen.seams[k], STATIC)
    # Uncovered corners are limited-range black, not Y = 0 or green chroma.
    rows, cols = np.nonzero(out_frames[30].y <= 20)
    assert len(rows) > 100
    assert abs(np.median(out_frames[30].y[rows, cols]) - 16) <= 2
    assert abs(np.median(out_frames[30].u[rows // 2, cols // 2]) - 128) <= 2


@pytest.mark.shared
@pytest.mark.parametrize("pair, frames, rate", [(("rooftop_handheld", "left.mp4", "right.mp4"), 296, 30),
                                                 (("office_static", "cam1.mp4", "cam2.mp4"), 385, 24)])
def test_full_shared_videos_give_every_frame_at_the_input_rate_with_the_audio(shared_dir, tmp_path, pair, frames, rate):
    """The whole shared recordings (not the bundled cuts): frames, pts grid, audio span as the input's."""
    folder, left, right = pair
    left, right = shared_dir / "videos" / folder / left, shared_dir / "videos" / folder / right
    out = tmp_path / "full.mp4"
    report = stitch_videos(left, right, out, FAST, VideoOptions.from_config(FAST))
    assert report["frames_out"] == frames and report["dropped"] == 0
    assert len(decoded_frames(out)) == frames
    spans = stream_spans(out)
    n_video, t_video, _ = spans["video"]
    assert n_video == frames and t_video[0] == 0 and set(np.diff(t_video)) == {Fraction(1, rate)}
    assert ("audio" in spans) == ("audio" in stream_spans(left))
    if "audio" in spans:  # rooftop: the left phone's audio, as long as it is in the input
        _, t_in, end_in = stream_spans(left)["audio"]
        _, t_out, end_out = spans["audio"]
        assert abs(float(end_out - t_out[0]) - float(end_in - t_in[0])) < 0.1


def test_first_estimate_falls_back_to_the_next_best_pair_when_the_best_fails_later(clips, monkeypatch):
    """Pairs are ranked by their step-1 inliers; a full estimate that fails moves on to the next one."""
    left, right = clips / "rooftop_left.mp4", clips / "rooftop_right.mp4"
    full_estimates = []
    real_estimate_pair = estimate.estimate_pair

    def estimate_pair(frame_l, frame_r, cfg, reference, matches=None):
        full_estimates.append(frame_l.time_s)
        if len(full_estimates) == 1:
            raise GeometryError("canvas too large (test)")
        return real_estimate_pair(frame_l, frame_r, cfg, reference, matches)

    monkeypatch.setattr(estimate, "estimate_pair", estimate_pair)
    cfg = CFG.replace(video_estimate_pairs=3)
    maps, chosen, attempts = best_first_estimate(first_pairs(left, right, 0.0, cfg), cfg, "auto")
    assert len(attempts) == 3 and len(full_estimates) == 2  # screened all, fully estimated two
    ranked = sorted(attempts, key=lambda a: (-a.inliers, a.pair))
    assert ranked[0].error == "canvas too large (test)" and chosen == ranked[1].pair
    assert maps.warp.glob.n_inliers > 0.8 * ranked[1].inliers  # the same pair's model, re-fitted


def test_office_static_rig_seam_never_moves(clips, tmp_path):
    out = tmp_path / "office.mp4"
    seen = SeamsSeen()
    report = stitch_videos(clips / "office_cam1.mp4", clips / "office_cam2.mp4", out, FAST,
                           VideoOptions.from_config(FAST), observer=seen)
    assert report["frames_out"] == 48
    spans = stream_spans(out)
    assert spans["video"][0] == 48 and set(np.diff(spans["video"][1])) == {Fraction(1, 24)}
    stitch = report["stitch"]
    assert stitch["rig"]["source"] == "right"  # cam2 is the left view in this pair
    assert stitch["rig"]["aligned_in_front"] is False  # its estimate is on the still room: maps made once
    assert stitch["reestimations"]["attempted"] == 0
    assert stitch["jitter"] == {"seam_jitter_px_mean": 0.0, "seam_jitter_px_max": 0.0,
                                "map_change_p99_px_max": 0.0, "frames": 48}
    out_frames, in_1 = decoded_frames(out), decoded_frames(clips / "office_cam1.mp4")
    assert out_frames[0].y.shape[1] > 640 * 1.2
    assert target_region_diff(out_frames[20], in_1[20], report, seen.seams[20], FAST) < 3.0


@pytest.mark.shared
def test_a_fixed_rig_whose_estimate_is_on_a_person_in_front_can_be_aligned_every_frame(shared_dir, tmp_path):
    """The cafe: two fixed webcams, a person close to both holds most of the first pairs' matches (the
    room behind him recurs, he does not). With ``video_align_in_front`` the rig stays static, its canvas
    held, and its maps are aligned to every frame; the seam glides. Off (the default), maps made once."""
    clip = shared_dir / "videos" / "cafe_person_close"
    cfg = CFG.replace(video_estimate_workers=0, video_end_s=1.5, video_align_in_front=True)
    report = stitch_videos(clip / "left.avi", clip / "right.avi", tmp_path / "cafe.mp4", cfg,
                           VideoOptions.from_config(cfg))
    rig = report["stitch"]["rig"]
    assert rig["aligned_in_front"] is True and [d["mode"] for d in rig["decisions"]] == ["static"]
    assert rig["alignment"]["frames"] == report["frames_out"] == 30 and rig["steady"]["frames"] == 0
    assert report["stitch"]["frame_seam"]["motion_px_max"] <= cfg.video_seam_speed_px
    off = stitch_videos(clip / "left.avi", clip / "right.avi", tmp_path / "off.mp4",
                        cfg.replace(video_align_in_front=False), VideoOptions.from_config(cfg))
    assert off["stitch"]["rig"]["aligned_in_front"] is False and off["stitch"]["rig"]["alignment"] is None


def test_moving_rig_aligns_every_frame_and_reports_the_jitter(clips, tmp_path):
    # On the loop's thread (no worker), so that what happens when does not depend on the machine's speed.
    cfg = FAST.replace(video_rig="moving", video_estimate_workers=0)
    report = stitch_videos(clips / "rooftop_left.mp4", clips / "rooftop_right.mp4", tmp_path / "m.mp4", cfg,
                           VideoOptions.from_config(cfg))
    stitch = report["stitch"]
    # The alignment follows the hand-held rig all through these 2 s (measured: 94 % of its points followed,
    # about 190 of them), so no re-estimate is asked for and the first estimate stays the key.
    assert stitch["reestimations"]["attempted"] == 0
    alignment = stitch["rig"]["alignment"]
    assert alignment["frames"] == 60 and alignment["keys"] == 0
    assert alignment["followed_share_mean"] > 0.8 and alignment["points_mean"] > 100
    # The map changes every frame, by far less than a rejected estimate would move it; the seam's home
    # (the key's) stays, and the per-frame seam glides.
    jitter, frame_seam = stitch["jitter"], stitch["frame_seam"]
    assert jitter["frames"] == 60 and jitter["seam_jitter_px_max"] == 0.0
    assert 0.0 < jitter["map_change_p99_px_max"] < cfg.video_max_median_change_px
    assert frame_seam["motion_px_max"] <= cfg.video_seam_speed_px
    assert report["frames_out"] == 60 and "align" in report["timing_s"]
    # Every frame makes a plan of its aligned maps; a frame's own transfers stay as few (FRAME_COUNTS).
    transfers = stitch["transfers"]
    assert transfers["per_frame_min"] == transfers["per_frame_max"] == FRAME_COUNTS
    assert transfers["total"]["upload"]["plan"] >= 60


def test_reestimates_on_the_worker_do_not_hold_up_the_frames(clips, tmp_path, monkeypatch):
    """With a worker the loop only starts and collects re-estimates: its per-frame update time stays far
    below the re-estimates' own time: a loop that waited for them would spend at least that (measured on
    this machine, under load: 0.30 s of blending and uploads against 1.18 s of re-estimates). Without the
    look-ahead: with it, the last re-estimate may still be running when the 2 s clip ends, and its
    time is then not counted. The alignment asks for a re-estimate on every frame here; its own time
    (``align``, every frame) is part of the update and left out."""
    monkeypatch.setattr(MovingRig, "wants_estimate", lambda self: True)
    cfg = FAST.replace(video_rig="moving", video_reestimate_s=0.3, video_estimate_workers=1,
                       video_estimate_lookahead_s=0.0)
    report = stitch_videos(clips / "rooftop_left.mp4", clips / "rooftop_right.mp4", tmp_path / "w.mp4", cfg,
                           VideoOptions.from_config(cfg))
    assert report["frames_out"] == 60 and report["stitch"]["reestimations"]["attempted"] >= 1
    timing = report["timing_s"]
    assert timing["maps_update"] - timing["align"] < 0.5 * timing["reestimate"], timing


def test_copy_at_another_frame_rate_is_paired_by_time_and_stitched(clips, tmp_path):
    right_24 = tmp_path / "right_24fps.mp4"
    frames = decoded_frames(clips / "rooftop_right.mp4")
    ticks = [Fraction(j, 24) for j in range(int(frames[-1].time_s * 24) + 1)]
    pairs_24, _ = pair_times(ticks, [f.time_s for f in frames], Fraction(1, 30))
    with VideoWriter(right_24, 270, 480, Fraction(24)) as writer:
        for j, i in pairs_24:
            writer.write(frames[i].y, frames[i].u, frames[i].v, pts=j)
    out = tmp_path / "mix.mp4"
    # The output held on the target's frame (no steady canvas: the hand-held rig's window would move the
    # target's region on the output), so the target's pixels are where the report says.
    cfg = FAST.replace(video_steady_max_px=0.0)
    seen = SeamsSeen()
    report = stitch_videos(clips / "rooftop_left.mp4", right_24, out, cfg, VideoOptions.from_config(cfg),
                           observer=seen)
    # ticks k/30 (k < 60) take 24 fps frame round(0.8 k): 0..47 each used, 12 twice; 48, 49 left over.
    assert report["frames_out"] == 60
    assert (report["repeated"], report["dropped"], report["pairing"]["leftover_other"]) == (12, 0, 2)
    out_frames, in_24 = decoded_frames(out), decoded_frames(right_24)
    for k in (10, 45):
        assert target_region_diff(out_frames[k], in_24[round(0.8 * k)], report, seen.seams[k], cfg) < 3.0


def test_the_prior_seam_of_a_re_estimate_is_per_target_row_and_unknown_above_a_cropped_canvas():
    """A moving rig's re-estimate stays near the current seam, given per target row: the canvas lines
    from the target's top on, less its x offset; a cropped canvas that starts 3 rows inside the target
    knows no seam for those 3 rows."""
    positions = np.array([10.0, 11.0, 12.0, 13.0, 14.0], np.float32)
    assert np.array_equal(seam_per_target_line(positions, np.array([4.0, 2.0])), [8.0, 9.0, 10.0])
    cropped = seam_per_target_line(positions, np.array([4.0, -3.0]))
    assert len(cropped) == 8 and np.isnan(cropped[:3]).all()
    assert np.array_equal(cropped[3:], positions - 4.0)


def test_chroma_map_samples_the_luma_map_at_the_chroma_centre():
    offset = np.array([6.0, 2.0])
    chroma = chroma_positions(target_map((8, 12), offset))
    # Chroma pixel (xc, yc) <- luma (2xc + 0.5 - ox, 2yc + 0.5 - oy) <- chroma ((that - 0.5) / 2).
    assert chroma.shape == (4, 6, 2)
    np.testing.assert_allclose(chroma[1, 4], [4 - 3.0, 1 - 1.0])


def test_cli_errors_are_one_line_and_leave_no_output(clips, tmp_path, capsys):
    out = tmp_path / "out.mp4"
    left = clips / "rooftop_left.mp4"
    assert main(["video", str(left), str(tmp_path / "missing.mp4"), "-o", str(out), "--device", "cpu"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("sena-warp: error: ") and "missing.mp4: file not found" in err[-1]
    copy = tmp_path / "copy.mp4"
    copy.write_bytes(left.read_bytes())
    assert main(["video", str(copy), str(clips / "rooftop_right.mp4"), "-o", str(copy), "--device", "cpu"]) == 6
    assert "overwrite an input" in capsys.readouterr().err.strip().splitlines()[-1]
    assert copy.read_bytes() == left.read_bytes()
    assert main(["video", str(left), str(left), "-o", str(out), "--rig", "static", "--reestimate", "1",
                 "--device", "cpu"]) == 2
    assert "drop --rig static" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["copy.mp4"]


def test_cli_writes_video_report_and_summary(clips, tmp_path, capsys):
    out, report_path = tmp_path / "o.mp4", tmp_path / "r.json"
    code = main(["video", str(clips / "rooftop_left.mp4"), str(clips / "rooftop_right.mp4"), "-o", str(out),
                 "--report", str(report_path), "--device", "cpu", "--audio", "none", "--crf", "30", "--rig", "static"])
    assert code == 0 and out.exists()
    report = json.loads(report_path.read_text())
    assert report["frames_out"] == 60 and report["output"]["audio_mode"] is None
    stitch = report["stitch"]
    assert stitch["rig"]["mode"] == "static"
    # The bundled rooftop clip is hand-held: its views move, so the static rig's drift check moves the
    # maps (where it can still compare the views); they change only then, and nothing is re-estimated.
    drift = stitch["drift"]
    assert drift["checks"] >= 3 and len(drift["applied"]) + drift["unclear"] > 0
    assert (stitch["jitter"]["seam_jitter_px_max"] > 0.0) == bool(drift["applied"])
    assert stitch["reestimations"]["attempted"] == 0
    assert set(stream_spans(out)) == {"video"}
    summary = capsys.readouterr().out.strip().splitlines()
    assert len(summary) == 1 and "60 frames at 30 fps" in summary[0]


def synthetic_maps(shift_px: float, inliers: int, shape=(40, 60), change=None) -> PlaneMaps:
    """PlaneMaps whose source map is the target map moved by ``shift_px`` in x (a rig that turned a little),
    then changed by ``change(map_src)`` (in place) before the maps are made (they are read-only after)."""
    map_tgt = target_map(shape, np.array([10.0, 0.0]))
    map_src = map_tgt + np.float32([shift_px + 20.0, 0.0])
    if change is not None:
        change(map_src)
    alpha = np.full(shape, 0.5, np.float32)
    seam = np.full(shape[0], 30.0 + shift_px, np.float32)
    seam_luma = SeamLayout(seam, True, 10.0, 8.0, 1.5, 0.0)
    return PlaneMaps(map_src, map_tgt, alpha, chroma_positions(map_src), chroma_positions(map_tgt),
                     alpha[::2, ::2].copy(), seam_luma, chroma_seam(seam_luma), seam, inliers, None)


def test_reestimates_with_few_inliers_or_a_large_map_change_are_rejected():
    current = synthetic_maps(0.0, 300)
    planes = (40, 60)
    assert rejection_reason(synthetic_maps(2.0, 280, planes), current, 300, planes, planes, CFG) is None
    assert "inliers" in rejection_reason(synthetic_maps(2.0, 100, planes), current, 300, planes, planes, CFG)
    cfg = CFG.replace(video_max_median_change_px=8.0)  # within the synthetic planes' 60 px
    too_far = cfg.video_max_median_change_px + 1.0
    assert rejection_reason(synthetic_maps(too_far - 2.0, 300), current, 300, planes, planes, cfg) is None
    assert "median map change" in rejection_reason(synthetic_maps(too_far, 300), current, 300, planes, planes, cfg)


def test_blend_moves_maps_and_seam_linearly_and_takes_the_goal_where_the_start_had_nothing():
    start, goal = synthetic_maps(0.0, 300, change=lambda m: m.__setitem__((0, 0), np.nan)), synthetic_maps(8.0, 320)
    half = MapsBlend(start, goal).at(0.5)
    np.testing.assert_allclose(half.map_src_luma[5, 5], start.map_src_luma[5, 5] + [4.0, 0.0])
    np.testing.assert_allclose(half.map_src_luma[0, 0], goal.map_src_luma[0, 0])
    assert seam_change_px(start, half) == pytest.approx(4.0)
    np.testing.assert_allclose(half.seam_luma.positions, 34.0)
    assert map_change_px(start, half, (40, 60), 99.0) == pytest.approx(4.0)
    assert half.inliers == 320


def test_a_blends_steps_are_the_four_pass_lerp_bit_for_bit():
    """``MapsBlend`` works out ``goal - start`` once per blend; each step must still be exactly
    ``start + w * (goal - start)`` in float32, the goal where either side is NaN, and keep what both share."""
    rng = np.random.default_rng(3)

    def noisy(map_src: np.ndarray) -> None:
        map_src[:] += rng.normal(scale=3.0, size=map_src.shape).astype(np.float32)
        map_src[rng.random(map_src.shape[:2]) < 0.2] = np.nan

    start, goal = synthetic_maps(0.0, 300, change=noisy), synthetic_maps(8.0, 320, change=noisy)
    goal = replace(goal, map_tgt_luma=start.map_tgt_luma)  # as in a drift: the target map is shared
    with pytest.raises(ValueError, match="read-only"):
        start.map_src_luma[0, 0] = 1.0  # a value: what moves the maps makes new ones
    blend = MapsBlend(start, goal)
    for weight in (1 / 7, 0.5, 5 / 7, 1.0):
        step = blend.at(weight)
        a, b = start.map_src_luma, goal.map_src_luma
        expected = (b - a) * np.float32(weight) + a
        expected[np.isnan(expected)] = b[np.isnan(expected)]
        np.testing.assert_array_equal(step.map_src_luma, expected)
        assert step.map_src_luma.dtype == np.float32 and step.map_tgt_luma is start.map_tgt_luma
        assert step.inliers == 320 and step.seam_luma.band_px == goal.seam_luma.band_px
    assert not np.shares_memory(blend.at(0.5).map_src_luma, blend.at(0.5).map_src_luma)  # each step a new array
    a, b = (np.asfortranarray(m.map_src_luma[:, :, 0]) for m in (start, goal))  # any memory order
    expected = (b - a) * np.float32(0.25) + a
    expected[np.isnan(expected)] = b[np.isnan(expected)]
    np.testing.assert_array_equal(ArrayLerp(a, b).at(0.25), expected)


def test_the_office_rig_gets_the_border_blend_on_its_y_plane(clips):
    """The office estimate's target border lies between canvas rows 37 and 38 and 517 and 518 of the
    fixed canvas (its target offset); the Y pass adds the estimate's border offsets there and nowhere
    beyond their fade, and where the source goes on above the target's top border (the columns the
    offsets reach) the first frame's Y step across it is smaller than without them. The source above
    this target's top is kept (``thin_strip_ratio=0``, ``source_past_target``): it is a thin strip on
    the target's side of the seam, left out by default."""
    import av

    def first_y(path: Path) -> np.ndarray:
        with av.open(str(path)) as container:
            frame = next(container.decode(video=0)).reformat(format="yuv420p")
        return frame.to_ndarray()[:frame.height]  # yuv420p as one array: Y's rows first

    y_l, y_r = first_y(clips / "office_cam1.mp4"), first_y(clips / "office_cam2.mp4")
    uv = np.full(((y_l.shape[0] + 1) // 2, (y_l.shape[1] + 1) // 2), 128, np.uint8)
    outs = {}
    for on in (True, False):
        comp = SenaFrameCompositor.from_videos(clips / "office_cam1.mp4", clips / "office_cam2.mp4", 0.0,
                                               CFG.replace(video_estimate_pairs=1, border_blend=on, thin_strip_ratio=0.0,
                                                           source_past_target=True),
                                               "auto")
        try:
            outs[on] = comp.composite_yuv(y_l, uv, uv, y_r, uv, uv)[0].astype(np.float64)
            if on:
                oy = int(comp.offset_tgt[1])
                border = comp.maps.border_luma
                lines, border_src, border_tgt = border.lines, border.src, border.tgt
                fade = comp.maps.seam_luma.lf_px
                assert lines == (oy - 0.5, oy + y_r.shape[0] - 0.5)
                assert np.abs(border_tgt).max() > 2 and np.allclose(border_src, -border_tgt)
            else:
                assert comp.maps.border_luma is None
        finally:
            comp.close()
    changed_rows = np.flatnonzero(np.abs(outs[True] - outs[False]).max(axis=1) > 0)
    near = np.minimum(np.abs(changed_rows - lines[0]), np.abs(changed_rows - lines[1]))
    assert changed_rows.size and near.max() <= fade
    cols = np.flatnonzero(np.abs(border_tgt[0, :, 0]) > 0.5)

    def step(y: np.ndarray) -> float:
        return float(y[oy - 3:oy, cols].mean() - y[oy:oy + 3, cols].mean())

    assert abs(step(outs[True])) < abs(step(outs[False])) - 3  # measured: 52.4 -> 42.5 (content changes there too)


def test_the_frame_seam_stays_on_the_lines_where_nothing_moved(clips):
    """The office rig's first frame twice, then once more with a bright square crossing the seam on a
    few lines of the source: the lines the square changed (and a band's width around them) may move,
    every other line is still and keeps the last frame's seam exactly."""
    import av

    def first_y(path: Path) -> np.ndarray:
        with av.open(str(path)) as container:
            frame = next(container.decode(video=0)).reformat(format="yuv420p")
        return frame.to_ndarray()[:frame.height]  # yuv420p as one array: Y's rows first

    comp = SenaFrameCompositor.from_videos(clips / "office_cam1.mp4", clips / "office_cam2.mp4", 0.0,
                                           CFG.replace(video_estimate_pairs=1), "auto")
    try:
        y_l, y_r = first_y(clips / "office_cam1.mp4"), first_y(clips / "office_cam2.mp4")
        uv = np.full(((y_l.shape[0] + 1) // 2, (y_l.shape[1] + 1) // 2), 128, np.uint8)
        for _ in range(2):
            comp.composite_yuv(y_l, uv, uv, y_r, uv, uv)
        seam = comp.frame_seam
        before = seam.positions.copy()
        assert seam.still.all()  # the same frame again: every line still
        # cam2 is the source (left view): a bright square on its rows 200-240, where the seam is.
        oy = int(comp.offset_tgt[1])
        x = int(comp.maps.map_src_luma[oy + 220, int(before[oy + 220]), 0])  # the source column at the seam
        square = y_r.copy()
        square[200:240, max(x - 30, 0):x + 30] = 250
        comp.composite_yuv(y_l, uv, uv, square, uv, uv)
        still = seam.still
        assert not still.all() and still.sum() > 0.5 * len(still)
        np.testing.assert_array_equal(seam.positions[still], before[still])
    finally:
        comp.close()


def test_a_vertical_rig_gets_its_per_frame_seam_along_columns(clips, tmp_path):
    """The rooftop clips turned by 90 degrees (the left camera on top): the rig is found vertical, the
    canvas grows downwards, and the per-frame seam (one position per canvas column, solved on every
    second column) stays in its band on every frame."""
    paths = []
    for name in ("rooftop_left", "rooftop_right"):
        frames = decoded_frames(clips / f"{name}.mp4")
        height, width = frames[0].y.shape
        path = tmp_path / f"{name}_turned.mp4"
        with VideoWriter(path, height, width, Fraction(30), "libx264", 12, "veryfast") as writer:
            for index, frame in enumerate(frames):
                writer.write(*(np.ascontiguousarray(plane.T) for plane in (frame.y, frame.u, frame.v)), index)
        paths.append(path)
    seams = []
    report = stitch_videos(paths[0], paths[1], tmp_path / "out.mp4", FAST, VideoOptions.from_config(FAST),
                           observer=lambda frame: seams.append((frame.seam.copy(), frame.seam_home.copy(),
                                                                frame.seam_reach_px)))
    stitch = report["stitch"]
    assert report["frames_out"] == 60 and stitch["rig"]["vertical"] is True
    assert stitch["canvas"]["height"] > 1.2 * width  # the turned frames are `width` rows tall
    assert all(np.abs(seam - home).max() <= reach for seam, home, reach in seams)
    assert len(seams[0][0]) == stitch["canvas"]["width"]  # one position per column


def test_with_a_look_ahead_a_re_estimate_starts_on_a_later_frame_and_lands_on_it(clips, tmp_path, monkeypatch):
    """The loop holds video_estimate_lookahead_s of pairs: a due re-estimate starts on the newest one
    and becomes the key when the loop reaches that frame, not before. The worker here answers at once
    (the first frames' maps, made beforehand), so the first lands exactly on its own frame; without the
    look-ahead's wait it would land 12 frames before the frame it was made on. The alignment asks for
    a re-estimate on every frame here."""
    from sena_warp.video import timeline

    monkeypatch.setattr(MovingRig, "wants_estimate", lambda self: True)
    first_l, first_r = decoded_frames(clips / "rooftop_left.mp4")[0], decoded_frames(clips / "rooftop_right.mp4")[0]
    maps = estimate.estimate_pair(first_l, first_r, FAST, "auto")
    monkeypatch.setattr(timeline, "estimate_pair", lambda *args, **kwargs: maps)
    cfg = FAST.replace(video_rig="moving", video_reestimate_s=0.5, video_estimate_workers=1,
                       video_estimate_lookahead_s=0.4)
    report = stitch_videos(clips / "rooftop_left.mp4", clips / "rooftop_right.mp4", tmp_path / "la.mp4", cfg,
                           VideoOptions.from_config(cfg))
    applied = report["stitch"]["reestimations"]["applied"]
    assert report["frames_out"] == 60 and len(applied) >= 2
    assert applied[0]["at_s"] == applied[0]["made_on_s"], applied
    # Never before its frame; a later one may wait for its frame to be reached (measured: 1 frame).
    assert all(0 <= a["at_s"] - a["made_on_s"] <= 3 / 30 + 1e-3 for a in applied), applied


def test_looked_ahead_pairs_keep_their_order_and_are_seen_that_many_pairs_early():
    from sena_warp.video.loop import looked_ahead

    seen: list[int] = []
    out = []
    for pair in looked_ahead(((i, -i) for i in range(7)), lambda a, b: seen.append(a), 3):
        out.append(pair[0])
        assert seen[-1] == min(pair[0] + 3, 6)  # the newest pair seen is 3 ahead (or the last)
    assert out == list(range(7)) and seen == list(range(7))
    assert [p[0] for p in looked_ahead(((i, i) for i in range(4)), lambda a, b: None, 0)] == [0, 1, 2, 3]


def test_a_picture_output_is_the_frame_a_video_from_there_starts_with(clips, tmp_path):
    left, right = clips / "rooftop_left.mp4", clips / "rooftop_right.mp4"
    cfg = FAST.replace(video_start_s=1.0, video_audio="none")
    still = stitch_videos(left, right, tmp_path / "at1.png", cfg, VideoOptions.from_config(cfg))
    video = stitch_videos(left, right, tmp_path / "from1.mp4", cfg.replace(video_end_s=1.2),
                          VideoOptions.from_config(cfg.replace(video_end_s=1.2)))
    assert still["still"]["left_time_s"] == 1.0 and "frames_out" not in still and video["frames_out"] == 6
    picture = cv2.imread(str(tmp_path / "at1.png"))
    first = decoded_frames(tmp_path / "from1.mp4")[0].to_bgr()
    assert picture.shape == first.shape == (video["output"]["height"], video["output"]["width"], 3)
    assert float(np.mean(cv2.absdiff(picture, first))) < 2.0  # the same stitch of the same frame, less the encoding


def test_scaled_maps_sample_where_the_canvas_does_and_carry_the_seam_along():
    maps = synthetic_maps(0.0, 300, shape=(40, 60))
    border = BorderBlend((9.5, 30.5), np.arange(120, dtype=np.float32).reshape(2, 60, 1), np.zeros((2, 60, 1), np.float32))
    maps = replace(maps, border_luma=border)
    half = scaled_plane_maps(maps, output_shape(maps.shape, 30))
    assert half.shape == (20, 30) and output_shape((40, 61), 30) == (20, 30) and output_shape((40, 60), 100) == (40, 60)
    # Output (x, y) covers canvas (2x + 0.5, 2y + 0.5): the maps there (they are linear, so exactly).
    np.testing.assert_allclose(half.map_src_luma[7, 11], maps.map_src_luma[14, 22] + 0.5)
    np.testing.assert_allclose(half.map_tgt_luma[7, 11], maps.map_tgt_luma[14, 22] + 0.5)
    np.testing.assert_allclose(half.map_src_chroma, chroma_positions(half.map_src_luma))
    # The seam at canvas x 30 is at output x 14.75 on every row, its widths halved; the border's rows and
    # its offsets along them likewise.
    np.testing.assert_allclose(half.seam_luma.positions, 14.75)
    assert (half.seam_luma.band_px, half.seam_luma.transition_px) == (5.0, 4.0)
    assert half.border_luma.lines == (4.5, 15.0)
    np.testing.assert_allclose(half.border_luma.src[0, :3, 0], [0.5, 2.5, 4.5])
    # What works on the canvas gets the seam back per canvas line.
    np.testing.assert_allclose(seam_on_canvas_lines(half.seam_luma.positions, 40, canvas_scale((40, 60), (20, 30)),
                                                    True), 30.0)


def test_windowed_maps_sample_where_the_window_shows_the_canvas_and_carry_the_seam_along():
    maps = synthetic_maps(0.0, 300, shape=(40, 60), change=lambda m: m.__setitem__((slice(None), slice(0, 6)), np.nan))
    border = BorderBlend((9.5, 30.5), np.arange(120, dtype=np.float32).reshape(2, 60, 1), np.zeros((2, 60, 1), np.float32))
    maps = replace(maps, border_luma=border)
    corner = np.array([2.25, -3.5])
    window = windowed_plane_maps(maps, corner, (40, 60), np.array([10.0, 0.0]))
    # Output (x, y) shows canvas (x + 2.25, y - 3.5): the maps there (they are linear, so exactly) ...
    np.testing.assert_allclose(window.map_src_luma[7, 11], maps.map_src_luma[7, 11] + [2.25, -3.5], atol=1e-4)
    np.testing.assert_allclose(window.map_tgt_luma[7, 11], maps.map_tgt_luma[7, 11] + [2.25, -3.5], atol=1e-4)
    np.testing.assert_allclose(window.map_src_chroma[3, 5], maps.map_src_chroma[3, 5] + [1.125, -1.75], atol=1e-4)
    np.testing.assert_allclose(window.map_tgt_chroma[3, 5], maps.map_tgt_chroma[3, 5] + [1.125, -1.75], atol=1e-4)
    # ... no source where it lies off the canvas (rows 0-3, columns 57 on) or where a tap the canvas does
    # not sample counts (canvas columns 0-5: output columns 0-3, whose taps are canvas columns 2-6)
    assert np.isnan(window.map_src_luma[:4]).all() and np.isnan(window.map_src_luma[:, 57:]).all()
    assert np.isnan(window.map_src_luma[4:, :4]).all() and np.isfinite(window.map_src_luma[4:, 4:57]).all()
    # The seam at canvas x 30 is at output x 27.75 on every row, the border's rows 3.5 lower, its offsets
    # read 2.25 along; whole pixels copy the maps as they are.
    np.testing.assert_allclose(window.seam_luma.positions, 27.75)
    assert window.border_luma.lines == (13.0, 34.0)
    np.testing.assert_allclose(window.border_luma.src[0, :3, 0], [2.25, 3.25, 4.25])
    whole = windowed_plane_maps(maps, np.array([3.0, 2.0]), (40, 60), np.array([10.0, 0.0]))
    np.testing.assert_array_equal(whole.map_src_luma[:38, :57], maps.map_src_luma[2:, 3:])
    assert np.isnan(whole.map_src_luma[38:]).all()
    np.testing.assert_array_equal(whole.map_tgt_luma[:38, :57], maps.map_tgt_luma[2:, 3:])
    # A frame's seam and its offsets per canvas line, read for the window's lines.
    np.testing.assert_allclose(windowed_seam(np.arange(40, dtype=np.float32), corner, True, 40)[5:8], [-0.75, 0.25, 1.25])


def test_a_narrower_output_is_the_stitch_made_smaller_by_its_maps(clips, tmp_path):
    left, right = clips / "rooftop_left.mp4", clips / "rooftop_right.mp4"
    # A moving rig is not aligned at --max-width: static. What is in front, and the route round it, is
    # judged on each output's own cells: on this hand-held rig stitched as static everything moves, and
    # the two sizes route the seam apart (frame 40: 3.5 grey levels). The seam here goes round nothing,
    # so what is compared is what the maps make; and it stays on the estimate's seam (the rooftop's overlap
    # spans 83 % of the target, whose edge home lies video_seam_edge_px inside it at each size).
    cfg = FAST.replace(video_audio="none", video_rig="static", video_seam_motion_cost=0.0,
                       video_seam_object_cost=0.0, video_edge_home_share=2.0)
    full = stitch_videos(left, right, tmp_path / "full.mp4", cfg, VideoOptions.from_config(cfg))
    small_cfg = cfg.replace(video_max_width=166)
    small = stitch_videos(left, right, tmp_path / "small.mp4", small_cfg, VideoOptions.from_config(small_cfg))
    width, height = small["output"]["width"], small["output"]["height"]
    canvas = small["stitch"]["canvas"]
    assert (canvas["stitched_width"], canvas["stitched_height"]) == (full["output"]["width"], full["output"]["height"])
    assert width == 166 and height % 2 == 0 and abs(height / width - canvas["stitched_height"] / canvas["stitched_width"]) < 0.01
    for k in (0, 40):  # each frame: what the full-size stitch shows, made smaller (a 2x2 box at this half size)
        frame_full, frame_small = decoded_frames(tmp_path / "full.mp4")[k], decoded_frames(tmp_path / "small.mp4")[k]
        made_small = cv2.resize(frame_full.y, (width, height), interpolation=cv2.INTER_AREA)
        assert float(np.mean(cv2.absdiff(made_small, frame_small.y))) < 2.5
    # A moving rig is aligned every frame at the stitched size only: refused at a narrower output, and
    # --rig auto says that it keeps the static plan.
    moving = small_cfg.replace(video_rig="moving", video_estimate_workers=0)
    with pytest.raises(VideoError, match="drop --max-width"):
        stitch_videos(left, right, tmp_path / "moving.mp4", moving, VideoOptions.from_config(moving))
    auto = small_cfg.replace(video_rig="auto")
    report = stitch_videos(left, right, tmp_path / "auto.mp4", auto, VideoOptions.from_config(auto))
    decisions = report["stitch"]["rig"]["decisions"]
    assert [d["mode"] for d in decisions] == ["moving"] and "the static plan is kept" in decisions[0]["reason"]
    assert report["stitch"]["rig"]["alignment"] is None and report["output"]["width"] == 166


@pytest.mark.parametrize("max_side", [1920, 256])  # the frames as they are, and made smaller for the estimate
def test_debug_writes_the_first_estimate_s_stage_pictures(clips, tmp_path, max_side):
    cfg = FAST.replace(video_audio="none", video_estimate_max_side=max_side, video_end_s=0.5)
    report = stitch_videos(clips / "rooftop_left.mp4", clips / "rooftop_right.mp4", tmp_path / "o.mp4", cfg,
                           VideoOptions.from_config(cfg), debug=tmp_path / "debug")
    names = sorted(p.name for p in (tmp_path / "debug").iterdir())
    assert names == ["01_matches.jpg", "02_overlap_cells.jpg", "03_ffd_field.jpg", "05_warped_over_target.jpg",
                     "06_zone_chain_seam.jpg", "07_alpha.jpg"]
    seam = cv2.imread(str(tmp_path / "debug" / "06_zone_chain_seam.jpg"))
    canvas = report["stitch"]["canvas"]
    # The panorama the seam is drawn on: the video's canvas (up to its even crop), or the estimate's smaller one.
    scale = max(480 / max_side, 1.0)
    assert abs(seam.shape[1] * scale - canvas["stitched_width"]) <= 2 * scale
    assert abs(seam.shape[0] * scale - canvas["stitched_height"]) <= 2 * scale
    matches = cv2.imread(str(tmp_path / "debug" / "01_matches.jpg"))
    assert matches.shape[1] == round(2 * 270 / scale)  # the pair side by side, as the estimate saw it
