"""Where and how the Warp kernels run: device choice, row-band launches, pre-warm.

Every kernel of this package takes ``row0: int`` as its first argument and is launched with
``dim=(rows, width)``; the pixel row it handles is ``row0 + i``. Warp's CPU backend runs one launch
on one thread, so on CPU ``launch_rows`` cuts the image into horizontal bands and launches each band
from a small persistent thread pool (a launch releases the GIL while it runs); a launch of one band
is recorded once per kernel and grid and replayed (:func:`_launch_on_host`: the per-frame seam's small
kernels paid more to ``wp.launch`` than to their work). On CUDA one launch covers the whole image.

The device is chosen once per run: the job (``stitch_images``, ``stitch_videos``, ``sena-warp eval``)
calls :func:`resolve_config` and hands the result to every stage, which allocates on ``cfg.device``
and launches with ``cfg.cpu_threads``::

    from sena_warp.kernels import runtime
    out = wp.zeros((height, width), dtype=float, device=cfg.device)
    runtime.launch_rows(my_kernel, height, width, [arg1, arg2, out], cfg.device, cfg.cpu_threads)
"""

from __future__ import annotations

import atexit
import importlib
import math
import os
import pkgutil
import shutil
import tempfile
import threading
import time
import weakref
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path

import warp as wp
import warp._src.build  # init_kernel_cache: where Warp keeps compiled kernels
from warp._src.codegen import StructInstance  # a struct's value, held by reference in a recorded launch

from sena_warp.config import Config
from sena_warp.errors import InputError
from sena_warp import native_stderr
from sena_warp.kernels import transfer
from sena_warp.progress import LOGGER, Count, stage

# The init banner would go to stdout of every CLI run; Warp reads the level when it initialises
# (``config.quiet`` is deprecated in favour of this in Warp 1.19).
wp.config.log_level = wp.LOG_WARNING


def _usable_kernel_cache() -> None:
    """Point Warp at a temporary kernel cache, saying so once, when its own cannot be written.

    Warp keeps compiled kernels under ``WARP_CACHE_PATH`` or the user's cache folder (under HOME) and
    fails to start when that cannot be created; a read-only HOME or a mistyped path would stop every
    run with a traceback. The temporary cache is removed at exit, so such runs compile every time.
    """
    try:
        # Warp's own resolution of the folder (WARP_CACHE_PATH, else the user cache), as wp.init() does it.
        warp._src.build.init_kernel_cache(wp.config.kernel_cache_dir)
        with tempfile.TemporaryFile(dir=wp.config.kernel_cache_dir):
            pass
    except OSError as exc:
        unusable = exc.filename or wp.config.kernel_cache_dir or os.environ.get("WARP_CACHE_PATH", "")
        wp.config.kernel_cache_dir = tempfile.mkdtemp(prefix="sena-warp-kernels-")
        atexit.register(shutil.rmtree, wp.config.kernel_cache_dir, ignore_errors=True)
        LOGGER.warning(f"kernel cache {unusable} cannot be written ({exc.strerror}): using a temporary one, so "
                       f"kernels compile on every run; set WARP_CACHE_PATH to a writable folder")


def _init_without_driver_noise() -> None:
    """``wp.init()`` with the native library's stderr silenced.

    On a machine without a GPU, Warp's C++ core prints "Could not find or load the NVIDIA CUDA
    driver" on every run: a second stderr line in front of the CLI's one-line messages. Whether
    CUDA is there is decided by ``resolve_device``, which says so in its own words.
    """
    with native_stderr.caught():
        wp.init()


_usable_kernel_cache()
_init_without_driver_noise()

_pools: dict[int, ThreadPoolExecutor] = {}
_pools_lock = threading.Lock()
_loaded: set[tuple[str, str]] = set()
_loads: dict[tuple[str, str], Future] = {}  # (module name, device) -> its load, under way or done
_loads_lock = threading.Lock()
_compile_pool = ThreadPoolExecutor(max_workers=os.cpu_count() or 1, thread_name_prefix="sena-warp-load")
_compile_count: "_CompileCount | None" = None
# Shipped builds, one folder per module (tools/ship_kernels.py), under the Warp version they were built with:
# a CPU object holds that version's native code, so another version compiles instead of loading it.
SHIPPED = Path(__file__).resolve().parent / "built"
BUILT = SHIPPED / wp.config.version
SHIPPED_PTX_ARCH = 75  # the CUDA build shipped: PTX that the driver compiles on load for any GPU from sm_75 on
# The kernel modules in the order a stitch first launches them: the estimate's (the lattice, the gate, the warp
# map and its samples, the seam), then the frames'. Loaded in this order, the estimate's come first.
FIRST_LAUNCHED = ("ffd", "gate", "remap", "sampling", "seam", "seam_path", "composite", "frame_seam", "map_change")
# The frame kernels built per channel count (by that count in a dict): a stitch loads those of its images only.
PER_CHANNELS = ("COMPOSITE_FRAME_KERNELS", "COMPOSITE_PIXEL_KERNELS")


def resolve_device(name: str) -> str:
    """Warp device for a ``Config.device`` value: "auto" -> "cuda" when a GPU is present else "cpu".

    Raises InputError for "cuda" without a GPU or for an unknown name.
    """
    has_cuda = wp.get_cuda_device_count() > 0
    if name == "auto":
        return "cuda" if has_cuda else "cpu"
    if name == "cuda" and not has_cuda:
        raise InputError("device 'cuda' was requested but no CUDA GPU is available; use --device cpu or auto")
    if name not in ("cpu", "cuda"):
        raise InputError(f"unknown device {name!r}; choose auto, cpu or cuda")
    return name


def resolve_config(cfg: Config) -> Config:
    """``cfg`` with its device resolved (:func:`resolve_device`): what a run computes once, at its start,
    and passes to every stage, so that stages only ever see "cpu" or "cuda"."""
    return cfg.replace(device=resolve_device(cfg.device))


CORES = os.cpu_count() or 1  # asked once: a launch's thread count is worked out on every frame
BAND_THREADS = 1  # small per-frame kernels (the seam's band, a row's runs): a second CPU thread costs more than it saves


def cpu_threads(threads: int) -> int:
    """Number of CPU launch threads: ``threads`` when > 0, else one per core."""
    return threads if threads > 0 else CORES


def _pool(threads: int) -> ThreadPoolExecutor:
    """The persistent pool of ``threads`` workers (created once per size)."""
    with _pools_lock:
        if threads not in _pools:
            _pools[threads] = ThreadPoolExecutor(max_workers=threads, thread_name_prefix="sena-warp")
        return _pools[threads]


def _ensure_loaded(kernel, device: str) -> None:
    """Load the kernel's module once, before bands launch concurrently: wait for a load under way in the
    background (:func:`prewarm`), or load it now."""
    if (kernel.module.name, device) not in _loaded:
        _load([kernel.module], device)


def _load(modules: list[wp.Module], device: str) -> None:
    """Load Warp ``modules`` on ``device`` (:func:`_start`) and wait until they are."""
    for load in _start(modules, device):
        load.result()


def _start(modules: list[wp.Module], device: str) -> list[Future]:
    """Start loading those of ``modules`` not loaded nor loading on ``device``, in their order, on a thread
    per core (Warp >= 1.19 loads CPU modules concurrently without losing any: NVIDIA/warp issues 1474 and
    1705); the load of each of ``modules``. Those that must be compiled (neither shipped nor in Warp's
    kernel cache) are counted as they finish, with an estimate of the time left: a first run's wait."""
    global _compile_count
    with _loads_lock:
        new = [m for m in modules if (m.name, device) not in _loads]
        compiling = [m for m in new if shipped_build(m, device) is None and not _in_kernel_cache(m, device)]
        if compiling:
            if _compile_count is None or _compile_count.done >= _compile_count.total:
                stage("compiling kernels (first run only)")
                _compile_count = _CompileCount(compiling)
            else:
                _compile_count.total += len(compiling)
        for module in new:
            _loads[(module.name, device)] = _compile_pool.submit(
                _load_one, module, device, _compile_count if module in compiling else None)
        return [_loads[(m.name, device)] for m in modules]


class _CompileCount(Count):
    """Kernel modules compiled so far of those a run started compiling, shown as each one ends (with the
    time left at the rate so far)."""

    def __init__(self, modules: list[wp.Module]):
        super().__init__("kernel modules compiled", len(modules), "modules/s")
        self.done = 0

    def finished(self, module: wp.Module, seconds: float) -> None:
        with _loads_lock:
            self.done += 1
            done = self.done
        LOGGER.debug("compiled %s in %.1f s", module.name.removeprefix("sena_warp.kernels."), seconds)
        if done >= self.total:
            self.close(done)
        else:
            self.update(done)


def _load_one(module: wp.Module, device: str, count: _CompileCount | None) -> None:
    """Load ``module`` on ``device``: its shipped build (``built/``), else Warp's kernel cache, else a compile
    (a shipped build that does not load, e.g. for another LLVM, is compiled instead)."""
    t0 = time.perf_counter()
    built = shipped_build(module, device)
    loaded = False
    if built is not None:
        binary, meta, arch = built
        try:
            module.load(device, block_dim=_block_dim(module, device), binary_path=str(binary), output_arch=arch,
                        meta_path=str(meta))
            loaded = True
        except Exception:  # Warp raises plain Exception for a binary it cannot load
            loaded = False
    if not loaded:
        wp.force_load(device=device, modules=[module], max_workers=0)
    _loaded.add((module.name, device))
    if count is not None:
        count.finished(module, time.perf_counter() - t0)


def _block_dim(module: wp.Module, device: str) -> int:
    """The block size a launch of ``module``'s kernels loads: 1 on the CPU, the module's own on CUDA."""
    return 1 if wp.get_device(device).is_cpu else module.options["block_dim"]


def shipped_build(module: wp.Module, device: str) -> tuple[Path, Path, int | None] | None:
    """(binary, metadata, CUDA arch or None) of the build of ``module`` for ``device`` in :data:`BUILT`, or
    None where there is none for the module as it is now (its folder is named by the hash of its code and
    options, so a kernel changed since ``tools/ship_kernels.py`` ran is compiled instead). CPU: an object
    for any CPU of this kind (x86-64 Linux, by Warp's target hash in its name); CUDA: PTX for sm_75, which
    the driver compiles on load for any GPU from sm_75 on."""
    dev = wp.get_device(device)
    ident = module.get_module_identifier(_block_dim(module, device))
    folder = BUILT / ident
    if dev.is_cpu:
        binary, arch = folder / module._get_compile_output_name(dev, block_dim=1), None
    elif dev.arch >= SHIPPED_PTX_ARCH:
        binary, arch = folder / f"{ident}.sm{SHIPPED_PTX_ARCH}.ptx", SHIPPED_PTX_ARCH
    else:
        return None
    meta = folder / f"{ident}.meta"
    return (binary, meta, arch) if binary.is_file() and meta.is_file() else None


def _in_kernel_cache(module, device: str) -> bool:
    """Whether Warp's kernel cache holds a build of ``module`` for ``device``: its folder is named by the
    hash of the variant that loads (CPU launches build block_dim 1, CUDA the module's block_dim)."""
    return os.path.isdir(os.path.join(wp.config.kernel_cache_dir, module.get_module_identifier(_block_dim(module, device))))


REPLAYS_KEPT = 64  # one-band CPU launches a thread keeps recorded (one per kernel and grid: a video's are a few)
_replays = threading.local()  # per thread: (kernel, dim) -> (its recorded wp.Launch, the inputs it was last given)


def _launch_on_host(kernel, dim: tuple[int, int], inputs: list) -> None:
    """One launch of ``kernel`` over ``dim`` on the CPU, on the calling thread: recorded the first time on
    that grid (``record_cmd``) and replayed after, setting only the inputs that are not as it holds them
    (:func:`_as_given`, :func:`_held_as_is`): arrays and structs by reference (a struct changed in place
    is read as it is at the launch), known by weak references so that a recording keeps no input alive;
    ints and floats by value; other values are set every time. A replay costs the host about 6 us and
    each input set about 5, ``wp.launch`` about 40: the per-frame seam makes about ten such launches a
    frame. Recorded per thread, so that threads launching one kernel never set each other's inputs."""
    kept = getattr(_replays, "kept", None)
    if kept is None:
        kept = _replays.kept = {}
    held = kept.get((kernel, dim))
    if held is None:
        if len(kept) >= REPLAYS_KEPT:  # the oldest goes (an image batch's grids change with each image)
            kept.pop(next(iter(kept)))
        launch = wp.launch(kernel, dim=dim, inputs=inputs, device="cpu", record_cmd=True)
        launch.fwd_args = None  # the inputs themselves, kept for Warp's CPU graph capture, which no launch here uses
        held = kept[(kernel, dim)] = (launch, [_as_given(value) for value in inputs])
    else:
        launch, last = held
        for index, value in enumerate(inputs):
            if not _held_as_is(value, last[index]):
                launch.set_param_at_index(index, value)
                last[index] = _as_given(value)
    held[0].launch()


def _as_given(value):
    """How a recorded launch remembers an input: an array or a struct by a weak reference, else itself."""
    return weakref.ref(value) if isinstance(value, (wp.array, StructInstance)) else value


def _held_as_is(value, held) -> bool:
    """Whether a recorded launch that was given ``held`` (:func:`_as_given`) may keep it for ``value``: the
    same array or struct, still alive (held by reference), an equal int, a float of the same bits (0.0 is
    not -0.0)."""
    if isinstance(value, (wp.array, StructInstance)):
        return isinstance(held, weakref.ref) and held() is value
    if type(value) is not type(held) or type(value) not in (int, float):
        return False
    return value == held and math.copysign(1.0, value) == math.copysign(1.0, held)


def row_bands(height: int, bands: int) -> list[tuple[int, int]]:
    """Split rows [0, height) into at most ``bands`` contiguous (row0, rows) pieces of near-equal size."""
    bands = max(1, min(bands, height))
    edges = [height * k // bands for k in range(bands + 1)]
    return [(edges[k], edges[k + 1] - edges[k]) for k in range(bands) if edges[k + 1] > edges[k]]


def launch_rows(kernel, height: int, width: int, inputs: list, device: str, threads: int) -> None:
    """Run ``kernel(row0, *inputs)`` over a (height, width) grid.

    ``device``: a resolved Warp device ("cpu" or "cuda", :func:`resolve_device`). On "cpu" the rows
    are split into ``cpu_threads(threads)`` bands launched in parallel, done when this returns; on
    "cuda" one launch of dim (height, width), queued on the thread's stream (``transfer.stream``)
    without waiting: a download waits for it (``transfer.py``). Arrays in ``inputs`` must live on
    ``device``.
    """
    if height <= 0 or width <= 0:
        return
    _ensure_loaded(kernel, device)
    if device != "cpu":
        wp.launch(kernel, dim=(height, width), inputs=[0, *inputs], device=device, stream=transfer.stream(device))
        return
    bands = row_bands(height, cpu_threads(threads))
    if len(bands) == 1:
        _launch_on_host(kernel, (height, width), [0, *inputs])
        return
    futures = [
        _pool(len(bands)).submit(wp.launch, kernel, (rows, width), [row0, *inputs], device=device)
        for row0, rows in bands
    ]
    for future in futures:
        future.result()


def launch_row_loops(kernel, height: int, width: int, inputs: list, device: str, threads: int) -> None:
    """Run ``kernel(row0, col_step, width, *inputs)`` over rows [0, height) (as :func:`launch_rows`).

    For kernels whose thread (i, j) loops over columns ``j, j + col_step, ... < width`` of row
    ``row0 + i``: on "cpu" one thread per row (``col_step`` 1), rows split into parallel bands as in
    :func:`launch_rows`, which saves Warp's per-thread overhead on the hottest kernels; on "cuda" one
    thread per pixel (``col_step`` = width).
    """
    if height <= 0 or width <= 0:
        return
    _ensure_loaded(kernel, device)
    if device != "cpu":
        wp.launch(kernel, dim=(height, width), inputs=[0, width, width, *inputs], device=device,
                  stream=transfer.stream(device))
        return
    bands = row_bands(height, cpu_threads(threads))
    if len(bands) == 1:
        _launch_on_host(kernel, (height, 1), [0, 1, width, *inputs])
        return
    futures = [
        _pool(len(bands)).submit(wp.launch, kernel, (rows, 1), [row0, 1, width, *inputs], device=device)
        for row0, rows in bands
    ]
    for future in futures:
        future.result()


def loaded() -> frozenset[tuple[str, str]]:
    """(kernel module name, device) of every kernel module loaded so far by this runtime."""
    return frozenset(_loaded)


def kernel_modules(device: str, channels: tuple[int, ...] | None = None) -> dict[str, list[wp.Module]]:
    """Per Warp device, the modules of ``sena_warp.kernels``, in the order a stitch first launches them (the
    estimate's, then the frames'): those at module level and the variants a module builds with a factory and
    lists in a dict (of the frame kernels only those for ``channels``; None: all), each where it is defined. On
    ``device``, or where a module says its kernels always run (its ``DEVICE``: work on host arrays)."""
    package = importlib.import_module("sena_warp.kernels")
    found: dict[str, dict[str, wp.Module]] = {}
    names = sorted((info.name for info in pkgutil.iter_modules(package.__path__)),
                   key=lambda name: FIRST_LAUNCHED.index(name) if name in FIRST_LAUNCHED else len(FIRST_LAUNCHED))
    for name in names:
        module = importlib.import_module(f"sena_warp.kernels.{name}")
        on = getattr(module, "DEVICE", device)
        for attribute, obj in vars(module).items():
            kernels = obj.items() if isinstance(obj, dict) else ((None, obj),)
            for key, kernel in kernels:
                if attribute in PER_CHANNELS and channels is not None and key not in channels:
                    continue
                if isinstance(kernel, wp.Kernel) and kernel.func.__module__ == module.__name__:
                    found.setdefault(on, {}).setdefault(kernel.module.name, kernel.module)
    return {on: list(modules.values()) for on, modules in found.items()}


def prewarm(device: str, channels: tuple[int, ...] | None = None, wait: bool = True) -> None:
    """Load every module of ``sena_warp.kernels`` a stitch launches (:func:`kernel_modules`; ``channels``:
    the frame kernels' channel counts it needs, None: all): shipped builds load at once, others come from
    Warp's cache or are compiled, counted as they finish. ``wait`` False starts the loads in the
    background and returns: a launch waits for its own module only, so a first run compiles the frame
    kernels while the estimate's features run."""
    for on, modules in kernel_modules(device, channels).items():
        loads = _start(modules, on)
        if wait:
            for load in loads:
                load.result()
