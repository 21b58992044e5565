"""The ``sena-warp`` command line: one subcommand per job.

Every expected failure is a :class:`~sena_warp.errors.StitchError`; it is printed as one line
(``sena-warp: error: ...``) and the process exits with that error's code (see the README).
"""

from __future__ import annotations

import argparse
import importlib
import json
import sys
import time

from . import __version__
from .config import Config
from .errors import InputError, StitchError


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
    from sena_warp.evaluation.figures import report_figures
    from sena_warp.kernels.runtime import resolve_config

    from .crop import largest_inner_rectangle
    from .debug import dump_stages
    from .imageio import check_output_folder, check_output_path, read_image, write_image
    from .report import image_report, write_json
    from .stitch import stitch_images

    cfg = resolve_config(_config_from(args))  # once: the stitch, the debug pictures and the report share it
    inputs = (args.image_a, args.image_b)
    _check_output_suffix(args.output, (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".webp"))
    for path in filter(None, (args.output, args.report)):
        check_output_path(path, inputs)  # before the stitch: a bad path must not leave a panorama behind
    if args.debug:
        check_output_folder(args.debug)
    img_a, img_b = read_image(args.image_a), read_image(args.image_b)
    pano = stitch_images(img_a, img_b, cfg, reference=args.reference)
    crop = largest_inner_rectangle(pano.image[:, :, 3]) if args.crop else None
    image = pano.image if crop is None else pano.image[crop[1]:crop[1] + crop[3], crop[0]:crop[0] + crop[2]]
    write_image(args.output, image, inputs=inputs)
    if args.debug:
        dump_stages(args.debug, img_a, img_b, pano, cfg)
    # The front end measures the stitch for its report; the pipeline itself never imports the evaluation.
    report = image_report(pano, img_a, img_b, report_figures(img_a, img_b, pano, cfg), crop)
    if args.report:
        write_json(args.report, report)
    m = report["metrics"]
    print(f"{args.output}: {image.shape[1]}x{image.shape[0]} px, source={report['rig']['source']}, "
          f"{report['features']['matches']} matches, {report['global_affine']['inliers']} inliers, "
          f"{report['anchors']['count']} anchors, overlap PSNR {m['overlap_psnr_db']} dB, "
          f"{sum(pano.seconds.values()):.2f} s")
    return 0


def cmd_video(args: argparse.Namespace) -> int:
    from sena_warp.kernels.runtime import resolve_config
    from sena_warp.video.loop import VideoOptions, write_report
    from sena_warp.video.stitch import stitch_videos

    from .imageio import check_output_path

    _check_output_suffix(args.output, (".mp4", ".mov", ".mkv"))
    for path in filter(None, (args.output, args.report)):
        check_output_path(path, (args.left, args.right))  # before decoding: a bad --report must not leave a video
    if args.reestimate is not None and args.rig != "moving":
        raise InputError("--reestimate re-estimates a moving rig; add --rig moving")
    cfg = resolve_config(_config_from(args).replace(video_rig=args.rig, video_crop=args.crop))
    if args.reestimate is not None:
        cfg = cfg.replace(video_reestimate_s=args.reestimate)
    # NVENC only where the kernels run on a GPU too; the writer falls back to libx264 if it cannot open.
    codec = args.codec or ("h264_nvenc" if cfg.device == "cuda" else cfg.video_codec)
    options = VideoOptions.from_config(cfg, offset_s=args.offset, audio=args.audio, codec=codec,
                                       crf=cfg.video_crf if args.crf is None else args.crf,
                                       preset=args.preset or cfg.video_preset, progress=args.progress or None)
    observer = None
    if args.figures:
        # The front end measures the video for its report; the pipeline only calls the observer.
        from sena_warp.evaluation.video_figures import VideoFigures

        observer = VideoFigures(cfg)
    report = stitch_videos(args.left, args.right, args.output, cfg, options, reference=args.reference,
                           observer=observer)
    if observer is not None:
        report["figures"] = observer.figures()
    if args.report:
        write_report(report, args.report)
    out, st = report["output"], report["stitch"]
    print(f"{args.output}: {out['width']}x{out['height']} px, {report['frames_out']} frames at {out['fps']:g} fps "
          f"({out['codec']}), source={st['rig']['source']}, {st['first_estimate']['inliers']} inliers, "
          f"re-estimations {st['reestimations']['accepted']} accepted / {st['reestimations']['rejected']} rejected, "
          f"seam jitter {st['jitter']['seam_jitter_px_mean']} px, dropped {report['dropped']}, "
          f"repeated {report['repeated']}, {report['output_fps']} fps")
    if observer is not None:
        fig = report["figures"]
        print(f"figures: seam motion p99 {fig['seam_motion_px']['p99']} px, exposure step mean "
              f"{fig['exposure_step_grey']['mean']}, misalignment median {fig['misalignment_px']['median']} px, "
              f"stability {fig['stability']['value']}")
    return 0


def _check_output_suffix(path: str, allowed: tuple[str, ...]) -> None:
    from pathlib import Path

    from .errors import OutputError

    if Path(path).suffix.lower() not in allowed:
        raise OutputError(f"{path}: unsupported output type; use one of {', '.join(allowed)}")


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

    p = sub.add_parser("video", help="stitch two synchronised videos")
    p.add_argument("left", help="left (or top) video; its frames and times drive the output")
    p.add_argument("right", help="right (or bottom) video, paired to the left one by time")
    p.add_argument("-o", "--output", required=True, help="output video (.mp4, .mov or .mkv), H.264")
    p.add_argument("--offset", type=float, default=0.0, metavar="S",
                   help="seconds the right video started after the left one (default: 0)")
    p.add_argument("--rig", choices=("static", "moving"), default=Config.video_rig,
                   help="static: maps estimated once; moving: re-estimated now and then (default: %(default)s)")
    p.add_argument("--crop", action="store_true",
                   help="crop to the largest rectangle the first estimate covers, fixed for the whole video")
    p.add_argument("--reestimate", type=float, metavar="S",
                   help=f"seconds between re-estimations of a moving rig (default: {Config.video_reestimate_s})")
    p.add_argument("--crf", type=int, help=f"constant quality, lower is better (default: {Config.video_crf})")
    p.add_argument("--preset", help=f"libx264 preset (default: {Config.video_preset})")
    p.add_argument("--codec", choices=("libx264", "h264_nvenc"),
                   help="H.264 encoder (default: h264_nvenc when the device is cuda and it opens, else libx264)")
    p.add_argument("--audio", choices=("left", "right", "none"), default=Config.video_audio,
                   help="whose audio to copy (default: %(default)s)")
    p.add_argument("--report", help="write a JSON report (frames, drops, re-estimations, jitter, time per stage)")
    p.add_argument("--figures", action="store_true",
                   help="measure the video over time (seam motion, exposure step, misalignment at the seam, "
                        "stability) into the report's 'figures'; slows the run")
    p.add_argument("--reference", choices=("auto", "a", "b"), default="auto",
                   help="input kept unwarped: a = left, b = right (default: auto = the right or bottom view)")
    p.add_argument("--progress", action="store_true", help="show progress on stderr even when it is not a terminal")
    _add_common(p)
    p.set_defaults(run=cmd_video)

    p = sub.add_parser("bench", help="frame-rate benchmark: transcode baseline vs stitch, per stage, kernel")
    p.add_argument("--sizes", nargs="+", metavar="SIZE",
                   help="clip sizes: 720p, 1080p, 4k or WIDTHxHEIGHT (default: 720p 1080p 4k)")
    p.add_argument("--seconds", type=float, default=10.0, help="clip length in seconds (default: %(default)s)")
    p.add_argument("--markdown", metavar="FILE", help="also write the table as Markdown")
    p.add_argument("--work", default="bench_work", help="folder for the clips and outputs (default: %(default)s)")
    p.add_argument("--data", help="the shared data set holding pairs/rew_lawn_2160 (default: ../shared/data "
                                  "beside the source tree)")
    p.add_argument("--rss", type=float, nargs="*", default=[], metavar="S",
                   help="also measure the peak RSS of 1080p stitches of these lengths in seconds (e.g. 10 60)")
    p.add_argument("--device", choices=("auto", "cpu", "cuda"), default=Config.device,
                   help="where the Warp kernels run (default: %(default)s)")
    p.set_defaults(run=_lazy("evaluation.bench", "cmd_bench"))

    p = sub.add_parser("eval", help="quality evaluation: SENA vs global affine, homography, OpenCV's stitcher")
    p.add_argument("data_dir", help="folder of pair folders, each holding a.* and b.* (or one pair folder)")
    p.add_argument("--out", required=True, metavar="DIR", help="folder for results.csv, summary.md and the sheets")
    p.add_argument("--progress", action="store_true", help="show progress on stderr even when it is not a terminal")
    _add_common(p)
    p.set_defaults(run=_lazy("evaluation.evaluate", "cmd_eval"))
    return parser


def _lazy(module: str, function: str):
    """A subcommand runner that imports its module only when run, so ``sena-warp --help`` stays quick."""
    def run(args: argparse.Namespace) -> int:
        return getattr(importlib.import_module(f"{__package__}.{module}"), function)(args)
    return run


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
