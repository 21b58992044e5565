"""Peak memory of refusing an input that is small on disk and huge once decoded: one image of each
format whose size the header gives, and a video holding one huge frame.

Usage (from the repository root)::

    .venv/bin/python benchmarks/input_bombs.py [--side 12000] [--work DIR]

Writes each file (``--side`` x ``--side`` px: 144 MP by default, above the 100 MP limit), runs
``sena-warp image FILE a.jpg`` or ``sena-warp video FILE right.mp4`` on it in a child process and prints
its exit code, peak RSS (``ru_maxrss`` of the child, as ``/usr/bin/time -v`` reports it) and error
line. Files that decode fully (every strip, scanline or tile of real data) show what the decoder
allocates when nothing refuses them first; the bundled pair and clip are the other inputs.
"""

from __future__ import annotations

import argparse
import resource
import struct
import subprocess
import sys
import tempfile
import zlib
from fractions import Fraction
from pathlib import Path

import av
import cv2
import numpy as np

REPO = Path(__file__).resolve().parents[1]
PAIR = REPO / "tests" / "data" / "udisd_test_000001"
CLIP = REPO / "tests" / "data" / "video" / "rooftop_right.mp4"


def bigtiff_rgba16(side: int) -> bytes:
    """A BigTIFF of side x side RGBA 16-bit whose every 16-row strip points at one deflated block of zeros."""
    rows = 16
    block = zlib.compress(bytes(side * 8 * rows), 9)
    strips = -(-side // rows)
    entries = [(256, 4, 1, side), (257, 4, 1, side), (258, 3, 4, None), (259, 3, 1, 8), (262, 3, 1, 2),
               (273, 16, strips, None), (277, 3, 1, 4), (278, 4, 1, rows), (279, 16, strips, None), (284, 3, 1, 1),
               (338, 3, 1, 2)]
    arrays_at = 16 + 8 + 20 * len(entries) + 8
    block_at = arrays_at + 16 * strips
    ifd = struct.pack("<Q", len(entries))
    for tag, kind, count, value in entries:
        if tag == 258:
            raw = struct.pack("<HHHH", 16, 16, 16, 16)
        elif tag in (273, 279):
            raw = struct.pack("<Q", arrays_at + (0 if tag == 273 else 8 * strips))
        else:
            raw = struct.pack({3: "<H", 4: "<I"}[kind], value).ljust(8, b"\0")
        ifd += struct.pack("<HHQ", tag, kind, count) + raw
    arrays = struct.pack(f"<{strips}Q", *[block_at] * strips) + struct.pack(f"<{strips}Q", *[len(block)] * strips)
    return b"II+\x00" + struct.pack("<HHQ", 8, 0, 16) + ifd + struct.pack("<Q", 0) + arrays + block


def radiance_zeros(side: int) -> bytes:
    """A Radiance HDR of side x side black pixels, every scanline run-length encoded."""
    line = bytes([2, 2, side >> 8, side & 255])
    for _ in range(4):
        left = side
        while left:
            run = min(127, left)
            line += bytes([128 + run, 0])
            left -= run
    return b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y %d +X %d\n" % (side, side) + line * side


def gif_screen(side: int) -> bytes:
    """A GIF whose logical screen is side x side around one 1x1 image."""
    head = b"GIF89a" + struct.pack("<HHBBB", side, side, 0x80, 0, 0) + b"\0\0\0\xff\xff\xff"
    return head + b"\x2c" + struct.pack("<HHHHB", 0, 0, 1, 1, 0) + b"\x02\x02\x44\x01\x00\x3b"


def jpeg2000_sparse(side: int) -> bytes:
    img = np.zeros((side, side), np.uint8)
    img[::97, ::89] = 255
    return cv2.imencode(".jp2", img)[1].tobytes()


def mjpeg_mov(path: Path, side: int) -> None:
    """A .mov holding one side x side MJPEG frame."""
    with av.open(str(path), "w") as c:
        stream = c.add_stream("mjpeg", rate=1)
        stream.width = stream.height = side
        stream.pix_fmt = "yuvj420p"
        frame = av.VideoFrame(side, side, "yuvj420p")
        frame.pts, frame.time_base = 0, Fraction(1, 1)
        c.mux(stream.encode(frame))
        c.mux(stream.encode(None))


def run(argv: list[str]) -> tuple[int, float, str]:
    """(exit code, peak RSS in MB, last stderr line) of ``sena-warp argv`` in a child process: the largest
    RSS of this process's children, so a fresh Python calls it once (:func:`subprocess_peak`)."""
    done = subprocess.run([sys.executable, "-m", "sena_warp.cli", *argv, "-q"], capture_output=True, text=True)
    lines = done.stderr.strip().splitlines()
    return done.returncode, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024, lines[-1] if lines else ""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--side", type=int, default=12000, help="pixels a side (default: %(default)s)")
    parser.add_argument("--work", type=Path, help="folder for the files (default: a temporary one)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        work = args.work or Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        images = {"BigTIFF RGBA16": ("bomb.tif", bigtiff_rgba16), "Radiance HDR": ("bomb.hdr", radiance_zeros),
                  "GIF screen": ("bomb.gif", gif_screen), "JPEG 2000": ("bomb.jp2", jpeg2000_sparse)}
        rows = []
        for name, (file_name, make) in images.items():
            path = work / file_name
            path.write_bytes(make(args.side))
            rows.append((name, path, ["image", str(path), str(PAIR / "a.jpg"), "-o", str(work / "p.png")]))
        movie = work / "bomb.mov"
        mjpeg_mov(movie, args.side)
        rows.append(("MJPEG .mov, --max-megapixels 1", movie,
                     ["video", str(movie), str(CLIP), "-o", str(work / "v.mp4"), "--max-megapixels", "1"]))
        for name, path, argv in rows:
            code, peak_mb, said = subprocess_peak(argv)
            print(f"{name:32s} {path.stat().st_size / 1024:9.1f} KB  exit {code}  peak RSS {peak_mb:7.0f} MB  {said}")


def subprocess_peak(argv: list[str]) -> tuple[int, float, str]:
    """:func:`run` in a fresh Python, so each figure is that run's own peak (children's peaks only grow)."""
    code = (f"import sys; sys.path.insert(0, {str(REPO / 'benchmarks')!r}); import input_bombs as b; "
            f"r = b.run({argv!r}); print(r[0]); print(r[1]); print(r[2])")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    exit_code, peak, said = (done.stdout.splitlines() + ["", "", ""])[:3]
    return int(exit_code or -1), float(peak or "nan"), said


if __name__ == "__main__":
    main()
