"""What ``--rig auto`` decides on every shared recording, and when it would switch.

Usage (from the repository root)::

    .venv/bin/python benchmarks/rig_decisions.py [--videos ../shared/data/videos]

Each recording's two views go through :class:`~sena_warp.video.rig_motion.RigMotion` frame by frame,
as the video loop shows them to it (its thumbnails, every ``CHECK_S``), over the whole recording.
Prints a Markdown table: the recording, whether it is hand-held (its folder's name), each decision
(mode, at which second, why) and the mean time of a frame's check.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from sena_warp.config import Config
from sena_warp.evaluation.rig_decisions import RECORDINGS, decisions

REPO = Path(__file__).resolve().parents[1]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--videos", type=Path, default=REPO.parent / "shared" / "data" / "videos")
    args = parser.parse_args(argv)
    cfg = Config()
    print("| recording | rig | decisions (mode at s: why) | right | ms a frame |")
    print("|---|---|---|---|---:|")
    for name, (left, right, rig) in RECORDINGS.items():
        found, per_frame_s = decisions(args.videos / name / left, args.videos / name / right, cfg)
        said = "; ".join(f"{d.mode} at {d.time_s:.1f} s: {d.reason}" for d in found)
        right_mode = bool(found) and all(d.mode == rig for d in found)
        print(f"| {name} | {rig} | {said} | {'yes' if right_mode else 'NO'} | {1e3 * per_frame_s:.2f} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
