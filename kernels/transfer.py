"""Every copy between the host and the Warp device, and every wait for the device, in one place, counted.

A video frame on CUDA crosses the bus four times and waits for the device twice: its decoded planes
go up once (one pinned staging block, :class:`Staged`), the seam band's difference comes down and the
frame's seam and offsets go up (small blocks), and the output planes come down once for the encoder;
each download waits for the stream first, and nothing else in a frame does (kernel launches queue
without waiting, ``runtime.py``). What a new map set moves (its maps, the border blend, the band's
cells) is counted apart, as ``"plan"``.

Each call is counted per thread, by kind (``"upload"``, ``"download"``, ``"sync"``) and by what moved,
on the CPU too, where nothing moves and nothing waits: the counts are the path's shape, the same on
every device, and a test checks a video's per-frame counts on any machine (:func:`tally`).

A moving rig's re-estimate worker runs in :func:`own_stream`: its launches and copies go on a CUDA
stream of its own, so the frame loop neither waits for it nor for its downloads. Arrays allocated in
the worker are zeroed on the device's stream, so the worker's stream waits (on the device) for that
stream before each launch.

Arrays that stay on the host (a band of cells, work on Warp's CPU device) are not transfers:
:func:`host_array` wraps numpy memory for a CPU kernel without counting anything.
"""

from __future__ import annotations

import threading
from collections import Counter
from contextlib import contextmanager
from collections.abc import Iterator

import numpy as np
import warp as wp

KINDS = ("upload", "download", "sync")
ALIGN_BYTES = 256  # each field of a staged block starts on this boundary (CUDA's copy alignment)

_local = threading.local()


def tally() -> Counter:
    """This thread's counts so far, by (kind, what): a copy, to subtract one from the next."""
    return Counter(getattr(_local, "counts", ()))


def _count(kind: str, what: str) -> None:
    if not hasattr(_local, "counts"):
        _local.counts = Counter()
    _local.counts[(kind, what)] += 1


def stream(device: str) -> wp.Stream | None:
    """The stream this thread launches and copies on: its own (:func:`own_stream`), made to wait first
    for the device's stream (where allocations are zeroed); None for the device's current one."""
    own = getattr(_local, "stream", None)
    if own is None or device == "cpu":
        return None
    own.wait_stream(wp.get_device(device).stream)
    return own


@contextmanager
def own_stream(device: str) -> Iterator[None]:
    """Inside the block this thread's launches and copies on ``device`` go on a CUDA stream of its own
    (nothing changes on the CPU)."""
    if device == "cpu":
        yield
        return
    saved = getattr(_local, "stream", None)
    _local.stream = wp.Stream(device)
    try:
        yield
    finally:
        _local.stream = saved


def host_array(values: np.ndarray, dtype) -> wp.array:
    """A Warp array on the CPU device over the memory of the contiguous numpy ``values`` (no copy, no
    transfer): host work that a CPU kernel does in place."""
    return wp.array(values, dtype=dtype, device="cpu", copy=False)


def to_device(values, dtype, device: str, what: str) -> wp.array:
    """A new array on ``device`` holding a copy of the numpy ``values`` (on the CPU too): one upload."""
    _count("upload", what)
    host = wp.array(np.ascontiguousarray(values), dtype=dtype, device="cpu")  # converted to dtype's scalars
    if device == "cpu":
        return host
    out = wp.empty_like(host, device=device)
    wp.copy(out, host, stream=stream(device))
    return out


def for_reading(values: np.ndarray, dtype, device: str, what: str) -> wp.array:
    """:func:`to_device` for an array kernels only read: on the CPU a read-only ``values`` (a value
    nobody may change, such as a video's maps) is used where it is, anything else is copied, so that a
    caller changing its array later changes nothing on any device."""
    if device == "cpu" and isinstance(values, np.ndarray) and not values.flags.writeable \
            and values.flags.c_contiguous and values.dtype == _numpy_dtype(dtype):
        _count("upload", what)
        return wp.array(values, dtype=dtype, device="cpu", copy=False)
    return to_device(values, dtype, device, what)


def _numpy_dtype(dtype) -> np.dtype:
    """The numpy scalar type of a Warp dtype (a vector's component type)."""
    return np.dtype(wp.dtype_to_numpy(getattr(dtype, "_wp_scalar_type_", dtype)))


def upload(array: wp.array, values, what: str) -> None:
    """Copy ``values`` (array-like of ``array``'s shape) into the existing ``array``: in place through
    its numpy view on the CPU, from host memory on a GPU."""
    _count("upload", what)
    if array.device.is_cpu:
        np.copyto(array.numpy(), values, casting="unsafe")
        return
    host = host_array(np.ascontiguousarray(values, _numpy_dtype(array.dtype)), array.dtype)
    wp.copy(array, host, stream=stream(str(array.device)))


def _wait(device: str, what: str) -> None:
    _count("sync", what)
    if device != "cpu":
        wp.synchronize_stream(stream(device) or wp.get_device(device).stream)


def download(array: wp.array, what: str) -> np.ndarray:
    """``array``'s values on the host once the stream's work is done (one download, one wait): the
    array's own memory on the CPU (valid while it lives), a new host copy from a GPU."""
    _count("download", what)
    device = str(array.device)
    if array.device.is_cpu:
        _wait(device, what)
        return array.numpy()
    host = wp.empty(array.shape, dtype=array.dtype, device="cpu")
    wp.copy(host, array, stream=stream(device))
    _wait(device, what)
    return host.numpy()


class Staged:
    """One block of memory on ``device`` holding named typed fields, and its mirror on the host (pinned,
    on a GPU; the block itself on the CPU), moved in one copy: ``fields`` maps a name to (shape, numpy
    dtype). ``host[name]`` is a numpy view to fill or read, ``device[name]`` the Warp array (flat) a
    kernel takes; :meth:`upload` and :meth:`download` move the whole block."""

    def __init__(self, fields: dict[str, tuple[tuple[int, ...], np.dtype]], device: str, what: str):
        self.what = what
        self.device_name = device
        starts, end = {}, 0
        for name, (shape, dtype) in fields.items():
            starts[name] = end
            end += -(-int(np.prod(shape)) * np.dtype(dtype).itemsize // ALIGN_BYTES) * ALIGN_BYTES
        self._block = wp.empty(max(end, 1), dtype=wp.uint8, device=device)
        # On a GPU the host side is pinned: the copies run as DMA, and the next frame's fill waits for
        # the last frame's download (its wait), which has finished using it.
        self._mirror = self._block if device == "cpu" else wp.empty(max(end, 1), dtype=wp.uint8, device="cpu",
                                                                    pinned=True)
        self.host: dict[str, np.ndarray] = {}
        self.device: dict[str, wp.array] = {}
        for name, (shape, dtype) in fields.items():
            count = int(np.prod(shape))
            warp_dtype = wp.dtype_from_numpy(np.dtype(dtype))
            self.host[name] = wp.array(ptr=self._mirror.ptr + starts[name], dtype=warp_dtype, shape=(count,),
                                       device="cpu").numpy().reshape(shape)
            self.device[name] = wp.array(ptr=self._block.ptr + starts[name], dtype=warp_dtype, shape=(count,),
                                         device=device)

    def zero(self) -> None:
        """Every field 0, on the device and the host (set on each side: nothing moves)."""
        self._block.zero_()
        self._mirror.zero_()

    def upload(self) -> None:
        """The host's fields onto the device, in one copy."""
        _count("upload", self.what)
        if self._mirror is not self._block:
            wp.copy(self._block, self._mirror, stream=stream(self.device_name))

    def download(self) -> None:
        """The device's fields into the host's, in one copy after the stream's work (one download, one
        wait: the only wait a frame has besides the band's)."""
        _count("download", self.what)
        if self._mirror is not self._block:
            wp.copy(self._mirror, self._block, stream=stream(self.device_name))
        _wait(self.device_name, self.what)
