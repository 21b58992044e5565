"""Helpers shared by several test modules (imported as ``helpers``: pytest puts tests/ on sys.path)."""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path

import av
import numpy as np

from sena_warp.cli import main
from sena_warp.imageio import read_image
from sena_warp.video.reader import FrameReader, YuvFrame


def read_pair(folder: Path) -> tuple[np.ndarray, np.ndarray]:
    """(img_a, img_b) uint8 BGR (H, W, 3) of a pair folder holding one a.* and one b.* image."""
    return read_image(next(folder.glob("a.*"))), read_image(next(folder.glob("b.*")))


def decoded_frames(path) -> list[YuvFrame]:
    with FrameReader(path) as reader:
        return list(reader)


def stream_spans(path) -> dict:
    """Per stream type: (packet count, sorted pts as exact seconds, end in seconds)."""
    spans = {}
    with av.open(str(path)) as c:
        for stream in c.streams:
            times, end = [], Fraction(0)
            for packet in c.demux(stream):
                if packet.pts is None:
                    continue
                t = packet.pts * Fraction(stream.time_base)
                times.append(t)
                end = max(end, t + packet.duration * Fraction(stream.time_base))
            spans[stream.type] = (len(times), sorted(times), end)
            c.seek(0)
    return spans


def run_cli(argv, capfd, warp_device):
    """(exit code, stderr lines, stdout) of ``sena-warp argv -q`` on the session's Warp device.

    ``-q``: stderr holds the warnings and errors only, not the progress lines.
    """
    capfd.readouterr()
    rc = main([*map(str, argv), "-q", "--device", warp_device])
    captured = capfd.readouterr()
    return rc, captured.err.splitlines(), captured.out
