"""Helpers shared by several test modules (imported as ``helpers``: pytest puts tests/ on sys.path) and
by ``benchmarks/soak.py``: running the CLI, reading media back, making damaged, huge-claiming,
rotated or black-starting inputs from the bundled data, a worker task, a process's children."""

from __future__ import annotations

import os
import struct
import time
import zlib
from fractions import Fraction
from pathlib import Path

import av
import cv2
import numpy as np

from sena_warp.cli import main
from sena_warp.imageio import read_image
from sena_warp.outputs import OutputPlan
from sena_warp.video.reader import FrameReader, YuvFrame, probe_video
from sena_warp.video.writer import VideoWriter

ERROR_PREFIX = "sena-warp: error: "


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


def assert_one_line_error(err_lines, *words):
    """``err_lines`` (stderr as lines) is exactly one error line, no traceback, holding every word."""
    assert len(err_lines) == 1, err_lines
    assert err_lines[0].startswith(ERROR_PREFIX) and "Traceback" not in err_lines[0], err_lines
    for word in words:
        assert word in err_lines[0], (word, err_lines[0])


def index_first(src, dst):
    """Remux ``src``'s video with the MP4 index (moov) before the data, as streaming files are."""
    with av.open(str(src)) as cin, av.open(str(dst), "w", options={"movflags": "+faststart"}) as cout:
        sin = cin.streams.video[0]
        sout = cout.add_stream_from_template(sin)
        for packet in cin.demux(sin):
            if packet.dts is not None:
                packet.stream = sout
                cout.mux(packet)
    return dst


def top_level_box(data: bytes, name: bytes) -> tuple[int, int]:
    """(start, size) of the first top-level MP4 box called ``name``."""
    pos = 0
    while pos + 8 <= len(data):
        size = int.from_bytes(data[pos:pos + 4], "big")
        if data[pos + 4:pos + 8] == name:
            return pos, size
        pos += size
    raise AssertionError(f"no {name!r} box")


def truncated(src, dst, fraction=0.6):
    """The first ``fraction`` of file ``src`` as ``dst``: a copy cut short."""
    data = src.read_bytes()
    dst.write_bytes(data[: int(len(data) * fraction)])
    return dst


def damage_the_middle(src, dst, span=4000):
    """``src`` with ``span`` random bytes in the middle of its media data."""
    data = bytearray(src.read_bytes())
    start, size = top_level_box(bytes(data), b"mdat")
    middle = start + size // 2
    data[middle:middle + span] = np.random.default_rng(1).integers(0, 256, span, dtype=np.uint8).tobytes()
    dst.write_bytes(bytes(data))
    return dst


def png_claiming(width: int, height: int) -> bytes:
    """A 16-bit grey PNG header claiming width x height, with a token of (zero) image data."""
    def chunk(kind: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body) & 0xFFFFFFFF)
    ihdr = struct.pack(">IIBBBBB", width, height, 16, 0, 0, 0, 0)
    data = chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(bytes(1000))) + chunk(b"IEND", b"")
    return b"\x89PNG\r\n\x1a\n" + data


def tiff_orientation(value: int) -> bytes:
    return b"II*\x00" + struct.pack("<IH", 8, 1) + struct.pack("<HHIHH", 274, 3, 1, value, 0) + struct.pack("<I", 0)


def with_orientation(encoded: bytes, ext: str, value: int) -> bytes:
    """``encoded`` (a .jpg or .png file) with an EXIF orientation: a hand-built APP1 segment or eXIf chunk."""
    if ext == ".jpg":
        body = b"Exif\x00\x00" + tiff_orientation(value)
        return encoded[:2] + b"\xff\xe1" + struct.pack(">H", len(body) + 2) + body + encoded[2:]
    body = tiff_orientation(value)
    chunk = struct.pack(">I", len(body)) + b"eXIf" + body + struct.pack(">I", zlib.crc32(b"eXIf" + body) & 0xFFFFFFFF)
    return encoded[:33] + chunk + encoded[33:]  # after IHDR


def reencode_with_black_start(src, dst, black_frames: int) -> None:
    """``src``'s video (no audio) with its first ``black_frames`` frames black, at its frame rate."""
    frames = decoded_frames(src)
    h, w = frames[0].y.shape
    with VideoWriter(dst, w, h, probe_video(src).fps) as writer:
        for i, f in enumerate(frames):
            if i < black_frames:
                writer.write(np.full_like(f.y, 16), np.full_like(f.u, 128), np.full_like(f.v, 128), pts=i)
            else:
                writer.write(f.y, f.u, f.v, pts=i)


def bigtiff(width: int, height: int, pixels: bytes = b"") -> bytes:
    """A little-endian BigTIFF of 8-bit RGB ``width`` x ``height``, one uncompressed strip of ``pixels``
    (row-major RGB bytes; missing rows read as absent data)."""
    entries = [(256, 4, width), (257, 4, height), (258, 3, 8), (259, 3, 1), (262, 3, 2), (273, 16, None),
               (277, 3, 3), (278, 4, height), (279, 16, len(pixels) or width * height * 3)]
    data_at = 16 + 8 + 20 * len(entries) + 8
    ifd = struct.pack("<Q", len(entries))
    for tag, kind, value in entries:
        value = data_at if tag == 273 else value
        count = 3 if tag == 258 else 1
        raw = struct.pack("<HHH", 8, 8, 8) if tag == 258 else struct.pack({3: "<H", 4: "<I", 16: "<Q"}[kind], value)
        ifd += struct.pack("<HHQ", tag, kind, count) + raw.ljust(8, b"\0")
    return b"II+\x00" + struct.pack("<HHQ", 8, 0, 16) + ifd + struct.pack("<Q", 0) + pixels


def encoded(fmt: str, img: np.ndarray) -> bytes:
    """``img`` (BGR uint8) as a file of format ``fmt``: an OpenCV extension, "bigtiff" or "j2k" (a bare
    JPEG 2000 codestream: the JP2 file's ``jp2c`` box)."""
    if fmt == "bigtiff":
        return bigtiff(img.shape[1], img.shape[0], np.ascontiguousarray(img[:, :, ::-1]).tobytes())
    if fmt == "j2k":
        data = encoded(".jp2", img)
        return data[data.find(b"jp2c") + 4:]
    if fmt in (".hdr", ".pfm"):
        img = img.astype(np.float32) / 255
    elif fmt in (".pbm", ".pgm"):
        img = img[:, :, 0]
    return cv2.imencode(fmt, img)[1].tobytes()


def ts_clip(frames, path, first_pts: int = 0, size: tuple[int, int] | None = None, pts_step: int = 3000) -> None:
    """``frames`` (YuvFrame) encoded as an MPEG-TS file (90 kHz clock, H.264 without B-frames) whose frame
    ``i`` has pts ``first_pts + i * pts_step`` (3000: 30 fps); ``size`` (width, height) rescales them.
    TS files joined byte by byte play as one stream: what a camera's split recording or ``cat`` makes."""
    height, width = frames[0].y.shape if size is None else size[::-1]
    with av.open(str(path), "w", format="mpegts") as c:
        stream = c.add_stream("libx264", rate=30, options={"bf": "0", "preset": "ultrafast"})
        stream.width, stream.height, stream.pix_fmt = width, height, "yuv420p"
        for i, f in enumerate(frames):
            frame = av.VideoFrame.from_ndarray(np.concatenate([f.y.ravel(), f.u.ravel(), f.v.ravel()]).reshape(
                -1, f.y.shape[1]), format="yuv420p").reformat(width=width, height=height)
            frame.pts, frame.time_base = first_pts + i * pts_step, Fraction(1, 90000)
            c.mux(stream.encode(frame))
        c.mux(stream.encode(None))


def with_repeated_pts(src, dst, repeats: range) -> None:
    """``src`` (a 30 fps TS file without B-frames, 90 kHz) remuxed with each packet in ``repeats`` given the
    presentation time of the packet before it: duplicate pts. (Decoding times stay increasing, one frame
    behind, as a muxer needs.)"""
    with av.open(str(src)) as c_in, av.open(str(dst), "w", format="mpegts") as c_out:
        stream_in = c_in.streams.video[0]
        stream_out = c_out.add_stream_from_template(stream_in)
        previous = None
        for i, packet in enumerate(p for p in c_in.demux(stream_in) if p.size):
            packet.dts = packet.pts - 3000
            if i in repeats:
                packet.pts, packet.dts = previous[0], previous[1] + 1
            previous = packet.pts, packet.dts
            packet.stream = stream_out
            c_out.mux(packet)


def shortened(src: Path, dst: Path, frames: int) -> Path:
    """The first ``frames`` frames of ``src``, re-encoded at its rate: a recording stopped early."""
    kept = decoded_frames(src)[:frames]
    with VideoWriter(dst, *kept[0].y.shape[::-1], probe_video(src).fps) as writer:
        for i, frame in enumerate(kept):
            writer.write(frame.y, frame.u, frame.v, pts=i)
    return dst


def without_key_frames(src: Path, dst: Path) -> Path:
    """``src``'s video packets but its key frames: a piece cut out of a longer stream."""
    with av.open(str(src)) as cin, av.open(str(dst), "w") as cout:
        sin = cin.streams.video[0]
        sout = cout.add_stream_from_template(sin)
        for packet in cin.demux(sin):
            if packet.dts is not None and not packet.is_keyframe:
                packet.stream = sout
                cout.mux(packet)
    return dst

def worker_task(task):
    """A task for ``sena_warp.workers`` in tests: ("double", n) -> 2n; ("die", code) ends its process
    with that code; ("hold", folder) writes a temporary of folder/out.bin and waits to be stopped."""
    what, arg = task
    if what == "die":
        os._exit(arg)
    if what == "hold":
        plan = OutputPlan()
        plan.add(Path(arg) / "out.bin", "-o")
        plan.check()
        with plan, plan.writing(Path(arg) / "out.bin") as tmp:
            tmp.write_bytes(b"partial")
            time.sleep(600)
    return 2 * arg


def child_processes(pid: int, marker: str) -> list[int]:
    """The live child processes of ``pid`` whose command line holds ``marker`` (Linux /proc)."""
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit() and alive(int(entry.name)):
            try:
                ppid = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
                cmdline = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
            except (OSError, IndexError, ValueError):
                continue
            if ppid == pid and marker in cmdline:
                found.append(int(entry.name))
    return found


def alive(pid: int) -> bool:
    """Process ``pid`` exists and is not a zombie (one nobody reaped counts as gone)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except (OSError, IndexError):
        return False


def claiming(ext: str, width: int, height: int, img: np.ndarray) -> bytes:
    """A small real ``ext`` file whose header is patched to claim width x height."""
    if ext == ".png":
        return png_claiming(width, height)
    data = bytearray(cv2.imencode(ext, img)[1].tobytes())
    if ext == ".jpg":
        sof = next(i for i in range(2, len(data) - 1) if data[i] == 0xFF and data[i + 1] in (0xC0, 0xC2))
        struct.pack_into(">HH", data, sof + 5, height, width)
    elif ext == ".tif":
        order = "<" if data[:2] == b"II" else ">"
        (ifd,) = struct.unpack_from(order + "I", data, 4)
        (count,) = struct.unpack_from(order + "H", data, ifd)
        for i in range(count):
            entry = ifd + 2 + 12 * i
            tag, kind = struct.unpack_from(order + "HH", data, entry)
            if tag in (256, 257):
                fmt = order + ("H" if kind == 3 else "I")
                struct.pack_into(fmt, data, entry + 8, width if tag == 256 else height)
    elif ext == ".webp":
        assert data[12:16] == b"VP8L"  # OpenCV writes lossless WebP: 14-bit width - 1, height - 1 after 0x2f
        (bits,) = struct.unpack_from("<I", data, 21)
        struct.pack_into("<I", data, 21, (bits & ~0xFFFFFFF) | (width - 1) | ((height - 1) << 14))
    elif ext == ".bmp":
        struct.pack_into("<ii", data, 18, width, height)
    return bytes(data)


def claiming_more(fmt: str, width: int, height: int, img: np.ndarray) -> bytes:
    """A small real file of a format beyond ``claiming``'s, whose header claims width x height."""
    if fmt == "bigtiff":
        return bigtiff(width, height, bytes(1000))  # what the 19 KB BigTIFF bomb is: a size and a token of data
    data = bytearray(encoded(fmt, img))
    if fmt == ".gif":
        struct.pack_into("<HH", data, 6, width, height)
    elif fmt == ".ras":
        struct.pack_into(">II", data, 4, width, height)
    elif fmt in (".jp2", "j2k"):
        if fmt == ".jp2":
            at = data.find(b"ihdr")
            struct.pack_into(">II", data, at + 4, height, width)
        at = data.find(b"\xff\x4f\xff\x51")
        struct.pack_into(">IIII", data, at + 8, width, height, 0, 0)
    elif fmt == ".hdr":
        blank = data.find(b"\n\n")
        end = data.find(b"\n", blank + 2)
        data[blank + 2:end] = b"-Y %d +X %d" % (height, width)
    elif fmt == ".pam":
        end = data.find(b"ENDHDR")
        data[:end] = b"P7\nWIDTH %d\nHEIGHT %d\nDEPTH 3\nMAXVAL 255\nTUPLTYPE RGB\n" % (width, height)
    else:  # PNM and PFM: "P6\n37 23\n..."
        first, second = data.find(b"\n"), data.find(b"\n", data.find(b"\n") + 1)
        data[first + 1:second] = b"%d %d" % (width, height)
    return bytes(data)


def one_mjpeg_frame(path: Path, width: int, height: int) -> Path:
    """A .mov holding one black MJPEG frame of ``width`` x ``height``: a small file with a large frame."""
    with av.open(str(path), "w") as c:
        stream = c.add_stream("mjpeg", rate=1)
        stream.width, stream.height, stream.pix_fmt = width, height, "yuvj420p"
        frame = av.VideoFrame(width, height, "yuvj420p")
        frame.pts, frame.time_base = 0, Fraction(1, 1)
        c.mux(stream.encode(frame))
        c.mux(stream.encode(None))
    return path


def joined_ts_files(left, right, folder: Path) -> Path:
    """TS files made from two 60-frame 30 fps clips' frames (YuvFrame lists) in ``folder``: the left
    joined to itself (its time stamps go back to 0 at 2 s: back.ts), with four repeated pts
    (repeated.ts), and joined to itself at twice the size with times going on (resized.ts); the right
    joined to itself with times going on (right_4s.ts, to pair with the latter)."""
    ts_clip(left, folder / "left.ts")
    ts_clip(left, folder / "left_2x.ts", first_pts=3000 * len(left), size=(540, 960))
    ts_clip(right[:60], folder / "right_a.ts")
    ts_clip(right[:60], folder / "right_b.ts", first_pts=3000 * 60)
    (folder / "back.ts").write_bytes((folder / "left.ts").read_bytes() * 2)
    (folder / "resized.ts").write_bytes((folder / "left.ts").read_bytes() + (folder / "left_2x.ts").read_bytes())
    (folder / "right_4s.ts").write_bytes((folder / "right_a.ts").read_bytes() + (folder / "right_b.ts").read_bytes())
    with_repeated_pts(folder / "left.ts", folder / "repeated.ts", range(10, 14))
    return folder
