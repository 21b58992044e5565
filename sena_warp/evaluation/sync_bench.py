"""Accuracy of ``--offset auto``: clips cut from recorded pairs at known shifts.

``cut_pair`` cuts a window of one recording and the same window of another (or the same) one
started ``shift_s`` later (earlier when negative). The video is re-encoded (H.264), the audio
packets copied with their timing against the first frame kept, so a clip's audio stays where its
video is. Each clip's clock starts at its first frame, so the cut adds the *realised* shift (the
first frames' source times differ by whole frames) to the recordings' own offset: zero when both
clips come from one recording, which makes that offset exact. ``benchmarks/bench_sync.py`` runs
:func:`main` over the shared recordings; the tests use the same cuts.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path

import av

from sena_warp.config import Config
from sena_warp.errors import SyncError
from sena_warp.video.reader import probe_video
from sena_warp.video.sync import METHODS, SyncEstimate, measure_offset

REPO = Path(__file__).resolve().parents[2]
SHIFTS_S = (0.5, 1.37, -2.0)  # the shifts of the cut clips
# (name, left, right) under shared/data/videos
RECORDINGS = (
    ("rooftop_handheld", "left.mp4", "right.mp4"),
    ("office_static", "cam1.mp4", "cam2.mp4"),
    ("house_handheld_stereo", "left.mp4", "right.mp4"),
    ("lecture_hall_static", "left.mp4", "right.mp4"),
    ("futsal_night_static", "cam1.mp4", "cam2.mp4"),
)
CLIP_START_S = 2.0  # the left window starts here, so a -2 s shift still starts inside the recording
CLIP_SECONDS = 6.0  # window length where the recordings are long enough
CLIP_CRF = "23"
CLIP_TIMESCALE = "96000"  # MP4 movie timescale (ticks/s): places every audio start to the sample
CLIP_PRESET = "ultrafast"  # quick to cut; the codec's block noise is part of what sync must ignore


@dataclass(frozen=True)
class CutPair:
    """Two clips and the source times (s, on each recording's video clock) of their first frames."""

    left: Path
    right: Path
    first_left_s: Fraction
    first_right_s: Fraction

    @property
    def realised_shift_s(self) -> float:
        """What the cut adds to the recordings' own offset."""
        return float(self.first_right_s - self.first_left_s)


def cut_clip(src: Path, dst: Path, start_s: float, seconds: float, keep_audio: bool) -> Fraction:
    """Cut the frames of ``[start_s, start_s + seconds)`` of ``src`` (and its audio over their span) to ``dst``.

    Returns the source time of the clip's first frame, which is the clip's time zero.
    """
    # The MP4 muxer writes a late audio start as an edit in the movie timescale: 1 ms by default.
    with av.open(str(src)) as inp, av.open(str(dst), "w", options={"movie_timescale": CLIP_TIMESCALE}) as out:
        v_in = inp.streams.video[0]
        rate = Fraction(v_in.average_rate)
        v_out = out.add_stream("libx264", rate=rate, options={"crf": CLIP_CRF, "preset": CLIP_PRESET})
        v_out.width, v_out.height = v_in.codec_context.width, v_in.codec_context.height
        v_out.pix_fmt = v_in.codec_context.format.name
        v_out.codec_context.time_base = 1 / rate
        a_in = inp.streams.audio[0] if keep_audio and inp.streams.audio else None
        a_out = out.add_stream_from_template(a_in) if a_in is not None else None

        v_tb, v_start = Fraction(v_in.time_base), v_in.start_time or 0
        first = None
        for frame in inp.decode(v_in):
            t = (frame.pts - v_start) * v_tb
            if t < start_s:
                continue
            if t >= start_s + seconds:
                break
            first = t if first is None else first
            frame.pts, frame.time_base = round((t - first) * rate), 1 / rate
            out.mux(v_out.encode(frame))
        out.mux(v_out.encode(None))

        if a_in is not None:
            a_tb = Fraction(a_in.time_base)
            zero = v_start * v_tb + first  # the first frame's time on the container's timeline
            shift = round(zero / a_tb)
            inp.seek(0)
            for packet in inp.demux(a_in):
                if packet.pts is None or not zero <= packet.pts * a_tb < zero + seconds:
                    continue
                packet.pts -= shift
                packet.dts -= shift
                packet.stream = a_out
                out.mux(packet)
    return first


def cut_pair(left: Path, right: Path, work: Path, shift_s: float, keep_audio: bool,
             start_s: float = CLIP_START_S, seconds: float = CLIP_SECONDS) -> CutPair:
    """Cut ``left`` from ``start_s`` and ``right`` from ``start_s + shift_s`` into ``work``.

    The windows are ``seconds`` long, shorter where a recording ends sooner. ``left`` and
    ``right`` may be one file.
    """
    work.mkdir(parents=True, exist_ok=True)
    seconds = min(seconds, probe_video(left).duration_s - start_s, probe_video(right).duration_s - start_s - shift_s)
    tag = f"{shift_s:+.2f}{'' if keep_audio else '_mute'}"
    clips = work / f"a_{left.stem}_{tag}{left.suffix}", work / f"b_{right.stem}_{tag}{right.suffix}"
    first_l = cut_clip(left, clips[0], start_s, seconds, keep_audio)
    first_r = cut_clip(right, clips[1], start_s + shift_s, seconds, keep_audio)
    return CutPair(clips[0], clips[1], first_l, first_r)


def _try(left: Path, right: Path, method: str, cfg: Config) -> SyncEstimate | SyncError:
    try:
        return measure_offset(left, right, method, cfg)
    except SyncError as exc:
        return exc


def _text(result: SyncEstimate | SyncError) -> str:
    if isinstance(result, SyncError):
        return f"refused: {result}"
    return f"{result.offset_s * 1000:+.1f} ms (confidence {result.peak.confidence:.2f})"


def _error_text(result: SyncEstimate | SyncError, expected_s: float | None) -> str:
    if isinstance(result, SyncError) or expected_s is None:
        return _text(result)
    return f"{(result.offset_s - expected_s) * 1000:+.2f} ms"


def measure(videos: Path, work: Path, cfg: Config) -> tuple[list[str], list[str]]:
    """Two Markdown tables: each recorded pair's offset by each method, and the cut clips' errors.

    A cut's expected offset is its realised shift plus, for clips of two cameras, the pair's own
    offset (by audio where it is accepted, else by motion; none when both refuse).
    """
    own_rows = ["| recording | audio | motion |", "|---|---|---|"]
    cut_rows = ["| recording | clips from | method | " + " | ".join(f"{s:+g} s: error" for s in SHIFTS_S) + " |",
                "|---|---|---|" + "---:|" * len(SHIFTS_S)]
    for name, left_name, right_name in RECORDINGS:
        left, right = videos / name / left_name, videos / name / right_name
        audio = probe_video(left).has_audio and probe_video(right).has_audio
        methods = METHODS if audio else METHODS[1:]
        own = {method: _try(left, right, method, cfg) for method in methods}
        own_rows.append(f"| {name} | {_text(own['audio']) if audio else 'no audio'} | {_text(own['motion'])} |")
        accepted = [r for r in own.values() if isinstance(r, SyncEstimate)]
        for source, other, own_s in ((left_name, left, 0.0),
                                     (f"{left_name} + {right_name}", right, accepted[0].offset_s if accepted else None)):
            cuts = [cut_pair(left, other, work / name, shift_s, keep_audio=True) for shift_s in SHIFTS_S]
            for method in methods:
                cells = [_error_text(_try(cut.left, cut.right, method, cfg),
                                     None if own_s is None else own_s + cut.realised_shift_s) for cut in cuts]
                cut_rows.append(f"| {name} | {source} | {method} | " + " | ".join(cells) + " |")
    return own_rows, cut_rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--videos", type=Path, default=REPO.parent / "shared" / "data" / "videos")
    parser.add_argument("--work", type=Path, default=Path("sync_work"), help="folder for the cut clips")
    args = parser.parse_args()
    own_rows, cut_rows = measure(args.videos, args.work, Config())
    print("\n".join(own_rows) + "\n\n" + "\n".join(cut_rows))
