"""Build the kernel modules the package ships (``kernels/built/``), so that a first run need not compile them.

Usage (from the repository root, after any change to ``kernels/``)::

    .venv/bin/python tools/ship_kernels.py

For each module of ``sena_warp.kernels`` (``runtime.kernel_modules``, every frame-kernel variant): the CPU
object as a launch loads it (block size 1), built for any x86-64 CPU (``MODULE_OPTIONS``), and PTX for
sm_75, which the CUDA driver compiles on load for any GPU from sm_75 on. Each lands in a folder named as
Warp names the module (its code's and options' hash), with its metadata, under the installed Warp's version;
folders of modules that no longer exist, and other versions' builds, are removed. ``tests/test_kernels_runtime.py`` fails while the builds are not those of the
kernels as they are. CUDA compiles here without a GPU: NVRTC ships in the warp-lang wheel.
"""

from __future__ import annotations

import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

CACHE = tempfile.mkdtemp(prefix="sena-warp-ship-")
os.environ["WARP_CACHE_PATH"] = CACHE  # before Warp starts: the CPU builds are compiled into an empty cache


def main() -> int:
    import warp as wp

    from sena_warp.kernels import runtime

    modules = runtime.kernel_modules("cpu")["cpu"]
    runtime.BUILT.mkdir(parents=True, exist_ok=True)
    for other in runtime.SHIPPED.iterdir():
        if other != runtime.BUILT:
            shutil.rmtree(other)
            print(f"removed the builds of Warp {other.name}")
    kept = set()
    for module in modules:
        t0 = time.perf_counter()
        cpu_id = module.get_module_identifier(1)
        module.load("cpu", block_dim=1)  # compiled into the empty cache, as a CPU launch builds it
        cpu_folder = runtime.BUILT / cpu_id
        shutil.rmtree(cpu_folder, ignore_errors=True)
        cpu_folder.mkdir()
        for path in Path(wp.config.kernel_cache_dir, cpu_id).iterdir():
            if path.suffix in (".o", ".meta"):
                shutil.copy(path, cpu_folder / path.name)
        cuda_id = module.get_module_identifier(module.options["block_dim"])
        cuda_folder = runtime.BUILT / cuda_id
        shutil.rmtree(cuda_folder, ignore_errors=True)
        wp.compile_aot_module(module, arch=runtime.SHIPPED_PTX_ARCH, module_dir=cuda_folder, use_ptx=True)
        for path in cuda_folder.iterdir():
            if path.suffix not in (".ptx", ".meta"):
                path.unlink()  # the generated CUDA source: not needed to load
        kept |= {cpu_id, cuda_id}
        print(f"{module.name}: {cpu_id}, {cuda_id} ({time.perf_counter() - t0:.1f} s)", flush=True)
    for folder in runtime.BUILT.iterdir():
        if folder.name not in kept:
            shutil.rmtree(folder)
            print(f"removed {folder.name}")
    shutil.rmtree(CACHE, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
