"""Video over time: the figures of every shared recording and of two pans, with seam-over-time pictures.

Usage (from the repository root)::

    .venv/bin/python benchmarks/video_figures.py [--videos ../shared/data/videos] [--out out/video_figures]
        [--runs office_static:static rooftop_handheld:moving-1 ...] [--cpu] [--pans out/pans]
        [--code main --main-repo ../main]
    .venv/bin/python benchmarks/video_figures.py --tables out/video_figures out/video_figures_main

Each run stitches one recording (``sena-warp video``'s code path, libx264 ``veryfast`` crf 20)
with :class:`~sena_warp.evaluation.video_figures.VideoFigures` attached, exactly what
``sena-warp video ... --figures --report`` measures, and writes into ``--out``: ``NAME.mp4``, ``NAME.json``
(the report with ``figures``), ``NAME_strip.png`` (the output's seam band of every 10th frame side by
side, lines top to bottom, the seam in red), ``NAME_frame_K.png`` (a few whole output frames, the
seam in red) and ``NAME_every10/`` (every 10th output frame as composited, the seam dotted in red, for
looking at it frame by frame).
Then it prints a Markdown table per recording; ``--tables DIR ...`` prints them again from the reports
in those folders. A run's mode is ``default`` (the settings as shipped), ``static`` or ``moving-S``
(``--rig moving --reestimate S``). With ``--cpu`` every run is made a second time with only
:class:`~sena_warp.evaluation.video_figures.FrameClock` attached (the figures cost more than the
stitch): its CPU ms per frame goes into the report as ``cpu_per_frame``.

The pans (``pan_rew_theater``, ``pan_rew_lawn_2160``) are made from shared image pairs by
``sena_warp.evaluation.pans`` into ``--pans`` the first time they are needed (1280x720, 5 s, the rig
sliding 400 / 480 px).

``--code main`` measures the moving mode of the code on ``main`` instead ("today's moving mode"):
main's tree (``git archive HEAD`` of ``--main-repo``) is unpacked into a temporary folder as the
package ``sena_warp_main`` and its frame compositor is wrapped so that the same observer sees each
frame (main has no observer; its seam is per estimate, its alpha a map, its gains none).
"""

from __future__ import annotations

import argparse
import ast
import io
import json
import re
import subprocess
import sys
import tarfile
import tempfile
from pathlib import Path

import cv2
import numpy as np

from sena_warp.config import Config
from sena_warp.evaluation.pans import make_pan
from sena_warp.evaluation.video_figures import FrameClock, VideoFigures
from sena_warp.kernels.runtime import resolve_config
from sena_warp.report import write_json
from sena_warp.video.loop import VideoOptions
from sena_warp.video.reader import YuvFrame, probe_video
from sena_warp.video.stitch import CompositedFrame, stitch_videos

REPO = Path(__file__).resolve().parents[1]
RECORDINGS = {  # name: (left, right, modes)
    "rooftop_handheld": ("left.mp4", "right.mp4", ("default", "moving-1")),
    "house_handheld_stereo": ("left.mp4", "right.mp4", ("default", "moving-1")),
    "window_phones_drift": ("left.mp4", "right.mp4", ("default", "moving-1")),
    "pan_rew_theater": ("left.mp4", "right.mp4", ("default", "moving-1")),
    "pan_rew_lawn_2160": ("left.mp4", "right.mp4", ("default", "moving-1")),
    "office_static": ("cam1.mp4", "cam2.mp4", ("default",)),
    "lecture_hall_static": ("left.mp4", "right.mp4", ("default",)),
    "futsal_night_static": ("cam1.mp4", "cam2.mp4", ("default",)),  # it drifts by up to 25 px
    "cafe_person_close": ("left.avi", "right.avi", ("default",)),
}
PANS = {"pan_rew_theater": ("rew_theater", 400.0), "pan_rew_lawn_2160": ("rew_lawn_2160", 480.0)}  # pair, slide px
MAIN_MODES = {name: tuple(m for m in spec[2] if m.startswith("moving")) for name, spec in RECORDINGS.items()
              if any(m.startswith("moving") for m in spec[2])}  # main's moving mode wherever the recording moves
STRIP_EVERY = 10
FRAME_SHARES = (0.0, 0.33, 0.66, 0.99)  # whole frames kept at these shares of the video


def config_for(mode: str, changes: dict) -> Config:
    """The run's settings: ``default`` (as shipped), ``static``, ``moving-S`` (``--rig moving --reestimate S``)
    or ``moving-S-onthread`` (the same with the re-estimates on the loop's thread,
    ``video_estimate_workers=0``, as main makes them: the same frames are estimated every run);
    ``changes``: ``Config`` fields set on top (``--set``)."""
    if mode == "default":
        return Config().replace(**changes)
    if mode == "static":
        return Config(video_rig="static").replace(**changes)
    rig, period, *where = mode.split("-")
    workers = 0 if where == ["onthread"] else Config.video_estimate_workers
    return Config(video_rig=rig, video_reestimate_s=float(period), video_estimate_workers=workers).replace(**changes)


def to_bgr(planes) -> np.ndarray:
    return YuvFrame(0, 0, *planes).to_bgr()


def draw_seam(img: np.ndarray, seam: np.ndarray, rows: bool, shift: np.ndarray | None = None,
              every: int = 1) -> np.ndarray:
    """``img`` with the seam (per line; ``shift`` added) drawn in red, on every ``every``-th line."""
    out = img.copy()
    positions = np.rint(seam + (0 if shift is None else shift)).astype(int)
    for line, pos in enumerate(positions):
        if line % every:
            continue
        if rows and 0 <= pos < out.shape[1]:
            out[line, pos] = (0, 0, 255)
        elif not rows and 0 <= pos < out.shape[0]:
            out[pos, line] = (0, 0, 255)
    return out


def write_pictures(observer: VideoFigures, name: str, out: Path, rows: bool, whole: set[int]) -> None:
    """The seam-over-time strip, the ``whole`` frames with the seam drawn, and every 10th frame of one run."""
    tiles = []
    for _, band, seam, _ in observer.strips:
        tile = draw_seam(cv2.cvtColor(band, cv2.COLOR_GRAY2BGR), seam, True)
        tiles += [tile, np.full((tile.shape[0], 2, 3), 255, np.uint8)]
    if tiles:
        strip = np.hstack(tiles)
        cv2.imwrite(str(out / f"{name}_strip.png"), strip if rows else strip.transpose(1, 0, 2))
    every10 = out / f"{name}_every10"
    every10.mkdir(exist_ok=True)
    for index, (planes, seam) in observer.frames.items():
        if index in whole:
            cv2.imwrite(str(out / f"{name}_frame_{index}.png"), draw_seam(to_bgr(planes), seam, rows))
        if index % STRIP_EVERY == 0:  # the seam dotted on every 8th line: the picture beside it stays visible
            cv2.imwrite(str(every10 / f"frame_{index:04d}.png"), draw_seam(to_bgr(planes), seam, rows, every=8))


def pan_videos(name: str, pans: Path) -> Path:
    """The folder of pan ``name`` (:data:`PANS`), made there the first time (``evaluation.pans``)."""
    folder = pans / name
    if not (folder / "right.mp4").exists():
        pair, slide_px = PANS[name]
        root = REPO.parent / "shared" / "data" / "pairs" / pair
        img_left, img_right = (cv2.imread(str(next(root.glob(f"{side}.*")))) for side in "ab")
        make_pan(img_left, img_right, folder, slide_px)
    return folder


def main_package(main_repo: Path, into: Path) -> None:
    """main's tree as the importable package ``sena_warp_main`` under ``into`` (read from git, not the worktree)."""
    archive = subprocess.run(["git", "-C", str(main_repo), "archive", "HEAD"], check=True, capture_output=True).stdout
    root = into / "sena_warp_main"
    with tarfile.open(fileobj=io.BytesIO(archive)) as tar:
        for member in tar.getmembers():
            parts = Path(member.name).parts
            if not member.isfile() or not parts or parts[0] not in ("sena_warp", "kernels", "video"):
                continue
            rel = Path(*parts[1:]) if parts[0] == "sena_warp" else Path(parts[0], *parts[1:])
            target = root / rel
            target.parent.mkdir(parents=True, exist_ok=True)
            data = tar.extractfile(member).read()
            if target.suffix == ".py":
                data = re.sub(rb"\bsena_warp\b", b"sena_warp_main", data)
            target.write_bytes(data)


def main_compositor_class(observer: VideoFigures):
    """main's ``SenaFrameCompositor`` wrapped so that ``observer`` sees every composited frame."""
    from sena_warp_main.video import stitch as main_stitch  # noqa: PLC0415 (built by main_package)

    identity = (np.ones(1), np.zeros(1), np.ones(1), np.zeros(1))
    # The class main's stitch_videos builds is replaced for each run: wrap main's own, not the last wrapper.
    base = main_stitch.__dict__.setdefault("_UNOBSERVED", main_stitch.SenaFrameCompositor)

    class Observed(base):
        frames = 0
        time_s = None

        def update(self, frame_l, frame_r):
            self.time_s = float(frame_l.time_s)
            super().update(frame_l, frame_r)

        def composite_yuv(self, y_l, u_l, v_l, y_r, u_r, v_r):
            out = super().composite_yuv(y_l, u_l, v_l, y_r, u_r, v_r)
            planes_src, planes_tgt = self.source_target((y_l, u_l, v_l), (y_r, u_r, v_r))
            maps = self.maps
            home = main_stitch_filled(maps.seam_x_working)
            zeros = np.zeros((len(home), 1))
            observer(CompositedFrame(
                index=self.frames, time_s=self.time_s, source="left" if self.rig.source == "a" else "right",
                planes_src=planes_src, planes_tgt=planes_tgt, planes_out=out,
                window=(0.0, 0.0, out[0].shape[1], out[0].shape[0]), maps=maps, seam=home, gains_luma=identity,
                knee_luma=None, offsets_luma=(zeros, zeros),
                weights=lambda: (maps.alpha_luma, np.zeros_like(maps.alpha_luma)), canvas=lambda: out))
            self.frames += 1
            return out
    return main_stitch, Observed


def main_stitch_filled(positions: np.ndarray) -> np.ndarray:
    known = np.isfinite(positions)
    lines = np.arange(len(positions))
    return np.interp(lines, lines[known], positions[known]).astype(np.float32)


def run_one(recording: str, mode: str, offset_s: float, videos: Path, out: Path, code: str, changes: dict,
            cpu: bool = False, pans: Path | None = None) -> dict:
    """One run (``--offset offset_s``): its report with ``figures`` (and ``cpu_per_frame`` with ``cpu``);
    writes the video, report and pictures."""
    left_name, right_name, _ = RECORDINGS[recording]
    folder = pan_videos(recording, pans) if recording in PANS else videos / recording
    left, right = folder / left_name, folder / right_name
    name = f"{recording}_{mode}" + (f"_offset{offset_s:+g}" if offset_s else "") + ("_main" if code == "main" else "")
    frames = min(probe_video(left).frame_count or 300, probe_video(right).frame_count or 300)
    keep = tuple(sorted({int(share * (frames - 1)) for share in FRAME_SHARES}))
    cfg = resolve_config(config_for(mode, changes))
    observer = VideoFigures(cfg, strip_every=STRIP_EVERY, keep_frames=keep + tuple(range(0, frames, STRIP_EVERY)))
    output = out / f"{name}.mp4"
    if code == "main":
        main_stitch, observed = main_compositor_class(observer)
        main_cfg = resolve_config(main_stitch.Config(video_rig=cfg.video_rig, video_reestimate_s=cfg.video_reestimate_s))
        main_stitch.SenaFrameCompositor = observed  # the factory in main's stitch_videos builds this class
        report = main_stitch.stitch_videos(left, right, output, main_cfg, main_stitch.VideoOptions.from_config(
            main_cfg, offset_s=offset_s))
    else:
        report = stitch_videos(left, right, output, cfg, VideoOptions.from_config(cfg, offset_s=offset_s),
                               observer=observer)
    if cpu:
        clock = FrameClock()
        with tempfile.TemporaryDirectory() as temp:
            stitch_videos(left, right, Path(temp) / "cpu.mp4", cfg, VideoOptions.from_config(cfg, offset_s=offset_s),
                          observer=clock)
        report["cpu_per_frame"] = clock.figures()
    report["figures"] = observer.figures()
    report["figures_code"] = code
    report["figures_mode"] = mode
    report["figures_settings"] = changes
    write_json(out / f"{name}.json", report)
    write_pictures(observer, name, out, not report["stitch"]["rig"]["vertical"], set(keep))
    return report


def _fmt(value, digits: int = 2) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


def table(recording: str, reports: dict[str, dict]) -> str:
    """The Markdown table of one recording's runs."""
    lines = [f"**{recording}**", "",
             "| run | frames | seam motion mean / p99 / max px | frames the seam moved | where nothing moves: max px "
             "(frames moved / with still lines) | exposure step mean / p99 (settled) | every line: mean (lines aligned %) "
             "| step change p99 (settled) "
             "| misalignment median / p95 px | stability | output shake mean / p95 px "
             "| uncovered max / largest change % | CPU ms/frame | re-est. acc/rej |",
             "|---|---:|---|---:|---|---|---|---|---|---:|---|---|---:|---|"]
    for run, report in reports.items():
        fig, st = report["figures"], report["stitch"]
        motion, step, change = fig["seam_motion_px"], fig["exposure_step_grey"], fig["exposure_step_change_grey"]
        mis, re_est, uncovered = fig["misalignment_px"], st["reestimations"], fig.get("uncovered_pct", {})
        shake = fig.get("output_shake_px", {})
        lines.append(
            f"| {run} | {fig['frames']} | {_fmt(motion['mean'])} / {_fmt(motion['p99'])} / {_fmt(motion['max'])} "
            f"| {motion['frames_moving']} | {_fmt(motion['where_still_max'])} ({motion['frames_moving_where_still']} / "
            f"{motion['frames_with_still_lines']}) | {_fmt(step['mean'])} / {_fmt(step['p99'])} "
            f"({_fmt(step['settled_mean'])} / {_fmt(step['settled_p99'])}) "
            f"| {_fmt(step.get('all_lines_mean'))} ({_fmt(step.get('aligned_lines_pct'), 1)}) | {_fmt(change['p99'])} "
            f"({_fmt(change['settled_p99'])}) | {_fmt(mis['median'])} / {_fmt(mis['p95'])} "
            f"| {_fmt(fig['stability']['value'], 3)} | {_fmt(shake.get('mean'))} / {_fmt(shake.get('p95'))} "
            f"| {_fmt(uncovered.get('max'))} / "
            f"{_fmt(uncovered.get('largest_change'))} | {_fmt(report.get('cpu_per_frame', {}).get('mean_ms'), 1)} "
            f"| {re_est['accepted']}/{re_est['rejected']} |")
    return "\n".join(lines)


def run_label(report: dict) -> str:
    """`static` / `moving-S`, the offset when there is one, and (main) for main's code."""
    rig = report["stitch"]["rig"]
    mode = "static" if rig["mode"] == "static" else f"moving-{rig['reestimate_s']:g}"
    mode = "default: " + mode if report.get("figures_mode") == "default" else mode
    mode += "-onthread" if report.get("figures_mode", "").endswith("onthread") else ""
    offset = report["inputs"]["right"]["offset_s"]
    return f"`{mode}`" + (f" `--offset {offset:g}`" if offset else "") + \
        (" (main)" if report.get("figures_code") == "main" else "")


def print_tables(folders: list[Path]) -> None:
    by_recording: dict[str, dict[str, dict]] = {}
    for folder in folders:
        for path in sorted(folder.glob("*.json")):
            report = json.loads(path.read_text())
            recording = Path(report["inputs"]["left"]["path"]).parent.name
            by_recording.setdefault(recording, {})[run_label(report)] = report
    for recording in RECORDINGS:
        if recording in by_recording:
            print(table(recording, by_recording[recording]))
            print()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--videos", type=Path, default=REPO.parent / "shared" / "data" / "videos")
    parser.add_argument("--out", type=Path, default=REPO / "out" / "video_figures")
    parser.add_argument("--runs", nargs="*",
                        help="RECORDING:MODE[:OFFSET_S] (default: every recording, every mode, offset 0)")
    parser.add_argument("--set", nargs="*", default=[], metavar="NAME=VALUE",
                        help="Config changes for every run of this tree's code (e.g. video_align_follow=0.5)")
    parser.add_argument("--code", choices=("branch", "main"), default="branch")
    parser.add_argument("--main-repo", type=Path, default=REPO.parent / "main")
    parser.add_argument("--tables", type=Path, nargs="+", metavar="DIR", help="only print the tables of these reports")
    parser.add_argument("--cpu", action="store_true", help="run each case again for its CPU time per frame")
    parser.add_argument("--pans", type=Path, default=REPO / "out" / "pans", help="where the pans are (made if missing)")
    args = parser.parse_args(argv)
    if args.tables:
        print_tables(args.tables)
        return 0
    changes = {k: ast.literal_eval(v) for k, v in (item.split("=", 1) for item in args.set)}
    args.out.mkdir(parents=True, exist_ok=True)
    modes = MAIN_MODES if args.code == "main" else {name: spec[2] for name, spec in RECORDINGS.items()}
    runs = [(*r.split(":")[:2], float(r.split(":")[2]) if r.count(":") == 2 else 0.0) for r in args.runs] \
        if args.runs else [(name, mode, 0.0) for name, names in modes.items() for mode in names]
    if args.code == "main":
        temp = Path(tempfile.mkdtemp(prefix="sena_main_"))
        main_package(args.main_repo, temp)
        sys.path.insert(0, str(temp))
    reports: dict[str, dict[str, dict]] = {}
    for recording, mode, offset_s in runs:
        report = run_one(recording, mode, offset_s, args.videos, args.out, args.code, changes, args.cpu, args.pans)
        label = run_label(report)
        reports.setdefault(recording, {})[label] = report
        print(f"{recording} {label}: {json.dumps({k: v for k, v in report['figures'].items() if k != 'per_frame'})}",
              flush=True)
    for recording, by_run in reports.items():
        print()
        print(table(recording, by_run))
    return 0


if __name__ == "__main__":
    sys.exit(main())
