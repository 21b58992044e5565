"""How far each camera's view of the shared recordings moves over the recording (a static rig's drift).

Usage (from the repository root)::

    .venv/bin/python benchmarks/view_drift.py [--videos ../shared/data/videos] [--every 10]

Every ``--every``-th frame of each view is compared with its first frame by the drift watch's own
comparison (``video/drift.py``: a thumbnail, phase correlation with a Hann window), whole views. Prints
per recording and camera the largest shift (input px), the smallest peak response (below
``drift.MIN_RESPONSE`` the watch does not trust a shift: a hand-held view that went elsewhere) and
the mean time of one comparison.
"""

from __future__ import annotations

import argparse
import time
from itertools import islice
from pathlib import Path

import numpy as np

from sena_warp.evaluation.sync_bench import RECORDINGS
from sena_warp.video.drift import hann_window, thumbnail, view_shift
from sena_warp.video.reader import FrameReader

REPO = Path(__file__).resolve().parents[1]


def view_moves(path: Path, every: int) -> tuple[float, float, float]:
    """(largest shift px, smallest response, mean seconds a comparison) of a video's every ``every``-th
    frame against its first."""
    moves, responses, seconds = [], [], []
    with FrameReader(path) as reader:
        frames = islice(reader, 0, None, every)
        reference, scale = thumbnail(next(frames).y)
        window = hann_window(reference)
        for frame in frames:
            start = time.perf_counter()
            move, response = view_shift(reference, thumbnail(frame.y)[0], scale, window)
            seconds.append(time.perf_counter() - start)
            moves.append(float(np.hypot(*move)))
            responses.append(response)
    return max(moves), min(responses), float(np.mean(seconds))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--videos", type=Path, default=REPO.parent / "shared" / "data" / "videos")
    parser.add_argument("--every", type=int, default=10)
    args = parser.parse_args()
    print("| recording | camera | max shift px | min response | ms a comparison |\n|---|---|---:|---:|---:|")
    for recording, *cameras in RECORDINGS:
        for camera in cameras:
            shift, response, seconds = view_moves(args.videos / recording / camera, args.every)
            print(f"| {recording} | {camera} | {shift:.1f} | {response:.2f} | {seconds * 1e3:.2f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
