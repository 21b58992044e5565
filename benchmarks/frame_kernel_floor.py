"""How far the per-frame Y pass is from a kernel that only samples (the per-frame CPU target, docs/benchmarks.md).

Usage (from the repository root)::

    .venv/bin/python benchmarks/frame_kernel_floor.py [--left L --right R] [--work DIR] [--calls 20]

Without ``--left``/``--right`` it makes (or reuses) ``sena-warp bench``'s 1080p clip pair in ``--work``.
The compositor is made as ``sena-warp video`` makes it (one estimate pair, no drift checks). First the
whole per-frame path but the maps' update (``composite_yuv``: exposure, the frame's seam, both passes)
over the first ``--frames`` pairs, in order: process CPU time per frame after the first ten. Then, on
the last pair's plan and planes, the process CPU time per call (mean of ``--calls``, after one
untimed call) of:

- the Y pass's frame kernel as the loop launches it (``DeviceFrame.composite_pass``: seam, gains with
  the knee, seam and border blends);
- :func:`sample_only_kernel`: the same launch, plan words and copy runs, but each pixel outside the
  runs is only its one side's bilinear tap, gained, stored: no seam, no blend, no offsets. No frame
  kernel on this plan can cost less than this floor;
- the UV pass's frame kernel (two channels at half resolution);
- both passes once more with and without their runs, call by call in turn (every pixel by the
  full rule when without): the median process CPU time of each, so that what the runs buy is
  measured under the same load (this machine's speed drifts between runs);
- both passes by the per-pixel kernel (CUDA's, here on the CPU: one thread per pixel, no runs).
"""

from __future__ import annotations

import argparse
import statistics
import time
from dataclasses import replace
from itertools import islice
from pathlib import Path

import warp as wp

from sena_warp.composite import frame_runs, kernel_plan
from sena_warp.config import Config
from sena_warp.evaluation.bench import DATA_DIR, bench_pair, make_clip_pair
from sena_warp.kernels import runtime
from sena_warp.kernels.composite import (KIND_FILL, KIND_TARGET, Gains, Plan, Planes, adjusted, grey_level,
                                         sample_fixed, word_fx, word_fy, word_offset)
from sena_warp.kernels.runtime import resolve_config
from sena_warp.video.reader import FrameReader
from sena_warp.video.stitch import SenaFrameCompositor


wp.set_module_options({"enable_backward": False})  # forward only, as the package's kernels

WARMUP_FRAMES = 10  # not timed: the seam's background model and the exposure settle


@wp.kernel
def sample_only_kernel(row0: int, col_step: int, width: int, planes: Planes, plan: Plan, gains: Gains,
                       out: wp.array(dtype=wp.uint8)):
    """One channel: per pixel of row ``row0 + i``, columns j, j + col_step, ..., its plan word's side
    alone, or in the row's copy run its target element through ``gains.table``."""
    i, j = wp.tid()
    y = row0 + i
    run = plan.runs[y]
    for x in range(j, width, col_step):
        q = y * width + x
        if x >= run[0] and x < run[1]:
            out[q] = gains.table[int(planes.tgt[run[2] + x])]
            continue
        word = plan.words[q]
        kind = int(word & wp.int64(3))
        if kind == KIND_FILL:
            out[q] = wp.uint8(0)
            continue
        p = word_offset(word)
        if kind == KIND_TARGET:
            sample = sample_fixed(planes.tgt, p, word_fx(word), word_fy(word), planes.steps[2], planes.steps[3])
        else:
            sample = sample_fixed(planes.src, p, word_fx(word), word_fy(word), planes.steps[0], planes.steps[1])
        out[q] = grey_level(adjusted(sample, gains.gain_src[0], gains.bias_src[0], 0, gains.tone,
                                     wp.vec2i(sample, sample)))


def cpu_ms(call, calls: int) -> float:
    """Mean process CPU ms of ``call`` over ``calls`` calls, after one untimed call."""
    call()
    start = time.process_time()
    for _ in range(calls):
        call()
    return (time.process_time() - start) / calls * 1e3


def y_floor_ms(compositor: SenaFrameCompositor, gains: Gains, cfg: Config, calls: int) -> float:
    """Process CPU ms a call of :func:`sample_only_kernel` over ``compositor``'s last Y plan and planes
    (still loaded), with its runs for the last frame's seam."""
    plan, luma, _ = compositor.last_frame
    arrays = compositor.device.frame_arrays("luma", plan.luma)
    rows, cols = plan.luma.canvas_shape
    out = wp.zeros(rows * cols, dtype=wp.uint8, device="cpu")
    seam = wp.array(luma.seam, dtype=float, device="cpu")
    runs = frame_runs(plan.luma, seam, arrays.runs, arrays.no_runs)
    inputs = [arrays.planes, kernel_plan(plan.luma, runs), gains, out]
    return cpu_ms(lambda: runtime.launch_row_loops(sample_only_kernel, rows, cols, inputs, "cpu", cfg.cpu_threads),
                  calls)


def with_and_without_runs_ms(compositor: SenaFrameCompositor, name: str, gains: Gains, calls: int
                             ) -> tuple[float, float]:
    """Median process CPU ms of a pass of ``compositor``'s last plan on its loaded pair with its runs and
    with none (every pixel by the full rule), ``calls`` each, in turn."""
    plan = getattr(compositor.last_frame[0], name)
    device = compositor.device
    with_runs, without = [], []
    for _ in range(calls + 1):
        for pass_plan, times in ((plan, with_runs), (replace(plan, runs=None), without)):
            start = time.process_time()
            device.composite_pass(name, pass_plan, gains)
            times.append(time.process_time() - start)
    return statistics.median(with_runs[1:]) * 1e3, statistics.median(without[1:]) * 1e3


def clip_parser(description: str, work: str) -> argparse.ArgumentParser:
    """A script's arguments for its clip pair: ``--left``/``--right``, or ``--work`` (default ``work``)."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--left", type=Path)
    parser.add_argument("--right", type=Path)
    parser.add_argument("--work", type=Path, default=Path(work))
    return parser


def clip_pair(args: argparse.Namespace) -> tuple[Path, Path]:
    """``--left``/``--right``, or the bench's 1080p clip pair made (or reused) in ``--work``."""
    args.work.mkdir(parents=True, exist_ok=True)
    if args.left is not None:
        return args.left, args.right
    return make_clip_pair(bench_pair(DATA_DIR), args.work, (1920, 1080), 5.0)


def main() -> int:
    parser = clip_parser(__doc__.split("\n")[0], "out/frame_kernel_floor")
    parser.add_argument("--calls", type=int, default=20)
    parser.add_argument("--frames", type=int, default=40)
    args = parser.parse_args()
    cfg = resolve_config(Config(device="cpu"))
    args.left, args.right = clip_pair(args)
    with FrameReader(args.left) as reader_l, FrameReader(args.right) as reader_r:
        pairs = list(zip(islice(reader_l, args.frames), islice(reader_r, args.frames)))
    compositor = SenaFrameCompositor.from_videos(
        args.left, args.right, 0.0, cfg.replace(video_estimate_pairs=1, video_drift_check_s=0.0), "auto")
    start = 0.0
    for index, (frame_l, frame_r) in enumerate(pairs):
        start = time.process_time() if index == WARMUP_FRAMES else start
        compositor.composite_yuv(frame_l.y, frame_l.u, frame_l.v, frame_r.y, frame_r.u, frame_r.v)
    per_frame = (time.process_time() - start) / max(1, len(pairs) - WARMUP_FRAMES) * 1e3
    plan = compositor.last_frame[0]
    device = compositor.device
    _, luma_state, chroma_state = compositor.last_frame
    luma_gains, chroma_gains = device.gains(plan, luma_state.gains, chroma_state.gains)
    floor = y_floor_ms(compositor, luma_gains, cfg, args.calls)
    y_pass = cpu_ms(lambda: device.composite_pass("luma", plan.luma, luma_gains), args.calls)
    uv_pass = cpu_ms(lambda: device.composite_pass("chroma", plan.chroma, chroma_gains), args.calls)
    chroma_runs = with_and_without_runs_ms(compositor, "chroma", chroma_gains, args.calls)
    luma_runs = with_and_without_runs_ms(compositor, "luma", luma_gains, args.calls)
    y_pixels = cpu_ms(lambda: device.composite_pass("luma", plan.luma, luma_gains, per_pixel=True), args.calls)
    uv_pixels = cpu_ms(lambda: device.composite_pass("chroma", plan.chroma, chroma_gains, per_pixel=True), args.calls)
    compositor.close()
    rows, cols = plan.luma.canvas_shape
    print(f"{args.left.name}: canvas {cols}x{rows}, {runtime.cpu_threads(cfg.cpu_threads)} row bands")
    print(f"  composite_yuv (exposure, the frame's seam, both passes): {per_frame:.2f} ms CPU a frame, "
          f"{len(pairs) - WARMUP_FRAMES} frames")
    print(f"  Y pass, frame kernel: {y_pass:.2f} ms CPU a call")
    print(f"  Y pass, sample only (the floor): {floor:.2f} ms CPU a call")
    print(f"  UV pass, frame kernel: {uv_pass:.2f} ms CPU a call")
    print(f"  in turn, median: Y pass {luma_runs[0]:.2f} ms with its runs, {luma_runs[1]:.2f} without; "
          f"UV pass {chroma_runs[0]:.2f} with, {chroma_runs[1]:.2f} without")
    print(f"  per-pixel kernel (CUDA's) on the CPU: Y pass {y_pixels:.2f} ms, UV pass {uv_pixels:.2f} ms a call")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
