"""A recorded two-camera pair scaled to another size, to measure the per-frame video path there on a
real scene (the per-frame seam's 1080p budget: the shared recordings are at most 720p).

Usage (from the repository root)::

    .venv/bin/python benchmarks/upscale_pair.py LEFT RIGHT OUT_DIR [--size 1920x1080] [--crf 16]

Each input is decoded with the video loop's reader, its planes resized (bicubic) and encoded with the
loop's writer (libx264, crf ``--crf``, the input's frame rate, no audio) into ``OUT_DIR`` under its own
file name, so a pair keeps its names (``cam1.mp4``, ``cam2.mp4``). Existing outputs are replaced.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import cv2

from sena_warp.outputs import atomic_output
from sena_warp.video.reader import FrameReader, probe_video
from sena_warp.video.writer import VideoWriter


def upscale(source: Path, target: Path, width: int, height: int, crf: int) -> int:
    """Write ``source`` resized to ``width`` x ``height`` into ``target``; the number of frames."""
    rate = probe_video(source).fps
    with FrameReader(source) as reader, atomic_output(target) as tmp, \
            VideoWriter(tmp, width, height, rate, "libx264", crf, "veryfast") as writer:
        for index, frame in enumerate(reader):
            planes = [cv2.resize(plane, size, interpolation=cv2.INTER_CUBIC)
                      for plane, size in zip((frame.y, frame.u, frame.v),
                                             ((width, height), (width // 2, height // 2), (width // 2, height // 2)))]
            writer.write(*planes, pts=index)
        return writer.frames


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("left", type=Path)
    parser.add_argument("right", type=Path)
    parser.add_argument("out", type=Path)
    parser.add_argument("--size", default="1920x1080", help="WIDTHxHEIGHT (even)")
    parser.add_argument("--crf", type=int, default=16)
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.lower().split("x"))
    args.out.mkdir(parents=True, exist_ok=True)
    for source in (args.left, args.right):
        frames = upscale(source, args.out / source.name, width, height, args.crf)
        print(f"{args.out / source.name}: {frames} frames of {width}x{height}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
