"""Frame-rate benchmark of the video path (issue 6): the same code as ``sena-warp bench``.

Usage: ``.venv/bin/python benchmarks/bench_video.py [--sizes 720p 1080p 4k] [--seconds N]
[--markdown FILE] [--device cpu] [--work DIR] [--rss 10 60]``.
"""

from __future__ import annotations

import argparse
import sys

from sena_warp.bench import register
from sena_warp.errors import StitchError


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="bench_video.py")
    register(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(["bench", *(sys.argv[1:] if argv is None else argv)])
    try:
        return args.run(args)
    except StitchError as exc:
        print(f"bench_video.py: error: {exc}", file=sys.stderr)
        return exc.exit_code


if __name__ == "__main__":
    sys.exit(main())
