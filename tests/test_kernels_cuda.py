"""Every kernel module compiles for CUDA on any machine, a GPU or not.

The CUDA path runs only where a GPU is lent, but NVRTC ships in the warp-lang wheel and compiles
without a GPU or a driver: each module of ``sena_warp.kernels`` (``runtime.kernel_modules``, the frame
kernels' per-channel variants included) is built ahead of time as sm_90 CUBIN (H100, H200) and as
sm_75 PTX (any GPU from Turing on: the driver compiles PTX for newer ones). A CUDA compile error, also
one only ``__CUDA_ARCH__`` code has, fails here. The builds go to a folder of Warp's kernel cache,
named by each module's hash, so a run with unchanged kernels finds them instead of compiling again.
"""

from __future__ import annotations

from pathlib import Path

import pytest
import warp as wp

from sena_warp.kernels import runtime

TARGETS = ((90, False), (75, True))  # (arch, PTX instead of CUBIN)


def aot_dir() -> Path:
    return Path(wp.config.kernel_cache_dir) / "sena_warp_aot"


def test_every_kernel_module_compiles_for_cuda():
    modules = [module for on in runtime.kernel_modules("cuda").values() for module in on]
    assert len(modules) >= 15  # the package's modules and the frame kernels' variants
    built = []
    for module in modules:
        for arch, ptx in TARGETS:
            built += wp.compile_aot_module(module, arch=arch, module_dir=aot_dir(), use_ptx=ptx)
    assert len(built) == 2 * len(modules)
    assert all(path.is_file() and path.stat().st_size > 0 for path in built)
    assert {path.suffix for path in built} == {".cubin", ".ptx"}


BROKEN_ON_CUDA = """
#if defined(__CUDA_ARCH__)
    out[0] = no_such_name;
#else
    out[0] = x;
#endif
"""


@wp.func_native(BROKEN_ON_CUDA)
def copy_on_the_host(x: float, out: wp.array(dtype=float)):
    ...


@wp.kernel(module="unique", module_options={"enable_backward": False})
def broken_on_cuda_kernel(out: wp.array(dtype=float)):
    copy_on_the_host(1.0, out)


def test_a_compile_error_only_cuda_code_has_fails_the_check(tmp_path):
    """The check can fail: a native snippet that is fine on the CPU and wrong under ``__CUDA_ARCH__``."""
    out = wp.zeros(1, dtype=float, device="cpu")
    wp.launch(broken_on_cuda_kernel, dim=1, inputs=[out], device="cpu")
    assert out.numpy()[0] == 1.0
    with pytest.raises(Exception, match="(?i)compil|nvrtc|error"):
        wp.compile_aot_module(broken_on_cuda_kernel.module, arch=75, module_dir=tmp_path, use_ptx=True)
