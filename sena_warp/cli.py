"""The ``sena-warp`` command line: one subcommand per job.

Every expected failure is a :class:`~sena_warp.errors.StitchError`; it is printed as one line
(``sena-warp: error: ...``) and the process exits with that error's code (see the README); so is a
malformed command line (exit 2). SIGINT, SIGTERM and SIGHUP end a run as Ctrl-C does, with 128 + the
signal's number. Each command plans all its outputs first (``sena_warp.outputs``): they are checked
before any input is read and written together at the end. What a run is doing goes to stderr through
:mod:`sena_warp.progress` (``-q``, ``-v``, ``--progress``); stdout carries results only.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import json
import logging
import signal
import sys
import threading
import time

from . import __version__
from .config import CHOICES, OFFSET_AUTO, Config
from .errors import InputError, StitchError
from .outputs import OutputPlan
from .progress import LOGGER, ConsoleHandler, echo

PROGRESS_MODES = ("auto", "bar", "plain", "json")
# Command-line options that set a Config field: option dest -> field name.
SETTING_OPTIONS = {"features": "features", "device": "device", "threads": "cpu_threads",
                   "max_megapixels": "max_input_megapixels", "rig": "video_rig", "reestimate": "video_reestimate_s",
                   "crf": "video_crf", "preset": "video_preset", "codec": "video_codec", "audio": "video_audio"}
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


def _positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"{value} is not a positive whole number")
    return value


def _output_options() -> argparse.ArgumentParser:
    """Options every subcommand takes: version, verbosity, progress style."""
    p = argparse.ArgumentParser(add_help=False)
    p.add_argument("--version", action="version", version=f"sena-warp {__version__}")
    loud = p.add_mutually_exclusive_group()
    loud.add_argument("-q", "--quiet", action="store_true", help="only warnings and errors on stderr, no summary")
    loud.add_argument("-v", "--verbose", action="store_true", help="also each step inside a stage and its time")
    p.add_argument("--progress", choices=PROGRESS_MODES, default="auto",
                   help="progress on stderr: a redrawn line (bar), whole lines (plain) or one JSON object per "
                        "line (json); auto = bar on a terminal, else plain (default: %(default)s)")
    return p


def _settings_options() -> argparse.ArgumentParser:
    """Options that set Config fields (over a --config file, which is over the defaults)."""
    p = argparse.ArgumentParser(add_help=False)
    p.add_argument("--config", metavar="FILE.toml",
                   help="settings file (see 'sena-warp config'); options given here win over it")
    p.add_argument("--threads", type=_positive_int, metavar="N",
                   help="threads for the Warp CPU kernels, onnxruntime and the video codecs (default: one per core)")
    p.add_argument("--features", choices=CHOICES["features"], help=f"feature detector (default: {Config.features})")
    p.add_argument("--device", choices=CHOICES["device"], help=f"where the Warp kernels run (default: {Config.device})")
    p.add_argument("--max-megapixels", dest="max_megapixels", type=float, metavar="MP",
                   help=f"refuse inputs larger than this, before decoding them (default: "
                        f"{Config.max_input_megapixels:g}; see README)")
    return p


def _overwrite_options() -> argparse.ArgumentParser:
    """-y / -n: what an existing output gets (one of ``outputs.OVERWRITE_MODES``; default: refused)."""
    p = argparse.ArgumentParser(add_help=False)
    group = p.add_mutually_exclusive_group()
    group.add_argument("-y", "--overwrite", dest="overwrite", action="store_const", const="overwrite",
                       default="refuse", help="replace outputs that exist (default: refuse them)")
    group.add_argument("-n", "--no-overwrite", dest="overwrite", action="store_const", const="skip",
                       help="do nothing when an output exists (exit 0)")
    return p


def _settings(args: argparse.Namespace) -> dict:
    """Config changes asked for: the --config file's, then the options given on the command line (a bad
    value is refused naming the option)."""
    from .config_file import check_value, load_settings

    settings = load_settings(args.config) if args.config else {}
    given = {field: check_value(field, getattr(args, dest), f"--{dest.replace('_', '-')}")
             for dest, field in SETTING_OPTIONS.items() if getattr(args, dest, None) is not None}
    return {**settings, **given}


def cmd_match(args: argparse.Namespace) -> int:
    from .debug import draw_matches
    from .features import match_images
    from .imageio import IMAGE_SUFFIXES, read_image, write_image
    from .jobs import checked, job_config

    cfg = job_config(args.settings)
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


def _run_job(job) -> int:
    """Run a :class:`~sena_warp.jobs.Job` and print its summary line after the output's name (none when
    -n found an existing output)."""
    from .jobs import run_job, summary_line

    report = run_job(job)
    if report is not None:
        echo(f"{job.output}: {summary_line(job.kind, report)}")
    return 0


def cmd_image(args: argparse.Namespace) -> int:
    from .jobs import Job

    return _run_job(Job("image", (args.image_a, args.image_b), args.output, args.settings, report=args.report,
                        reference=args.reference, crop=args.crop, debug=args.debug, overwrite=args.overwrite))


def cmd_video(args: argparse.Namespace) -> int:
    from .jobs import Job

    if args.reestimate is not None and args.settings.get("video_rig") == "static":
        raise InputError("--reestimate re-estimates a moving rig; a static rig is estimated once (drop --rig static)")
    return _run_job(Job("video", (args.left, args.right), args.output, args.settings, report=args.report,
                        reference=args.reference, crop=args.crop, offset_s=args.offset, strict=args.strict,
                        figures=args.figures, overwrite=args.overwrite))


def cmd_config(args: argparse.Namespace) -> int:
    from .config_file import check_config, config_toml

    print(config_toml(check_config(Config().replace(**args.settings), "settings")), end="")
    return 0


def _offset(text: str) -> float | str:
    """``--offset``: seconds, or "auto" to estimate them from the inputs' audio or motion."""
    if text == OFFSET_AUTO:
        return text
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is neither a number of seconds nor {OFFSET_AUTO!r}") from None


def build_parser() -> argparse.ArgumentParser:
    common, settings, overwrite = _output_options(), _settings_options(), _overwrite_options()
    parser = _Parser(
        prog="sena-warp",
        description="Parallax-tolerant two-camera stitching (SENA) for image pairs and paired videos.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    def command(name: str, help_text: str, *parents: argparse.ArgumentParser) -> argparse.ArgumentParser:
        return sub.add_parser(name, help=help_text, description=help_text[0].upper() + help_text[1:] + ".",
                              parents=[common, *parents])

    p = command("match", "find and match features between two images", settings, overwrite)
    p.add_argument("image_a")
    p.add_argument("image_b")
    p.add_argument("-o", "--output", help="write a picture of the matches (.jpg/.png)")
    p.set_defaults(run=cmd_match)

    p = command("image", "stitch two images into a panorama", settings, overwrite)
    p.add_argument("image_a")
    p.add_argument("image_b")
    p.add_argument("-o", "--output", required=True, help="panorama file: .png (transparent where uncovered) or .jpg")
    p.add_argument("--report", help="write a JSON report (docs/report.md)")
    p.add_argument("--debug", metavar="DIR", help="write a picture of each stage into DIR")
    p.add_argument("--crop", action="store_true", help="crop to the largest fully covered rectangle")
    p.add_argument("--reference", choices=("auto", "a", "b"), default="auto",
                   help="input kept unwarped (default: auto = the right or bottom view)")
    p.set_defaults(run=cmd_image)

    p = command("video", "stitch two synchronised videos", settings, overwrite)
    p.add_argument("left", help="left (or top) video; its frames and times drive the output")
    p.add_argument("right", help="right (or bottom) video, paired to the left one by time")
    p.add_argument("-o", "--output", required=True, help="output video (.mp4, .mov or .mkv), H.264")
    p.add_argument("--offset", type=_offset, default=0.0, metavar="S|auto",
                   help="seconds the right video started after the left one, or auto: estimated from the "
                        "audio of both (else their motion), refused when unclear (default: 0)")
    p.add_argument("--rig", choices=CHOICES["video_rig"],
                   help=f"auto: decided from the first second and watched (a line on stderr says what and why); "
                        f"static: maps estimated once (and moved with a camera that drifts); moving: aligned every "
                        f"frame (default: {Config.video_rig})")
    p.add_argument("--crop", action="store_true",
                   help="crop to the largest rectangle the first estimate covers, fixed for the whole video")
    p.add_argument("--reestimate", type=float, metavar="S",
                   help=f"a moving rig is re-estimated when its alignment falls behind, at most every S seconds "
                        f"(default: {Config.video_reestimate_s})")
    p.add_argument("--crf", type=int, help=f"constant quality, lower is better (default: {Config.video_crf})")
    p.add_argument("--preset", choices=CHOICES["video_preset"], help=f"libx264 preset (default: {Config.video_preset})")
    p.add_argument("--codec", choices=CHOICES["video_codec"],
                   help="H.264 encoder (default: h264_nvenc when the device is cuda and it opens, else libx264)")
    p.add_argument("--audio", choices=CHOICES["video_audio"], help=f"whose audio to copy (default: {Config.video_audio})")
    p.add_argument("--report", help="write a JSON report (docs/report.md)")
    p.add_argument("--figures", action="store_true",
                   help="measure the video over time (seam motion, exposure step, misalignment at the seam, "
                        "stability) into the report's 'figures'; slows the run")
    p.add_argument("--reference", choices=("auto", "a", "b"), default="auto",
                   help="input kept unwarped: a = left, b = right (default: auto = the right or bottom view)")
    p.add_argument("--strict", action="store_true",
                   help="fail (exit 5) on damaged frames or a truncated input instead of replacing them with a warning")
    p.set_defaults(run=cmd_video)

    p = command("batch", "stitch many pairs on local worker processes or a Ray cluster", settings)
    p.add_argument("jobs", metavar="JOBS",
                   help="folder of pair folders (a.* + b.* images, or left.* + right.* videos), or a .toml/.csv job list")
    p.add_argument("--out", required=True, metavar="DIR", help="folder for the outputs, reports and summary")
    p.add_argument("--jobs", dest="workers", type=_positive_int, metavar="N",
                   help="jobs at a time: local worker processes (default: 1), or the CPUs of '--ray local' "
                        "(default: one per core)")
    p.add_argument("--ray", metavar="ADDRESS",
                   help="run the jobs as Ray tasks on this cluster ('auto', 'HOST:PORT', 'ray://HOST:PORT') or on a "
                        "Ray started here ('local'); needs the cluster extra: pip install 'sena-warp[cluster]'")
    p.set_defaults(run=_lazy("batch", "cmd_batch"))

    p = command("config", "print the settings (defaults, or as a --config file and options change them) as TOML",
                settings)
    p.set_defaults(run=cmd_config)

    p = command("bench", "frame-rate benchmark: transcode baseline vs stitch, per stage, kernel", overwrite)
    p.add_argument("--sizes", nargs="+", metavar="SIZE",
                   help="clip sizes: 720p, 1080p, 4k or WIDTHxHEIGHT (default: 720p 1080p 4k)")
    p.add_argument("--seconds", type=float, default=10.0, help="clip length in seconds (default: %(default)s)")
    p.add_argument("--markdown", metavar="FILE", help="also write the table as Markdown")
    p.add_argument("--work", default="bench_work", help="folder for the clips and outputs (default: %(default)s)")
    p.add_argument("--data", help="the shared data set holding pairs/rew_lawn_2160 (default: ../shared/data "
                                  "beside the source tree)")
    p.add_argument("--rss", type=float, nargs="*", default=[], metavar="S",
                   help="also measure the peak RSS of 1080p stitches of these lengths in seconds (e.g. 10 60)")
    p.add_argument("--device", choices=CHOICES["device"], default=Config.device,
                   help="where the Warp kernels run (default: %(default)s)")
    p.set_defaults(run=_lazy("evaluation.bench", "cmd_bench"))

    p = command("eval", "quality evaluation: SENA vs global affine, homography, OpenCV's stitcher", settings,
                overwrite)
    p.add_argument("data_dir", help="folder of pair folders, each holding a.* and b.* (or one pair folder)")
    p.add_argument("--out", required=True, metavar="DIR", help="folder for results.csv, summary.md and the sheets")
    p.set_defaults(run=_lazy("evaluation.evaluate", "cmd_eval"))
    return parser


def _lazy(module: str, function: str):
    """A subcommand runner that imports its module only when run, so ``sena-warp --help`` stays quick."""
    def run(args: argparse.Namespace) -> int:
        return getattr(importlib.import_module(f"{__package__}.{module}"), function)(args)
    return run


def _console(args: argparse.Namespace) -> ConsoleHandler:
    """Show the run's stages, counts and messages on stderr as the output options ask."""
    mode = args.progress
    if mode == "auto":
        mode = "bar" if sys.stderr.isatty() else "plain"
    console = ConsoleHandler(sys.stderr, mode, verbose=args.verbose)
    LOGGER.addHandler(console)
    LOGGER.setLevel(logging.WARNING if args.quiet else logging.DEBUG if args.verbose or mode == "bar" else logging.INFO)
    return console


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
    level = LOGGER.level
    console = _console(args)
    try:
        with _signals_as_interrupts():
            if hasattr(args, "config"):
                args.settings = _settings(args)
            return args.run(args)
    except StitchError as exc:
        LOGGER.error(str(exc))
        return exc.exit_code
    except MemoryError:  # a raised --max-megapixels, or a machine busy with other work
        LOGGER.error("out of memory; lower --max-megapixels, downscale the inputs or free some memory")
        return StitchError.exit_code
    except KeyboardInterrupt as exc:
        signum = getattr(exc, "signum", signal.SIGINT)
        by = "" if signum == signal.SIGINT else f" by {signal.Signals(signum).name}"
        LOGGER.error(f"interrupted{by}", extra={"label": ""})
        return 128 + signum
    finally:
        LOGGER.removeHandler(console)
        LOGGER.setLevel(level)
        console.close()


if __name__ == "__main__":
    sys.exit(main())
