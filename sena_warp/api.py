"""Stitching from Python, files in and files out, as ``sena-warp image`` and ``video`` do.

Each call is one :class:`~sena_warp.jobs.Job`: its outputs are checked before any input is read and
written together at the end, the Warp device is chosen on the machine that runs it, and it returns
the report ``--report`` writes (``docs/report.md``). Settings are a :class:`~sena_warp.config.Config`
(every field of ``sena-warp config``; :func:`load_config` reads a settings file). An output that exists
is refused with :class:`~sena_warp.errors.OutputError` unless ``overwrite=True`` replaces it (the
command line's ``-y``). Failures are :class:`~sena_warp.errors.StitchError`\\ s whose ``exit_code`` is
the command line's. Progress goes to the ``sena_warp`` logger (silent until logging is configured).
For images as arrays, see :func:`sena_warp.stitch.stitch_images`.
"""

from __future__ import annotations

import os

from .config import Config
from .config_file import load_settings, non_default
from .jobs import Job, run_job

Path = str | os.PathLike


def _overwrite(overwrite: bool) -> str:
    return "overwrite" if overwrite else "refuse"


def stitch_images(a: Path, b: Path, output: Path, config: Config | None = None, *, crop: bool = False,
                  reference: str = "auto", report: Path | None = None, debug: Path | None = None,
                  overwrite: bool = False) -> dict:
    """Stitch the photos ``a`` and ``b`` into ``output`` (.png: transparent where uncovered, .jpg, ...);
    the report. ``crop``: the largest fully covered rectangle; ``reference``: the input kept unwarped
    ("a", "b" or "auto": the right or bottom view); ``report``: also write the report as JSON there;
    ``debug``: a folder for one picture per stage."""
    settings = non_default(config or Config())
    return run_job(Job("image", (a, b), output, settings, report=report, reference=reference, crop=crop,
                       debug=debug, overwrite=_overwrite(overwrite)))


def stitch_videos(left: Path, right: Path, output: Path, config: Config | None = None, *,
                  offset: float | str = 0.0, crop: bool = False, reference: str = "auto",
                  report: Path | None = None, debug: Path | None = None, figures: bool = False,
                  strict: bool = False, overwrite: bool = False) -> dict:
    """Stitch two synchronised videos into ``output`` (.mp4, .mov, .mkv; or .png / .jpg: the stitched frame
    at ``config.video_start_s``); the report. ``offset``: seconds the right video started after the left
    one, or "auto" to estimate them; the span (``video_start_s``, ``video_end_s``), output width,
    codec and rate are settings of ``config``. ``crop``, ``reference``, ``report``, ``debug`` as
    :func:`stitch_images`' (the pictures are of the first estimate); ``figures``: measure the video over
    time into the report; ``strict``: damaged or truncated inputs fail instead of a warning."""
    settings = non_default(config or Config())
    return run_job(Job("video", (left, right), output, settings, report=report, reference=reference, crop=crop,
                       offset_s=offset, strict=strict, figures=figures, debug=debug,
                       overwrite=_overwrite(overwrite)))


def load_config(path: Path) -> Config:
    """The settings of a file written as ``sena-warp config`` prints them (``--config FILE.toml``), checked
    as the command line checks them: InputError on one line for a wrong name, type or value."""
    return Config().replace(**load_settings(path))
