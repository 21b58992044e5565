"""How much the picture on one side of a stitched video moves from frame to frame (a jolt finder).

Usage (from the repository root)::

    .venv/bin/python benchmarks/output_motion.py OUTPUT.mp4 [--columns X0 X1]

Each pair of consecutive frames' columns X0..X1 (default: the left 700 px, a left source's side) is
phase-correlated at half size (OpenCV, a Hann window); prints the median, p99 and largest shift in
px and how many frames moved by more than 1 and 2 px. A fixed rig's picture moves by its noise
only; a map update blended in too fast shows as frames moving 2 px and more.
"""

from __future__ import annotations

import argparse

import cv2
import numpy as np

from sena_warp.video.drift import hann_window, view_shift
from sena_warp.video.reader import FrameReader


def frame_shifts(path: str, x0: int, x1: int) -> np.ndarray:
    """Per consecutive frame pair, the shift (px) of columns x0..x1 of the luma."""
    shifts, previous, window = [], None, None
    with FrameReader(path) as reader:
        for frame in reader:
            part = frame.y[:, x0:x1]
            half = cv2.resize(part, (part.shape[1] // 2, part.shape[0] // 2), interpolation=cv2.INTER_AREA)
            half = half.astype(np.float32)
            if previous is not None:
                window = hann_window(half) if window is None else window
                move, _ = view_shift(previous, half, 2.0, window)
                shifts.append(float(np.hypot(*move)))
            previous = half
    return np.array(shifts)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("video")
    parser.add_argument("--columns", type=int, nargs=2, default=(0, 700), metavar=("X0", "X1"))
    args = parser.parse_args()
    shifts = frame_shifts(args.video, *args.columns)
    print(f"{args.video}: columns {args.columns[0]}-{args.columns[1]}, {len(shifts)} frame pairs: shift median "
          f"{np.median(shifts):.2f} px, p99 {np.percentile(shifts, 99):.2f}, max {shifts.max():.2f}; "
          f"frames > 1 px: {(shifts > 1).sum()}, > 2 px: {(shifts > 2).sum()}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
