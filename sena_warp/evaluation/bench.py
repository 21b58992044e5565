"""Frame-rate benchmark of the video path: ``sena-warp bench``.

From one real pair it makes two-camera clips at 720p, 1080p and 4K: a slow pan of both views together
(a 16:9 crop window moving across each image, the same motion in both, resized to the clip size),
encoded with libx264 into a work folder. The pair is the shared data set's ``pairs/rew_lawn_2160``
(2160x1440) when it is there (``--data``), else the one the package ships (``data/bench``, 1000x750:
its clips above 1000 px wide are upscaled, softer, so their figures are not the shared pair's). Then,
per size and in one run, it measures

- a transcode-only baseline: decode both clips, place them side by side, encode with the stitcher's
  encoder settings (the same decode threads, pipeline and writer as ``sena-warp video``);
- ``sena-warp video`` end to end, in a child process (its report gives the fps and the time of each
  stage; the child's VmHWM its peak RSS);
- the per-frame compositing (``SenaFrameCompositor.composite_yuv``) against a reference built from
  OpenCV (``cv2.remap`` of both views with maps converted once by ``cv2.convertMaps``, then
  ``cv2.blendLinear``, then the black fill) on the same YUV planes and maps.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import textwrap
import time
from dataclasses import dataclass
from datetime import datetime
from fractions import Fraction
from pathlib import Path

import cv2
import numpy as np

from sena_warp.config import Config
from sena_warp.gains import tone_curve
from sena_warp.errors import InputError, error_for_exit_code
from sena_warp.imageio import read_image
from sena_warp.outputs import OutputPlan, atomic_output, make_folder
from sena_warp.progress import LOGGER, stage

SIZES = {"720p": (1280, 720), "1080p": (1920, 1080), "4k": (3840, 2160)}
MAX_SIDE_PX = 8192  # --sizes: each side at most this, and ...
MAX_PIXELS = 7680 * 4320  # ... at most 8K's pixels (the clips of both views are encoded at that size)
REPO = Path(__file__).resolve().parents[2]
DATA_DIR = REPO.parent / "shared" / "data"
PAIR = "rew_lawn_2160"
BUNDLED_PAIR = Path(__file__).resolve().parents[1] / "data" / "bench"  # shipped: spw_13 (ATTRIBUTION.md there)
ERROR_PREFIX = "sena-warp: error: "


@dataclass(frozen=True)
class BenchPair:
    """The pair the clips are made from: its name (in the clips' file names and the table's header)
    and its (a, b) image paths."""

    name: str
    paths: tuple[Path, Path]


@dataclass(frozen=True)
class BenchSettings:
    """How the clips are made and the kernels timed (benchmark settings, not stitching tunables)."""

    fps: int = 30  # frame rate of the made clips
    clip_crf: int = 18  # libx264 quality of the made clips (they are inputs: keep them clean)
    clip_preset: str = "ultrafast"  # libx264 preset of the made clips (fast to make)
    crop_fraction: float = 0.85  # crop window side / the largest 16:9 window of the image
    kernel_repeats: int = 15  # timed compositing calls per size (median reported)
    kernel_warmup: int = 2  # untimed calls first (plan build, caches)


def parse_size(text: str) -> tuple[str, tuple[int, int]]:
    """``"1080p"`` / ``"4k"`` / ``"WxH"`` -> (label, (width, height)); even sides (yuv420p)."""
    key = text.lower()
    if key in SIZES:
        return key, SIZES[key]
    try:
        width, height = (int(v) for v in key.split("x"))
    except ValueError:
        raise InputError(f"size {text!r} unknown; use {', '.join(SIZES)} or WIDTHxHEIGHT") from None
    if width < 16 or height < 16 or width % 2 or height % 2:
        raise InputError(f"size {text!r}: width and height must be even and at least 16")
    if max(width, height) > MAX_SIDE_PX or width * height > MAX_PIXELS:
        raise InputError(f"size {text!r}: at most {MAX_SIDE_PX} px a side and {MAX_PIXELS / 1e6:.1f} MP (8K)")
    return f"{width}x{height}", (width, height)


def bench_pair(data_dir: Path | None = None) -> BenchPair:
    """The pair in the shared data set at ``data_dir`` (InputError when it lacks it); without one, the
    shared set beside the source tree when it is there, else the pair the package ships."""
    paths = tuple((data_dir or DATA_DIR) / "pairs" / PAIR / name for name in ("a.jpg", "b.jpg"))
    missing = [str(p) for p in paths if not p.is_file()]
    if not missing:
        return BenchPair(PAIR, paths)
    if data_dir is None:
        return BenchPair("bundled_spw_13", (BUNDLED_PAIR / "a.jpg", BUNDLED_PAIR / "b.jpg"))
    raise InputError(f"benchmark pair not found ({', '.join(missing)}); give --data the shared data set's "
                     f"folder, or leave --data out to use the pair the package ships")


def pan_window(image_shape: tuple[int, int], aspect: float, crop_fraction: float,
               t: float) -> tuple[int, int, int, int]:
    """Crop window (x0, y0, width, height) in an image of ``image_shape`` (rows, cols) at pan time t in [0, 1].

    The window has the clip's ``aspect`` (width / height) and ``crop_fraction`` of the largest such
    window; it moves linearly from the top-left to the bottom-right free corner as t goes 0 -> 1.
    """
    rows, cols = image_shape
    full_w = min(cols, rows * aspect)
    width, height = int(full_w * crop_fraction), int(full_w * crop_fraction / aspect)
    return int(round(t * (cols - width))), int(round(t * (rows - height))), width, height


def make_clip_pair(pair: BenchPair, work: Path, size: tuple[int, int], seconds: float,
                   settings: BenchSettings = BenchSettings()) -> tuple[Path, Path]:
    """Encode the slow-pan clips of both views at ``size`` (W, H) for ``seconds``; reuse existing ones.

    Returns (left, right) paths in ``work``: left shows image a, right image b, same window each frame.
    """
    from sena_warp.video.writer import VideoWriter

    width, height = size
    frames = max(1, round(seconds * settings.fps))
    images = [read_image(path) for path in pair.paths]
    outputs = []
    for side, image in zip(("left", "right"), images):
        path = work / f"{pair.name}_{width}x{height}_{frames}f_{side}.mp4"
        outputs.append(path)
        if path.is_file():
            continue
        with atomic_output(path) as tmp, VideoWriter(tmp, width, height, Fraction(settings.fps), "libx264",
                                                     settings.clip_crf, settings.clip_preset) as writer:
            for index in range(frames):
                x0, y0, w, h = pan_window(image.shape[:2], width / height, settings.crop_fraction,
                                          index / max(frames - 1, 1))
                frame = cv2.resize(image[y0:y0 + h, x0:x0 + w], (width, height), interpolation=cv2.INTER_AREA)
                i420 = cv2.cvtColor(frame, cv2.COLOR_BGR2YUV_I420)
                u, v = i420[height:].reshape(2, height // 2, width // 2)
                writer.write(i420[:height], u, v, pts=index)
    return outputs[0], outputs[1]


class SideBySide:
    """Baseline frame compositor: left planes then right planes on one row (no stitching at all)."""

    def __init__(self, pairs):
        first_l, first_r = next(pairs)
        self.width_l = first_l.y.shape[1]
        self.output_size = (first_l.y.shape[1] + first_r.y.shape[1], max(first_l.y.shape[0], first_r.y.shape[0]))

    def composite_yuv(self, y_l, u_l, v_l, y_r, u_r, v_r):
        return tuple(np.hstack((left, right)) for left, right in ((y_l, y_r), (u_l, u_r), (v_l, v_r)))


def transcode_baseline(left: Path, right: Path, output: Path, cfg: Config) -> dict:
    """Decode both, place side by side, encode with the stitcher's settings; frames, seconds, fps."""
    from sena_warp.video.loop import VideoOptions, run_video

    report = run_video(left, right, output, SideBySide, VideoOptions.from_config(cfg, audio="none"))
    seconds = report["timing_s"]["total"]
    return {"frames": report["frames_out"], "seconds": seconds, "fps": report["frames_out"] / seconds,
            "size": (report["output"]["width"], report["output"]["height"])}


# The child runs the CLI, then prints its own peak RSS. VmHWM belongs to the child's address space;
# getrusage/wait4's ru_maxrss would not do: Linux carries the parent's peak across fork and exec.
_CHILD = """import sys
from sena_warp.cli import main
code = main(sys.argv[1:])
print(next(line for line in open("/proc/self/status") if line.startswith("VmHWM:")).strip())
sys.exit(code)"""


def stitch_in_child(left: Path, right: Path, output: Path, device: str) -> dict:
    """``sena-warp video`` in a child process; its report plus ``max_rss_mib`` (the child's peak RSS) and
    ``spawned`` (the time the child was started, as ``time.time()``)."""
    report_path = output.with_suffix(".json")
    cmd = [sys.executable, "-c", _CHILD, "video", str(left), str(right), "-o", str(output),
           "--report", str(report_path), "--audio", "none", "--device", device, "-y"]
    spawned = time.time()
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:  # the child's own error, with its exit code
        said = (proc.stderr or proc.stdout).strip().splitlines() or [f"exit {proc.returncode}"]
        raise error_for_exit_code(proc.returncode)(f"stitching {left.name}: {said[-1].removeprefix(ERROR_PREFIX)}")
    hwm_kib = int(proc.stdout.strip().splitlines()[-1].split()[1])  # "VmHWM:  123456 kB"
    report = json.loads(report_path.read_text())
    report["max_rss_mib"] = hwm_kib / 1024
    report["spawned"] = spawned
    return report


class OpenCVReference:
    """The compositing rule with OpenCV: remap both sides, each side's gains and offsets, alpha-blend,
    fill where nothing is sampled.

    ``plane``: a :class:`~sena_warp.video.stitch.PlanePass` (maps (Hc, Wc, 2) float32 (x, y), NaN =
    none; alpha; gains; per-pixel offsets; fill); ``shape_src`` / ``shape_tgt`` = (rows, cols) of the
    planes. Everything that depends only on the maps (fixed-point maps, blend weights with validity
    folded in, the uncovered pixels) is done once here, as the Warp path does once per map set.
    """

    def __init__(self, plane, shape_src, shape_tgt):
        from sena_warp.video.maps import sampled_mask

        valid_src, valid_tgt = sampled_mask(plane.map_src, shape_src), sampled_mask(plane.map_tgt, shape_tgt)
        a = np.where(valid_src, np.where(valid_tgt, np.clip(plane.alpha, 0.0, 1.0), 1.0), 0.0)
        self.weight_src = a.astype(np.float32)
        self.weight_tgt = np.where(valid_tgt, 1.0 - a, 0.0).astype(np.float32)
        self.maps_src = self._fixed_maps(plane.map_src)
        self.maps_tgt = self._fixed_maps(plane.map_tgt)
        self.uncovered = np.flatnonzero(~(valid_src | valid_tgt))
        self.fill = np.asarray(plane.fill, dtype=np.uint8)
        gain_src, bias_src, gain_tgt, bias_tgt = plane.gains
        self.knee = plane.knee
        self.affine_src = (gain_src.astype(np.float32), bias_src, plane.offsets_src.astype(np.float32))
        self.affine_tgt = (gain_tgt.astype(np.float32), bias_tgt, plane.offsets_tgt.astype(np.float32))

    @staticmethod
    def _fixed_maps(map_canvas: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        outside = np.where(np.isnan(map_canvas), -1.0, map_canvas).astype(np.float32)  # NaN: sample nothing
        return cv2.convertMaps(outside[:, :, 0], outside[:, :, 1], cv2.CV_16SC2)

    def _adjusted(self, sampled: np.ndarray, affine: tuple[np.ndarray, np.ndarray, np.ndarray]) -> np.ndarray:
        """``gain * sampled + bias`` per channel (with the knee, ``gains.tone_curve``) plus the offsets,
        float32, in the shape of the offsets (Hc, Wc, C)."""
        gain, bias, offset = affine
        values = sampled.reshape(offset.shape)
        if self.knee is None:
            scale = tuple(float(g) for g in gain) + (0.0,) * (4 - len(gain))  # an OpenCV scalar: one factor per channel
            return cv2.add(cv2.multiply(values.astype(np.float32), scale), offset + bias.astype(np.float32))
        return cv2.add(tone_curve(values, gain, bias, *self.knee), offset)

    def apply(self, img_src: np.ndarray, img_tgt: np.ndarray) -> np.ndarray:
        """uint8 (Hc, Wc[, C]) composite of two uint8 (H, W[, C]) images."""
        sampled_src = cv2.remap(img_src, *self.maps_src, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
        sampled_tgt = cv2.remap(img_tgt, *self.maps_tgt, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
        shape = sampled_src.shape
        adjusted_src = self._adjusted(sampled_src, self.affine_src)
        adjusted_tgt = self._adjusted(sampled_tgt, self.affine_tgt)
        out = cv2.blendLinear(adjusted_src, adjusted_tgt, self.weight_src, self.weight_tgt)
        out = np.clip(out + 0.5, 0, 255).astype(np.uint8).reshape(shape)
        out.reshape(len(self.weight_src.ravel()), -1)[self.uncovered] = self.fill
        return out


def chroma_shape(shape_y: tuple[int, int]) -> tuple[int, int]:
    """(rows, cols) of a 4:2:0 chroma plane for a Y plane of ``shape_y``."""
    return (shape_y[0] + 1) // 2, (shape_y[1] + 1) // 2


class OpenCVFrameReference:
    """``SenaFrameCompositor.composite_yuv`` rebuilt on :class:`OpenCVReference`: the same roles and the
    same maps (its public ``source_target`` and ``passes``), on the same planes."""

    def __init__(self, compositor, shape_y_src: tuple[int, int], shape_y_tgt: tuple[int, int]):
        luma, chroma = compositor.passes()
        self.source_target = compositor.source_target
        self.luma = OpenCVReference(luma, shape_y_src, shape_y_tgt)
        self.chroma = OpenCVReference(chroma, chroma_shape(shape_y_src), chroma_shape(shape_y_tgt))

    def composite_yuv(self, y_l, u_l, v_l, y_r, u_r, v_r):
        y_src, y_tgt = self.source_target(y_l, y_r)
        uv_src, uv_tgt = self.source_target(np.dstack((u_l, v_l)), np.dstack((u_r, v_r)))
        uv = self.chroma.apply(uv_src, uv_tgt)
        return self.luma.apply(y_src, y_tgt), uv[:, :, 0], uv[:, :, 1]


def time_calls(call, repeats: int, warmup: int) -> tuple[float, float]:
    """(median wall ms, mean process CPU ms) per call of ``call``.

    CPU time counts every thread of this process (Warp bands, OpenCV workers) and not other
    processes' load, so it is the steadier figure on a shared machine.
    """
    for _ in range(warmup):
        call()
    wall = []
    cpu0 = time.process_time()
    for _ in range(repeats):
        t0 = time.perf_counter()
        call()
        wall.append(time.perf_counter() - t0)
    return 1000.0 * float(np.median(wall)), 1000.0 * (time.process_time() - cpu0) / repeats


def compare_compositing(left: Path, right: Path, cfg: Config, settings: BenchSettings = BenchSettings()) -> dict:
    """Per-frame compositing time of the Warp path and of the OpenCV reference on the first frame pair.

    Maps come from the estimate ``sena-warp video`` makes, on the first frame pair only (the others
    it tries change the maps, not the per-frame work, and an estimate at 4K takes tens of seconds). Returns ``warp_ms``,
    ``opencv_ms`` (median wall), ``warp_cpu_ms``, ``opencv_cpu_ms`` (mean process CPU), ``ratio`` /
    ``cpu_ratio`` (Warp / OpenCV) and ``max_diff`` (grey levels, over Y, U, V).
    """
    from sena_warp.video.reader import FrameReader
    from sena_warp.video.stitch import SenaFrameCompositor

    compositor = SenaFrameCompositor.from_videos(left, right, 0.0, cfg.replace(video_estimate_pairs=1), "auto")
    with FrameReader(left) as reader_l, FrameReader(right) as reader_r:
        frame_l, frame_r = next(iter(reader_l)), next(iter(reader_r))
    planes = (frame_l.y, frame_l.u, frame_l.v, frame_r.y, frame_r.u, frame_r.v)
    shape_src, shape_tgt = (f.y.shape for f in compositor.source_target(frame_l, frame_r))
    warp_ms, warp_cpu_ms = time_calls(lambda: compositor.composite_yuv(*planes), settings.kernel_repeats,
                                      settings.kernel_warmup)
    # The reference composites with what the last frame was composited with: seam, gains, offsets.
    out = compositor.composite_yuv(*planes)
    reference = OpenCVFrameReference(compositor, shape_src, shape_tgt)
    opencv_ms, opencv_cpu_ms = time_calls(lambda: reference.composite_yuv(*planes), settings.kernel_repeats,
                                          settings.kernel_warmup)
    diff = max(int(np.abs(a.astype(np.int16) - b).max()) for a, b in zip(out, reference.composite_yuv(*planes)))
    return {"warp_ms": warp_ms, "opencv_ms": opencv_ms, "ratio": warp_ms / opencv_ms, "warp_cpu_ms": warp_cpu_ms,
            "opencv_cpu_ms": opencv_cpu_ms, "cpu_ratio": warp_cpu_ms / opencv_cpu_ms, "max_diff": diff}


def bench_size(label: str, size: tuple[int, int], seconds: float, work: Path, pair: BenchPair,
               cfg: Config, settings: BenchSettings = BenchSettings()) -> dict:
    """One table row: clips of ``size`` (W, H), baseline, end-to-end stitch, stages, compositing."""
    stage(f"{label}: making the clips")
    left, right = make_clip_pair(pair, work, size, seconds, settings)
    stage(f"{label}: the transcode baseline")
    baseline = transcode_baseline(left, right, work / f"baseline_{label}.mp4", cfg)
    stage(f"{label}: sena-warp video, in a process of its own")
    stitch = stitch_in_child(left, right, work / f"stitch_{label}.mp4", cfg.device)
    timing, frames = stitch["timing_s"], stitch["frames_out"]
    # Whole run, and the steady rate after the first estimate (once per video, whatever its length).
    run_fps = frames / timing["total"]
    stitch_fps = frames / (timing["total"] - timing["compositor_setup"])
    # From the child's start to its first frame composited: until its run started, then the run's own.
    first_frame_s = datetime.fromisoformat(stitch["started"]).timestamp() - stitch["spawned"] + timing["first_frame"]
    stage(f"{label}: compositing, Warp against OpenCV")
    compositing = compare_compositing(left, right, cfg, settings)
    decode_s = sum(stitch["inputs"][side]["decode_s"] for side in ("left", "right"))
    return {
        "size": label, "clip": f"{size[0]}x{size[1]}",
        "canvas": f"{stitch['output']['width']}x{stitch['output']['height']}",
        "frames": frames, "baseline_fps": baseline["fps"], "run_fps": run_fps, "run_ratio": run_fps / baseline["fps"],
        "stitch_fps": stitch_fps, "fps_ratio": stitch_fps / baseline["fps"], "setup_s": timing["compositor_setup"],
        "first_frame_s": first_frame_s,
        "decode_ms": 1000 * decode_s / frames, "composite_ms": 1000 * timing["composite"] / frames,
        "encode_ms": 1000 * timing["encode"] / frames, "warp_ms": compositing["warp_ms"],
        "opencv_ms": compositing["opencv_ms"], "kernel_ratio": compositing["ratio"],
        "warp_cpu_ms": compositing["warp_cpu_ms"], "opencv_cpu_ms": compositing["opencv_cpu_ms"],
        "kernel_cpu_ratio": compositing["cpu_ratio"],
        "max_diff": compositing["max_diff"], "rss_mib": stitch["max_rss_mib"],
    }


COLUMNS = (  # (key, header, format)
    ("size", "size", "{}"), ("canvas", "stitched canvas", "{}"), ("frames", "frames", "{}"),
    ("baseline_fps", "transcode fps", "{:.1f}"), ("run_fps", "stitch fps, whole run", "{:.1f}"),
    ("run_ratio", "whole run / transcode", "{:.2f}"), ("stitch_fps", "stitch fps after estimate", "{:.1f}"),
    ("fps_ratio", "after estimate / transcode", "{:.2f}"), ("setup_s", "estimate s", "{:.1f}"),
    ("first_frame_s", "process start to first frame s", "{:.2f}"),
    ("decode_ms", "decode ms/frame", "{:.1f}"), ("composite_ms", "composite ms/frame", "{:.1f}"),
    ("encode_ms", "encode ms/frame", "{:.1f}"), ("warp_ms", "Warp composite ms", "{:.1f}"),
    ("opencv_ms", "OpenCV ref ms", "{:.1f}"), ("kernel_ratio", "Warp / OpenCV", "{:.2f}"),
    ("warp_cpu_ms", "Warp CPU ms", "{:.1f}"), ("opencv_cpu_ms", "OpenCV CPU ms", "{:.1f}"),
    ("kernel_cpu_ratio", "Warp / OpenCV (CPU)", "{:.2f}"),
    ("max_diff", "max diff", "{}"), ("rss_mib", "peak RSS MiB", "{:.0f}"),
)


# The plain table: the headline figures in columns that fit an 80-column terminal, said in the legend below.
SHORT_COLUMNS = (  # (key, header, format)
    ("size", "size", "{}"), ("canvas", "canvas", "{}"), ("baseline_fps", "base", "{:.1f}"),
    ("run_fps", "run", "{:.1f}"), ("stitch_fps", "steady", "{:.1f}"), ("fps_ratio", "x base", "{:.2f}"),
    ("setup_s", "est s", "{:.1f}"), ("composite_ms", "comp ms", "{:.1f}"), ("kernel_ratio", "vs cv2", "{:.2f}"),
    ("rss_mib", "RSS MiB", "{:.0f}"),
)
LEGEND = ("frames per second: base = decode both, side by side, encode (no stitch); run = sena-warp video, the "
          "whole run; steady = after its one-time estimate (est s); x base = steady / base. comp ms: compositing "
          "per frame; vs cv2: Warp compositing / an OpenCV reference. Every column: --markdown FILE")
TERMINAL_COLUMNS = 80


def format_table(rows: list[dict], markdown: bool = False) -> str:
    """The rows as the wide Markdown table (every column) or as a plain text table that fits a terminal
    (:data:`SHORT_COLUMNS`, then :data:`LEGEND`)."""
    columns = COLUMNS if markdown else SHORT_COLUMNS
    cells = [[header for _, header, _ in columns]] + [[fmt.format(row[key]) for key, _, fmt in columns] for row in rows]
    if markdown:
        lines = ["| " + " | ".join(r) + " |" for r in cells]
        lines.insert(1, "|" + "|".join("---" if i < 2 else "---:" for i in range(len(columns))) + "|")
        return "\n".join(lines)
    widths = [max(len(r[i]) for r in cells) for i in range(len(columns))]
    table = ["  ".join(c.rjust(w) for c, w in zip(r, widths)) for r in cells]
    return "\n".join(table + [textwrap.fill(LEGEND, TERMINAL_COLUMNS)])


def run_bench(sizes: list[str], seconds: float, work: Path, cfg: Config, pair: BenchPair,
              settings: BenchSettings = BenchSettings()) -> list[dict]:
    """Benchmark every size (labels as :func:`parse_size` takes) on clips made from ``pair``; one row
    dict per size (keys: COLUMNS).

    ``cfg``: the stitcher's settings (its device is resolved here, once for every size).
    """
    from sena_warp.kernels.runtime import resolve_config

    parsed = [parse_size(size) for size in sizes]  # all of them before anything is read or made
    make_folder(work, "--work")
    cfg = resolve_config(cfg)
    return [bench_size(*size, seconds, work, pair, cfg, settings) for size in parsed]


def machine_line() -> str:
    """CPU count, load average and date: the conditions the figures were taken under."""
    load = ", ".join(f"{v:.2f}" for v in os.getloadavg())
    return f"{os.cpu_count()} CPUs, load average {load}, {time.strftime('%Y-%m-%d %H:%M %Z')}"


def cmd_bench(args: argparse.Namespace) -> int:
    """``sena-warp bench``: print the table (and write it as Markdown with --markdown)."""
    from sena_warp.jobs import checked

    sizes = args.sizes or list(SIZES)
    plan = OutputPlan((), args.overwrite)
    if args.markdown:
        plan.add(args.markdown, "--markdown")
    if not checked(plan):
        return 0
    for size in sizes:
        parse_size(size)  # a bad size is refused before the pair is looked for
    pair = bench_pair(Path(args.data) if args.data else None)
    LOGGER.info("clips made from the pair %s (%s)", pair.name, pair.paths[0].parent)
    rows = run_bench(sizes, args.seconds, Path(args.work), Config(device=args.device), pair)
    rss_rows = [measure_rss(seconds, Path(args.work), args.device, pair) for seconds in args.rss]
    text = format_table(rows)
    print(f"sena-warp bench: {rows[0]['frames']} frames a clip, made from the pair {pair.name}\n{machine_line()}\n"
          f"{text}")
    for rss in rss_rows:
        print(f"peak RSS, 1080p {rss['seconds']:g} s ({rss['frames']} frames): {rss['rss_mib']:.0f} MiB")
    if args.markdown:
        with plan, atomic_output(args.markdown, plan=plan) as tmp:
            lines = [f"Machine: {machine_line()}; clips from the pair {pair.name}", "",
                     format_table(rows, markdown=True), ""]
            lines += [f"- peak RSS of `sena-warp video`, 1080p {r['seconds']:g} s ({r['frames']} frames): "
                      f"{r['rss_mib']:.0f} MiB" for r in rss_rows]
            tmp.write_text("\n".join(lines) + "\n")
    return 0


def measure_rss(seconds: float, work: Path, device: str, pair: BenchPair) -> dict:
    """Peak RSS (MiB) of ``sena-warp video`` on 1080p clips of ``seconds`` made from ``pair`` (child process)."""
    left, right = make_clip_pair(pair, work, SIZES["1080p"], seconds)
    report = stitch_in_child(left, right, work / f"rss_{seconds:g}s.mp4", device)
    return {"seconds": seconds, "frames": report["frames_out"], "rss_mib": report["max_rss_mib"]}
