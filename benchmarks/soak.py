"""Soak run (issue 7): every image pair in both orders and every video pair through the real CLI.

Counts outcomes by exit code and, above all, unhandled exceptions (anything that is not a
``StitchError`` reaching ``main``). Prints one line per run and a summary; exits 1 if any run raised.

    .venv/bin/python benchmarks/soak.py [--data ../shared/data] [--work DIR] [--video-seconds S]
"""

from __future__ import annotations

import argparse
import collections
import contextlib
import io
import sys
import tempfile
import time
import traceback
from pathlib import Path

from sena_warp.cli import main as cli_main

REPO = Path(__file__).resolve().parents[1]


def image_runs(data: Path):
    for pair in sorted(p for p in (data / "pairs").iterdir() if p.is_dir()):
        a, b = (next(pair.glob(f"{name}.*")) for name in ("a", "b"))
        yield f"{pair.name} (a,b)", ["image", str(a), str(b)], ".png"
        yield f"{pair.name} (b,a)", ["image", str(b), str(a)], ".png"


def video_runs(data: Path):
    for folder in sorted(p for p in (data / "videos").iterdir() if p.is_dir()):
        left, right = sorted(folder.glob("*.mp4"))[:2]
        yield f"{folder.name} static", ["video", str(left), str(right)], ".mp4"
        yield f"{folder.name} moving", ["video", str(left), str(right), "--rig", "moving"], ".mp4"


def run_one(args: list[str], output: Path) -> tuple[int | str, str, float]:
    """(exit code or 'EXCEPTION', last stderr line or traceback tail, seconds)."""
    err = io.StringIO()
    t0 = time.perf_counter()
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            code = cli_main(args + ["-o", str(output)])
    except Exception:  # the point of the soak: anything escaping main is a bug
        return "EXCEPTION", traceback.format_exc().strip().splitlines()[-1], time.perf_counter() - t0
    lines = [line for line in err.getvalue().splitlines() if line.startswith("sena-warp")]
    return code, lines[-1] if lines else "", time.perf_counter() - t0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
    parser.add_argument("--work", type=Path, default=None, help="keep outputs here (default: a temp folder)")
    args = parser.parse_args()
    if not (args.data / "pairs").is_dir():
        print(f"soak: {args.data} has no pairs/ folder", file=sys.stderr)
        return 2
    counts: collections.Counter = collections.Counter()
    with tempfile.TemporaryDirectory() as tmp:
        work = args.work or Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        runs = list(image_runs(args.data)) + list(video_runs(args.data))
        for i, (name, cli_args, suffix) in enumerate(runs):
            code, message, seconds = run_one(cli_args, work / f"run{i:03d}{suffix}")
            counts[code] += 1
            print(f"{name:32s} exit {code!s:9s} {seconds:6.1f} s  {message}", flush=True)
    exceptions = counts.pop("EXCEPTION", 0)
    summary = ", ".join(f"exit {code}: {n}" for code, n in sorted(counts.items()))
    print(f"soak: {len(runs)} runs; {summary}; unhandled exceptions: {exceptions}")
    return 1 if exceptions else 0


if __name__ == "__main__":
    sys.exit(main())
