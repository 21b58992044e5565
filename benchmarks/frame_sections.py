"""Where a clip's per-frame path spends its CPU time, part by part: maps' updates, plans, runs, the seam.

Usage (from the repository root)::

    .venv/bin/python benchmarks/frame_sections.py [--left L --right R] [--work DIR] [--frames 300]
        [--set FIELD=VALUE ...]

Without ``--left``/``--right`` it makes (or reuses) ``sena-warp bench``'s 5 s 1080p clip pair in
``--work``. The bench's 60 s clip, whose slow pan a static rig's drift watch follows, is the one that
blends maps in: pass its two files (``*_1800f_left.mp4`` and ``*_right.mp4`` in the ``--work`` of
``sena-warp bench --seconds 60``) as ``--left`` and ``--right``. The compositor is made as ``sena-warp video``
makes it; each of the first ``--frames`` pairs is updated and composited as the frame loop does, with
the parts below wrapped in process CPU timers (a part called inside another counts in both). Prints
ms CPU a frame over all the frames, the calls, and ms a call.
"""

from __future__ import annotations

import collections
import time

from output_digest import clip_compositor, composited, compositor_parser, run
from sena_warp import composite
from sena_warp.video import device_frame, stitch, timeline
from sena_warp.video.device_frame import DeviceFrame
from sena_warp.video.drift import DriftWatch
from sena_warp.video.exposure import ExposureTracker
from sena_warp.video.frame_seam import FrameSeam
from sena_warp.video.maps import MapsBlend

PARTS = (
    (stitch.SenaFrameCompositor, "update", "update (all of it)"),
    (stitch.SenaFrameCompositor, "composite_yuv", "composite_yuv (all of it)"),
    (MapsBlend, "__init__", "MapsBlend (a blend begins)"),
    (MapsBlend, "at", "MapsBlend.at (a blend step)"),
    (timeline, "drifted_maps", "drifted_maps (a drift move)"),
    (stitch, "map_change_px", "map_change_px (the jitter figure)"),
    (DriftWatch, "shifts", "DriftWatch.shifts"),
    (ExposureTracker, "update", "ExposureTracker.update"),
    (FrameSeam, "next", "FrameSeam.next"),
    (device_frame, "frame_plan", "frame_plan (a map set's plans)"),
    (device_frame, "with_runs", "with_runs (a plan's runs)"),
    (composite, "frame_runs", "frame_runs (each frame's runs)"),
    (DeviceFrame, "load", "DeviceFrame.load (the planes up)"),
    (DeviceFrame, "band", "DeviceFrame.band (the band's difference)"),
    (DeviceFrame, "composite", "DeviceFrame.composite (both passes)"),
)


def timed(owner, name: str, label: str, seconds: dict, calls: collections.Counter) -> None:
    """Wrap ``owner.name`` so that its process CPU time and calls add up under ``label``."""
    original = getattr(owner, name)

    def wrapper(*args, **kwargs):
        start = time.process_time()
        try:
            return original(*args, **kwargs)
        finally:
            seconds[label] += time.process_time() - start
            calls[label] += 1

    setattr(owner, name, wrapper)


def main() -> int:
    args = compositor_parser(__doc__.split("\n")[0], "out/frame_sections", 300).parse_args()
    left, right, compositor = clip_compositor(args)
    seconds: dict[str, float] = collections.defaultdict(float)
    calls: collections.Counter = collections.Counter()
    for owner, name, label in PARTS:
        timed(owner, name, label, seconds, calls)
    start = time.process_time()
    frames = sum(1 for _ in composited(compositor, left, right, args.frames))
    total = time.process_time() - start
    compositor.close()
    print(f"{left.name}: {frames} frames, {total / frames * 1e3:.1f} ms CPU a frame in all (decoding included)")
    for label, spent in sorted(seconds.items(), key=lambda item: -item[1]):
        print(f"  {label:36s} {spent / frames * 1e3:7.2f} ms a frame, {calls[label]:5d} calls, "
              f"{spent / calls[label] * 1e3:7.2f} ms a call")
    return 0


if __name__ == "__main__":
    run(main, __file__)
