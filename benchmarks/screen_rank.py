"""Which first pair a video's first estimate takes when its pairs are screened at a lower resolution
(the video set-up; ``video/estimate.py``'s ``video_screen_max_side``).

Usage (from the repository root)::

    .venv/bin/python benchmarks/screen_rank.py [--videos ../shared/data/videos] [--extra LEFT RIGHT ...]
        [--sides 1024 640 512]

For every recording (both input orders) and every screening side, prints the global-affine inlier
count of each first pair (``-`` where screening failed), the pair the estimate would take and the
mean seconds of one pair's screening. A side at or above the input's long side screens the pair as
the estimate sees it (1024 px: the working resolution, as before screening had a side of its own).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from sena_warp.config import Config
from sena_warp.errors import StitchError
from sena_warp.evaluation.sync_bench import RECORDINGS
from sena_warp.kernels.runtime import resolve_config
from sena_warp.video.estimate import first_pairs, screen_pair

REPO = Path(__file__).resolve().parents[1]


def ranking(left: Path, right: Path, side: int) -> tuple[list[int | None], int, float]:
    """(inliers per first pair or None, the index of the pair taken, mean seconds of a screening)."""
    cfg = resolve_config(Config(device="cpu", video_screen_max_side=side))
    inliers, indices, seconds = [], [], []
    for index, frame_l, frame_r in first_pairs(left, right, 0.0, cfg):
        indices.append(index)
        t0 = time.perf_counter()
        try:
            inliers.append(screen_pair(frame_l, frame_r, cfg, "auto")[1])
        except StitchError:
            inliers.append(None)
        seconds.append(time.perf_counter() - t0)
    taken = max(range(len(inliers)), key=lambda k: (-1 if inliers[k] is None else inliers[k], -k))
    return inliers, indices[taken], sum(seconds) / len(seconds)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--videos", type=Path, default=REPO.parent / "shared" / "data" / "videos")
    parser.add_argument("--extra", type=Path, nargs="*", default=[], metavar="VIDEO",
                        help="more pairs of videos, LEFT RIGHT ...")
    parser.add_argument("--sides", type=int, nargs="+", default=[1024, 640, 512])
    args = parser.parse_args(argv)
    pairs = [(name, args.videos / name / a, args.videos / name / b) for name, a, b in RECORDINGS
             if (args.videos / name).is_dir()]
    pairs += [(left.parent.name or left.stem, left, right) for left, right in zip(args.extra[::2], args.extra[1::2])]
    print("| recording | order | " + " | ".join(f"{side} px: inliers per pair, taken, s a pair" for side in args.sides) + " |")
    print("|---|---|" + "---|" * len(args.sides))
    for name, left, right in pairs:
        for order, (a, b) in (("left, right", (left, right)), ("right, left", (right, left))):
            cells = []
            for side in args.sides:
                inliers, taken, seconds = ranking(a, b, side)
                shown = ", ".join("-" if n is None else str(n) for n in inliers)
                cells.append(f"{shown}; pair {taken}; {seconds:.3f}")
            print(f"| {name} | {order} | " + " | ".join(cells) + " |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
