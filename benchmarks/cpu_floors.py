"""What the CPU targets (docs/benchmarks.md) cannot beat on this machine: the set-up's floor, the whole run's ceiling.

Usage (from the repository root)::

    .venv/bin/python benchmarks/cpu_floors.py [--left L --right R] [--work DIR] [--frames 60] [--repeats 3]

Without ``--left``/``--right`` it makes (or reuses) ``sena-warp bench``'s 1080p clip pair in ``--work``.
Every figure leaves out work the real run does, so each is a bound the real run cannot beat.

*Set-up floor* (target: <= 0.8 s from process start to the first frame composited), the least of
``--repeats`` tries of each part:
- a new process that only imports what a first frame needs (numpy, OpenCV, onnxruntime, PyAV, the
  reader and XFeat's matching; then Warp, the video loop and the cached kernels): from its spawn
  (this process's clock) to its last import;
- opening both readers and decoding their first frames;
- XFeat's matching of that pair at the screening side (``video_screen_max_side``), the cheapest the
  estimate can use, with onnxruntime's session made by the first call as in a real run;
- the rest of an estimate (steps 1-9 without the matching) on that pair made as small as the
  screening's side, with its matches: an estimate at a working resolution at the least
  resolution the tool works at anywhere (the full-resolution maps it would then build are left out);
- the first ``composite_yuv`` of a compositor already made (the estimate itself, the rest of the
  set-up, is left out).
The floor is their sum; "Warp overlapped" counts the Warp imports as if they cost nothing.

*Whole-run ceiling* (target: whole process >= 0.9x the transcode on 5 s, >= 1.0x on 60 s), in process
CPU per frame pair over ``--frames`` pairs: decoding both inputs, encoding the stitched canvas (frames
the compositor made), and the Y pass's sample-only floor (``frame_kernel_floor.py``: no seam, no
blend, no UV pass). On 2 cores a run takes at least its CPU time / 2 of wall, so the stitch's
fps cannot pass ``2 / (that CPU per frame)``, against the transcode's measured fps
(``sena-warp bench``'s baseline on the same clip, whole run). The same with today's per-frame path
(``composite_yuv``: exposure, the frame's seam, both passes) in place of the floor. The encoder for the
side-by-side frames is timed too, to show where the transcode's time goes.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from fractions import Fraction
from itertools import islice
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from frame_kernel_floor import clip_pair, clip_parser, y_floor_ms  # noqa: E402

from sena_warp.config import Config  # noqa: E402
from sena_warp.evaluation.bench import SideBySide, transcode_baseline  # noqa: E402
from sena_warp.features import Matches, match_images  # noqa: E402
from sena_warp.kernels.runtime import cpu_threads, prewarm, resolve_config  # noqa: E402
from sena_warp.stitch import estimate_maps  # noqa: E402
from sena_warp.video.estimate import screening_config  # noqa: E402
from sena_warp.video.reader import FrameReader  # noqa: E402
from sena_warp.video.stitch import SenaFrameCompositor  # noqa: E402
from sena_warp.video.working import shrunk_pair, small_matches, working_scale  # noqa: E402
from sena_warp.video.writer import VideoWriter  # noqa: E402

FIRST_FRAME_IMPORTS = "import numpy, cv2, onnxruntime, av; import sena_warp.features, sena_warp.video.reader"
WARP_IMPORTS = ("import sena_warp.video.loop, sena_warp.video.stitch; from sena_warp.kernels import runtime; "
                "runtime.prewarm('cpu')")


def imports_s(code: str) -> float:
    """Seconds from spawning ``python -c code`` to the end of ``code`` (the child's clock, then printed)."""
    spawned = time.time()
    out = subprocess.run([sys.executable, "-c", f"{code}\nimport time; print(time.time())"], capture_output=True,
                         text=True, check=True)
    return float(out.stdout.strip().splitlines()[-1]) - spawned


def first_pair_s(left: Path, right: Path, threads: int) -> tuple[float, tuple]:
    """Wall seconds to open both readers and decode their first frames; and those frames."""
    start = time.perf_counter()
    with FrameReader(left, threads=threads) as reader_l, FrameReader(right, threads=threads) as reader_r:
        pair = next(iter(reader_l)), next(iter(reader_r))
    return time.perf_counter() - start, pair


def small_estimate_s(bgr: tuple[np.ndarray, np.ndarray], matches: Matches, side: int, cfg: Config,
                     repeats: int) -> float:
    """Wall seconds (least of ``repeats``) of an estimate's steps 1-9 on ``bgr`` made as small as a long side
    of ``side`` (as ``video/working.py`` makes them), with ``matches`` (of the full-size pair) carried to it."""
    small, scales = shrunk_pair(bgr, working_scale(tuple(img.shape for img in bgr), side))
    scaled = small_matches(matches, *scales)
    return min(wall_s(lambda: estimate_maps(*small, cfg, matches=scaled)) for _ in range(repeats))


def wall_s(call) -> float:
    start = time.perf_counter()
    call()
    return time.perf_counter() - start


def cpu_per_frame_ms(call, frames: int) -> float:
    start = time.process_time()
    call()
    return (time.process_time() - start) / frames * 1e3


def encode(frames: list[tuple[np.ndarray, np.ndarray, np.ndarray]], path: Path, cfg: Config) -> None:
    """Encode planes as ``sena-warp video`` would (crf, preset, threads as ``cfg``)."""
    rows, cols = frames[0][0].shape
    with VideoWriter(path, cols, rows, Fraction(30), crf=cfg.video_crf, preset=cfg.video_preset,
                     threads=cfg.cpu_threads, thread_type=cfg.video_encoder_thread_type) as writer:
        for index, planes in enumerate(frames):
            writer.write(*planes, pts=index)


def decode(left: Path, right: Path, frames: int, threads: int) -> None:
    with FrameReader(left, threads=threads) as reader_l, FrameReader(right, threads=threads) as reader_r:
        for _ in zip(islice(reader_l, frames), islice(reader_r, frames)):
            pass


def main() -> int:
    parser = clip_parser(__doc__.split("\n")[0], "out/cpu_floors")
    parser.add_argument("--frames", type=int, default=60)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    cfg = resolve_config(Config(device="cpu"))
    args.left, args.right = clip_pair(args)

    imports = min(imports_s(FIRST_FRAME_IMPORTS) for _ in range(args.repeats))
    imports_warp = min(imports_s(f"{FIRST_FRAME_IMPORTS}; {WARP_IMPORTS}") for _ in range(args.repeats))
    decode_first, (first_l, first_r) = min((first_pair_s(args.left, args.right, cfg.cpu_threads)
                                            for _ in range(args.repeats)), key=lambda t: t[0])
    screen = screening_config(cfg, (first_l.y.shape, first_r.y.shape))
    bgr = first_l.to_bgr(), first_r.to_bgr()
    match_cold = wall_s(lambda: match_images(*bgr, screen))  # the first call makes onnxruntime's session
    match_warm = min(wall_s(lambda: match_images(*bgr, screen)) for _ in range(args.repeats))
    prewarm(cfg.device)
    small_estimate = small_estimate_s(bgr, match_images(*bgr, screen), screen.xfeat_max_side, cfg, args.repeats)
    with FrameReader(args.left) as reader_l, FrameReader(args.right) as reader_r:
        pairs = list(zip(islice(reader_l, args.frames), islice(reader_r, args.frames)))
    compositor = SenaFrameCompositor.from_videos(
        args.left, args.right, 0.0, cfg.replace(video_estimate_pairs=1, video_drift_check_s=0.0), "auto")
    def composited(pair: tuple) -> tuple[np.ndarray, ...]:
        return tuple(np.array(p) for p in compositor.composite_yuv(*(p for f in pair for p in (f.y, f.u, f.v))))

    start = time.perf_counter()
    stitched = [composited(pairs[0])]
    first_composite = time.perf_counter() - start
    start = time.process_time()
    stitched += [composited(pair) for pair in pairs[1:]]
    composite_ms = (time.process_time() - start) / max(1, len(pairs) - 1) * 1e3
    plan, luma, chroma = compositor.last_frame
    y_floor = y_floor_ms(compositor, compositor.device.gains(plan, luma.gains, chroma.gains)[0], cfg, args.repeats * 5)
    compositor.close()
    side_by_side = SideBySide(iter(pairs))
    sbs = [side_by_side.composite_yuv(a.y, a.u, a.v, b.y, b.u, b.v) for a, b in pairs]

    decode_ms = cpu_per_frame_ms(lambda: decode(args.left, args.right, len(pairs), cfg.cpu_threads), len(pairs))
    with tempfile.TemporaryDirectory(dir=args.work) as temp:
        encode_canvas_ms = cpu_per_frame_ms(lambda: encode(stitched, Path(temp) / "canvas.mp4", cfg), len(pairs))
        encode_sbs_ms = cpu_per_frame_ms(lambda: encode(sbs, Path(temp) / "sbs.mp4", cfg), len(pairs))
        baseline = transcode_baseline(args.left, args.right, Path(temp) / "baseline.mp4", cfg)
    cores = cpu_threads(0)
    stitch_cpu_ms = decode_ms + encode_canvas_ms + y_floor
    stitch_fps_max = cores * 1e3 / stitch_cpu_ms
    clip_frames = baseline["frames"]
    floor = imports_warp + decode_first + match_cold + small_estimate + first_composite
    floor_overlapped = imports + decode_first + match_cold + small_estimate + first_composite
    rows, cols = stitched[0][0].shape
    print(f"{args.left.name}: canvas {cols}x{rows}, {cores} cores")
    print("set-up floor, process start to the first frame (target: <= 0.8 s):")
    print(f"  imports for a first frame: {imports:.3f} s; "
          f"with Warp, the loop and the cached kernels: {imports_warp:.3f} s")
    print(f"  first pair opened and decoded: {decode_first:.3f} s")
    print(f"  matching at {screen.xfeat_max_side} px: {match_cold:.3f} s first call ({match_warm:.3f} s warm)")
    print(f"  the rest of an estimate at {screen.xfeat_max_side} px: {small_estimate:.3f} s")
    print(f"  first composite: {first_composite:.3f} s")
    print(f"  floor: {floor:.2f} s ({floor_overlapped:.2f} s with Warp's imports overlapped)")
    print(f"whole-run ceiling ({len(pairs)} frame pairs, process CPU a frame pair):")
    print(f"  decode both: {decode_ms:.1f} ms; encode the canvas: {encode_canvas_ms:.1f} ms; "
          f"Y pass floor: {y_floor:.1f} ms; together {stitch_cpu_ms:.1f} ms")
    print(f"  (the transcode's encode of {sbs[0][0].shape[1]}x{sbs[0][0].shape[0]}: {encode_sbs_ms:.1f} ms)")
    print(f"  stitch at most {stitch_fps_max:.1f} fps on {cores} cores; transcode {baseline['fps']:.1f} fps "
          f"({clip_frames} frames, whole run)")
    print(f"  long run: whole / transcode <= {stitch_fps_max / baseline['fps']:.2f} (target: >= 1.0)")
    short = baseline["seconds"] / (floor + clip_frames / stitch_fps_max)
    print(f"  this clip with the set-up floor: whole / transcode <= {short:.2f} (target: >= 0.9 on 5 s)")
    today_fps = cores * 1e3 / (decode_ms + encode_canvas_ms + composite_ms)
    print(f"  with today's composite_yuv ({composite_ms:.1f} ms, frames 1-{len(pairs) - 1}): stitch at most "
          f"{today_fps:.1f} fps, whole / transcode <= {today_fps / baseline['fps']:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
