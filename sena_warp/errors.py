"""One exception family with messages a user can act on.

The CLI prints ``str(error)`` on one line and exits with ``error.exit_code``; nothing else in the
package prints tracebacks for expected failures. Exit codes are listed in the README.
"""

from __future__ import annotations


class StitchError(Exception):
    """Base of every user-facing failure: the message says what is wrong and what to try."""

    exit_code = 1


class InputError(StitchError):
    """A missing, unreadable, corrupt, too large or unsuitable input file, or a bad option value
    (out of range, unknown name, an unsupported output type)."""

    exit_code = 2


class MatchError(StitchError):
    """Too few features, matches or inliers: the images may not overlap."""

    exit_code = 3


class GeometryError(StitchError):
    """The estimated model is implausible (huge canvas, degenerate warp, empty overlap)."""

    exit_code = 4


class VideoError(StitchError):
    """A video stream problem: no video stream, mismatched inputs, decoding or encoding failure."""

    exit_code = 5


class SyncError(VideoError):
    """``--offset auto`` found no clear time offset: a silent or static input, or an ambiguous peak."""


class OutputError(StitchError):
    """An output cannot be written where asked: it is an input or another output, exists (without -y),
    its folder is missing or not writable, or the disk is full."""

    exit_code = 6


OUT_OF_MEMORY = "out of memory; lower --max-megapixels, downscale the inputs or free some memory"
# How the native libraries say an allocation failed: Warp ("Failed to allocate N bytes on device 'cpu'"),
# onnxruntime's arena ("Failed to allocate memory for requested buffer", or a C++ bad_alloc), CUDA, OpenCV
# ("(-4:Insufficient memory) Failed to allocate N bytes").
_ALLOCATION_FAILED = ("Failed to allocate", "bad_alloc", "out of memory", "CUDA_ERROR_OUT_OF_MEMORY",
                      "Insufficient memory")
_NATIVE_MODULES = ("onnxruntime", "cv2")  # libraries whose own exception types carry their allocation failures


def out_of_memory(exc: BaseException) -> StitchError | None:
    """The one-line error (exit code 1) for an allocation that failed, in numpy (``MemoryError``), Warp,
    onnxruntime or OpenCV (a RuntimeError or the library's own exception saying so); None for any other
    exception."""
    native = isinstance(exc, RuntimeError) or type(exc).__module__.startswith(_NATIVE_MODULES)
    if isinstance(exc, MemoryError) or native and any(text in str(exc) for text in _ALLOCATION_FAILED):
        return StitchError(OUT_OF_MEMORY)
    return None


def error_for_exit_code(code: int) -> type[StitchError]:
    """The error class that exits with ``code`` (StitchError itself for an unknown one), so a child
    process's failure can be raised again with its own code."""
    return next((cls for cls in StitchError.__subclasses__() if cls.exit_code == code), StitchError)
