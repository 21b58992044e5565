"""Whether the CPU kernels could be shipped built: a portable build against the default -march=native.

Usage (from the repository root)::

    .venv/bin/python benchmarks/cpu_portable.py [--work DIR] [--frames 30] [--rounds 3]

Warp compiles CPU kernels with ``-march=native`` unless ``cpu_compiler_flags`` says otherwise; a build
that could ship must run on any x86-64 CPU, so it is compiled without it (``cpu_compiler_flags = ""``).
Each try is a new process with an empty kernel cache (``WARP_CACHE_PATH``), the shipped builds out of
its reach (they would load whatever the flags) and one of the two flag settings: it compiles every
kernel module (timed), builds a video compositor on the first pair of
``sena-warp bench``'s 1080p clips (made or reused in ``--work``) and composites ``--frames`` pairs; the
process CPU time per composited frame is the figure (steadier than wall time on a shared machine).
The two builds alternate for ``--rounds`` rounds; the median of each is printed.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

PROBE = """
import json, sys, time
import warp as wp
wp.config.cpu_compiler_flags = None if sys.argv[1] == "native" else ""
from itertools import islice
from sena_warp.config import Config
from sena_warp.kernels import runtime
runtime.BUILT = runtime.BUILT.with_name("not_shipped")  # compile with these flags, never load the shipped builds
from sena_warp.video.reader import FrameReader
from sena_warp.video.stitch import SenaFrameCompositor
t0 = time.perf_counter()
runtime.prewarm("cpu")
compile_s = time.perf_counter() - t0
left, right, frames = sys.argv[2], sys.argv[3], int(sys.argv[4])
cfg = Config(device="cpu", video_estimate_pairs=1)
compositor = SenaFrameCompositor.from_videos(left, right, 0.0, cfg, "auto")
with FrameReader(left) as reader_l, FrameReader(right) as reader_r:
    pairs = list(islice(zip(reader_l, reader_r), frames))
compositor.composite_yuv(*(p for f in pairs[0] for p in (f.y, f.u, f.v)))  # plans and buffers made once
cpu0 = time.process_time()
for frame_l, frame_r in pairs:
    compositor.composite_yuv(frame_l.y, frame_l.u, frame_l.v, frame_r.y, frame_r.u, frame_r.v)
print(json.dumps({"compile_s": compile_s, "cpu_ms": 1000 * (time.process_time() - cpu0) / len(pairs)}))
"""


def one_try(build: str, left: Path, right: Path, frames: int) -> dict:
    with tempfile.TemporaryDirectory(prefix="sena-warp-cache-") as cache:
        done = subprocess.run([sys.executable, "-c", PROBE, build, str(left), str(right), str(frames)],
                              capture_output=True, text=True, check=True, env={**os.environ, "WARP_CACHE_PATH": cache})
    return json.loads(done.stdout.strip().splitlines()[-1])


def main() -> int:
    from sena_warp.evaluation.bench import SIZES, bench_pair, make_clip_pair

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--work", type=Path, default=Path("bench_work"))
    parser.add_argument("--frames", type=int, default=30)
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args()
    args.work.mkdir(exist_ok=True)
    left, right = make_clip_pair(bench_pair(), args.work, SIZES["1080p"], 2.0)
    seen: dict[str, list[dict]] = {"native": [], "portable": []}
    for round_ in range(args.rounds):
        for build in seen:
            seen[build].append(one_try(build, left, right, args.frames))
            print(f"round {round_ + 1} {build}: {json.dumps(seen[build][-1])}", flush=True)
    for build, tries in seen.items():
        print(f"{build}: compile {statistics.median(t['compile_s'] for t in tries):.1f} s, composite_yuv "
              f"{statistics.median(t['cpu_ms'] for t in tries):.1f} ms process CPU a frame (median of {len(tries)})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
