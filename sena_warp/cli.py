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


def cmd_image(args: argparse.Namespace) -> int:
    from .crop import largest_inner_rectangle
    from .debug import dump_stages
    from .imageio import read_image, write_image
    from .report import image_report, write_json
    from .stitch import stitch_images

    cfg = _config_from(args)
    _check_output_suffix(args.output, (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".webp"))
    img_a, img_b = read_image(args.image_a), read_image(args.image_b)
    pano = stitch_images(img_a, img_b, cfg, reference=args.reference)
    crop = largest_inner_rectangle(pano.image[:, :, 3]) if args.crop else None
    image = pano.image if crop is None else pano.image[crop[1]:crop[1] + crop[3], crop[0]:crop[0] + crop[2]]
    write_image(args.output, image, inputs=(args.image_a, args.image_b))
    if args.debug:
        dump_stages(args.debug, img_a, img_b, pano)
    report = image_report(pano, img_a, img_b, cfg, crop)
    if args.report:
        write_json(args.report, report)
    m = report["metrics"]
    print(f"{args.output}: {image.shape[1]}x{image.shape[0]} px, source={report['rig']['source']}, "
          f"{report['features']['matches']} matches, {report['global_affine']['inliers']} inliers, "
          f"{report['anchors']['count']} anchors, overlap PSNR {m['overlap_psnr_db']} dB, "
          f"{sum(pano.seconds.values()):.2f} s")
    return 0


def _check_output_suffix(path: str, allowed: tuple[str, ...]) -> None:
    from pathlib import Path

    from .errors import OutputError

    if Path(path).suffix.lower() not in allowed:
        raise OutputError(f"{path}: unsupported output type; use one of {', '.join(allowed)}")


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

    p = sub.add_parser("image", help="stitch two images into a panorama")
    p.add_argument("image_a")
    p.add_argument("image_b")
    p.add_argument("-o", "--output", required=True, help="panorama file: .png (transparent where uncovered) or .jpg")
    p.add_argument("--report", help="write a JSON report (counts, zone, anchors, metrics, time per stage)")
    p.add_argument("--debug", metavar="DIR", help="write a picture of each stage into DIR")
    p.add_argument("--crop", action="store_true", help="crop to the largest fully covered rectangle")
    p.add_argument("--reference", choices=("auto", "a", "b"), default="auto",
                   help="input kept unwarped (default: auto = the right or bottom view)")
    _add_common(p)
    p.set_defaults(run=cmd_image)

    for name, text in (("video", "stitch two synchronised videos"),
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
