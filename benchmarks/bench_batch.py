"""Jobs per hour of ``sena-warp batch``: image pairs and short video pairs, on 1 and 2 local
worker processes and on a Ray started for the run.

Usage: ``.venv/bin/python benchmarks/bench_batch.py [--images 20] [--videos 4] [--seconds 3]
[--work DIR] [--markdown FILE]``. The image jobs are the first pair folders of
``../shared/data/pairs`` (by name); the video jobs are the first ``--seconds`` of the shared
recordings, re-encoded once into ``--work`` (kept for the next run). Each configuration runs
``sena-warp batch ... -q`` as a fresh process into its own output folder, so nothing is skipped;
the figures are its ``summary.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import time
from fractions import Fraction
from pathlib import Path

import av

from sena_warp.evaluation.bench import machine_line

REPO = Path(__file__).resolve().parents[1]
DATA = REPO.parent / "shared" / "data"
# name -> (left file, right file) in ../shared/data/videos
VIDEOS = {"rooftop_handheld": ("left.mp4", "right.mp4"), "office_static": ("cam1.mp4", "cam2.mp4"),
          "house_handheld_stereo": ("left.mp4", "right.mp4"), "lecture_hall_static": ("left.mp4", "right.mp4"),
          "futsal_night_static": ("cam1.mp4", "cam2.mp4")}
RUNNERS = {"1 local worker": ["--jobs", "1"], "2 local workers": ["--jobs", "2"],
           "Ray (--ray local, 2 CPUs)": ["--ray", "local", "--jobs", "2"]}
CLIP_CRF = 18  # the cut clips are re-encoded nearly transparently


def cut_clip(source: Path, target: Path, seconds: float) -> None:
    """The first ``seconds`` of ``source``'s video as H.264 (no audio), re-encoded from decoded frames."""
    with av.open(str(source)) as inp, av.open(str(target), "w") as out:
        stream = inp.streams.video[0]
        rate = Fraction(stream.average_rate)
        enc = out.add_stream("libx264", rate=rate, options={"crf": str(CLIP_CRF), "preset": "veryfast"})
        enc.width, enc.height, enc.pix_fmt = stream.codec_context.width, stream.codec_context.height, "yuv420p"
        for index, frame in enumerate(inp.decode(stream)):
            if index >= round(seconds * rate):
                break
            frame = frame.reformat(format="yuv420p")
            frame.pts, frame.time_base = index, 1 / rate
            out.mux(enc.encode(frame))
        out.mux(enc.encode(None))


def prepare(work: Path, images: int, videos: int, seconds: float) -> dict[str, Path]:
    image_dir, video_dir = work / "images", work / f"videos_{seconds:g}s"
    pairs = sorted(p for p in (DATA / "pairs").iterdir() if p.is_dir())[:images]
    shutil.rmtree(image_dir, ignore_errors=True)
    image_dir.mkdir(parents=True)
    for pair in pairs:
        (image_dir / pair.name).symlink_to(pair)
    for name, files in list(VIDEOS.items())[:videos]:
        for side, file in zip(("left", "right"), files):
            clip = video_dir / name / f"{side}.mp4"
            if not clip.exists():
                clip.parent.mkdir(parents=True, exist_ok=True)
                cut_clip(DATA / "videos" / name / file, clip, seconds)
    return {f"{images} image pairs": image_dir, f"{videos} video pairs ({seconds:g} s)": video_dir}


def run(jobs: Path, out: Path, argv: list[str]) -> dict:
    shutil.rmtree(out, ignore_errors=True)
    sena = Path(sys.executable).with_name("sena-warp")
    t0 = time.perf_counter()
    done = subprocess.run([str(sena), "batch", str(jobs), "--out", str(out), "-q", *argv], capture_output=True,
                          text=True)
    summary = json.loads((out / "summary.json").read_text())
    summary["process_s"] = time.perf_counter() - t0  # includes start-up (and Ray's)
    summary["load_1min"] = os.getloadavg()[0]  # other work on the machine at the end of the run
    if done.returncode not in (0, 7):
        raise SystemExit(f"batch failed ({done.returncode}): {done.stderr}")
    return summary


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--images", type=int, default=20)
    parser.add_argument("--videos", type=int, default=4)
    parser.add_argument("--seconds", type=float, default=3.0)
    parser.add_argument("--work", default="bench_work/batch")
    parser.add_argument("--markdown", help="also write the table as Markdown")
    args = parser.parse_args()
    work = Path(args.work).resolve()
    sets = prepare(work, args.images, args.videos, args.seconds)
    rows = []
    for set_name, jobs in sets.items():
        for runner, argv in RUNNERS.items():
            s = run(jobs, work / "out" / f"{jobs.name}_{argv[1]}_{argv[-1]}", argv)
            rows.append((set_name, runner, s["ok"], s["failed"], s["wall_s"], s["process_s"], s["jobs_per_hour"],
                         s["load_1min"]))
            print(f"{set_name:24} {runner:28} ok {s['ok']:3} failed {s['failed']:2}  wall {s['wall_s']:7.1f} s  "
                  f"process {s['process_s']:7.1f} s  {s['jobs_per_hour']:7.0f} jobs/h  load {s['load_1min']:.1f}",
                  flush=True)
    if args.markdown:
        lines = [f"Machine: {machine_line()}", "",
                 "| jobs | runner | ok | failed | batch wall s | process s | jobs per hour | load (1 min) after |",
                 "|---|---|---:|---:|---:|---:|---:|---:|"]
        lines += [f"| {a} | {b} | {c} | {d} | {e:.1f} | {f:.1f} | {g:.0f} | {h:.1f} |" for a, b, c, d, e, f, g, h in rows]
        Path(args.markdown).write_text("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
