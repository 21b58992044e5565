"""Frame-rate benchmark of the video path: ``sena-warp bench`` run from the source tree.

Usage: ``.venv/bin/python benchmarks/bench_video.py [--sizes 720p 1080p 4k] [--seconds N]
[--markdown FILE] [--device cpu] [--work DIR] [--rss 10 60]`` (see ``sena-warp bench --help``).
"""

from __future__ import annotations

import sys

from sena_warp.cli import main

if __name__ == "__main__":
    sys.exit(main(["bench", *sys.argv[1:]]))
