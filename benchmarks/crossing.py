"""The crossing measurement: which frames show the crossing object twice or cut.

Usage (from the repository root)::

    .venv/bin/python benchmarks/crossing.py [--sizes 48 24] [--set video_seam_band_ratio=0.08 ...] [--out out/crossing]

Per object size (and the settings given with ``--set``, applied to ``Config``): the crossing clip of
``tests/test_crossing.py`` (the bundled udisd_test_000001 pair, a graf_gt patch 12 px nearer than the
background, 60 frames), stitched as a static rig with the ground truth observed; prints one
Markdown row, and writes ``crossing_SIZE.png``: the output around the object's row in frames 18-33
with the seam in red.
"""

from __future__ import annotations

import argparse
import ast
import sys
from pathlib import Path

import cv2
import numpy as np

from sena_warp.config import Config
from sena_warp.evaluation.crossing import make_crossing_clip
from sena_warp.evaluation.video_figures import VideoFigures
from sena_warp.imageio import read_image
from sena_warp.kernels.runtime import resolve_config
from sena_warp.video.loop import VideoOptions
from sena_warp.video.reader import YuvFrame
from sena_warp.video.stitch import stitch_videos

REPO = Path(__file__).resolve().parents[1]
PAIR = REPO / "tests" / "data" / "udisd_test_000001"
TEXTURE = REPO / "tests" / "data" / "graf_gt" / "a.png"
SHOWN = range(18, 34)


def measure(size: int, changes: dict, out: Path) -> str:
    img_a, img_b = read_image(PAIR / "a.jpg"), read_image(PAIR / "b.jpg")
    clip = make_crossing_clip(img_b, img_a, read_image(TEXTURE), out / f"clip_{size}", size_px=size)
    cfg = resolve_config(Config(**changes))
    observer = VideoFigures(cfg, truth=clip.points, keep_frames=tuple(SHOWN))
    report = stitch_videos(clip.left, clip.right, out / f"clip_{size}" / "out.mp4", cfg,
                           VideoOptions.from_config(cfg), observer=observer)
    copies = observer.figures()["copies"]
    row = int(round(clip.centres_right[0, 1] + report["stitch"]["canvas"]["offset_tgt"][1]))
    tiles = []
    for index in SHOWN:
        planes, seam = observer.frames[index]
        img = YuvFrame(0, 0, *planes).to_bgr()
        for line, x in enumerate(np.rint(seam).astype(int)):
            img[line, min(max(x, 0), img.shape[1] - 1)] = (0, 0, 255)
        tile = img[max(row - 60, 0):row + 60, 100:420].copy()
        cv2.putText(tile, str(index), (4, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 255, 0), 1)
        tiles.append(tile)
    cv2.imwrite(str(out / f"crossing_{size}.png"), np.vstack([np.hstack(tiles[i:i + 4]) for i in range(0, 16, 4)]))
    bad = [c for c in copies["per_frame"] if c["duplicated"] or c["lost"]]
    worst = max((c["duplicated"] + c["lost"] for c in bad), default=0)
    settings = ", ".join(f"{k}={v}" for k, v in changes.items()) or "defaults"
    return (f"| {size} px | {settings} | {copies['frames_counted']} | {copies['frames_duplicated'] or '-'} "
            f"| {copies['frames_lost'] or '-'} | {worst} of 36 |")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[48])
    parser.add_argument("--set", nargs="*", default=[], metavar="NAME=VALUE", help="Config changes")
    parser.add_argument("--out", type=Path, default=REPO / "out" / "crossing")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    changes = {k: ast.literal_eval(v) for k, v in (item.split("=", 1) for item in args.set)}
    print("| object | settings | frames counted | frames duplicated | frames cut (lost points) | worst frame |")
    print("|---|---|---:|---|---|---|")
    for size in args.sizes:
        print(measure(size, changes, args.out), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
