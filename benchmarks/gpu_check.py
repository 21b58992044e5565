"""The Python steps of the GPU check (issue 17), called by ``benchmarks/gpu_check.sh``.

Each step writes one JSON file into the output folder, so a step that fails or runs out of time
leaves the others' figures; ``summary`` gathers them. Timing is ``sena-warp bench``'s own
(:func:`~sena_warp.evaluation.bench.run_bench`): nothing is timed here.

    gpu_check.py facts OUT                 Warp's CUDA devices, and whether NVENC opens and NVDEC decodes
    gpu_check.py bench SIZE DEVICE SECONDS DATA OUT
                                           one row of ``sena-warp bench`` and the encoder its stitch used
    gpu_check.py summary OUT               gpu_check.json and summary.txt from the steps' files
"""

from __future__ import annotations

import json
import sys
from fractions import Fraction
from pathlib import Path

NVENC = "h264_nvenc"
PROBE_SIZE = (1920, 1080)  # NVENC is opened at the size of the 1080p figures


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


def bench(size: str, device: str, seconds: float, data: Path, out: Path) -> None:
    from sena_warp.config import Config
    from sena_warp.evaluation.bench import bench_pair, run_bench

    work = out / "work"
    row = run_bench([size], seconds, work, Config(device=device), bench_pair(data))[0]
    stitch = json.loads((work / f"stitch_{row['size']}.json").read_text())  # the end-to-end run's report
    row.update(device=device, composite_fps=1000.0 / row["warp_ms"], encoder=stitch["output"]["encoder"],
               notes=stitch["notes"])
    (out / f"bench_{row['size']}.json").write_text(json.dumps(row, indent=1))


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
    elif step == "bench":
        bench(args[0], args[1], float(args[2]), Path(args[3]), Path(args[4]))
    elif step == "summary":
        summary(Path(args[0]))
    else:
        sys.exit(f"gpu_check.py: unknown step {step!r} (facts, bench, summary)")
