"""One stitch from files to files: what ``sena-warp image`` and ``video`` run, and each job of ``batch``.

A :class:`Job` names its inputs, outputs and the settings it changes; :func:`run_job` builds the
:class:`Config` on the machine that runs it (where the Warp device is resolved, so a Ray task on a GPU
node gets CUDA), checks every output path before any work, stitches, writes the outputs and returns
the report (``docs/report.md``).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

from sena_warp.kernels.runtime import resolve_config

from .config import Config
from .config_file import check_config
from .errors import OutputError
from .progress import stage

KINDS = ("image", "video")
PAIR_STEMS = {"image": ("a", "b"), "video": ("left", "right")}  # file stems of a pair folder
INPUT_SUFFIXES = {
    "image": (".jpg", ".jpeg", ".png", ".tif", ".tiff", ".bmp", ".webp"),
    "video": (".mp4", ".mov", ".mkv", ".m4v", ".avi", ".webm", ".ts"),
}
OUTPUT_SUFFIXES = {"image": (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".webp"), "video": (".mp4", ".mov", ".mkv")}


@dataclass(frozen=True)
class Job:
    """One stitch. ``inputs``: images (a, b) or videos (left, right); ``settings``: Config changes by name.

    ``reference``: input kept unwarped ("a" / "b", "auto" = the right or bottom view); ``crop`` (images):
    keep the largest fully covered rectangle; ``offset_s`` (videos): seconds the right video started after
    the left one; ``debug`` (images): folder for one picture per stage.
    """

    kind: str
    inputs: tuple[str, str]
    output: str
    settings: dict = field(default_factory=dict)
    report: str | None = None
    reference: str = "auto"
    crop: bool = False
    offset_s: float = 0.0
    debug: str | None = None


def job_config(settings: dict) -> Config:
    """The Config for ``settings`` (names and values already checked one by one), on this machine.

    The Warp device is resolved here; the encoder is h264_nvenc where that device is CUDA and the
    settings chose no codec (the writer falls back to libx264, saying so, where NVENC cannot open).
    """
    cfg = resolve_config(check_config(Config().replace(**settings), "settings"))
    codec = cfg.video_codec if "video_codec" in settings or cfg.device != "cuda" else "h264_nvenc"
    return cfg.replace(video_codec=codec)


def pair_inputs(folder: str | os.PathLike) -> tuple[str, tuple[Path, Path]] | None:
    """("image", (a, b)) or ("video", (left, right)) for a pair folder; None when ``folder`` is not one.

    A pair folder holds exactly one file per stem (``a.*`` and ``b.*``, or ``left.*`` and ``right.*``)
    with a suffix of that kind.
    """
    folder = Path(folder)
    for kind, stems in PAIR_STEMS.items():
        found = [[p for p in folder.glob(f"{stem}.*") if p.suffix.lower() in INPUT_SUFFIXES[kind]] for stem in stems]
        if all(len(paths) == 1 for paths in found):
            return kind, (found[0][0], found[1][0])
    return None


def check_output_suffix(path: str | os.PathLike, kind: str) -> None:
    """OutputError unless ``path`` ends in a suffix a ``kind`` job can write."""
    allowed = OUTPUT_SUFFIXES[kind]
    if Path(path).suffix.lower() not in allowed:
        raise OutputError(f"{path}: unsupported output type; use one of {', '.join(allowed)}")


def run_job(job: Job) -> dict:
    """Stitch ``job`` and write its outputs; its report (also written to ``job.report`` when set)."""
    cfg = job_config(job.settings)
    return _image(job, cfg) if job.kind == "image" else _video(job, cfg)


def _image(job: Job, cfg: Config) -> dict:
    from sena_warp.evaluation.figures import report_figures

    from .crop import crop_to_covered
    from .debug import dump_stages
    from .imageio import check_output_folder, check_output_path, read_image, write_image
    from .report import image_report, write_json
    from .stitch import stitch_images

    check_output_suffix(job.output, "image")
    for path in filter(None, (job.output, job.report)):
        check_output_path(path, job.inputs)  # before the stitch: a bad path must not leave a panorama behind
    if job.debug:
        check_output_folder(job.debug)
    stage("reading images")
    img_a, img_b = (read_image(path) for path in job.inputs)
    pano = stitch_images(img_a, img_b, cfg, reference=job.reference)
    image, crop = crop_to_covered(pano.image) if job.crop else (pano.image, None)
    stage("writing outputs")
    write_image(job.output, image, inputs=job.inputs)
    if job.debug:
        dump_stages(job.debug, img_a, img_b, pano, cfg)
    # The front end measures the stitch for its report; the pipeline itself never imports the evaluation.
    report = image_report(pano, img_a, img_b, report_figures(img_a, img_b, pano, cfg), cfg, crop)
    report["output"] = {"path": str(job.output), "width": int(image.shape[1]), "height": int(image.shape[0])}
    if job.report:
        write_json(job.report, report)
    return report


def _video(job: Job, cfg: Config) -> dict:
    from sena_warp.video.loop import VideoOptions
    from sena_warp.video.stitch import stitch_videos

    from .imageio import check_output_path
    from .report import write_json

    check_output_suffix(job.output, "video")
    for path in filter(None, (job.output, job.report)):
        check_output_path(path, job.inputs)  # before decoding: a bad report path must not leave a video
    report = stitch_videos(*job.inputs, job.output, cfg, VideoOptions.from_config(cfg, offset_s=job.offset_s),
                           reference=job.reference)
    if job.report:
        write_json(job.report, report)
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
    after_estimate_s = timing["total"] - timing["compositor_setup"]
    steady = f", {report['frames_out'] / after_estimate_s:.1f} fps after the first estimate" if after_estimate_s > 0 else ""
    return (f"{out['width']}x{out['height']} px, {report['frames_out']} frames at {out['fps']:g} fps "
            f"({out['encoder']['codec']}), source={st['rig']['source']}, {st['first_estimate']['inliers']} inliers, "
            f"re-estimations {st['reestimations']['accepted']} accepted / {st['reestimations']['rejected']} rejected, "
            f"seam jitter {st['jitter']['seam_jitter_px_mean']} px, dropped {report['dropped']}, "
            f"repeated {report['repeated']}, {report['output_fps']} fps overall{steady}")
