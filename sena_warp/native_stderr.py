"""What C libraries write straight to file descriptor 2, caught so the CLI's stderr stays one line.

libpng prints its errors there, Warp's core says "Could not find or load the NVIDIA CUDA driver" on a
machine without one, onnxruntime says it cannot persist a telemetry identifier when HOME cannot be
written. Python's own ``sys.stderr`` is not involved: these bypass it.
"""

from __future__ import annotations

import contextlib
import os
import sys
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass


@dataclass
class Caught:
    """The text written to file descriptor 2 inside :func:`caught`, on one line (set when the block ends)."""

    text: str = ""


@contextlib.contextmanager
def caught() -> Iterator[Caught]:
    """Run the block with file descriptor 2 going to a temporary file; its text is in the yielded
    :class:`Caught` afterwards, whitespace runs (newlines too) folded to single spaces."""
    sys.stderr.flush()
    found = Caught()
    saved_fd = os.dup(2)
    with tempfile.TemporaryFile() as sink:
        os.dup2(sink.fileno(), 2)
        try:
            yield found
        finally:
            os.dup2(saved_fd, 2)
            os.close(saved_fd)
            sink.seek(0)
            found.text = " ".join(sink.read().decode(errors="replace").split())
