"""The ``sena-warp`` command line: one subcommand per job.

Every expected failure is a :class:`~sena_warp.errors.StitchError`; it is printed as one line
(``sena-warp: error: ...``) and the process exits with that error's code (see the README).
"""

from __future__ import annotations

import argparse
import json
import sys
import time

from . import __version__
from .config import Config
from .errors import NotImplementedYet, StitchError


def _add_common(p: argparse.ArgumentParser) -> None:
    p.add_argument("--features", choices=("xfeat", "sift"), default=Config.features,
                   help="feature detector (default: %(default)s)")
    p.add_argument("--device", choices=("auto", "cpu", "cuda"), default=Config.device,
                   help="where the Warp kernels run (default: %(default)s)")


def _config_from(args: argparse.Namespace) -> Config:
    return Config(features=args.features, device=args.device)


def cmd_match(args: argparse.Namespace) -> int:
    from .features import match_images
    from .imageio import read_image, write_image
    from .debug import draw_matches

    cfg = _config_from(args)
    img_a, img_b = read_image(args.image_a), read_image(args.image_b)
    t0 = time.perf_counter()
    matches = match_images(img_a, img_b, cfg)
    elapsed = time.perf_counter() - t0
    summary = {
        "features": cfg.features,
        "keypoints_a": matches.n_keypoints_a,
        "keypoints_b": matches.n_keypoints_b,
        "matches": len(matches),
        "time_s": round(elapsed, 3),
    }
    print(json.dumps(summary))
    if args.output:
        write_image(args.output, draw_matches(img_a, img_b, matches), inputs=(args.image_a, args.image_b))
    return 0


def _not_implemented(name: str):
    def run(args: argparse.Namespace) -> int:
        raise NotImplementedYet(f"'sena-warp {name}' is not implemented yet (see the README's status list)")
    return run


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="sena-warp",
        description="Parallax-tolerant two-camera stitching (SENA) for image pairs and paired videos.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("match", help="find and match features between two images")
    p.add_argument("image_a")
    p.add_argument("image_b")
    p.add_argument("-o", "--output", help="write a picture of the matches (.jpg/.png)")
    _add_common(p)
    p.set_defaults(run=cmd_match)

    for name, text in (("image", "stitch two images into a panorama"),
                       ("video", "stitch two synchronised videos"),
                       ("bench", "frame-rate benchmark"),
                       ("eval", "quality evaluation against baselines")):
        p = sub.add_parser(name, help=f"{text} (not implemented yet)")
        p.add_argument("rest", nargs=argparse.REMAINDER)
        p.set_defaults(run=_not_implemented(name))
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.run(args)
    except StitchError as exc:
        print(f"sena-warp: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        print("sena-warp: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
