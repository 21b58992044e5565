"""Time of the per-frame seam (its target: <= 4 ms CPU per 1080p frame), frame by frame.

Usage (from the repository root)::

    .venv/bin/python benchmarks/frame_seam_time.py [--left L --right R] [--frames N] [--work DIR]
        [--set video_seam_frame_cells=360 ...] [--parts]

Without ``--left``/``--right`` it makes (or reuses) ``sena-warp bench``'s 1080p clip pair in ``--work``:
a slow pan over a real pair, so every line of the band changes every frame (the worst case: no line
is still, the free path is solved every frame). The first N frame pairs are decoded into memory, a
:class:`~sena_warp.video.stitch.SenaFrameCompositor` is made as ``sena-warp video`` makes it (static
rig, one estimate pair, OpenCV on ``video_opencv_threads``), and each frame is composited in order; the per-frame seam's calls (the
band's and the object band's differences over the overlap and their download, ``DeviceFrame.band``,
then ``FrameSeam.next``: what is in front and its route, still lines, paths, seam blend offsets, where
the next frame's band goes) are timed in wall and process CPU time (no drift checks: nothing else of the process runs
meanwhile; the estimate is made on the first pair, ``video_estimate_pairs=1``). Prints median,
mean and p95 over the frames after the first five, and the band's size. ``--parts`` also gives the
mean process CPU time per call of its parts (the band's difference, the dynamic programming, the
views' background models and their whole-band fits, the objects, still lines, the seam blend's
offsets, the paths' costs).
"""

from __future__ import annotations

import argparse
import ast
import time
from collections import defaultdict
from itertools import islice
from pathlib import Path

import cv2
import numpy as np

from sena_warp import seam_path
from sena_warp.config import Config
from sena_warp.evaluation.bench import DATA_DIR, bench_pair, make_clip_pair
from sena_warp.kernels.runtime import resolve_config
from sena_warp.video import device_frame, frame_objects, frame_seam
from sena_warp.video.reader import FrameReader
from sena_warp.video.stitch import SenaFrameCompositor

WARMUP = 5  # frames not counted: the first estimate's band, the background model's start
PARTS = ((device_frame, "band_difference", "band's difference (kernel)"),
         (seam_path.BandPath, "solve", "dynamic programming (per solve)"),
         (frame_objects.ObjectBand, "update", "objects and their route (all of it)"),
         (frame_objects.ViewBackground, "update", "... the views' background models"),
         (frame_objects, "whole_band_fit", "... their whole-band fits"),
         (frame_seam.FrameSeam, "foreground", "objects on the seam's band"),
         (frame_seam.FrameSeam, "still_lines", "still lines"),
         (frame_seam, "band_offsets", "seam blend's offsets"),
         (frame_seam.FrameSeam, "_solve", "paths with their costs (the DPs included)"))


def yuv_planes(path: Path, count: int) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """The first ``count`` frames of a video as (y, u, v) 4:2:0 planes (the video loop's reader)."""
    with FrameReader(path) as reader:
        return [(frame.y, frame.u, frame.v) for frame in islice(reader, count)]


def time_parts() -> dict[str, list[float]]:
    """Wrap the per-frame seam's parts (:data:`PARTS`) to record each call's process CPU seconds."""
    seconds: dict[str, list[float]] = defaultdict(list)
    for owner, name, label in PARTS:
        setattr(owner, name, _timed(getattr(owner, name), seconds[label]))
    return seconds


def _timed(call, seconds: list[float]):
    """``call``, appending each call's process CPU seconds to ``seconds``."""
    def timed(*args, **kwargs):
        start = time.process_time()
        result = call(*args, **kwargs)
        seconds.append(time.process_time() - start)
        return result
    return timed


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--left", type=Path)
    parser.add_argument("--right", type=Path)
    parser.add_argument("--frames", type=int, default=60)
    parser.add_argument("--work", type=Path, default=Path("out/frame_seam_time"))
    parser.add_argument("--set", nargs="*", default=[], metavar="FIELD=VALUE")
    parser.add_argument("--parts", action="store_true", help="also the CPU time of the seam's parts")
    args = parser.parse_args()
    parts = time_parts() if args.parts else {}
    changes = {k: ast.literal_eval(v) for k, v in (item.split("=", 1) for item in args.set)}
    cfg = resolve_config(Config(device="cpu", **changes))
    if args.left is None:
        args.work.mkdir(parents=True, exist_ok=True)
        args.left, args.right = make_clip_pair(bench_pair(DATA_DIR), args.work, (1920, 1080), 5.0)
    left, right = yuv_planes(args.left, args.frames), yuv_planes(args.right, args.frames)
    # A static rig (the pan is a moving one to --rig auto: its object band is what is timed), one
    # estimate, on the first pair, and no drift checks: nothing else of the process runs while the
    # seam is timed (a worker's estimate would count in the process's CPU time).
    compositor = SenaFrameCompositor.from_videos(
        args.left, args.right, 0.0, cfg.replace(video_rig="static", video_estimate_pairs=1, video_drift_check_s=0.0),
        "auto")
    if cfg.video_opencv_threads > 0:  # as ``sena-warp video`` sets them from the first estimate on
        cv2.setNumThreads(cfg.video_opencv_threads)
    seam = compositor.frame_seam  # the compositor's own FrameSeam, timed where the loop calls it
    solve, band = seam.next, device_frame.DeviceFrame.band
    wall, cpu = [0.0], [0.0]

    def timed(call, *args):
        t0, c0 = time.perf_counter(), time.process_time()
        result = call(*args)
        wall[-1] += time.perf_counter() - t0
        cpu[-1] += time.process_time() - c0
        return result

    seam.next = lambda *args: timed(solve, *args)
    device_frame.DeviceFrame.band = lambda device, *args: timed(band, device, *args)
    for planes_l, planes_r in zip(left, right):
        compositor.composite_yuv(*planes_l, *planes_r)
        wall.append(0.0)
        cpu.append(0.0)
    wall, cpu = wall[:-1], cpu[:-1]
    compositor.close()
    width, height = compositor.output_size
    print(f"{args.left.name}: canvas {width}x{height}, band {seam.band} px each side, cells of {seam.cell} px, "
          f"{len(seam.home)} lines (solved: every {seam.step}), {len(wall) - WARMUP} frames timed")
    for name, values in (("wall", wall), ("CPU", cpu)):
        ms = np.array(values[WARMUP:]) * 1e3
        print(f"  {name}: median {np.median(ms):.2f} ms, mean {ms.mean():.2f} ms, p95 {np.percentile(ms, 95):.2f} ms")
    for label, values in parts.items():
        print(f"  {label}: {np.mean(values) * 1e3:.2f} ms CPU a call, {len(values)} calls")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
