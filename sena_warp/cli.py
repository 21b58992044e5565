"""The ``sena-warp`` command line: one subcommand per job.

Every expected failure is a :class:`~sena_warp.errors.StitchError`; it is printed as one line
(``sena-warp: error: ...``) and the process exits with that error's code (see the README); so is a
malformed command line (exit 2). SIGINT, SIGTERM and SIGHUP end a run as Ctrl-C does, with 128 + the
signal's number. Each command plans all its outputs first (``sena_warp.outputs``): they are checked
before any input is read and written together at the end.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import json
import signal
import sys
import threading
import time

from . import __version__
from .config import Config
from .errors import InputError, StitchError
from .outputs import OutputPlan

VIDEO_SUFFIXES = (".mp4", ".mov", ".mkv")
HANDLED_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


class Interrupted(KeyboardInterrupt):
    """SIGINT, SIGTERM or SIGHUP, raised in the main thread as Ctrl-C is, so every output's temporary
    is removed on the way out; the exit code is 128 + the signal's number."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


class _Parser(argparse.ArgumentParser):
    """argparse with its errors on one line like every other error of the command (exit 2)."""

    def error(self, message: str):
        self.exit(InputError.exit_code, f"sena-warp: error: {message} (see {self.prog} --help)\n")


def _add_common(p: argparse.ArgumentParser) -> None:
    p.add_argument("--features", choices=("xfeat", "sift"), default=Config.features,
                   help="feature detector (default: %(default)s)")
    p.add_argument("--device", choices=("auto", "cpu", "cuda"), default=Config.device,
                   help="where the Warp kernels run (default: %(default)s)")
    p.add_argument("--max-megapixels", type=float, default=Config.max_input_megapixels, metavar="MP",
                   help="refuse inputs larger than this, before decoding them (default: %(default)g; see README)")


def _add_overwrite(p: argparse.ArgumentParser) -> None:
    group = p.add_mutually_exclusive_group()
    group.add_argument("-y", "--overwrite", dest="overwrite", action="store_const", const="overwrite",
                       default="refuse", help="replace outputs that exist (default: refuse them)")
    group.add_argument("-n", "--no-overwrite", dest="overwrite", action="store_const", const="skip",
                       help="do nothing when an output exists (exit 0)")


def config_from(args: argparse.Namespace) -> Config:
    """The Config of the options every stitching command shares (InputError for a bad value)."""
    if not args.max_megapixels > 0:
        raise InputError(f"--max-megapixels {args.max_megapixels:g} must be a positive number")
    return Config(features=args.features, device=args.device, max_input_megapixels=args.max_megapixels)


def checked(plan: OutputPlan) -> bool:
    """Check ``plan`` (raises on a broken rule); False, after saying so, when -n found an existing output."""
    existing = plan.check()
    for path in existing:
        print(f"{path}: exists, skipped (-n)")
    return not existing


def cmd_match(args: argparse.Namespace) -> int:
    from .features import match_images
    from .imageio import IMAGE_SUFFIXES, read_image, write_image
    from .debug import draw_matches

    cfg = config_from(args)
    plan = OutputPlan((args.image_a, args.image_b), args.overwrite)
    if args.output:
        plan.add(args.output, "-o", suffixes=IMAGE_SUFFIXES)
    if not checked(plan):
        return 0
    img_a, img_b = (read_image(path, cfg.max_input_megapixels) for path in (args.image_a, args.image_b))
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
    if args.output:
        with plan:
            write_image(args.output, draw_matches(img_a, img_b, matches), plan=plan)
    print(json.dumps(summary))
    return 0


def cmd_image(args: argparse.Namespace) -> int:
    from sena_warp.evaluation.figures import report_figures
    from sena_warp.kernels.runtime import resolve_config

    from .crop import largest_inner_rectangle
    from .debug import dump_stages
    from .imageio import IMAGE_SUFFIXES, read_image_masked, write_image
    from .report import image_report, write_json
    from .stitch import stitch_images

    cfg = resolve_config(config_from(args))  # once: the stitch, the debug pictures and the report share it
    plan = OutputPlan((args.image_a, args.image_b), args.overwrite)
    plan.add(args.output, "-o", suffixes=IMAGE_SUFFIXES)
    if args.report:
        plan.add(args.report, "--report")
    if args.debug:
        plan.add(args.debug, "--debug", folder=True)
    if not checked(plan):  # before the stitch: a bad --report must not cost a stitch or leave a panorama
        return 0
    (img_a, transparent_a), (img_b, transparent_b) = (read_image_masked(path, cfg.max_input_megapixels)
                                                      for path in (args.image_a, args.image_b))
    pano = stitch_images(img_a, img_b, cfg, reference=args.reference, transparent=(transparent_a, transparent_b))
    crop = largest_inner_rectangle(pano.image[:, :, 3]) if args.crop else None
    image = pano.image if crop is None else pano.image[crop[1]:crop[1] + crop[3], crop[0]:crop[0] + crop[2]]
    # The front end measures the stitch for its report; the pipeline itself never imports the evaluation.
    report = image_report(pano, img_a, img_b, report_figures(img_a, img_b, pano, cfg), crop)
    with plan:  # every output or none
        write_image(args.output, image, plan=plan)
        if args.debug:
            with plan.writing(args.debug) as folder:
                dump_stages(folder, img_a, img_b, pano, cfg)
        if args.report:
            write_json(args.report, report, plan)
    m = report["metrics"]
    print(f"{args.output}: {image.shape[1]}x{image.shape[0]} px, source={report['rig']['source']}, "
          f"{report['features']['matches']} matches, {report['global_affine']['inliers']} inliers, "
          f"{report['anchors']['count']} anchors, overlap PSNR {m['overlap_psnr_db']} dB, "
          f"{sum(pano.seconds.values()):.2f} s")
    return 0


def cmd_video(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from sena_warp.kernels.runtime import resolve_config
    from sena_warp.video.loop import VideoOptions, write_report
    from sena_warp.video.stitch import check_rig_settings, stitch_videos
    from sena_warp.video.sync import estimate_offset

    if args.reestimate is not None and args.rig != "moving":
        raise InputError("--reestimate re-estimates a moving rig; add --rig moving")
    cfg = resolve_config(config_from(args).replace(video_rig=args.rig))
    if args.reestimate is not None:
        cfg = cfg.replace(video_reestimate_s=args.reestimate)
    check_rig_settings(cfg)
    auto = args.offset == "auto"
    # NVENC only where the kernels run on a GPU too; the writer falls back to libx264 if it cannot open.
    codec = args.codec or ("h264_nvenc" if cfg.device == "cuda" else cfg.video_codec)
    # Every option is checked before any file is opened; with --offset auto, 0 stands in until the estimate.
    options = VideoOptions.from_config(cfg, offset_s=0.0 if auto else args.offset, audio=args.audio, codec=codec,
                                       crf=cfg.video_crf if args.crf is None else args.crf,
                                       preset=args.preset or cfg.video_preset, progress=args.progress or None,
                                       strict=args.strict)
    plan = OutputPlan((args.left, args.right), args.overwrite)
    plan.add(args.output, "-o", suffixes=VIDEO_SUFFIXES)
    if args.report:
        plan.add(args.report, "--report")
    if not checked(plan):  # before decoding: a bad --report must not cost a stitch or leave a video
        return 0
    sync = estimate_offset(args.left, args.right, cfg) if auto else None
    if sync is not None:
        print(f"sena-warp: offset auto: {sync.summary()}", file=sys.stderr)
        options = replace(options, offset_s=sync.offset_s)
    with plan:  # every output or none
        report = stitch_videos(args.left, args.right, args.output, cfg, options, reference=args.reference, plan=plan)
        report["sync"] = (sync.as_dict() if sync is not None
                          else {"method": "manual", "offset_ms": options.offset_s * 1000})
        if args.report:
            write_report(report, args.report, plan)
    if report["warnings"]:
        print(f"sena-warp: warning: {'; '.join(report['warnings'])}", file=sys.stderr)
    out, st = report["output"], report["stitch"]
    print(f"{args.output}: {out['width']}x{out['height']} px, {report['frames_out']} frames at {out['fps']:g} fps "
          f"({out['codec']}), source={st['rig']['source']}, {st['first_estimate']['inliers']} inliers, "
          f"re-estimations {st['reestimations']['accepted']} accepted / {st['reestimations']['rejected']} rejected, "
          f"seam jitter {st['jitter']['seam_jitter_px_mean']} px, dropped {report['dropped']}, "
          f"repeated {report['repeated']}, damaged {sum(report['damaged'].values())}, {report['output_fps']} fps"
          + (", with the warning above" if report["warnings"] else ""))
    return 0


def _offset(text: str) -> float | str:
    """``--offset``: seconds, or "auto" to estimate them from the inputs' audio or motion."""
    if text == "auto":
        return text
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is neither a number of seconds nor 'auto'") from None


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
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
    _add_overwrite(p)
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
    _add_overwrite(p)
    p.set_defaults(run=cmd_image)

    p = sub.add_parser("video", help="stitch two synchronised videos")
    p.add_argument("left", help="left (or top) video; its frames and times drive the output")
    p.add_argument("right", help="right (or bottom) video, paired to the left one by time")
    p.add_argument("-o", "--output", required=True, help="output video (.mp4, .mov or .mkv), H.264")
    p.add_argument("--offset", type=_offset, default=0.0, metavar="S|auto",
                   help="seconds the right video started after the left one, or auto: estimated from the "
                        "audio of both (else their motion), refused when unclear (default: 0)")
    p.add_argument("--rig", choices=("static", "moving"), default=Config.video_rig,
                   help="static: maps estimated once; moving: re-estimated now and then (default: %(default)s)")
    p.add_argument("--reestimate", type=float, metavar="S",
                   help=f"seconds between re-estimations of a moving rig (default: {Config.video_reestimate_s})")
    p.add_argument("--crf", type=int, help=f"constant quality, lower is better (default: {Config.video_crf})")
    p.add_argument("--preset", help=f"libx264 preset (default: {Config.video_preset})")
    p.add_argument("--codec", choices=("libx264", "h264_nvenc"),
                   help="H.264 encoder (default: h264_nvenc when the device is cuda and it opens, else libx264)")
    p.add_argument("--audio", choices=("left", "right", "none"), default=Config.video_audio,
                   help="whose audio to copy (default: %(default)s)")
    p.add_argument("--report", help="write a JSON report (frames, drops, re-estimations, jitter, time per stage)")
    p.add_argument("--reference", choices=("auto", "a", "b"), default="auto",
                   help="input kept unwarped: a = left, b = right (default: auto = the right or bottom view)")
    p.add_argument("--progress", action="store_true", help="show progress on stderr even when it is not a terminal")
    p.add_argument("--strict", action="store_true",
                   help="fail (exit 5) on damaged frames or a truncated input instead of replacing them with a warning")
    _add_common(p)
    _add_overwrite(p)
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
    _add_overwrite(p)
    p.set_defaults(run=_lazy("evaluation.bench", "cmd_bench"))

    p = sub.add_parser("eval", help="quality evaluation: SENA vs global affine, homography, OpenCV's stitcher")
    p.add_argument("data_dir", help="folder of pair folders, each holding a.* and b.* (or one pair folder)")
    p.add_argument("--out", required=True, metavar="DIR", help="folder for results.csv, summary.md and the sheets")
    p.add_argument("--progress", action="store_true", help="show progress on stderr even when it is not a terminal")
    _add_common(p)
    _add_overwrite(p)
    p.set_defaults(run=_lazy("evaluation.evaluate", "cmd_eval"))
    return parser


def _lazy(module: str, function: str):
    """A subcommand runner that imports its module only when run, so ``sena-warp --help`` stays quick."""
    def run(args: argparse.Namespace) -> int:
        return getattr(importlib.import_module(f"{__package__}.{module}"), function)(args)
    return run


@contextlib.contextmanager
def _signals_as_interrupts():
    """While the command runs, SIGINT, SIGTERM and SIGHUP raise :class:`Interrupted` (once: a second
    signal must not break the clean-up of the first). Only the main thread can set handlers."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    received: list[int] = []

    def interrupt(signum, frame):
        if not received:
            received.append(signum)
            raise Interrupted(signum)

    previous = {signum: signal.signal(signum, interrupt) for signum in HANDLED_SIGNALS}
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)


def main(argv: list[str] | None = None) -> int:
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as exc:  # --help, --version, or a malformed command line (said on one line)
        return int(exc.code or 0)
    try:
        with _signals_as_interrupts():
            return args.run(args)
    except StitchError as exc:
        print(f"sena-warp: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except MemoryError:  # a raised --max-megapixels, or a machine busy with other work
        print("sena-warp: error: out of memory; lower --max-megapixels, downscale the inputs or free some memory",
              file=sys.stderr)
        return StitchError.exit_code
    except KeyboardInterrupt as exc:
        signum = getattr(exc, "signum", signal.SIGINT)
        by = "" if signum == signal.SIGINT else f" by {signal.Signals(signum).name}"
        print(f"sena-warp: interrupted{by}", file=sys.stderr)
        return 128 + signum


if __name__ == "__main__":
    sys.exit(main())
