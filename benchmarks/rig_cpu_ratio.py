"""CPU of a moving rig against a static one at the same size (issue target: moving <= 1.5x static).

Usage (from the repository root)::

    .venv/bin/python benchmarks/rig_cpu_ratio.py [--rounds 3] [--videos ../shared/data/videos]
        [--pans out/pans] [--clips rooftop_handheld house_handheld_stereo ...]

Each clip (a shared recording, or one of ``video_figures.py``'s pans, made into ``--pans`` the first
time) is stitched by ``stitch_videos`` in ``default`` mode (``--rig auto``: moving on these clips) and
in ``static`` mode (the same canvas, no alignment and no window, the per-frame seam's object band kept;
``video_figures.config_for``), the two in turn, ``--rounds`` times, with only
:class:`~sena_warp.evaluation.video_figures.FrameClock` attached. Prints each run's process CPU ms a
frame (from 1 s on) and per clip the medians and their ratio, as a Markdown table.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
from pathlib import Path

from video_figures import PANS, RECORDINGS, REPO, config_for, pan_videos

from sena_warp.evaluation.video_figures import FrameClock
from sena_warp.kernels.runtime import resolve_config
from sena_warp.video.stitch import VideoOptions, stitch_videos

MOVING_CLIPS = ("rooftop_handheld", "house_handheld_stereo", "window_phones_drift", "pan_rew_theater",
                "pan_rew_lawn_2160")


def cpu_ms_a_frame(left: Path, right: Path, mode: str) -> float:
    """Mean process CPU ms a frame of one stitch of ``left`` and ``right`` in ``mode``."""
    cfg = resolve_config(config_for(mode, {}))
    clock = FrameClock()
    with tempfile.TemporaryDirectory() as temp:
        stitch_videos(left, right, Path(temp) / "out.mp4", cfg, VideoOptions.from_config(cfg), observer=clock)
    return float(clock.figures()["mean_ms"])


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--videos", type=Path, default=REPO.parent / "shared" / "data" / "videos")
    parser.add_argument("--pans", type=Path, default=Path("out/pans"))
    parser.add_argument("--clips", nargs="*", default=list(MOVING_CLIPS), choices=sorted(RECORDINGS))
    args = parser.parse_args()
    rows = []
    for clip in args.clips:
        folder = pan_videos(clip, args.pans) if clip in PANS else args.videos / clip
        if not folder.is_dir():
            print(f"rig_cpu_ratio: error: {folder} not found", file=sys.stderr)
            return 2
        left_name, right_name, _ = RECORDINGS[clip]
        runs: dict[str, list[float]] = {"static": [], "default": []}
        for round_ in range(args.rounds):
            for mode, times in runs.items():
                times.append(cpu_ms_a_frame(folder / left_name, folder / right_name, mode))
                print(f"{clip} round {round_ + 1} {mode}: {times[-1]:.1f} ms CPU a frame", flush=True)
        static, moving = (statistics.median(runs[m]) for m in ("static", "default"))
        rows.append(f"| {clip} | {static:.1f} ({min(runs['static']):.1f}-{max(runs['static']):.1f}) | "
                    f"{moving:.1f} ({min(runs['default']):.1f}-{max(runs['default']):.1f}) | {moving / static:.2f} |")
    print("\n| clip | static | moving | ratio |\n|---|---:|---:|---:|")
    print("\n".join(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
