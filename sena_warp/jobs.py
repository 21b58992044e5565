"""One stitch from files to files: what ``sena-warp image`` and ``video`` run, and each job of ``batch``.

A :class:`Job` names its inputs, outputs and the settings it changes; :func:`run_job` builds the
:class:`Config` on the machine that runs it (where the Warp device is resolved, so a Ray task on a GPU
node gets CUDA), plans every output (``sena_warp.outputs``: checked before any input is read, written
together at the end), stitches and returns the report (``docs/report.md``).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

from sena_warp.kernels.runtime import resolve_config

from .config import OFFSET_AUTO, Config, is_seconds
from .config_file import check_settings, settings_config
from .errors import InputError
from .imageio import IMAGE_SUFFIXES
from .outputs import OVERWRITE_MODES, OutputPlan
from .progress import LOGGER, stage, write_stdout
from .rig import REFERENCES

KINDS = ("image", "video")
PAIR_STEMS = {"image": ("a", "b"), "video": ("left", "right")}  # file stems of a pair folder
INPUT_SUFFIXES = {"image": IMAGE_SUFFIXES, "video": (".mp4", ".mov", ".mkv", ".m4v", ".avi", ".webm", ".ts")}
# The first: a batch job's default. A video job's .png or .jpg is a still of its first frame (``--ss``).
OUTPUT_SUFFIXES = {"image": IMAGE_SUFFIXES, "video": (".mp4", ".mov", ".mkv", ".png", ".jpg", ".jpeg")}


@dataclass(frozen=True)
class Job:
    """One stitch. ``inputs``: images (a, b) or videos (left, right); ``settings``: Config changes by name.

    ``reference``: input kept unwarped ("a" / "b", "auto" = the right or bottom view); ``crop``: keep the
    largest fully covered rectangle (images) or the largest the first estimate covers (videos, for the
    whole video); ``offset_s`` (videos): seconds the right video started after the left one, or "auto"
    to estimate them; ``strict`` (videos): damaged or truncated inputs fail the job instead of a
    warning; ``figures`` (videos): measure the video over time into the report's ``figures``
    (``evaluation.video_figures``); ``debug``: folder for one picture per stage (a video's: of its first
    estimate);
    ``overwrite``: what an existing output gets, one of ``outputs.OVERWRITE_MODES`` (the CLI's default
    refuses it, ``-y`` replaces it, ``-n`` skips the job).
    """

    kind: str
    inputs: tuple[str, str]
    output: str
    settings: dict = field(default_factory=dict)
    report: str | None = None
    reference: str = "auto"
    crop: bool = False
    offset_s: float | str = 0.0
    strict: bool = False
    figures: bool = False
    debug: str | None = None
    overwrite: str = "refuse"

    def __post_init__(self) -> None:
        """InputError for a field of the wrong kind, before anything runs (settings: names and values)."""
        if self.kind not in KINDS:
            raise InputError(f"Job: kind {self.kind!r} unknown; use one of {', '.join(KINDS)}")
        paths = (*self.inputs, self.output) if isinstance(self.inputs, (tuple, list)) else ()
        if len(paths) != 3 or not all(isinstance(p, (str, os.PathLike)) for p in paths):
            raise InputError(f"Job: inputs must be two paths ({' and '.join(PAIR_STEMS[self.kind])}) and output one "
                             f"path, got {self.inputs!r} and {self.output!r}")
        if not isinstance(self.settings, dict):
            raise InputError(f"Job: settings must be a dict of Config changes, got {type(self.settings).__name__}")
        check_settings(self.settings, "Job settings")
        if self.reference not in REFERENCES:
            raise InputError(f"Job: reference must be one of {', '.join(REFERENCES)}, not {self.reference!r}")
        if self.overwrite not in OVERWRITE_MODES:
            raise InputError(f"Job: overwrite must be one of {', '.join(OVERWRITE_MODES)}, not {self.overwrite!r}")
        if self.offset_s != OFFSET_AUTO and not is_seconds(self.offset_s):
            raise InputError(f"offset {self.offset_s!r} s is not a time; give a finite number of seconds or "
                             f"{OFFSET_AUTO!r} (--offset)")


def job_config(settings: dict) -> Config:
    """The Config for ``settings`` (names and values already checked one by one), on this machine.

    The Warp device is resolved here; the encoder is h264_nvenc where that device is CUDA and the
    settings chose no codec (the writer falls back to libx264, saying so, where NVENC cannot open).
    """
    cfg = resolve_config(settings_config(settings, "settings"))
    codec = cfg.video_codec if "video_codec" in settings or cfg.device != "cuda" else "h264_nvenc"
    return cfg.replace(video_codec=codec)


def pair_inputs(folder: str | os.PathLike) -> tuple[str, tuple[Path, Path]] | None:
    """("image", (a, b)) or ("video", (left, right)) for a pair folder; None when ``folder`` holds no
    input of either kind (a folder of something else); InputError saying what is wrong with one that
    tries to be a pair folder and is not.

    A pair folder holds exactly one file per stem (``a.*`` and ``b.*``, or ``left.*`` and ``right.*``;
    stems and suffixes in any case: ``A.JPG``) with a suffix of that kind, and not both pairs.
    Hidden files (``.name``) are not looked at.
    """
    folder = Path(folder)
    files = sorted(p for p in folder.iterdir() if not p.name.startswith(".") and p.is_file())
    found = {kind: {stem: [p for p in files if p.stem.lower() == stem and p.suffix.lower() in INPUT_SUFFIXES[kind]]
                    for stem in stems} for kind, stems in PAIR_STEMS.items()}
    complete = [kind for kind, by_stem in found.items() if all(len(paths) == 1 for paths in by_stem.values())]
    if len(complete) == 1:
        return complete[0], tuple(paths[0] for paths in found[complete[0]].values())
    listed = ", ".join(p.name for p in files)
    if complete:
        raise InputError(f"{folder}: holds both an image pair and a video pair ({listed}); keep one of them")
    for by_stem in found.values():
        for stem, paths in by_stem.items():
            if len(paths) > 1:
                raise InputError(f"{folder}: {len(paths)} files for {stem}.* ({', '.join(p.name for p in paths)}); "
                                 f"keep one")
    media = [p for p in files if any(p.suffix.lower() in suffixes for suffixes in INPUT_SUFFIXES.values())]
    if not media:
        return None
    kind = max(found, key=lambda k: sum(len(paths) for paths in found[k].values()))
    missing = " and ".join(f"{stem}.*" for stem, paths in found[kind].items() if not paths)
    raise InputError(f"{folder}: no {missing} {'image' if kind == 'image' else 'video'} (found {listed}); a pair "
                     f"folder holds {' + '.join(s + '.*' for s in PAIR_STEMS['image'])} images or "
                     f"{' + '.join(s + '.*' for s in PAIR_STEMS['video'])} videos")


def checked(plan: OutputPlan) -> bool:
    """Check ``plan`` (raises on a broken rule); False, after saying so on stdout, when -n found an
    existing output (the command then does nothing)."""
    existing = plan.check()
    for path in existing:
        write_stdout(f"{path}: exists, skipped (-n)\n")
    return not existing


def output_plan(job: Job) -> OutputPlan:
    """The plan of ``job``'s outputs: the stitch, its report and debug folder (not yet checked)."""
    plan = OutputPlan(job.inputs, job.overwrite)
    plan.add(job.output, "-o", suffixes=OUTPUT_SUFFIXES[job.kind])
    if job.report:
        plan.add(job.report, "--report")
    if job.debug:
        plan.add(job.debug, "--debug", folder=True)
    return plan


def run_job(job: Job) -> dict | None:
    """Stitch ``job`` and write its outputs; its report (also written to ``job.report`` when set), or
    None when ``job.overwrite`` is "skip" and an output exists (nothing done)."""
    cfg = job_config(job.settings)
    return _image(job, cfg) if job.kind == "image" else _video(job, cfg)


def _image(job: Job, cfg: Config) -> dict | None:
    from sena_warp.evaluation.figures import report_figures

    from .crop import crop_to_covered
    from .debug import dump_stages
    from .imageio import read_image_masked, write_image
    from .report import image_report, write_json
    from .stitch import stitch_images

    plan = output_plan(job)
    if not checked(plan):  # before the stitch: a bad --report must not cost a stitch or leave a panorama
        return None
    stage("reading images")
    (img_a, transparent_a), (img_b, transparent_b) = (read_image_masked(path, cfg.max_input_megapixels)
                                                      for path in job.inputs)
    pano = stitch_images(img_a, img_b, cfg, reference=job.reference, transparent=(transparent_a, transparent_b))
    image, crop = crop_to_covered(pano.image) if job.crop else (pano.image, None)
    # The front end measures the stitch for its report; the pipeline itself never imports the evaluation.
    report = image_report(pano, img_a, img_b, report_figures(img_a, img_b, pano, cfg), cfg, crop)
    report["output"] = {"path": str(job.output), "width": int(image.shape[1]), "height": int(image.shape[0])}
    stage("writing outputs")
    with plan:  # every output or none
        write_image(job.output, image, plan=plan)
        if job.debug:
            with plan.writing(job.debug) as folder:
                dump_stages(folder, img_a, img_b, pano, cfg)
        if job.report:
            write_json(job.report, report, plan)
    return report


def _video(job: Job, cfg: Config) -> dict | None:
    from dataclasses import replace

    from sena_warp.video.loop import VideoOptions
    from sena_warp.video.stitch import stitch_videos
    from sena_warp.video.sync import estimate_offset

    from .report import write_json

    auto = job.offset_s == OFFSET_AUTO
    # Every option is checked before any file is opened; with an automatic offset, 0 stands in until the estimate.
    options = VideoOptions.from_config(cfg, offset_s=0.0 if auto else job.offset_s, strict=job.strict)
    cfg = cfg.replace(video_crop=cfg.video_crop or job.crop)
    plan = output_plan(job)
    if not checked(plan):  # before decoding: a bad --report must not cost a stitch or leave a video
        return None
    sync = estimate_offset(*job.inputs, cfg) if auto else None
    if sync is not None:
        # Said even with -q, as a fallback is: the user must be able to check the offset the stitch used.
        LOGGER.warning(f"offset auto: {sync.summary()}", extra={"label": ""})
        options = replace(options, offset_s=sync.offset_s)
    observer = None
    if job.figures:  # the front end measures the video for its report; the pipeline only calls the observer
        from sena_warp.evaluation.video_figures import VideoFigures

        observer = VideoFigures(cfg)
    with plan:  # every output or none
        report = stitch_videos(*job.inputs, job.output, cfg, options, reference=job.reference, plan=plan,
                               observer=observer, debug=job.debug)
        if observer is not None:
            report["figures"] = observer.figures()
        report["sync"] = (sync.as_dict() if sync is not None
                          else {"method": "manual", "offset_ms": options.offset_s * 1000})
        if job.report:
            write_json(job.report, report, plan)
    return report


def summary_line(kind: str, report: dict) -> str:
    """What a finished job made, in one line (the CLI prints it after the output's name)."""
    if kind == "image":
        out, m = report["output"], report["metrics"]
        return (f"{out['width']}x{out['height']} px, source={report['rig']['source']}, "
                f"{report['features']['matches']} matches, {report['global_affine']['inliers']} inliers, "
                f"{report['anchors']['count']} anchors, overlap PSNR {m['overlap_psnr_db']} dB, "
                f"{report['timing_s']['total']:.2f} s")
    out, st, timing = report["output"], report["stitch"], report["timing_s"]
    if "still" in report:
        return (f"{out['width']}x{out['height']} px, the frame at {report['still']['left_time_s']:.2f} s, "
                f"source={st['rig']['source']}, {st['first_estimate']['inliers']} inliers, {timing['total']:.2f} s")
    after_estimate_s = timing["total"] - timing["compositor_setup"]
    steady = f", {report['frames_out'] / after_estimate_s:.1f} fps after the first estimate" if after_estimate_s > 0 else ""
    warnings = f", {len(report['warnings'])} warnings" if report["warnings"] else ""
    return (f"{out['width']}x{out['height']} px, {report['frames_out']} frames at {out['fps']:g} fps "
            f"({_rate_control(out['encoder'])}), source={st['rig']['source']}, {st['first_estimate']['inliers']} inliers, "
            f"re-estimations {st['reestimations']['accepted']} accepted / {st['reestimations']['rejected']} rejected, "
            f"seam jitter {st['jitter']['seam_jitter_px_mean']} px, dropped {report['dropped']}, "
            f"repeated {report['repeated']}, damaged {sum(report['damaged'].values())}, "
            f"{report['output_fps']} fps overall{steady}{warnings}{_figures_summary(report.get('figures'))}")


def _rate_control(encoder: dict) -> str:
    """The encoder and its rate control as the report gives them, e.g. "libx265, crf 20"."""
    rate = f"{encoder['bitrate_kbps']} kbit/s" if encoder["rate_control"] == "bitrate" else f"crf {encoder['crf']}"
    peak = f", peak {encoder['maxrate_kbps']} kbit/s" if encoder["maxrate_kbps"] else ""
    return f"{encoder['codec']}, {rate}{peak}"


def _figures_summary(fig: dict | None) -> str:
    """``video --figures``' headline figures, appended to the summary line."""
    if fig is None:
        return ""
    return (f"; seam motion p99 {fig['seam_motion_px']['p99']} px, exposure step mean "
            f"{fig['exposure_step_grey']['mean']}, misalignment median {fig['misalignment_px']['median']} px, "
            f"stability {fig['stability']['value']}")
