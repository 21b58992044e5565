"""One MD5 over every frame of an encoded video, decoded to its 4:2:0 planes: what ``sena-warp video``
wrote, end to end through the frame loop (``output_digest.py`` hashes the compositor's frames apart from
the loop). libx264 gives the same stream for the same frames and settings, so two versions whose
digests agree composited the same pictures. A panorama (.png, .jpg, .tif, .webp) is hashed the same way
over its decoded pixels, whatever the image encoder chose.

Usage (from anywhere; run ``sena-warp video`` or ``sena-warp image`` with each version first)::

    .venv/bin/python benchmarks/video_digest.py OUT.mp4 [OUT2.mp4 ...]
    for p in ../shared/data/pairs/*/; do sena-warp image $p/a.* $p/b.* -o OUT/$(basename $p).png -q; done
    .venv/bin/python benchmarks/video_digest.py OUT/*.png

Prints, per file: the path, its frame count (1 for an image) and the MD5.
"""

from __future__ import annotations

import argparse
import hashlib

import av
import cv2

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".webp")


def video_digest(path: str) -> tuple[int, str]:
    """(frames, MD5 of their Y, U and V planes in turn) of the video stream of ``path``."""
    digest, frames = hashlib.md5(), 0
    with av.open(path) as container:
        for frame in container.decode(video=0):
            digest.update(frame.to_ndarray(format="yuv420p").tobytes())
            frames += 1
    return frames, digest.hexdigest()


def image_digest(path: str) -> tuple[int, str]:
    """(1, MD5 of the size and the decoded pixels) of the image at ``path``."""
    pixels = cv2.imread(path, cv2.IMREAD_UNCHANGED)
    if pixels is None:
        raise SystemExit(f"{path}: not an image OpenCV can read")
    return 1, hashlib.md5(repr(pixels.shape).encode() + pixels.tobytes()).hexdigest()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("outputs", nargs="+", help="encoded videos or panoramas to hash")
    for path in parser.parse_args().outputs:
        frames, md5 = image_digest(path) if path.lower().endswith(IMAGE_SUFFIXES) else video_digest(path)
        print(f"{path} {frames} {md5}")


if __name__ == "__main__":
    main()
