"""Cut the short bundled test clips in ``tests/data/video/`` from the shared two-camera videos.

Usage: ``python tools/make_test_clips.py [--shared ../shared/data] [--out tests/data/video]``

Each clip is ~2 s re-encoded small with libx264 (single-threaded, so reruns give the same bytes),
keeping what the tests rely on: the source size, frame rate and pixel format (the office webcams are
yuv422p, which exercises the reader's conversion), timestamps starting at 0, rooftop's 3-frame length
difference (the right clip is 3 frames longer) and rooftop's AAC audio (packets copied, not
re-encoded, trimmed to the clip's span).
"""

from __future__ import annotations

import argparse
from fractions import Fraction
from pathlib import Path

import av

REPO = Path(__file__).resolve().parents[1]

# (source relative to shared/data/videos, clip name, start s, video length in frames, keep audio)
CLIPS = (
    ("rooftop_handheld/left.mp4", "rooftop_left.mp4", Fraction(2), 60, True),
    ("rooftop_handheld/right.mp4", "rooftop_right.mp4", Fraction(2), 63, True),
    ("office_static/cam1.mp4", "office_cam1.mp4", Fraction(4), 48, False),
    ("office_static/cam2.mp4", "office_cam2.mp4", Fraction(4), 48, False),
)
CRF = "30"  # small files; the tests check timing and counts, not picture quality
PRESET = "medium"


def cut_clip(src: Path, dst: Path, start_s: Fraction, n_frames: int, keep_audio: bool) -> None:
    """Re-encode ``n_frames`` video frames from ``start_s`` (and the audio over their span) to ``dst``."""
    with av.open(str(src)) as inp, av.open(str(dst), "w") as out:
        v_in = inp.streams.video[0]
        rate = Fraction(v_in.average_rate)
        v_out = out.add_stream("libx264", rate=rate, options={"crf": CRF, "preset": PRESET, "threads": "1"})
        v_out.width, v_out.height = v_in.codec_context.width, v_in.codec_context.height
        v_out.pix_fmt = v_in.codec_context.format.name
        v_out.codec_context.time_base = 1 / rate
        a_in = inp.streams.audio[0] if keep_audio and inp.streams.audio else None
        a_out = out.add_stream_from_template(a_in) if a_in is not None else None

        v_tb = Fraction(v_in.time_base)
        written = 0
        for frame in inp.decode(v_in):
            t = (frame.pts - (v_in.start_time or 0)) * v_tb
            if t + 1 / (2 * rate) < start_s:
                continue
            frame.pts, frame.time_base = round((t - start_s) * rate), 1 / rate
            out.mux(v_out.encode(frame))
            written += 1
            if written == n_frames:
                break
        out.mux(v_out.encode(None))

        if a_in is not None:
            end_s = start_s + n_frames / rate
            a_tb = Fraction(a_in.time_base)
            shift = round(start_s / a_tb)
            inp.seek(0)
            for packet in inp.demux(a_in):
                if packet.pts is None or not start_s <= packet.pts * a_tb < end_s:
                    continue
                packet.pts -= shift
                packet.dts -= shift
                packet.stream = a_out
                out.mux(packet)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--shared", type=Path, default=REPO.parent / "shared" / "data")
    parser.add_argument("--out", type=Path, default=REPO / "tests" / "data" / "video")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    for src, name, start_s, n_frames, keep_audio in CLIPS:
        dst = args.out / name
        cut_clip(args.shared / "videos" / src, dst, start_s, n_frames, keep_audio)
        print(f"{dst}: {dst.stat().st_size / 1024:.0f} KiB")


if __name__ == "__main__":
    main()
