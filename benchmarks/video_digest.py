"""One MD5 over every frame of an encoded video, decoded to its 4:2:0 planes: what ``sena-warp video``
wrote, end to end through the frame loop (``output_digest.py`` hashes the compositor's frames apart from
the loop). libx264 gives the same stream for the same frames and settings, so two versions whose
digests agree composited the same pictures.

Usage (from anywhere; run ``sena-warp video`` with each version first)::

    .venv/bin/python benchmarks/video_digest.py OUT.mp4 [OUT2.mp4 ...]

Prints, per file: the path, its frame count and the MD5.
"""

from __future__ import annotations

import argparse
import hashlib

import av


def video_digest(path: str) -> tuple[int, str]:
    """(frames, MD5 of their Y, U and V planes in turn) of the video stream of ``path``."""
    digest, frames = hashlib.md5(), 0
    with av.open(path) as container:
        for frame in container.decode(video=0):
            digest.update(frame.to_ndarray(format="yuv420p").tobytes())
            frames += 1
    return frames, digest.hexdigest()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("videos", nargs="+", help="encoded videos to hash")
    for path in parser.parse_args().videos:
        frames, md5 = video_digest(path)
        print(f"{path} {frames} {md5}")


if __name__ == "__main__":
    main()
