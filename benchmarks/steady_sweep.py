"""The steady canvas's two settings swept on the hand-held recordings' target views (``video/steady.py``).

Usage (from the repository root)::

    .venv/bin/python benchmarks/steady_sweep.py [--videos ../shared/data/videos] [--pans out/pans]
        [--follow 0.02 0.05 0.1 0.2] [--max-px 16 24 32]

For each recording's target view (the right one: the source is the left on all of them) and each
(``video_steady_follow``, ``video_steady_max_px``), a :class:`~sena_warp.video.steady.SteadyCanvas` follows
every frame as a stitch's does; printed: the camera path's shake and the output's (the second difference
``|P_{t-1} - 2 P_t + P_{t+1}|``, mean / p95 px, as ``evaluation/video_figures.py``'s output shake), the share
of frames the window sits at its lag bound and its mean distance from the target's own frame.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import av
import numpy as np

from sena_warp.config import Config
from sena_warp.evaluation.video_figures import second_difference
from sena_warp.video.steady import SteadyCanvas

REPO = Path(__file__).resolve().parents[1]
TARGETS = {"rooftop_handheld": "right.mp4", "house_handheld_stereo": "right.mp4", "window_phones_drift": "right.mp4"}
PANS = ("pan_rew_theater", "pan_rew_lawn_2160")


def target_planes(path: Path) -> list[np.ndarray]:
    with av.open(str(path)) as container:
        return [frame.to_ndarray(format="gray") for frame in container.decode(video=0)]


def sweep(planes: list[np.ndarray], follow: float, max_px: float) -> dict:
    cfg = Config(video_rig="moving", video_steady_follow=follow, video_steady_max_px=max_px)
    shape = planes[0].shape
    steady = SteadyCanvas(shape, shape, np.ones(2), cfg)
    camera, shown, lag = [], [], []
    for plane in planes:
        steady.follow(plane)
        camera.append(steady.path)
        shown.append(steady.path + steady.shift)
        lag.append(float(np.abs(steady.shift).max()))
    camera_shake, shown_shake = second_difference(np.array(camera)), second_difference(np.array(shown))
    return {"camera": (camera_shake.mean(), np.percentile(camera_shake, 95)),
            "shown": (shown_shake.mean(), np.percentile(shown_shake, 95)),
            "at_bound": float(np.mean(np.array(lag) >= max_px - 1e-6)), "lag_mean": float(np.mean(lag))}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--videos", type=Path, default=REPO.parent / "shared" / "data" / "videos")
    parser.add_argument("--pans", type=Path, default=REPO / "out" / "pans")
    parser.add_argument("--follow", type=float, nargs="+", default=[0.02, 0.05, 0.1, 0.2])
    parser.add_argument("--max-px", type=float, nargs="+", default=[16.0, 24.0, 32.0])
    args = parser.parse_args()
    clips = {name: args.videos / name / right for name, right in TARGETS.items()}
    clips.update({name: args.pans / name / "right.mp4" for name in PANS if (args.pans / name / "right.mp4").exists()})
    print("| clip | follow | max px | camera shake mean / p95 px | output shake mean / p95 px | at the bound | lag mean px |")
    print("|---|---:|---:|---|---|---:|---:|")
    for name, path in clips.items():
        planes = target_planes(path)
        for follow in args.follow:
            for max_px in args.max_px:
                found = sweep(planes, follow, max_px)
                print(f"| {name} | {follow} | {max_px:g} | {found['camera'][0]:.3f} / {found['camera'][1]:.3f} "
                      f"| {found['shown'][0]:.3f} / {found['shown'][1]:.3f} | {100 * found['at_bound']:.0f} % "
                      f"| {found['lag_mean']:.1f} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
