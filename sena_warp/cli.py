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
import os
import signal
import sys
import threading
import time
from typing import Iterator

from . import __version__
from .config import CHOICES, OFFSET_AUTO, Config
from .errors import InputError, StitchError, out_of_memory
from .outputs import OutputPlan
from .progress import LOGGER, ConsoleHandler, echo, write_stdout

PROGRESS_MODES = ("auto", "bar", "plain", "json")
# Command-line options that set a Config field: option dest -> field name.
SETTING_OPTIONS = {"features": "features", "device": "device", "threads": "cpu_threads",
                   "max_megapixels": "max_input_megapixels", "rig": "video_rig", "reestimate": "video_reestimate_s",
                   "crf": "video_crf", "preset": "video_preset", "codec": "video_codec", "audio": "video_audio",
                   "bitrate": "video_bitrate_kbps", "maxrate": "video_maxrate_kbps", "ss": "video_start_s",
                   "to": "video_end_s", "max_width": "video_max_width"}
RATE_UNITS = {"": 0.001, "k": 1.0, "m": 1000.0}  # --bitrate 8M / 8000k / 8000000 (bit/s), in kbit/s
HANDLED_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


class Interrupted(KeyboardInterrupt):
    """SIGINT, SIGTERM or SIGHUP, raised in the main thread as Ctrl-C is, so every output's temporary
    is removed on the way out; the exit code is 128 + the signal's number."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)


class _Parser(argparse.ArgumentParser):
    """argparse with its errors on one line like every other error of the command (exit 2)."""

    def error(self, message: str):
        self.exit(InputError.exit_code, f"sena-warp: error: {message} (see {self.prog} --help)\n")


def _positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"{value} is not a positive whole number")
    return value


def _seconds(text: str) -> float:
    """A time as ffmpeg takes one: seconds (``90``, ``90.5``) or ``[HH:]MM:SS[.fff]`` (``1:30``)."""
    try:
        parts = [float(part) for part in text.split(":")]
    except ValueError:
        parts = []
    if not 1 <= len(parts) <= 3 or any(part < 0 or part != part for part in parts):
        raise argparse.ArgumentTypeError(f"{text!r} is not a time; give seconds (90.5) or [HH:]MM:SS (1:30.5)")
    value = 0.0
    for part in parts:
        value = 60 * value + part
    return value


def _rate_kbps(text: str) -> int:
    """A bit rate as ffmpeg takes one (``8M``, ``8000k``, ``8000000``) in whole kbit/s."""
    number, unit = (text[:-1], text[-1].lower()) if text[-1:].lower() in ("k", "m") else (text, "")
    try:
        kbps = round(float(number) * RATE_UNITS[unit])
    except ValueError:
        kbps = 0
    if kbps < 1:
        raise argparse.ArgumentTypeError(f"{text!r} is not a bit rate; give e.g. 8M, 8000k or 8000000 (bit/s)")
    return kbps


MAX_BENCH_SECONDS = 3600.0  # bench --seconds and --rss: clips of at most an hour


def _clip_seconds(text: str) -> float:
    """``bench --seconds`` / ``--rss``: a clip length in seconds, in (0, MAX_BENCH_SECONDS]."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number of seconds") from None
    if not 0 < value <= MAX_BENCH_SECONDS:  # also refuses nan
        raise argparse.ArgumentTypeError(f"{text} s is not a clip length; give more than 0 and at most "
                                         f"{MAX_BENCH_SECONDS:g} seconds")
    return value


def _add_messages(parser: argparse.ArgumentParser) -> None:
    """Options every subcommand takes: verbosity and progress style (last in its help)."""
    p = parser.add_argument_group("messages on stderr")
    loud = p.add_mutually_exclusive_group()
    loud.add_argument("-q", "--quiet", action="store_true", help="only warnings and errors, no summary line")
    loud.add_argument("-v", "--verbose", action="store_true", help="also each step inside a stage and its time")
    p.add_argument("--progress", choices=PROGRESS_MODES, default="auto",
                   help="a redrawn line (bar), whole lines (plain) or one JSON object per line (json, its events "
                        "in the README); auto = bar on a terminal, else plain (default: %(default)s)")


def _add_settings(parser: argparse.ArgumentParser) -> None:
    """Options that set Config fields (over a --config file, which is over the defaults)."""
    p = parser.add_argument_group("settings (all of them: sena-warp config)")
    p.add_argument("--config", metavar="FILE.toml",
                   help="settings file (see 'sena-warp config'); options given here win over it")
    p.add_argument("--threads", type=_positive_int, metavar="N",
                   help="threads for the Warp CPU kernels, onnxruntime and the video codecs (default: one per core)")
    p.add_argument("--features", choices=CHOICES["features"], help=f"feature detector (default: {Config.features})")
    p.add_argument("--device", choices=CHOICES["device"],
                   help=f"where the Warp kernels run; auto: a CUDA GPU where there is one (default: {Config.device})")
    p.add_argument("--max-megapixels", dest="max_megapixels", type=float, metavar="MP",
                   help=f"refuse larger inputs, before decoding them (default: {Config.max_input_megapixels:g})")


def _add_overwrite(parser: argparse.ArgumentParser) -> None:
    """-y / -n: what an existing output gets (one of ``outputs.OVERWRITE_MODES``; default: refused)."""
    group = parser.add_argument_group("outputs that exist").add_mutually_exclusive_group()
    group.add_argument("-y", "--overwrite", dest="overwrite", action="store_const", const="overwrite",
                       default="refuse", help="replace them (default: refuse them, exit 6)")
    group.add_argument("-n", "--no-overwrite", dest="overwrite", action="store_const", const="skip",
                       help="leave them and do nothing (exit 0)")


def _add_video(parser: argparse.ArgumentParser) -> None:
    """Options of a video stitch (settings too), for ``video`` and for every video job of ``batch``."""
    span = parser.add_argument_group("span (times of the left video, after --offset: seconds or [HH:]MM:SS)")
    span.add_argument("--ss", type=_seconds, metavar="TIME",
                      help="start here, reached by seeking: only the span is decoded (default: the beginning)")
    span.add_argument("--to", type=_seconds, metavar="TIME", help="end before this time (default: where the videos end)")
    span.add_argument("-t", dest="duration", type=_seconds, metavar="TIME", help="or end this long after --ss")
    rig = parser.add_argument_group("rig")
    rig.add_argument("--offset", type=_offset, default=0.0, metavar="S|auto",
                     help="seconds the right video started after the left one, or auto: estimated from the "
                          "audio of both (else their motion), refused when unclear (default: 0)")
    rig.add_argument("--rig", choices=CHOICES["video_rig"],
                     help=f"auto: decided from the first second and watched (a line on stderr says what and why); "
                          f"static: maps estimated once (and moved with a camera that drifts); moving: aligned "
                          f"every frame (default: {Config.video_rig})")
    rig.add_argument("--reestimate", type=float, metavar="S",
                     help=f"a moving rig is re-estimated when its alignment falls behind, at most every S seconds "
                          f"(default: {Config.video_reestimate_s:g})")
    picture = parser.add_argument_group("picture")
    picture.add_argument("--crop", action="store_true",
                         help="crop to the largest rectangle the first estimate covers (a video: for all of it, "
                              "less the steady canvas's margin with --rig moving)")
    picture.add_argument("--max-width", dest="max_width", type=_positive_int, metavar="W",
                         help="at most W pixels wide, aspect kept, made by the stitch's maps (default: as stitched)")
    encoding = parser.add_argument_group("encoding")
    encoding.add_argument("--codec", choices=CHOICES["video_codec"],
                          help="H.264 (libx264, h264_nvenc) or HEVC (libx265, hevc_nvenc); NVENC falls back to the "
                               "software encoder where it cannot open (default: h264_nvenc on a CUDA device, else "
                               "libx264)")
    encoding.add_argument("--crf", type=int, metavar="N",
                          help=f"constant quality, 0-51: lower is better and larger (default: {Config.video_crf})")
    encoding.add_argument("--bitrate", type=_rate_kbps, metavar="RATE",
                          help="an average bit rate instead of --crf, e.g. 8M or 8000k")
    encoding.add_argument("--maxrate", type=_rate_kbps, metavar="RATE",
                          help="a peak bit rate capping --crf or --bitrate (with a buffer of 2 s of it)")
    encoding.add_argument("--preset", choices=CHOICES["video_preset"], metavar="PRESET",
                          help=f"x264/x265 speed preset, ultrafast ... placebo (default: {Config.video_preset})")
    encoding.add_argument("--audio", choices=CHOICES["video_audio"],
                          help=f"whose audio to copy (default: {Config.video_audio})")


def _settings(args: argparse.Namespace) -> dict:
    """Config changes asked for: the --config file's, then the options given on the command line (a bad
    value is refused naming the option)."""
    from .config_file import check_value, load_settings

    settings = load_settings(args.config) if args.config else {}
    given = {field: check_value(field, getattr(args, dest), f"--{dest.replace('_', '-')}")
             for dest, field in SETTING_OPTIONS.items() if getattr(args, dest, None) is not None}
    if getattr(args, "duration", None) is not None:  # -t: the span's end from its start
        if "video_end_s" in given:
            raise InputError("--to and -t both end the span; give one of them")
        given["video_end_s"] = check_value("video_end_s", given.get("video_start_s", settings.get(
            "video_start_s", Config.video_start_s)) + args.duration, "-t")
    if "video_crf" in given and "video_bitrate_kbps" in given:
        raise InputError("--crf and --bitrate are two ways to set the rate; give one of them")
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
    write_stdout(json.dumps(summary) + "\n")
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
                        figures=args.figures, debug=args.debug, overwrite=args.overwrite))


def cmd_config(args: argparse.Namespace) -> int:
    from .config_file import config_toml, settings_config

    write_stdout(config_toml(settings_config(args.settings, "settings")))
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
    parser = _Parser(
        prog="sena-warp",
        description="Parallax-tolerant two-camera stitching (SENA) for image pairs and paired videos. "
                    "'sena-warp COMMAND --help' says what a command takes.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    def command(name: str, help_text: str) -> argparse.ArgumentParser:
        return sub.add_parser(name, help=help_text, description=help_text[0].upper() + help_text[1:] + ".")

    def sections(p: argparse.ArgumentParser, *adders) -> None:
        """--version among the command's own options, the shared option groups after them, then the messages."""
        p.add_argument("--version", action="version", version=f"sena-warp {__version__}")
        for add in (*adders, _add_messages):
            add(p)

    p = command("image", "stitch two photos into a panorama")
    p.add_argument("image_a", help="one photo; which is left (or top) is found from the matches")
    p.add_argument("image_b", help="the other photo")
    p.add_argument("-o", "--output", required=True,
                   help="the panorama: .png (transparent where uncovered), .jpg, .tif or .webp")
    p.add_argument("--report", metavar="FILE.json", help="also write a JSON report (docs/report.md)")
    p.add_argument("--debug", metavar="DIR", help="write a picture of each stage into DIR")
    p.add_argument("--crop", action="store_true", help="crop to the largest fully covered rectangle")
    p.add_argument("--reference", choices=("auto", "a", "b"), default="auto",
                   help="photo kept unwarped: a = image_a, b = image_b (default: auto = the right or bottom view)")
    sections(p, _add_overwrite, _add_settings)
    p.set_defaults(run=cmd_image)

    p = command("video", "stitch two synchronised videos")
    p.add_argument("left", help="left (or top) video; its frames and times drive the output")
    p.add_argument("right", help="right (or bottom) video, paired to the left one by time")
    p.add_argument("-o", "--output", required=True,
                   help="the stitched video (.mp4, .mov or .mkv), or a picture (.png or .jpg) of the stitched frame "
                        "at --ss, made in about the time of the estimate: a look at the rig before a long encode")
    p.add_argument("--report", metavar="FILE.json", help="also write a JSON report (docs/report.md)")
    p.add_argument("--debug", metavar="DIR", help="write a picture of each stage of the first estimate into DIR")
    p.add_argument("--figures", action="store_true",
                   help="measure the video over time (seam motion, exposure step, misalignment at the seam, "
                        "stability) into the report's 'figures'; slows the run")
    p.add_argument("--reference", choices=("auto", "a", "b"), default="auto",
                   help="input kept unwarped: a = left, b = right (default: auto = the right or bottom view)")
    p.add_argument("--strict", action="store_true",
                   help="fail (exit 5) on damaged frames or a truncated input instead of replacing them with a warning")
    sections(p, _add_video, _add_overwrite, _add_settings)
    p.set_defaults(run=cmd_video)

    p = command("batch", "stitch many pairs on local worker processes or a Ray cluster, resumably")
    p.add_argument("jobs", metavar="JOBS",
                   help="folder of pair folders (a.* + b.* images, or left.* + right.* videos), or a .toml/.csv job list")
    p.add_argument("--out", required=True, metavar="DIR", help="folder for the outputs, reports and summary")
    p.add_argument("--jobs", dest="workers", type=_positive_int, metavar="N",
                   help="jobs at a time: local worker processes (default: 1), or the CPUs of '--ray local' "
                        "(default: one per core)")
    p.add_argument("--ray", metavar="ADDRESS",
                   help="run the jobs as Ray tasks on this cluster ('auto', 'HOST:PORT', 'ray://HOST:PORT') or on a "
                        "Ray started here ('local'); needs the cluster extra: pip install 'sena-warp[cluster]'")
    sections(p, _add_video, _add_overwrite, _add_settings)
    p.set_defaults(run=_lazy("batch", "cmd_batch"))

    p = command("match", "find and match features between two photos")
    p.add_argument("image_a", help="one photo")
    p.add_argument("image_b", help="the other photo")
    p.add_argument("-o", "--output", help="also write a picture of the matches (.jpg/.png)")
    sections(p, _add_overwrite, _add_settings)
    p.set_defaults(run=cmd_match)

    p = command("config", "print the settings (defaults, or as a --config file and options change them) as TOML")
    sections(p, _add_settings)
    p.set_defaults(run=cmd_config)

    p = command("eval", "quality evaluation: SENA vs global affine, homography, OpenCV's stitcher")
    p.add_argument("data_dir", help="folder of pair folders, each holding a.* and b.* (or one pair folder)")
    p.add_argument("--out", required=True, metavar="DIR", help="folder for results.csv, summary.md and the sheets")
    sections(p, _add_overwrite, _add_settings)
    p.set_defaults(run=_lazy("evaluation.evaluate", "cmd_eval"))

    p = command("bench", "frame-rate benchmark: transcode baseline vs stitch, per stage, compositing vs OpenCV")
    p.add_argument("--sizes", nargs="+", metavar="SIZE",
                   help="clip sizes: 720p, 1080p, 4k or WIDTHxHEIGHT, even sides from 16 up to 8K (default: 720p 1080p 4k)")
    p.add_argument("--seconds", type=_clip_seconds, default=10.0,
                   help=f"clip length in seconds, at most {MAX_BENCH_SECONDS:g} (default: %(default)s)")
    p.add_argument("--markdown", metavar="FILE", help="also write the table with every column as Markdown")
    p.add_argument("--work", default="bench_work", metavar="DIR",
                   help="folder for the clips and outputs, kept and reused by the next run (default: %(default)s)")
    p.add_argument("--data", metavar="DIR",
                   help="a data set holding pairs/rew_lawn_2160 to make the clips from (default: ../shared/data "
                        "beside the source tree if it is there, else the pair the package ships)")
    p.add_argument("--rss", type=_clip_seconds, nargs="*", default=[], metavar="S",
                   help="also measure the peak RSS of 1080p stitches of these lengths in seconds (e.g. 10 60)")
    p.add_argument("--device", choices=CHOICES["device"], default=Config.device,
                   help="where the Warp kernels run (default: %(default)s)")
    sections(p, _add_overwrite)
    p.set_defaults(run=_lazy("evaluation.bench", "cmd_bench"))
    return parser


def _lazy(module: str, function: str):
    """A subcommand runner that imports its module only when run, so ``sena-warp --help`` stays quick."""
    def run(args: argparse.Namespace) -> int:
        return getattr(importlib.import_module(f"{__package__}.{module}"), function)(args)
    return run


def _standard_streams() -> None:
    """Put /dev/null on any of file descriptors 0, 1 and 2 that the caller closed (``2>&-``), and a
    stream on it where Python left ``sys.stdin`` / ``stdout`` / ``stderr`` None: else the first file
    opened takes the number (a library's stderr lines would land in an output) and code that writes
    to ``sys.stderr`` fails."""
    for fd, name, mode in ((0, "stdin", "r"), (1, "stdout", "w"), (2, "stderr", "w")):
        try:
            os.fstat(fd)
        except OSError:
            os.open(os.devnull, os.O_RDWR)  # the lowest free number: fd itself
        if getattr(sys, name) is None:
            setattr(sys, name, open(fd, mode, closefd=False))


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
def _signals_as_interrupts() -> Iterator[list[int]]:
    """While the command runs, SIGINT, SIGTERM and SIGHUP raise :class:`Interrupted` (once: a second
    signal must not break the clean-up of the first). Yields the list of the signal received: a
    library that catches the interrupt may raise a KeyboardInterrupt of its own instead (Ray does).
    Only the main thread can set handlers."""
    received: list[int] = []
    if threading.current_thread() is not threading.main_thread():
        yield received
        return

    def interrupt(signum, frame):
        if not received:
            received.append(signum)
            raise Interrupted(signum)

    previous = {signum: signal.signal(signum, interrupt) for signum in HANDLED_SIGNALS}
    try:
        yield received
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)


def main(argv: list[str] | None = None) -> int:
    _standard_streams()
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as exc:  # --help, --version, or a malformed command line (said on one line)
        return int(exc.code or 0)
    level = LOGGER.level
    console = _console(args)
    received: list[int] = []
    try:
        with _signals_as_interrupts() as received:
            if hasattr(args, "config"):
                args.settings = _settings(args)
            code = args.run(args)
            write_stdout()  # flush what was printed: a full disk says so here, in one line
            return code
    except StitchError as exc:
        LOGGER.error(str(exc))
        return exc.exit_code
    except Exception as exc:  # out of memory (a raised --max-megapixels, a busy machine) in numpy, Warp or onnxruntime
        error = out_of_memory(exc)
        if error is None:
            raise
        LOGGER.error(str(error))
        return error.exit_code
    except KeyboardInterrupt:
        signum = received[0] if received else signal.SIGINT
        by = "" if signum == signal.SIGINT else f" by {signal.Signals(signum).name}"
        LOGGER.error(f"interrupted{by}", extra={"label": ""})
        return 128 + signum
    finally:
        LOGGER.removeHandler(console)
        LOGGER.setLevel(level)
        console.close()


if __name__ == "__main__":
    sys.exit(main())
