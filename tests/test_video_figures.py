"""The video figures (``sena_warp.evaluation.video_figures``) and the frame loop's observer.

The figures' parts are checked on cases with a known answer (a path that jitters by a known amount,
a map built from a known warp, a band shifted by a known amount, a panorama with a known step);
the observer end to end on the bundled clips: a static office rig (the maps never change: stability
0, a seam that does not move on this clip) and a moving rooftop rig through ``sena-warp video
--figures`` (the maps change: a finite, non-zero stability, bounded seam motion).
"""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from sena_warp.config import Config
from sena_warp.evaluation import naturalness
from sena_warp.evaluation.video_figures import (FrameClock, VideoFigures, aligned_lines, band_flow, forward_on_canvas, source_lattice,
                                                stability, stability_per_point, texture)
from sena_warp.video.loop import VideoOptions
from sena_warp.video.stitch import stitch_videos
from sena_warp.cli import main

CFG = Config(device="cpu", video_estimate_pairs=2)


def test_stability_of_a_path_that_alternates_by_a():
    # P_t = (+-a, 0): every odd distance differs by 2a in x, every even one by 0; per coordinate
    # (x and y averaged) each side contributes 2 a^2, so 0.9 * 4 a^2 + 0.1 * 4 a^2 = 4 a^2.
    a = 1.5
    t = np.arange(40)
    paths = np.zeros((40, 63, 2))
    paths[:, :, 0] = (a * (-1.0) ** t)[:, None]
    assert stability(paths) == pytest.approx(4 * a * a)
    assert stability(paths + 100.0) == pytest.approx(4 * a * a)  # where the lattice sits does not matter
    assert stability(np.ones((40, 63, 2))) == 0.0
    per_point = stability_per_point(np.concatenate([paths, np.zeros((40, 63, 2))], axis=1))
    assert per_point[:63] == pytest.approx(np.full(63, 4 * a * a)) and not per_point[63:].any()
    assert np.isnan(stability(np.zeros((6, 63, 2))))


def test_source_lattice_is_7_by_9_corner_to_corner():
    lattice = source_lattice((480, 270))
    assert lattice.shape == (63, 2)
    assert lattice.min(axis=0).tolist() == [0.0, 0.0] and lattice.max(axis=0).tolist() == [269.0, 479.0]
    assert len(np.unique(lattice[:, 0])) == 9 and len(np.unique(lattice[:, 1])) == 7


def test_forward_on_canvas_inverts_a_bent_map():
    # M_s(u) = A^-1 (u - c) + a smooth bend: the forward position P of a source point s must satisfy
    # M_s(P) = s; points the map never reaches come back NaN.
    height, width = 300, 400
    rows, cols = np.mgrid[0:height, 0:width].astype(np.float64)
    affine = np.array([[0.95, 0.05, 30.0], [-0.04, 1.02, 12.0]])  # source -> canvas
    inverse = np.linalg.inv(np.vstack([affine, [0, 0, 1]]))[:2]
    src_x = inverse[0, 0] * cols + inverse[0, 1] * rows + inverse[0, 2] + 3.0 * np.sin(rows / 50.0)
    src_y = inverse[1, 0] * cols + inverse[1, 1] * rows + inverse[1, 2] + 2.0 * np.cos(cols / 70.0)
    map_src = np.stack([src_x, src_y], axis=-1).astype(np.float32)
    pts = np.array([[50.0, 40.0], [200.0, 150.0], [300.0, 250.0], [5000.0, 10.0]])
    found = forward_on_canvas(map_src, pts, CFG)
    assert np.isnan(found[3]).all()
    x, y = found[:3, 0], found[:3, 1]
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    back = ((1 - fx) * (1 - fy) * map_src[y0, x0] + fx * (1 - fy) * map_src[y0, x0 + 1]
            + (1 - fx) * fy * map_src[y0 + 1, x0] + fx * fy * map_src[y0 + 1, x0 + 1])
    assert np.abs(back - pts[:3]).max() < 0.02


@pytest.mark.parametrize("shift_px", [0.0, 1.0, 2.5, 5.0])
def test_band_flow_reads_a_known_shift_of_a_real_band(udisd_pair, shift_px):
    grey = cv2.cvtColor(udisd_pair[0], cv2.COLOR_BGR2GRAY).astype(np.float32)
    move = np.float32([[1, 0, shift_px], [0, 1, 0]])
    tgt = grey[:, 200:281]
    src = cv2.warpAffine(grey, move, grey.shape[::-1], flags=cv2.INTER_LINEAR)[:, 200:281]
    valid = np.ones(tgt.shape, bool)
    flow = band_flow(src, tgt, valid, valid)
    seam = texture(tgt) >= 3.0
    seam[:, :36] = seam[:, 45:] = False  # the cells near a seam in the middle of the band
    assert seam.sum() > 1000
    assert np.median(flow[..., 0][seam]) == pytest.approx(shift_px, abs=0.1)
    assert np.median(np.abs(flow[..., 1][seam])) < 0.1


def test_seam_steps_read_a_known_exposure_step(udisd_pair):
    # The panorama shows the source left of the seam and the target, 5 levels brighter, right of it:
    # the views' own change cancels and the step is -5 on every row.
    grey = cv2.cvtColor(udisd_pair[0], cv2.COLOR_BGR2GRAY).astype(np.float32)
    seam = 200 + 30 * np.sin(np.arange(512) / 40.0)
    pano = np.where(np.arange(512)[None, :] < seam[:, None], grey, grey + 5.0)
    valid = np.ones(grey.shape, bool)
    steps = naturalness.seam_steps(pano, grey, grey, valid, valid, seam)
    assert np.isfinite(steps[8:-8]).all()
    assert np.nanmax(np.abs(steps + 5.0)) < 0.5
    assert naturalness.seam_step(pano, grey, grey, valid, valid, seam) == pytest.approx(5.0, abs=0.3)
    # The seam 3 px inside the target's border (a mostly shared view's home): left of it the source alone.
    # Both views on both strips nowhere; with one_view the source's own change is the scene's.
    valid_tgt = np.arange(512)[None, :] >= seam[:, None] - 3.0
    assert np.isnan(naturalness.seam_steps(pano, grey, grey, valid, valid_tgt, seam)).all()
    edge = naturalness.seam_steps(pano, grey, grey, valid, valid_tgt, seam, one_view=True)
    assert np.isfinite(edge[8:-8]).all() and np.nanmax(np.abs(edge + 5.0)) < 0.5


def test_aligned_lines_are_those_whose_views_agree_next_to_the_seam():
    flow = np.zeros((40, 30, 2), np.float32)
    flow[10:20, :, 0] = 20.0  # a near door 20 px apart in the two views on these lines ...
    flow[25:30, 20:, 0] = 20.0  # ... and on these, but farther from the seam than the step's strips reach
    both = np.ones((40, 30), bool)
    both[35:] = False  # no textured cell with both views there: nothing says these lines are not aligned
    seam = np.full(40, 8.0)
    aligned = aligned_lines(flow, np.arange(30)[None, :], seam, both)
    assert not aligned[10:20].any() and aligned[:10].all() and aligned[20:].all()


@pytest.fixture(scope="module")
def office(bundled_dir, tmp_path_factory):
    clips = bundled_dir / "video"
    observer = VideoFigures(CFG, strip_every=10, keep_frames=(0, 47))
    clock = FrameClock()
    seen = []

    def watch(frame):
        seen.append((frame.index, frame.time_s, frame.source, frame.seam.copy(), frame.seam_home.copy(),
                     frame.seam_reach_px, frame.planes_out[0].shape, frame.planes_src[0].shape))
        observer(frame)
        clock(frame)

    out = tmp_path_factory.mktemp("figures") / "office.mp4"
    report = stitch_videos(clips / "office_cam1.mp4", clips / "office_cam2.mp4", out, CFG,
                           VideoOptions.from_config(CFG), observer=watch)
    return report, observer, seen, clock


def test_the_observer_sees_every_frame_once_in_order(office):
    report, _, seen, _ = office
    assert [s[0] for s in seen] == list(range(report["frames_out"])) and len(seen) == 48
    times = np.array([s[1] for s in seen], np.float64)
    assert np.allclose(np.diff(times), 1 / 24, atol=1e-6)
    width, height = report["output"]["width"], report["output"]["height"]
    assert {s[6] for s in seen} == {(height, width)} and {s[7] for s in seen} == {(480, 640)}
    assert {s[2] for s in seen} == {report["stitch"]["rig"]["source"]}
    for _, _, _, seam, home, reach, _, _ in seen:  # the frame's seam stays in its band
        assert np.abs(seam - home).max() <= reach
    assert report["timing_s"]["observer"] > 0


def test_office_figures_static_rig(office):
    report, observer, _, clock = office
    fig = observer.figures()
    assert fig["frames"] == 48 and all(len(v) == 48 for v in fig["per_frame"].values())
    # A static rig's maps never change: one map set, stability 0 exactly.
    assert fig["stability"]["value"] == 0.0 and fig["stability"]["map_sets"] == 1
    assert fig["stability"]["scale_to"] == [480, 360] and len(fig["stability"]["per_point"]) == 63
    # ... and leave the same part of the canvas uncovered in every frame (measured 15.6 %: beyond the warped
    # source and the target).
    assert 5.0 < fig["uncovered_pct"]["mean"] == fig["uncovered_pct"]["max"] < 30.0
    assert fig["uncovered_pct"]["largest_change"] == 0.0
    # The clock reads the frames from 1 s on: 24 frames, 23 steps between them.
    cpu = clock.figures()
    assert cpu["frames"] == 23 and 0 < cpu["median_ms"] <= cpu["p95_ms"]
    assert fig["stability"]["points"] >= 50  # of 63: the lattice's corners fall off this canvas
    # Nothing crosses the seam in these 2 s: measured 0 seam motion in every frame.
    assert fig["seam_motion_px"]["max"] == 0.0 and fig["seam_motion_px"]["where_still_max"] == 0.0
    assert fig["seam_motion_px"]["still_lines_pct_mean"] > 95.0
    # Measured 1.73 grey levels mean, changing by 0.25 p99 frame to frame (the rows where the views disagree
    # about the scene's own change are left out of the step; 0.86 without the rows where one view alone
    # covers both strips, at the overlap's edge: its own change is the scene's there).
    assert 1.2 < fig["exposure_step_grey"]["mean"] < 2.2
    assert fig["exposure_step_change_grey"]["p99"] < 0.5
    # Where along the seam the settled step is: 16 runs of lines covering every line once.
    groups = fig["exposure_step_grey"]["settled_by_lines"]
    assert len(groups) == 16 and groups[0]["lines"][0] == 0
    assert all(a["lines"][1] + 1 == b["lines"][0] for a, b in zip(groups, groups[1:]))
    means = [g["mean"] for g in groups if g["mean"] is not None]
    assert len(means) >= 8 and min(means) <= fig["exposure_step_grey"]["settled_mean"] <= max(means)
    # Measured 2.48 px median, 39.4 px p95 at the textured seam cells of 24 sampled frames (near-field
    # furniture the rig's two webcams see with parallax), the flow read on one rectangle of the canvas.
    mis = fig["misalignment_px"]
    assert mis["frames"] == 24 and mis["cells"] > 5000
    assert 1.5 < mis["median"] < 7.0 and mis["median"] < mis["p95"] < 50.0
    assert [s[0] for s in observer.strips] == [0, 10, 20, 30, 40] and sorted(observer.frames) == [0, 47]
    index, band, seam, x0 = observer.strips[0]
    # The band: one rectangle of the canvas, reaching band_half_px past the seam's home on every line.
    assert band.dtype == np.uint8 and band.shape[0] == report["output"]["height"]
    assert band.shape[1] >= 2 * fig["band_half_px"] + 1 and np.all(x0 == x0[0])


def test_moving_rig_aligned_every_frame(bundled_dir, tmp_path):
    # Re-estimates on the loop's thread (video_estimate_workers=0): the same estimates every run.
    clips = bundled_dir / "video"
    cfg = CFG.replace(video_rig="moving", video_estimate_workers=0)
    observer = VideoFigures(cfg)
    stitch_videos(clips / "rooftop_left.mp4", clips / "rooftop_right.mp4", tmp_path / "moving.mp4", cfg,
                  VideoOptions.from_config(cfg), observer=observer)
    fig = observer.figures()
    assert fig["stability"]["map_sets"] == 60  # the source map is aligned to every frame
    motion = [v for v in fig["per_frame"]["seam_motion_px"] if v is not None]
    assert max(motion) <= cfg.video_seam_speed_px
    # Measured 0.48 px median at the seam (3.49 with the first estimate held: --rig static) and a stability
    # of 1.02 (0 held): the warp follows the rig, and some of its measurement's noise.
    assert fig["misalignment_px"]["median"] < 1.0
    assert 0.0 < fig["stability"]["value"] < 3.0
    # The warped source's footprint moves a little every frame and the output's window on the canvas
    # follows the rig (``steady.py``): the uncovered share changes, smoothly (measured 0.62 % of the
    # output a frame at most, the black band at the edge of an output 270 px wide; 0.06 % with the
    # window held still).
    assert 0.0 < fig["uncovered_pct"]["largest_change"] <= 1.0


def test_sena_warp_video_figures_go_into_the_report(bundled_dir, tmp_path, warp_device, capfd):
    clips = bundled_dir / "video"
    out, report_path = tmp_path / "static.mp4", tmp_path / "static.json"
    capfd.readouterr()
    rc = main(["video", str(clips / "rooftop_left.mp4"), str(clips / "rooftop_right.mp4"), "-o", str(out),
               "--figures", "--report", str(report_path), "--device", warp_device, "--rig", "static"])
    stdout = capfd.readouterr().out
    assert rc == 0
    assert "; seam motion p99" in stdout  # the summary line names the headline figures
    report = json.loads(report_path.read_text())
    fig = report["figures"]
    assert fig["frames"] == report["frames_out"] == 60
    assert fig["stability"]["value"] == 0.0 and fig["stability"]["map_sets"] == 1
    assert set(fig) >= {"seam_motion_px", "exposure_step_grey", "exposure_step_change_grey", "misalignment_px",
                        "per_frame"}
    assert "observer" in report["timing_s"]
