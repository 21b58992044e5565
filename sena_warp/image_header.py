"""What an image file's header says, read before decoding: its size and its EXIF orientation.

Decoding a huge image can take gigabytes before anything can refuse it (a 3.6 MB PNG of zeros may
claim 25000 x 25000 px, a 19 KB BigTIFF 20000 x 20000 RGBA16), so the size is read from the header
first, for every format OpenCV's decoder is given: PNG ``IHDR``, JPEG ``SOFn``, TIFF and BigTIFF
``ImageWidth`` / ``ImageLength``, WebP ``VP8`` / ``VP8L`` / ``VP8X``, BMP ``BITMAPINFOHEADER``, GIF's
logical screen, JPEG 2000 ``ihdr`` (JP2) or ``SIZ`` (codestream), PNM / PAM / PFM, Radiance HDR's
resolution line and Sun raster. The EXIF orientation (tag 274) comes from PNG ``eXIf``, JPEG ``APP1
Exif``, WebP ``EXIF`` or the TIFF's own first directory. OpenCV's ``IMREAD_UNCHANGED`` (the only mode
that keeps 16 bits and alpha) ignores it, so :func:`apply_orientation` turns the decoded pixels
upright. Other formats (AVIF, ...) and damaged headers give ``None`` sizes: the image is refused
before the decoder sees it.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np

ORIENTATION_TAG = 274  # EXIF / TIFF Orientation
WIDTH_TAG, HEIGHT_TAG = 256, 257  # TIFF ImageWidth, ImageLength
_TIFF_INTEGERS = {3: "H", 4: "I", 16: "Q"}  # SHORT, LONG, LONG8 (BigTIFF): the types a size may have
_JPEG_SOF = {0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF}
_EXIF_PREFIX = b"Exif\x00\x00"


@dataclass(frozen=True)
class ImageHeader:
    """``width`` x ``height`` in stored pixels (before orientation), ``orientation`` 1-8 (1 = upright)."""

    width: int | None = None
    height: int | None = None
    orientation: int = 1

    @property
    def pixels(self) -> int | None:
        return None if self.width is None or self.height is None else self.width * self.height


def tiff_tags(data: bytes | memoryview, wanted: tuple[int, ...]) -> dict[int, int]:
    """Integer values of the ``wanted`` tags in the first directory (IFD0) of TIFF-structured ``data``
    (a TIFF or BigTIFF file, or an EXIF block without its ``Exif\\0\\0`` prefix). Missing or damaged:
    left out."""
    magic = bytes(data[:4])
    if magic not in (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+"):
        return {}
    order = "<" if magic[:2] == b"II" else ">"
    # IFD offset, entry count, value count (formats), entry size, value position in an entry.
    offset, entries_kind, n_kind, size, value_pos = ("Q", "Q", "Q", 20, 12) if magic[2:] in (b"+\x00", b"\x00+") \
        else ("I", "H", "I", 12, 8)  # BigTIFF ("+"): 8-byte offsets and counts
    found: dict[int, int] = {}
    try:
        (ifd,) = struct.unpack_from(order + offset, data, 8 if offset == "Q" else 4)
        (entries,) = struct.unpack_from(order + entries_kind, data, ifd)
        first = ifd + struct.calcsize(entries_kind)
        for i in range(entries):
            at = first + size * i
            tag, kind, n = struct.unpack_from(order + "HH" + n_kind, data, at)
            if tag in wanted and n == 1 and kind in _TIFF_INTEGERS:
                found[tag] = struct.unpack_from(order + _TIFF_INTEGERS[kind], data, at + value_pos)[0]
    except struct.error:
        pass
    return found


def _orientation(exif: bytes | memoryview) -> int:
    exif = bytes(exif)
    if exif.startswith(_EXIF_PREFIX):
        exif = exif[len(_EXIF_PREFIX):]
    value = tiff_tags(exif, (ORIENTATION_TAG,)).get(ORIENTATION_TAG, 1)
    return value if 1 <= value <= 8 else 1


def _png(data: memoryview) -> ImageHeader:
    width, height = struct.unpack_from(">II", data, 16)  # IHDR is the first chunk
    pos, orientation = 8, 1
    while pos + 8 <= len(data):
        length, kind = struct.unpack_from(">I4s", data, pos)
        if kind == b"eXIf":
            orientation = _orientation(data[pos + 8:pos + 8 + length])
        if kind in (b"IDAT", b"IEND"):  # eXIf must come before the image data
            break
        pos += 12 + length
    return ImageHeader(width, height, orientation)


def _jpeg(data: memoryview) -> ImageHeader:
    pos, size, orientation = 2, None, 1
    while pos + 4 <= len(data) and data[pos] == 0xFF:
        marker = data[pos + 1]
        if marker == 0xFF:  # fill byte
            pos += 1
            continue
        if marker == 0xDA:  # start of scan: the header is over
            break
        (length,) = struct.unpack_from(">H", data, pos + 2)
        if marker == 0xE1 and data[pos + 4:pos + 10] == _EXIF_PREFIX:
            orientation = _orientation(data[pos + 4:pos + 2 + length])
        elif marker in _JPEG_SOF:
            height, width = struct.unpack_from(">HH", data, pos + 5)
            size = (width, height)
        pos += 2 + length
    return ImageHeader(*(size or (None, None)), orientation)


def _tiff(data: memoryview) -> ImageHeader:
    tags = tiff_tags(data, (WIDTH_TAG, HEIGHT_TAG, ORIENTATION_TAG))
    orientation = tags.get(ORIENTATION_TAG, 1)
    return ImageHeader(tags.get(WIDTH_TAG), tags.get(HEIGHT_TAG), orientation if 1 <= orientation <= 8 else 1)


def _webp(data: memoryview) -> ImageHeader:
    pos, size, orientation = 12, None, 1
    while pos + 8 <= len(data):
        kind, length = struct.unpack_from("<4sI", data, pos)
        body = data[pos + 8:pos + 8 + length]
        if kind == b"VP8X" and len(body) >= 10:
            size = (1 + int.from_bytes(body[4:7], "little"), 1 + int.from_bytes(body[7:10], "little"))
        elif kind == b"VP8 " and len(body) >= 10 and size is None:
            width, height = struct.unpack_from("<HH", body, 6)
            size = (width & 0x3FFF, height & 0x3FFF)
        elif kind == b"VP8L" and len(body) >= 5 and size is None:
            (bits,) = struct.unpack_from("<I", body, 1)
            size = (1 + (bits & 0x3FFF), 1 + ((bits >> 14) & 0x3FFF))
        elif kind == b"EXIF":
            orientation = _orientation(body)
        pos += 8 + length + (length & 1)  # chunks are padded to an even size
    return ImageHeader(*(size or (None, None)), orientation)


def _bmp(data: memoryview) -> ImageHeader:
    width, height = struct.unpack_from("<ii", data, 18)
    return ImageHeader(abs(width), abs(height))  # a negative height means rows stored top-down


def _gif(data: memoryview) -> ImageHeader:
    return ImageHeader(*struct.unpack_from("<HH", data, 6))  # the logical screen: what the decoder allocates


def _sun_raster(data: memoryview) -> ImageHeader:
    return ImageHeader(*struct.unpack_from(">II", data, 4))


def _jp2_boxes(data: memoryview, start: int, end: int):
    """(type, body start, body end) of the JPEG 2000 boxes between ``start`` and ``end``."""
    pos = start
    while pos + 8 <= end:
        length, kind = struct.unpack_from(">I4s", data, pos)
        body = pos + 8
        if length == 1:  # a 64-bit length follows the type
            (length,) = struct.unpack_from(">Q", data, body)
            body += 8
        box_end = end if length == 0 else pos + length
        if box_end <= pos:
            return
        yield kind, body, min(box_end, end)
        pos = box_end


def _jp2(data: memoryview) -> ImageHeader:
    for kind, body, body_end in _jp2_boxes(data, 0, len(data)):
        if kind == b"jp2h":
            for inner, inner_body, _ in _jp2_boxes(data, body, body_end):
                if inner == b"ihdr":
                    height, width = struct.unpack_from(">II", data, inner_body)
                    return ImageHeader(width, height)
    return ImageHeader()


def _j2k(data: memoryview) -> ImageHeader:
    # SOC, then SIZ: marker, Lsiz, Rsiz, then Xsiz, Ysiz (the grid) and XOsiz, YOsiz (the image's offset on it).
    x_end, y_end, x_origin, y_origin = struct.unpack_from(">IIII", data, 8)
    return ImageHeader(x_end - x_origin, y_end - y_origin)


def _text_tokens(data: memoryview, limit: int = 4096) -> list[bytes]:
    """The whitespace-separated words of the first ``limit`` bytes, ``#`` comments dropped (PNM headers)."""
    head = bytes(data[:limit])
    return [word for line in head.split(b"\n") for word in line.split(b"#", 1)[0].split()]


def _pnm(data: memoryview) -> ImageHeader:
    words = _text_tokens(data)
    if words[0] == b"P7":  # PAM: "WIDTH w", "HEIGHT h" lines up to ENDHDR
        fields = dict(zip(words[1::2], words[2::2]))
        return ImageHeader(int(fields[b"WIDTH"]), int(fields[b"HEIGHT"]))
    return ImageHeader(int(words[1]), int(words[2]))  # P1-P6, PF, Pf: magic, width, height, ...


def _radiance(data: memoryview) -> ImageHeader:
    lines = bytes(data[:65536]).split(b"\n")
    blank = lines.index(b"")  # the header ends with an empty line; the resolution line follows it
    axes = lines[blank + 1].split()  # e.g. "-Y 480 +X 640": rows first
    sizes = {axes[0][-1:]: int(axes[1]), axes[2][-1:]: int(axes[3])}
    return ImageHeader(sizes[b"X"], sizes[b"Y"])


def read_header(data: bytes | memoryview) -> ImageHeader:
    """The header of an image file given as its bytes (a memoryview avoids a copy of a large file)."""
    readers = ((b"\x89PNG\r\n\x1a\n", _png), (b"\xff\xd8", _jpeg), (b"II*\x00", _tiff), (b"MM\x00*", _tiff),
               (b"II+\x00", _tiff), (b"MM\x00+", _tiff), (b"BM", _bmp), (b"GIF87a", _gif), (b"GIF89a", _gif),
               (b"\x00\x00\x00\x0cjP  \r\n\x87\n", _jp2), (b"\xff\x4f\xff\x51", _j2k),
               (b"\x59\xa6\x6a\x95", _sun_raster), (b"#?RADIANCE", _radiance), (b"#?RGBE", _radiance))
    try:
        head = bytes(data[:12])
        for magic, reader in readers:
            if head.startswith(magic):
                return reader(data)
        if head[:4] == b"RIFF" and head[8:12] == b"WEBP":
            return _webp(data)
        if head[:1] == b"P" and head[1:2] in b"1234567Ff" and head[2:3].isspace():
            return _pnm(data)
    except (struct.error, ValueError, IndexError, KeyError):  # a header cut short or garbled: no size
        pass
    return ImageHeader()


def apply_orientation(img: np.ndarray, orientation: int) -> np.ndarray:
    """Stored pixels ``img`` (H, W[, C]) turned upright for EXIF ``orientation`` 1-8, contiguous.

    The same transforms as OpenCV's own EXIF handling (``IMREAD_COLOR``): 2 mirror x, 3 rotate 180,
    4 mirror y, 5 transpose, 6 transpose + mirror x (90 deg clockwise), 7 transpose + rotate 180,
    8 transpose + mirror y (90 deg counter-clockwise).
    """
    if orientation >= 5:
        img = img.swapaxes(0, 1)
    flip_x = orientation in (2, 3, 6, 7)
    flip_y = orientation in (3, 4, 7, 8)
    img = img[::-1 if flip_y else 1, ::-1 if flip_x else 1]
    return np.ascontiguousarray(img)
