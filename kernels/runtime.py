"""Where and how the Warp kernels run: device choice, row-band launches, pre-warm.

Every kernel of this package takes ``row0: int`` as its first argument and is launched with
``dim=(rows, width)``; the pixel row it handles is ``row0 + i``. Warp's CPU backend runs one launch
on one thread, so on CPU ``launch_rows`` cuts the image into horizontal bands and launches each band
from a small persistent thread pool (a launch releases the GIL while it runs). On CUDA one launch
covers the whole image.

The device is chosen once per run: the job (``stitch_images``, ``stitch_videos``, ``sena-warp eval``)
calls :func:`resolve_config` and hands the result to every stage, which allocates on ``cfg.device``
and launches with ``cfg.cpu_threads``::

    from sena_warp.kernels import runtime
    out = wp.zeros((height, width), dtype=float, device=cfg.device)
    runtime.launch_rows(my_kernel, height, width, [arg1, arg2, out], cfg.device, cfg.cpu_threads)
"""

from __future__ import annotations

import importlib
import os
import pkgutil
import threading
from concurrent.futures import ThreadPoolExecutor

import warp as wp

from sena_warp.config import Config
from sena_warp.errors import InputError
from sena_warp.kernels import transfer
from sena_warp.progress import stage

# The init banner would go to stdout of every CLI run; Warp reads the level when it initialises
# (``config.quiet`` is deprecated in favour of this in Warp 1.19).
wp.config.log_level = wp.LOG_WARNING


def _init_without_driver_noise() -> None:
    """``wp.init()`` with the native library's stderr silenced.

    On a machine without a GPU, Warp's C++ core prints "Could not find or load the NVIDIA CUDA
    driver" on every run: a second stderr line in front of the CLI's one-line messages. Whether
    CUDA is there is decided by ``resolve_device``, which says so in its own words.
    """
    saved = os.dup(2)
    try:
        with open(os.devnull, "w") as devnull:
            os.dup2(devnull.fileno(), 2)
            wp.init()
    finally:
        os.dup2(saved, 2)
        os.close(saved)


_init_without_driver_noise()

_pools: dict[int, ThreadPoolExecutor] = {}
_pools_lock = threading.Lock()
_loaded: set[tuple[str, str]] = set()
_compiling_said = False


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
    """Load (compile if needed) the kernel's module once, before bands launch concurrently."""
    if (kernel.module.name, device) not in _loaded:
        _load([kernel.module], device)


def _load(modules: list[wp.Module], device: str) -> None:
    """Load (compile if needed) Warp ``modules`` on ``device``, several at once on a thread per core
    (Warp >= 1.19 loads CPU modules concurrently without losing any: NVIDIA/warp issues 1474 and 1705);
    a first run says once that it compiles."""
    if not _compiling_said and not all(_in_kernel_cache(module, device) for module in modules):
        _say_compiling()
    wp.force_load(device=device, modules=modules, max_workers=CORES)
    _loaded.update((module.name, device) for module in modules)


def _in_kernel_cache(module, device: str) -> bool:
    """Whether Warp's kernel cache holds a build of ``module`` for ``device``: its folder is named by the
    hash of the variant that loads (CPU launches build block_dim 1, CUDA the module's block_dim)."""
    block_dim = 1 if wp.get_device(device).is_cpu else module.options["block_dim"]
    return os.path.isdir(os.path.join(wp.config.kernel_cache_dir, module.get_module_identifier(block_dim)))


def _say_compiling() -> None:
    """The one-time stage line of a first run, which spends seconds compiling (later runs load the cache)."""
    global _compiling_said
    _compiling_said = True
    stage("compiling kernels (first run only)")


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
        wp.launch(kernel, dim=(height, width), inputs=[0, *inputs], device=device)
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
        wp.launch(kernel, dim=(height, 1), inputs=[0, 1, width, *inputs], device=device)
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


def kernel_modules() -> list[tuple[wp.Module, str | None]]:
    """Every Warp module of ``sena_warp.kernels`` (each of its modules imported): those of the kernels
    at module level and of the variants a module builds with a factory and lists in a dict, each with
    the device its kernels always run on (the module's ``DEVICE``: work on host arrays), or None: the
    run's device."""
    package = importlib.import_module("sena_warp.kernels")
    found: dict[str, tuple[wp.Module, str | None]] = {}
    for info in pkgutil.iter_modules(package.__path__):
        module = importlib.import_module(f"sena_warp.kernels.{info.name}")
        for obj in vars(module).values():
            for kernel in obj.values() if isinstance(obj, dict) else (obj,):
                if isinstance(kernel, wp.Kernel) and kernel.func.__module__ == module.__name__:
                    found[kernel.module.name] = (kernel.module, getattr(module, "DEVICE", None))
    return list(found.values())


def prewarm(device: str) -> None:
    """Load (compile once, then cached) every kernel module of the package (:func:`kernel_modules`): on
    ``device``, or where a module says its kernels always run; the modules of one device together
    (:func:`_load`)."""
    due: dict[str, list[wp.Module]] = {}  # per device, the Warp modules not loaded yet
    for module, on in kernel_modules():
        if (module.name, on or device) not in _loaded:
            due.setdefault(on or device, []).append(module)
    for on, modules in due.items():
        _load(modules, on)
