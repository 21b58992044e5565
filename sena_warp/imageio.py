"""Reading images into one canonical form and writing outputs atomically.

Images inside the pipeline are ``uint8`` arrays of shape ``(H, W, 3)`` in OpenCV's BGR order,
row-major (``img[y, x]``). Inputs are never modified; outputs are written to a temporary file in the
destination folder and renamed over the final name only once complete.
"""

from __future__ import annotations

import contextlib
import os
import sys
import tempfile
from pathlib import Path
from typing import Iterator

import cv2
import numpy as np

from .errors import InputError, OutputError

MIN_SIDE_PX = 16


def _process_umask() -> int:
    """The process's umask (read once at import, before any thread: os.umask can only swap it)."""
    mask = os.umask(0)
    os.umask(mask)
    return mask


_UMASK = _process_umask()


def to_bgr8(img: np.ndarray, name: str = "image") -> np.ndarray:
    """Convert grey, BGRA or 16-bit images to 8-bit BGR ``(H, W, 3)``."""
    if img.dtype == np.uint16:
        img = (img.astype(np.float32) / 257.0 + 0.5).astype(np.uint8)
    elif img.dtype in (np.float32, np.float64):
        # NaN (e.g. no-data pixels of a float TIFF) would cast to an undefined byte with a warning: black.
        img = np.clip(np.nan_to_num(img, nan=0.0) * 255.0 + 0.5, 0, 255).astype(np.uint8)
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


def existing_file(path: str | os.PathLike) -> Path:
    """``path`` as a Path, or InputError when it is missing or not a regular file."""
    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: file not found")
    if not path.is_file():
        raise InputError(f"{path}: not a file")
    return path


def read_image(path: str | os.PathLike) -> np.ndarray:
    """Read an image file as 8-bit BGR, or raise InputError saying what is wrong with it."""
    path = existing_file(path)
    try:
        data = np.fromfile(str(path), dtype=np.uint8)
    except OSError as exc:
        raise InputError(f"{path}: cannot read ({exc.strerror})") from exc
    img, decoder_says = _decode_quietly(data) if data.size else (None, "")
    if img is None:
        reason = f"; the decoder says: {decoder_says}" if decoder_says else ""
        raise InputError(f"{path}: not a readable image (corrupt, truncated or unsupported format{reason})")
    img = to_bgr8(img, str(path))
    if min(img.shape[:2]) < MIN_SIDE_PX:
        raise InputError(
            f"{path}: image is {img.shape[1]}x{img.shape[0]} px; at least {MIN_SIDE_PX} px per side is needed"
        )
    return img


def _decode_quietly(data: np.ndarray) -> tuple[np.ndarray | None, str]:
    """``cv2.imdecode(data, IMREAD_UNCHANGED)`` and what the C decoders wrote to stderr, on one line.

    libpng prints its errors straight to file descriptor 2 (e.g. "libpng error: PNG input buffer is
    incomplete" for a truncated file), which would break the CLI's one-line error; the text is caught
    here so it can go into the InputError instead. Warnings on a file that still decodes are dropped.
    """
    sys.stderr.flush()
    saved_fd = os.dup(2)
    with tempfile.TemporaryFile() as sink:
        os.dup2(sink.fileno(), 2)
        try:
            img = cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
        finally:
            os.dup2(saved_fd, 2)
            os.close(saved_fd)
        sink.seek(0)
        decoder_says = " ".join(sink.read().decode(errors="replace").split())
    return img, decoder_says


def check_output_path(path: str | os.PathLike, inputs: tuple[str | os.PathLike, ...] = ()) -> Path:
    """``path`` as a Path, or OutputError when no file can be written there.

    Refused: one of the ``inputs`` (same file, also through links), an existing folder, a parent that
    is missing, not a folder or not writable. Cheap, so callers can check before any work.
    """
    path = Path(path)
    for src in inputs:
        if Path(src).exists() and path.exists() and os.path.samefile(src, path):
            raise OutputError(f"{path}: output would overwrite an input; choose another output name")
    if path.is_dir():
        raise OutputError(f"{path}: is a folder; give a file name")
    folder = path.parent
    if not folder.exists():
        raise OutputError(f"{path}: folder {folder} does not exist")
    if not folder.is_dir():
        raise OutputError(f"{path}: {folder} is not a folder")
    if not os.access(folder, os.W_OK):
        raise OutputError(f"{path}: folder {folder} is not writable")
    return path


def check_output_folder(path: str | os.PathLike) -> Path:
    """``path`` as a Path, or OutputError when it cannot be (or become) a writable folder.

    Creates nothing: the nearest existing ancestor must be a writable folder, so a folder made later
    (``--debug``) cannot fail after the real work is done.
    """
    path = Path(path)
    existing = next(p for p in (path, *path.parents) if p.exists())
    if not existing.is_dir():
        raise OutputError(f"{path}: {existing} is not a folder; choose another folder")
    if not os.access(existing, os.W_OK):
        raise OutputError(f"{path}: folder {existing} is not writable")
    return path


@contextlib.contextmanager
def atomic_output(path: str | os.PathLike, inputs: tuple[str | os.PathLike, ...] = ()) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it to ``path`` only if the block succeeds.

    Refuses an output that is one of the ``inputs`` or sits in a folder that cannot be written.
    On any exception (including KeyboardInterrupt) the temporary file is removed.
    """
    path = check_output_path(path, inputs)
    folder = path.parent
    try:
        fd, tmp_name = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=f".part{path.suffix}", dir=folder)
    except OSError as exc:
        raise OutputError(f"{path}: cannot create a file in {folder} ({exc.strerror}); choose another folder") from exc
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        yield tmp
        try:
            os.chmod(tmp, 0o666 & ~_UMASK)  # mkstemp makes 0600; the output gets a new file's usual mode
            os.replace(tmp, path)
        except OSError as exc:
            raise OutputError(f"{path}: cannot write it ({exc.strerror}); choose another output name") from exc
    finally:
        if tmp.exists():
            tmp.unlink()


def make_folder(path: str | os.PathLike) -> Path:
    """Create folder ``path`` (and its parents) if needed; OutputError saying why when it cannot be."""
    path = Path(path)
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"{path}: cannot create this folder ({exc.strerror or exc}); choose another folder") from exc
    return path


def write_image(path: str | os.PathLike, img: np.ndarray, inputs: tuple[str | os.PathLike, ...] = (),
                params: tuple[int, ...] = ()) -> None:
    """Encode ``img`` (BGR or BGRA uint8) by the file extension and write it atomically.

    ``params``: OpenCV encoder flags and values, e.g. ``(cv2.IMWRITE_JPEG_QUALITY, 80)``.
    """
    path = Path(path)
    ext = path.suffix.lower()
    if ext not in (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp", ".webp"):
        raise OutputError(f"{path}: unknown image extension {ext!r}; use .png or .jpg")
    if img.ndim == 3 and img.shape[2] == 4 and ext in (".jpg", ".jpeg", ".bmp"):
        img = img[:, :, :3]
    ok, buf = cv2.imencode(ext, img, list(params))
    if not ok:
        raise OutputError(f"{path}: image encoding failed")
    with atomic_output(path, inputs) as tmp:
        buf.tofile(str(tmp))
