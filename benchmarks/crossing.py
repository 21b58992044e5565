"""The crossing benchmark: a figure nearer than the background walks across a static rig's overlap.

Usage (from the repository root)::

    .venv/bin/python benchmarks/crossing.py [--parallax 0 10 25 40 60] [--widths 50 100 150]
        [--speeds 2 8] [--directions right left] [--left L.mp4 --right R.mp4] [--set NAME=VALUE ...]
        [--sheets] [--out out/crossing]

Per walk (every combination of the lists): the crossing clip of ``sena_warp.evaluation.crossing`` on
the recording ``--left`` / ``--right`` (default: ``office_static`` of ../shared/data, whose left
camera is ``cam2.mp4``), stitched at the defaults (``--rig auto``, which finds the rig static; and the
settings given with ``--set``) with :class:`CrossingFigures` observing. Prints one Markdown row per walk: frames counted,
frames where the figure is not whole (shown < 90 % of it or in more than one piece), frames where it
is doubled, the least shown share and the most pieces; then how many walks met the target. Writes
``crossing.json`` (every frame's figures) and with ``--sheets`` ``sheet_WALK.png``: every 4th
frame in which the figure touches the overlap, the output around it with the seam in red.
"""

from __future__ import annotations

import argparse
import ast
import itertools
import json
import sys
from pathlib import Path

import cv2
import numpy as np

from sena_warp.config import Config
from sena_warp.evaluation.crossing import CrossingFigures, Walk, make_crossing_clip
from sena_warp.kernels.runtime import resolve_config
from sena_warp.video.estimate import spaced_span
from sena_warp.video.loop import VideoOptions
from sena_warp.video.reader import YuvFrame
from sena_warp.video.stitch import stitch_videos

REPO = Path(__file__).resolve().parents[1]
OFFICE = REPO.parent / "shared" / "data" / "videos" / "office_static"
SHEET_EVERY = 4
SHEET_MARGIN_PX = 24


def sheet(observer: CrossingFigures, offset_tgt: np.ndarray, path: Path) -> None:
    """The kept frames around the figure (its target copy's box, widened), the seam in red, 4 a row."""
    clip = observer.clip
    height, width = clip.mask.shape
    tiles = []
    for index, (planes, seam, rows) in sorted(observer.frames.items()):
        img = YuvFrame(0, 0, *planes).to_bgr()
        for line, pos in enumerate(np.rint(seam).astype(int)):
            if rows:
                img[line, min(max(pos, 0), img.shape[1] - 1)] = (0, 0, 255)
            else:
                img[min(max(pos, 0), img.shape[0] - 1), line] = (0, 0, 255)
        x0, y0 = np.rint(clip.corner_right(index) + offset_tgt).astype(int)
        reach = int(abs(clip.walk.parallax_px)) + SHEET_MARGIN_PX
        top, left = max(y0 - SHEET_MARGIN_PX, 0), max(x0 - reach, 0)
        tile = np.zeros((height + 2 * SHEET_MARGIN_PX, width + 2 * reach, 3), np.uint8)
        part = img[top:top + tile.shape[0], left:left + tile.shape[1]]
        tile[:part.shape[0], :part.shape[1]] = part
        cv2.putText(tile, str(index), (4, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 255, 0), 1)
        tiles.append(tile)
    if tiles:
        rows_of = [np.hstack(tiles[i:i + 4] + [np.zeros_like(tiles[0])] * (4 - len(tiles[i:i + 4])))
                   for i in range(0, len(tiles), 4)]
        cv2.imwrite(str(path), np.vstack(rows_of))


def measure(walk: Walk, left: Path, right: Path, cfg: Config, out: Path, sheets: bool) -> dict:
    folder = out / walk.name
    clip = make_crossing_clip(left, right, folder, walk, spaced_span(cfg))
    keep = tuple(int(i) for i in np.flatnonzero(clip.in_overlap())[::SHEET_EVERY]) if sheets else ()
    probe = CrossingFigures(clip, keep_frames=keep)
    report = stitch_videos(clip.left, clip.right, folder / "out.mp4", cfg, VideoOptions.from_config(cfg),
                           observer=probe)
    if sheets:
        sheet(probe, np.asarray(report["stitch"]["canvas"]["offset_tgt"]), out / f"sheet_{walk.name}.png")
    return {**probe.figures(), "frame_seam": report["stitch"]["frame_seam"],
            "rig": [decision["mode"] for decision in report["stitch"]["rig"]["decisions"]]}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--parallax", type=float, nargs="+", default=[0, 10, 25, 40, 60])
    parser.add_argument("--widths", type=int, nargs="+", default=[50, 100, 150])
    parser.add_argument("--speeds", type=float, nargs="+", default=[2, 8])
    parser.add_argument("--directions", nargs="+", default=["right", "left"], choices=["right", "left"])
    parser.add_argument("--left", type=Path, default=OFFICE / "cam2.mp4")
    parser.add_argument("--right", type=Path, default=OFFICE / "cam1.mp4")
    parser.add_argument("--set", nargs="*", default=[], metavar="NAME=VALUE", help="Config changes")
    parser.add_argument("--sheets", action="store_true", help="contact sheets of the frames in the overlap")
    parser.add_argument("--out", type=Path, default=REPO / "out" / "crossing")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    changes = {k: ast.literal_eval(v) for k, v in (item.split("=", 1) for item in args.set)}
    cfg = resolve_config(Config(device="cpu", **changes))
    print("| parallax | width | direction | speed | frames | not whole | doubled | least shown % | most pieces |")
    print("|---:|---:|---|---:|---:|---|---|---:|---:|")
    results, met = [], 0
    for d, width, direction, speed in itertools.product(args.parallax, args.widths, args.directions, args.speeds):
        figures = measure(Walk(d, width, speed, direction), args.left, args.right, cfg, args.out, args.sheets)
        results.append(figures)
        bad, doubled = figures["frames_not_whole"], figures["frames_doubled"]
        met += not bad and not doubled
        rig = "" if figures["rig"] in ([], ["static"]) else f" (rig: {' -> '.join(figures['rig'])})"
        print(f"| {d:g} | {width} | {direction} | {speed:g} | {figures['frames_counted']} | {len(bad) or '-'} "
              f"| {len(doubled) or '-'} | {figures['shown_pct_min']} | {figures['pieces_max']}{rig} |", flush=True)
    print(f"\nwalks with the figure whole and never doubled in every frame: {met} of {len(results)}")
    (args.out / "crossing.json").write_text(json.dumps(results, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
