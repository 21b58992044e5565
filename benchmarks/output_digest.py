"""One MD5 over every composited frame of a clip pair: a change meant for speed alone must leave it as it was.

A second MD5 is over the compositor's report (the jitter, seam and exposure figures, the drift moves)
without what the machine did (``timing_s``, the first estimate's seconds, the ``transfers`` counts): the
figures a user reads about the pictures must not move either.

Usage (from the repository root)::

    .venv/bin/python benchmarks/output_digest.py [--left L --right R] [--work DIR] [--frames 150]
        [--set video_rig=moving --set video_estimate_workers=0 ...]

Without ``--left``/``--right`` it makes (or reuses) ``sena-warp bench``'s 1080p clip pair in ``--work``.
The compositor is made as ``sena-warp video`` makes it (offset 0, the first pairs screened); each of
the first ``--frames`` pairs is updated (drift checks, re-estimates, blends) and composited, and the
digest takes its Y, U and V planes in turn. ``--set`` changes ``Config`` fields (a moving rig's
re-estimates give the same frames every run only on the loop's thread: ``video_estimate_workers=0``).
Run it with another tree's package first on ``PYTHONPATH`` to compare two versions.
"""

from __future__ import annotations

import argparse
import ast
import hashlib
import json
from collections.abc import Callable, Iterator
from itertools import islice
from pathlib import Path

from frame_kernel_floor import clip_pair, clip_parser
from sena_warp.config import Config
from sena_warp.config_file import check_settings
from sena_warp.errors import InputError
from sena_warp.kernels.runtime import resolve_config
from sena_warp.video.reader import FrameReader
from sena_warp.video.stitch import SenaFrameCompositor


def setting_values(items: list[str]) -> dict:
    """Checked ``Config`` changes from ``--set FIELD=VALUE`` items; a value is a Python literal (``0``,
    ``1.5``, ``'moving'``), else the text itself (``moving``)."""
    def value(text: str):
        try:
            return ast.literal_eval(text)
        except (ValueError, SyntaxError):
            return text
    return check_settings({name: value(text) for name, text in (item.split("=", 1) for item in items)}, "--set")


def compositor_parser(description: str, work: str, frames: int) -> argparse.ArgumentParser:
    """A script's arguments for :func:`clip_compositor` and :func:`composited`: the clip pair
    (``clip_parser``), ``--frames`` (default ``frames``) and ``--set FIELD=VALUE`` items."""
    parser = clip_parser(description, work)
    parser.add_argument("--frames", type=int, default=frames)
    parser.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE")
    return parser


def clip_compositor(args: argparse.Namespace) -> tuple[Path, Path, SenaFrameCompositor]:
    """(left, right, compositor) of a script's ``clip_parser`` arguments and ``--set`` items: the
    compositor as ``sena-warp video`` makes it (offset 0, the first pairs screened), on the CPU."""
    cfg = resolve_config(Config(device="cpu").replace(**setting_values(args.set)))
    left, right = clip_pair(args)
    return left, right, SenaFrameCompositor.from_videos(left, right, 0.0, cfg, "auto")


def composited(compositor: SenaFrameCompositor, left: Path, right: Path, frames: int) -> Iterator[tuple]:
    """The (y, u, v) output planes of the first ``frames`` pairs, each updated and composited as the
    frame loop does (valid until the next one)."""
    with FrameReader(left) as reader_l, FrameReader(right) as reader_r:
        for frame_l, frame_r in islice(zip(reader_l, reader_r), frames):
            compositor.update(frame_l, frame_r)
            yield compositor.composite_yuv(frame_l.y, frame_l.u, frame_l.v, frame_r.y, frame_r.u, frame_r.v)


def run(main: Callable[[], int], script: str) -> None:
    """Exit with ``main()``'s status; a bad ``--set`` or a clip that cannot be read in one line."""
    try:
        raise SystemExit(main())
    except InputError as exc:
        raise SystemExit(f"{Path(script).name}: {exc}") from None


def main() -> int:
    args = compositor_parser(__doc__.split("\n")[0], "out/output_digest", 150).parse_args()
    left, right, compositor = clip_compositor(args)
    digest = hashlib.md5()
    frames = 0
    for planes in composited(compositor, left, right, args.frames):
        for plane in planes:
            digest.update(plane.tobytes())
        frames += 1
    compositor.close()
    report = compositor.report()
    del report["timing_s"], report["first_estimate"]["seconds"]
    report.pop("transfers", None)
    figures = hashlib.md5(json.dumps(report, sort_keys=True).encode()).hexdigest()
    print(f"{left.name} + {right.name}, {frames} frames: {digest.hexdigest()}, report {figures}")
    return 0


if __name__ == "__main__":
    run(main, __file__)
