"""Benchmark: clip maker, a tiny bench run (on the pair the package ships), and the fairness of the
compositing comparison.

The Warp compositor is checked against the OpenCV reference the benchmark times it with, on the same
real images, maps, seam, gains and offsets.
"""

from __future__ import annotations

import math
import subprocess

import numpy as np
import pytest

from sena_warp.evaluation.bench import (BUNDLED_PAIR, COLUMNS, BenchPair, OpenCVReference, bench_pair, format_table,
                                       make_clip_pair, pan_window, parse_size, run_bench)
from sena_warp.composite import BorderBlend, FrameState, composite_image, composite_plan, coverage
from sena_warp.config import Config
from sena_warp.errors import InputError
from sena_warp.video.reader import FrameReader, probe_video
from sena_warp.video.stitch import PlanePass
from test_composite import layout
from test_kernels_remap import scene  # noqa: F401  (a fixture)

INTER_STEPS = 32  # cv2.remap's sub-pixel resolution (INTER_BITS = 5)


@pytest.fixture(scope="module")
def pair():
    """The pair the package ships, which a bench without the shared data set makes its clips from."""
    return BenchPair("bundled", (BUNDLED_PAIR / "a.jpg", BUNDLED_PAIR / "b.jpg"))


def test_clip_maker_makes_decodable_panning_clips(pair, tmp_path):
    left, right = make_clip_pair(pair, tmp_path, (160, 96), 1.0)
    for path in (left, right):
        info = probe_video(path)
        assert (info.width, info.height, info.fps) == (160, 96, 30)
        with FrameReader(path) as reader:
            frames = list(reader)
        assert len(frames) == 30 and frames[0].y.shape == (96, 160)
        # The window pans: the first and last frames show different parts of the view.
        assert np.abs(frames[0].y.astype(int) - frames[-1].y).mean() > 5
    with FrameReader(left) as reader_l, FrameReader(right) as reader_r:
        first_l, first_r = next(iter(reader_l)), next(iter(reader_r))
    assert np.abs(first_l.y.astype(int) - first_r.y).mean() > 5  # two different views
    # A second call reuses the clips rather than re-encoding them.
    stamp = left.stat().st_mtime_ns
    assert make_clip_pair(pair, tmp_path, (160, 96), 1.0) == (left, right) and left.stat().st_mtime_ns == stamp


def test_pan_window_stays_inside_and_moves():
    start, end = pan_window((1440, 2160), 16 / 9, 0.85, 0.0), pan_window((1440, 2160), 16 / 9, 0.85, 1.0)
    x0, y0, w, h = end
    assert start[:2] == (0, 0) and start[2:] == end[2:]
    assert x0 > 0 and y0 > 0 and x0 + w <= 2160 and y0 + h <= 1440
    assert abs(w / h - 16 / 9) < 0.01


def test_bench_tiny_run_fills_every_column(pair, tmp_path):
    rows = run_bench(["192x108"], 1.0, tmp_path, Config(device="cpu"), pair)
    assert len(rows) == 1
    row = rows[0]
    assert set(key for key, _, _ in COLUMNS) <= set(row)
    assert row["frames"] == 30 and row["clip"] == "192x108" and row["canvas"] == "250x114"  # measured canvas
    for key in ("baseline_fps", "stitch_fps", "warp_ms", "opencv_ms", "warp_cpu_ms", "rss_mib", "encode_ms"):
        assert math.isfinite(row[key]) and row[key] > 0, key
    # How the columns relate: the whole run also pays the one-time estimate, the compositing runs on
    # the main thread frame after frame, the ratios are the figures' own.
    assert row["run_fps"] < row["stitch_fps"] and row["setup_s"] > 0
    # The process's start (imports, Warp) comes before the estimate; the run's start time and the
    # bench's clock agree (a time zone or clock mixed up would be hours off).
    assert row["setup_s"] < row["first_frame_s"] < row["setup_s"] + 30
    assert row["composite_ms"] < 1000.0 / row["stitch_fps"]
    assert row["fps_ratio"] == pytest.approx(row["stitch_fps"] / row["baseline_fps"])
    assert row["kernel_ratio"] == pytest.approx(row["warp_ms"] / row["opencv_ms"])
    assert 100 < row["rss_mib"] < 1000  # measured 282 MiB: a child process stitching a tiny clip
    # Both compositors ran on the same planes and maps: real maps are not on cv2's 1/32 px grid, so a
    # few edge pixels differ by more than 1 (docs/benchmarks.md: 3 at every size).
    assert row["max_diff"] <= 3
    # The plain table fits a terminal; the Markdown one has every column.
    plain, markdown = format_table(rows), format_table(rows, markdown=True)
    assert max(len(line) for line in plain.splitlines()) <= 80 and "steady" in plain
    assert markdown.splitlines()[0].count("|") == len(COLUMNS) + 1


def test_bench_sizes_and_missing_data(tmp_path):
    assert parse_size("1080p") == ("1080p", (1920, 1080)) and parse_size("4K")[1] == (3840, 2160)
    assert parse_size("320x180") == ("320x180", (320, 180))
    with pytest.raises(InputError, match="size"):
        parse_size("321x180")
    with pytest.raises(InputError, match="benchmark pair not found"):
        bench_pair(tmp_path / "nowhere")  # a data set named and missing is refused, not replaced


@pytest.mark.parametrize("channels", [1, 2])
def test_opencv_reference_agrees_with_warp_compositor(scene, channels, warp_device):  # noqa: F811
    """Fairness of the benchmark: both compositors compute the same thing (maps on cv2's 1/32 px grid),
    seam, gains and the seam blend's offsets (along the seam and the borders) included."""
    img_src, img_tgt, map_src, map_tgt, _ = scene
    map_src = (np.round(map_src * INTER_STEPS) / INTER_STEPS).astype(np.float32)
    map_src[:40, :40] = np.nan  # a NaN patch: nothing sampled from the source there
    plane_src = np.ascontiguousarray(img_src[:, :, :channels])
    plane_tgt = np.ascontiguousarray(img_tgt[:, :, :channels])
    fill = (16, 128)[:channels]
    cfg = Config(device=warp_device, cpu_threads=2)
    seam = layout(scene)
    lines = len(seam.positions)
    along = np.linspace(-8.0, 8.0, map_src.shape[1], dtype=np.float32)[:, None].repeat(channels, 1)
    border = BorderBlend((12.5, lines - 15.5), np.stack([along, -along]), np.stack([-along, along]))
    plan = composite_plan(map_src, map_tgt, seam, (plane_src.shape, plane_tgt.shape), cfg, border=border, fill=fill)
    gains = ([1.1, 1.0][:channels], [-4.0, 2.0][:channels], [0.9, 1.0][:channels], [3.0, -2.0][:channels])
    state = FrameState(seam.positions, gains, (np.full((lines, channels), -5.0, np.float32),
                                               np.full((lines, channels), 5.0, np.float32)))
    out = composite_image(plane_src, plane_tgt, plan, state, cfg).reshape(*map_src.shape[:2], channels)
    reference = OpenCVReference(PlanePass.of(plan, state, map_src, map_tgt, cfg), plane_src.shape[:2],
                                plane_tgt.shape[:2])
    expected = reference.apply(plane_src, plane_tgt).reshape(*map_src.shape[:2], channels)
    covered = coverage(plan)
    assert (covered == 0).any() and (covered > 0).any()
    assert np.abs(out.astype(int) - expected).max() <= 1
    np.testing.assert_array_equal(out[covered == 0], np.broadcast_to(fill, out[covered == 0].shape))


def test_bench_refuses_a_bad_size_before_making_its_work_folder(tmp_path, capfd):
    from sena_warp.cli import main

    capfd.readouterr()
    assert main(["bench", "--sizes", "320x180", "17x9", "--work", str(tmp_path / "w")]) == 2
    err = capfd.readouterr().err.splitlines()
    assert err == ["sena-warp: error: size '17x9': width and height must be even and at least 16"]
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("argv, words", [
    (["--seconds", "nan"], ("--seconds", "nan s is not a clip length")),
    (["--seconds", "inf"], ("--seconds", "inf s is not a clip length")),
    (["--seconds=-5"], ("--seconds", "-5 s is not a clip length", "at most 3600")),
    (["--seconds", "0"], ("--seconds", "0 s")),
    (["--seconds", "ten"], ("--seconds", "'ten' is not a number of seconds")),
    (["--rss", "10", "nan"], ("--rss", "nan s")),
    (["--sizes", "100000x100000"], ("size '100000x100000'", "at most 8192 px a side")),
    (["--sizes", "8192x8192"], ("size '8192x8192'", "33.2 MP (8K)")),
])
def test_bench_refuses_lengths_and_sizes_out_of_range_before_any_work(argv, words, tmp_path, capfd):
    from sena_warp.cli import main

    capfd.readouterr()
    assert main(["bench", *argv, "--work", str(tmp_path / "w")]) == 2
    err = capfd.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith("sena-warp: error: ") and all(w in err[0] for w in words), err
    assert list(tmp_path.iterdir()) == []


def test_bench_keeps_the_stitch_child_s_exit_code_and_message(tmp_path, monkeypatch):
    from sena_warp.evaluation import bench
    from sena_warp.errors import MatchError

    said = "sena-warp: error: only 3 of 40 matches agree on one affine model: check that the images overlap\n"
    monkeypatch.setattr(bench.subprocess, "run", lambda *a, **k: subprocess.CompletedProcess(a, 3, "", said))
    with pytest.raises(MatchError) as caught:
        bench.stitch_in_child(tmp_path / "l.mp4", tmp_path / "r.mp4", tmp_path / "o.mp4", "cpu")
    assert str(caught.value) == "stitching l.mp4: only 3 of 40 matches agree on one affine model: check that the " \
                                "images overlap"


def test_bench_with_a_missing_data_set_is_one_line_error(tmp_path, capsys):
    from sena_warp.cli import main

    assert main(["bench", "--sizes", "192x108", "--data", str(tmp_path / "nowhere"), "--work", str(tmp_path / "w")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "benchmark pair not found" in err and "--data" in err
    assert not (tmp_path / "w").exists()


def test_without_the_shared_data_set_the_bench_uses_the_pair_the_package_ships(monkeypatch, tmp_path):
    from sena_warp.evaluation import bench

    monkeypatch.setattr(bench, "DATA_DIR", tmp_path / "no_shared")
    shipped = bench_pair()
    assert shipped.name == "bundled_spw_13" and all(path.is_file() for path in shipped.paths)
