"""The Python steps of the GPU check, called by ``benchmarks/gpu_check.sh``.

Each step writes one JSON file into the output folder, so a step that fails or runs out of time
leaves the others' figures; ``summary`` gathers them.

    gpu_check.py facts OUT                 Warp's CUDA devices, and whether NVENC opens and NVDEC decodes
    gpu_check.py frame SIZE DEVICE SECONDS DATA OUT
                                           the device-resident frame (``frame``): whole, the device's part
                                           alone (with a CUDA graph where Warp captures it), its transfers,
                                           its largest difference from the CPU's planes
    gpu_check.py nvdec SIZE SECONDS DATA OUT
                                           decoding the clip pair with NVDEC against FFmpeg's software decoder
    gpu_check.py bench SIZE DEVICE SECONDS DATA OUT
                                           one row of ``sena-warp bench`` (end to end, the transcode
                                           baseline) and the encoder its stitch used
    gpu_check.py summary OUT               gpu_check.json and summary.txt from the steps' files
"""

from __future__ import annotations

import json
import statistics
import sys
import time
from fractions import Fraction
from pathlib import Path

NVENC = "h264_nvenc"
PROBE_SIZE = (1920, 1080)  # NVENC is opened at the size of the 1080p figures
FRAME_PAIRS = 40  # frame pairs of the clip composited by ``frame`` (decoded beforehand)
WARMUP = 5  # ... of them not timed: the plan's runs, the seam's background model, the first launches
REPEATS = 50  # the device's part alone, launched this many times (one graph launch each, when captured)


def nvdec_decodes(clip: Path) -> str:
    """"yes" when FFmpeg decodes the first frame of ``clip`` on the GPU, else why not.

    The software fallback is refused, so a frame only comes back when NVDEC decoded it.
    """
    import av
    from av.codec.hwaccel import HWAccel

    try:
        with av.open(str(clip), hwaccel=HWAccel("cuda", allow_software_fallback=False)) as container:
            stream = container.streams.video[0]
            next(container.decode(stream))
            return "yes" if stream.codec_context.is_hwaccel else "no: FFmpeg decoded it in software"
    except (av.error.FFmpegError, StopIteration, ValueError) as exc:
        return f"no: {getattr(exc, 'strerror', None) or exc}"


def facts(out: Path) -> None:
    import av
    import warp as wp

    from sena_warp.video.writer import choose_codec

    wp.init()
    count = wp.get_cuda_device_count()
    codec, note = choose_codec(NVENC, *PROBE_SIZE, Fraction(30))
    clip = Path(__file__).resolve().parents[1] / "tests" / "data" / "video" / "rooftop_left.mp4"
    found = {
        "warp_version": wp.__version__, "cuda_devices": count,
        "cuda_names": [wp.get_device(f"cuda:{i}").name for i in range(count)],
        "pyav_version": av.__version__, "libavcodec_version": ".".join(map(str, av.library_versions["libavcodec"])),
        "nvenc_opens": codec == NVENC, "nvenc_note": note,
        "nvdec_decodes": nvdec_decodes(clip),
    }
    (out / "facts.json").write_text(json.dumps(found, indent=1))
    print(json.dumps(found, indent=1))


def clip(size: str, seconds: float, data: Path, out: Path) -> tuple[str, Path, Path]:
    """(label, left, right) of ``sena-warp bench``'s clip pair at ``size`` (made in ``out``/work, or reused)."""
    from sena_warp.evaluation.bench import make_clip_pair, pair_paths, parse_size

    label, dims = parse_size(size)
    work = out / "work"
    work.mkdir(parents=True, exist_ok=True)
    return (label, *make_clip_pair(pair_paths(data), work, dims, seconds))


def device_part_ms(compositor, device: str) -> dict:
    """ms of the device's part of a frame alone (both passes' launches, the pair and seams already on the
    device), as launched and, on CUDA, as one captured graph (``wp.ScopedCapture``) replayed."""
    import warp as wp

    plan, luma, chroma = compositor.last_frame
    frame = compositor.device
    gains = frame.gains(plan, luma.gains, chroma.gains)

    def launches():
        frame.composite_pass("luma", plan.luma, gains[0])
        frame.composite_pass("chroma", plan.chroma, gains[1])

    def per_call_ms(call) -> float:
        call()
        wp.synchronize_device(device)
        start = time.perf_counter()
        for _ in range(REPEATS):
            call()
        wp.synchronize_device(device)
        return (time.perf_counter() - start) / REPEATS * 1e3

    found = {"launches_ms": per_call_ms(launches), "graph_ms": None, "graph_note": "not on CUDA"}
    if device != "cpu":
        try:
            with wp.ScopedCapture(device) as capture:
                launches()
            found["graph_ms"] = per_call_ms(lambda: wp.capture_launch(capture.graph))
            found["graph_note"] = "captured"
        except Exception as exc:  # Warp refuses some captures (e.g. without mempool support): say why
            found["graph_note"] = f"not captured: {exc}"
    return found


def cpu_difference(compositor, planes_src: tuple, planes_tgt: tuple, out: tuple) -> int:
    """The largest difference (grey levels, Y, U and V) between ``out``, the last frame as composited on
    the compositor's device, and the same plans and states composited on the CPU."""
    import numpy as np

    from sena_warp.composite import composite_image
    from sena_warp.config import Config
    from sena_warp.video.device_frame import frame_plan

    plan, luma, chroma = compositor.last_frame
    cpu = Config(device="cpu")
    on_cpu = frame_plan(plan.maps, plan.shapes, cpu)
    y = composite_image(planes_src[0], planes_tgt[0], on_cpu.luma, luma, cpu)
    uv = composite_image(*(np.dstack(planes[1:]) for planes in (planes_src, planes_tgt)), on_cpu.chroma, chroma, cpu)
    return max(int(np.abs(a.astype(np.int16) - b).max()) for a, b in zip(out, (y, uv[:, :, 0], uv[:, :, 1])))


def frame(size: str, device: str, seconds: float, data: Path, out: Path) -> None:
    """The device-resident frame at ``size`` on ``device``, on the bench's clip pair (static rig, one
    estimate pair, no drift checks: nothing else runs meanwhile): the whole per-frame path
    (``composite_yuv``: exposure, planes up, the band's difference down, the seam, both passes, the
    planes down) per frame, the device's part alone, the per-frame transfers, and the largest
    difference from the CPU's planes."""
    from itertools import islice

    from sena_warp.config import Config
    from sena_warp.kernels.runtime import resolve_config
    from sena_warp.video.reader import FrameReader
    from sena_warp.video.stitch import SenaFrameCompositor

    label, left, right = clip(size, seconds, data, out)
    cfg = resolve_config(Config(device=device, video_estimate_pairs=1, video_drift_check_s=0.0))
    with FrameReader(left) as reader_l, FrameReader(right) as reader_r:
        pairs = list(zip(islice(reader_l, FRAME_PAIRS), islice(reader_r, FRAME_PAIRS)))
    compositor = SenaFrameCompositor.from_videos(left, right, 0.0, cfg, "auto")
    wall = []
    for frame_l, frame_r in pairs:
        start = time.perf_counter()
        planes = compositor.composite_yuv(frame_l.y, frame_l.u, frame_l.v, frame_r.y, frame_r.u, frame_r.v)
        wall.append(time.perf_counter() - start)
    frame_ms = statistics.median(wall[WARMUP:]) * 1e3
    planes_src, planes_tgt = compositor.source_target((frame_l.y, frame_l.u, frame_l.v),
                                                      (frame_r.y, frame_r.u, frame_r.v))
    row = {"size": label, "device": cfg.device, "canvas": "x".join(map(str, compositor.output_size)),
           "frames": len(wall) - WARMUP, "frame_ms": frame_ms, "frame_fps": 1000.0 / frame_ms,
           **device_part_ms(compositor, cfg.device),
           "transfers": compositor.report()["transfers"],
           "max_diff_vs_cpu": cpu_difference(compositor, planes_src, planes_tgt, planes)}
    row["composite_fps"] = 1000.0 / (row["graph_ms"] or row["launches_ms"])
    compositor.close()
    (out / f"frame_{label}.json").write_text(json.dumps(row, indent=1))
    print(json.dumps(row, indent=1))


def nvdec(size: str, seconds: float, data: Path, out: Path) -> None:
    """Decoding the clip pair's frames to host planes with NVDEC (``HWAccel("cuda")``, no software
    fallback) and with FFmpeg's software decoder: frames per second each (one input, whole clip)."""
    import av
    from av.codec.hwaccel import HWAccel

    label, left, _ = clip(size, seconds, data, out)

    def fps(hwaccel) -> float:
        with av.open(str(left), hwaccel=hwaccel) as container:
            start, frames = time.perf_counter(), 0
            for decoded in container.decode(video=0):
                decoded.to_ndarray(format="yuv420p")
                frames += 1
        return frames / (time.perf_counter() - start)

    row = {"size": label, "software_fps": fps(None)}
    try:
        row["nvdec_fps"] = fps(HWAccel("cuda", allow_software_fallback=False))
    except (av.error.FFmpegError, ValueError, PermissionError) as exc:
        row["nvdec_fps"], row["nvdec_note"] = None, str(exc)
    (out / f"nvdec_{label}.json").write_text(json.dumps(row, indent=1))
    print(json.dumps(row, indent=1))


def bench(size: str, device: str, seconds: float, data: Path, out: Path) -> None:
    from sena_warp.config import Config
    from sena_warp.evaluation.bench import bench_pair, run_bench

    work = out / "work"
    row = run_bench([size], seconds, work, Config(device=device), bench_pair(data))[0]
    stitch = json.loads((work / f"stitch_{row['size']}.json").read_text())  # the end-to-end run's report
    row.update(device=device, composite_fps=1000.0 / row["warp_ms"], encoder=stitch["output"]["encoder"],
               notes=stitch["notes"])
    (out / f"bench_{row['size']}.json").write_text(json.dumps(row, indent=1))


FRAME_SUMMARY = (  # (key of a frame row, words, format)
    ("composite_fps", "device-resident composite (both passes' launches, graph where captured), fps", "{:.1f}"),
    ("launches_ms", "  both passes launched, ms per frame", "{:.3f}"),
    ("graph_ms", "  both passes as one CUDA graph, ms per frame", "{}"),
    ("graph_note", "  graph", "{}"),
    ("frame_fps", "whole frame (composite_yuv: gains, planes up, band down, seam, passes, planes down), fps",
     "{:.1f}"),
    ("transfers", "  transfers per frame (min, max) and in all", "{}"),
    ("max_diff_vs_cpu", "  largest difference from the CPU's planes, grey levels", "{}"),
)

SUMMARY = (  # (key of a bench row, words, format)
    ("composite_fps", "per-frame composite (composite_yuv, per-frame seam), fps", "{:.1f}"),
    ("warp_ms", "  the same, ms per frame (median)", "{:.2f}"),
    ("opencv_ms", "  OpenCV reference on the host, ms per frame", "{:.2f}"),
    ("max_diff", "  largest difference from the reference, grey levels", "{}"),
    ("run_fps", "sena-warp video end to end, fps (whole run)", "{:.1f}"),
    ("stitch_fps", "  after the first estimate, fps", "{:.1f}"),
    ("baseline_fps", "transcode-only baseline (host libx264), fps", "{:.1f}"),
)


def summary(out: Path) -> None:
    """gpu_check.json (everything) and summary.txt (the figures in words) from the steps' files."""
    found = {path.stem: json.loads(path.read_text()) for path in sorted(out.glob("*.json"))
             if path.name != "gpu_check.json"}
    (out / "gpu_check.json").write_text(json.dumps(found, indent=1))
    lines = []
    for name, row in found.items():
        if name.startswith("frame_"):
            lines.append(f"{row['size']} device-resident frame on {row['device']} (canvas {row['canvas']}, "
                         f"{row['frames']} frames timed)")
            lines += [f"  {words}: {fmt.format(row[key])}" for key, words, fmt in FRAME_SUMMARY]
        elif name.startswith("nvdec_"):
            lines.append(f"{row['size']} decoding one input: software {row['software_fps']:.1f} fps, NVDEC "
                         + (f"{row['nvdec_fps']:.1f} fps" if row["nvdec_fps"] else f"none ({row.get('nvdec_note')})"))
        if not name.startswith("bench_"):
            continue
        encoder = row["encoder"]
        lines.append(f"{row['size']} on {row['device']} ({row['clip']} clips, canvas {row['canvas']}, "
                     f"{row['frames']} frames; encoder {encoder['codec']}, asked {encoder['requested']})")
        lines += [f"  {words}: {fmt.format(row[key])}" for key, words, fmt in SUMMARY]
        lines += [f"  note: {note}" for note in row["notes"]]
    (out / "summary.txt").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    if len(sys.argv) < 2 or sys.argv[1] in ("-h", "--help"):
        print("usage:\n" + __doc__.split("\n\n")[2].rstrip())
        sys.exit(0 if len(sys.argv) > 1 else 2)
    step, args = sys.argv[1], sys.argv[2:]
    if step == "facts":
        facts(Path(args[0]))
    elif step == "frame":
        frame(args[0], args[1], float(args[2]), Path(args[3]), Path(args[4]))
    elif step == "nvdec":
        nvdec(args[0], float(args[1]), Path(args[2]), Path(args[3]))
    elif step == "bench":
        bench(args[0], args[1], float(args[2]), Path(args[3]), Path(args[4]))
    elif step == "summary":
        summary(Path(args[0]))
    else:
        sys.exit(f"gpu_check.py: unknown step {step!r} (facts, frame, nvdec, bench, summary)")
