"""Reading images into one canonical form and writing them atomically.

Images inside the pipeline are ``uint8`` arrays of shape ``(H, W, 3)`` in OpenCV's BGR order,
row-major (``img[y, x]``), upright (EXIF orientation applied); a separate mask says which pixels
were fully transparent. Inputs are never modified; outputs go through ``sena_warp.outputs``.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

import cv2
import numpy as np

from . import native_stderr
from .errors import InputError, OutputError
from .image_header import apply_orientation, read_header
from .outputs import OutputPlan, atomic_output


MIN_SIDE_PX = 16
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp", ".webp")
OPENCV_MAX_PIXELS = 1 << 30  # OpenCV's decoder refuses larger images (CV_IO_MAX_IMAGE_PIXELS)
# Float images are scaled from the smallest of these ranges that holds their largest value (else
# from that value): 0-1 is the float convention, but 0-255 and 0-65535 floats are common too.
FLOAT_RANGES = (1.0, 255.0, 65535.0)


def to_bgr8(img: np.ndarray, name: str = "image") -> np.ndarray:
    """Convert grey, BGRA, 16-bit or float images to 8-bit BGR ``(H, W, 3)``.

    16-bit values are scaled by their type (65535 -> 255); float values by their range (see
    ``FLOAT_RANGES``), NaN and negative values reading as 0.
    """
    if img.dtype == np.uint16:
        img = cv2.convertScaleAbs(img, alpha=1 / 257)  # rounds; no float copy of a large image
    elif img.dtype in (np.float32, np.float64):
        img = _float_to_uint8(img)
    elif img.dtype != np.uint8:
        raise InputError(f"{name}: unsupported pixel type {img.dtype}; convert it to 8- or 16-bit PNG or JPEG")
    if img.ndim == 2:
        return cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
    if img.ndim == 3 and img.shape[2] == 1:
        return cv2.cvtColor(img[:, :, 0], cv2.COLOR_GRAY2BGR)
    if img.ndim == 3 and img.shape[2] == 4:
        return cv2.cvtColor(img, cv2.COLOR_BGRA2BGR)
    if img.ndim == 3 and img.shape[2] == 3:
        return np.ascontiguousarray(img)
    raise InputError(f"{name}: unsupported image shape {img.shape}")


def described(value) -> str:
    """What ``value`` is, for an error about an argument: an array's shape and type, else its type."""
    if isinstance(value, np.ndarray):
        return f"a {value.dtype} array of shape {value.shape}"
    return "None" if value is None else f"a {type(value).__name__}"


def check_image(img, name: str, channels: int = 3) -> np.ndarray:
    """``img`` when it is a uint8 array of shape (H, W, ``channels``) with both sides at least
    ``MIN_SIDE_PX`` (BGR for 3, BGRA for 4); else InputError saying what was expected (a public
    function's argument check)."""
    kind = {3: "BGR", 4: "BGRA"}[channels]
    if not (isinstance(img, np.ndarray) and img.dtype == np.uint8 and img.ndim == 3 and img.shape[2] == channels):
        how = ("read_image() reads a file as one; to_bgr8() converts grey, BGRA, 16-bit or float arrays"
               if channels == 3 else "stitch_images() gives one as Panorama.image")
        raise InputError(f"{name}: expected a {kind} uint8 array of shape (H, W, {channels}), got {described(img)}; "
                         f"{how}")
    if min(img.shape[:2]) < MIN_SIDE_PX:
        raise InputError(f"{name}: image is {img.shape[1]}x{img.shape[0]} px; at least {MIN_SIDE_PX} px per side "
                         f"is needed")
    return img


def _float_to_uint8(img: np.ndarray) -> np.ndarray:
    colour = img[:, :, :3] if img.ndim == 3 and img.shape[2] == 4 else img  # alpha does not set the range
    finite = colour[np.isfinite(colour)]
    peak = float(finite.max()) if finite.size else 1.0
    full = next((r for r in FLOAT_RANGES if peak <= r), peak)
    # NaN (e.g. no-data pixels of a float TIFF) would cast to an undefined byte with a warning: black.
    scaled = np.nan_to_num(img, nan=0.0, posinf=full, neginf=0.0) * np.float32(255.0 / full)
    return np.clip(scaled + 0.5, 0, 255).astype(np.uint8)


def transparent_mask(img: np.ndarray) -> np.ndarray | None:
    """(H, W) bool True where a decoded image with alpha is fully transparent; None when no pixel is."""
    if img.ndim != 3 or img.shape[2] != 4:
        return None
    transparent = img[:, :, 3] == 0
    return transparent if transparent.any() else None


def input_stat(path: str | os.PathLike) -> os.stat_result:
    """``os.stat`` of input ``path``, or InputError when it is missing or a name the file system refuses
    (too long, a loop of links)."""
    try:
        return os.stat(path)
    except (FileNotFoundError, NotADirectoryError):
        raise InputError(f"{path}: file not found") from None
    except OSError as exc:
        raise InputError(f"{path}: cannot be opened ({exc.strerror})") from None


def existing_file(path: str | os.PathLike) -> Path:
    """``path`` as a Path, or InputError when it is missing, not a regular file or cannot be looked up."""
    if not stat.S_ISREG(input_stat(path).st_mode):
        raise InputError(f"{path}: not a file")
    return Path(path)


def check_size(name: str, width: int, height: int, max_megapixels: float | None, what: str = "image") -> None:
    """InputError when a ``width`` x ``height`` input is above ``max_megapixels`` (None: no limit of
    ours) or above what OpenCV decodes, before anything that size is allocated."""
    megapixels = width * height / 1e6
    shown = f"{megapixels:.3g}" if megapixels < 1000 else f"{megapixels:.0f}"  # 0.307, 625, 1600: never "0 MP"
    size = f"{width}x{height} px ({shown} MP)"
    if width * height > OPENCV_MAX_PIXELS:
        raise InputError(f"{name}: {what} is {size}, above the "
                         f"{OPENCV_MAX_PIXELS / 1e6:.0f} MP OpenCV decodes; downscale it first")
    if max_megapixels is not None and megapixels > max_megapixels:
        raise InputError(f"{name}: {what} is {size}, above the limit of "
                         f"{max_megapixels:g} MP per input; downscale it first, or raise --max-megapixels if the "
                         f"machine has the memory (see the README)")


def read_image_masked(path: str | os.PathLike, max_megapixels: float | None = None
                      ) -> tuple[np.ndarray, np.ndarray | None]:
    """Read an image file upright as 8-bit BGR, with its fully transparent pixels; or raise
    InputError saying what is wrong with it.

    Returns (BGR uint8 (H, W, 3), (H, W) bool transparent mask or None when no pixel is). The size
    is checked against ``max_megapixels`` from the header, before decoding; a file whose header gives
    no size (a format ``image_header`` does not read, or a damaged header) is refused undecoded. The
    EXIF orientation is applied (see ``image_header``).
    """
    path = existing_file(path)
    try:
        data = np.fromfile(str(path), dtype=np.uint8)
    except OSError as exc:
        raise InputError(f"{path}: cannot read ({exc.strerror})") from exc
    header = read_header(memoryview(data))
    if not header.pixels:  # no size to check: the decoder could allocate anything, so it is not asked
        raise InputError(f"{path}: not a readable image (corrupt, truncated or unsupported format)")
    check_size(str(path), header.width, header.height, max_megapixels)
    img, decoder_says = _decode_quietly(data)
    if img is None:
        reason = f"; the decoder says: {decoder_says}" if decoder_says else ""
        raise InputError(f"{path}: not a readable image (corrupt, truncated or unsupported format{reason})")
    del data
    img = apply_orientation(img, header.orientation)
    transparent = transparent_mask(img)
    img = to_bgr8(img, str(path))
    if min(img.shape[:2]) < MIN_SIDE_PX:
        raise InputError(
            f"{path}: image is {img.shape[1]}x{img.shape[0]} px; at least {MIN_SIDE_PX} px per side is needed"
        )
    return img, transparent


def read_image(path: str | os.PathLike, max_megapixels: float | None = None) -> np.ndarray:
    """Read an image file upright as 8-bit BGR (H, W, 3) (see :func:`read_image_masked`)."""
    return read_image_masked(path, max_megapixels)[0]


def _decode_quietly(data: np.ndarray) -> tuple[np.ndarray | None, str]:
    """``cv2.imdecode(data, IMREAD_UNCHANGED)`` and what the C decoders wrote to stderr, on one line.

    libpng prints its errors straight to file descriptor 2 (e.g. "libpng error: PNG input buffer is
    incomplete" for a truncated file), which would break the CLI's one-line error; the text is caught
    here so it can go into the InputError instead. Warnings on a file that still decodes are dropped.
    """
    error = ""
    with native_stderr.caught() as said:
        try:
            img = cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
        except cv2.error as exc:  # e.g. a size the decoder refuses to allocate
            img, error = None, exc.err
    return img, " ".join(f"{said.text} {error}".split())


def encode_image(path: str | os.PathLike, img: np.ndarray, params: tuple[int, ...] = ()) -> np.ndarray:
    """``img`` (BGR or BGRA uint8) encoded as the extension of ``path`` says: the file's bytes (uint8).

    ``params``: OpenCV encoder flags and values, e.g. ``(cv2.IMWRITE_JPEG_QUALITY, 80)``. Formats
    without alpha get the colour channels only.
    """
    path = Path(path)
    ext = path.suffix.lower()
    if ext not in IMAGE_SUFFIXES:
        raise InputError(f"{path}: unsupported output type; use one of {', '.join(IMAGE_SUFFIXES)}")
    if img.ndim == 3 and img.shape[2] == 4 and ext in (".jpg", ".jpeg", ".bmp"):
        img = img[:, :, :3]
    try:
        ok, buf = cv2.imencode(ext, img, list(params))
    except cv2.error as exc:  # e.g. a JPEG side above 65535 px
        ok, buf = False, exc.err
    if not ok:
        raise OutputError(f"{path}: the {ext} encoder refuses this {img.shape[1]}x{img.shape[0]} px image; use .png")
    return buf


def write_image(path: str | os.PathLike, img: np.ndarray, inputs: tuple[str | os.PathLike, ...] = (),
                params: tuple[int, ...] = (), plan: OutputPlan | None = None) -> None:
    """Encode ``img`` by the file extension (see :func:`encode_image`) and write it atomically.

    ``plan``: commit the file with that plan's other outputs (see ``outputs.atomic_output``).
    """
    buf = encode_image(path, img, params)
    with atomic_output(path, inputs, plan) as tmp:
        tmp.write_bytes(memoryview(buf))  # an OSError with its errno (EFBIG, ENOSPC), unlike ndarray.tofile
