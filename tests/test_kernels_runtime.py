"""Runtime: device choice, row bands, threaded launches equal one launch, pre-warm covers every kernel module."""

from __future__ import annotations

import gc
import json
import os
import subprocess
import sys
import weakref

import numpy as np
import pytest
import warp as wp

from conftest import REPO
from sena_warp.errors import InputError
from sena_warp.kernels import runtime
from sena_warp.kernels.frame_objects import CellGrid, coarse_masks_kernel
from test_kernels_maps import HAS_CUDA, scene_geometry, smooth_field, source_map_reference
from test_kernels_remap import run_remap


def test_resolve_device():
    assert runtime.resolve_device("auto") == ("cuda" if HAS_CUDA else "cpu")
    assert runtime.resolve_device("cpu") == "cpu"
    with pytest.raises(InputError, match="unknown device"):
        runtime.resolve_device("tpu")


@pytest.mark.skipif(HAS_CUDA, reason="a GPU is present")
def test_cuda_without_gpu_is_an_input_error():
    with pytest.raises(InputError, match="no CUDA GPU"):
        runtime.resolve_device("cuda")


@pytest.mark.parametrize("height, bands", [(1, 4), (7, 3), (480, 16), (5, 5)])
def test_row_bands_cover_each_row_once(height, bands):
    pieces = runtime.row_bands(height, bands)
    rows = np.concatenate([np.arange(r0, r0 + n) for r0, n in pieces])
    np.testing.assert_array_equal(rows, np.arange(height))
    assert len(pieces) == min(height, bands) and min(n for _, n in pieces) >= height // bands


def test_threaded_launch_equals_single_launch(udisd_pair, warp_device):
    img_src, img_tgt = udisd_pair
    geo = scene_geometry(img_src.shape, img_tgt.shape)
    map_src = source_map_reference(geo["canvas"], geo["affine_src_to_tgt"], smooth_field(geo["canvas"].shape, 8.0))
    map_src = map_src.astype(np.float32)
    out_one, valid_one = run_remap(img_src, map_src, warp_device, threads=1)
    for threads in (2, 3, 7):
        out, valid = run_remap(img_src, map_src, warp_device, threads=threads)
        np.testing.assert_array_equal(out, out_one)
        np.testing.assert_array_equal(valid, valid_one)
    assert valid_one.any()


def test_a_replayed_launch_reads_its_inputs_as_they_are_at_each_launch():
    """One-band CPU launches are recorded and replayed: new arrays, new values and a struct changed in
    place all reach the kernel (``coarse_masks_kernel``, against a launch packed afresh)."""
    lines = wp.array(np.arange(4, dtype=np.int32), dtype=int, device="cpu")
    coarse = CellGrid()
    coarse.x0, coarse.cell, coarse.step = wp.array(np.zeros(4, np.int32), dtype=int, device="cpu"), 4, 1
    rng = np.random.default_rng(3)
    masks = [wp.array(rng.integers(0, 2, (4, 3)).astype(np.uint8), dtype=wp.uint8, device="cpu") for _ in range(2)]
    fine = CellGrid()
    fine.cell, fine.step = 2, 1
    for x0, width in (([0, 2, 4, 0], 6), ([2, 0, 0, 6], 5), ([4, 4, 2, 2], 5)):
        fine.x0 = wp.array(np.array(x0, np.int32), dtype=int, device="cpu")  # the same struct, changed in place
        replayed, fresh = ([wp.zeros((4, 6), dtype=wp.uint8, device="cpu") for _ in range(2)] for _ in range(2))
        runtime.launch_row_loops(coarse_masks_kernel, 4, width, [lines, fine, coarse, *masks, *replayed], "cpu", 1)
        wp.launch(coarse_masks_kernel, dim=(4, 1), inputs=[0, 1, width, lines, fine, coarse, *masks, *fresh],
                  device="cpu")
        for a, b in zip(replayed, fresh):
            np.testing.assert_array_equal(a.numpy(), b.numpy())
        assert replayed[0].numpy().any()
    gone = weakref.ref(replayed[0])  # a recording keeps no input alive
    del replayed
    gc.collect()
    assert gone() is None


# Run in a fresh process, where nothing is loaded yet, with an empty kernel cache (a first run): prewarm,
# then an image stitch and both frame kernels (row runs, per pixel) of the video's Y (1 channel) and UV
# (2 channels) passes; print what was loaded before and after.
PREWARM_PROBE = """
import json, sys
import numpy as np
from sena_warp.composite import FrameState, composite_image, composite_plan
from sena_warp.config import Config
from sena_warp.imageio import read_image
from sena_warp.kernels import runtime
from sena_warp.stitch import stitch_images

before = runtime.loaded()
runtime.prewarm("cpu")
warmed = runtime.loaded()
cfg = Config(device="cpu")
img_a, img_b = (read_image(sys.argv[1] + name) for name in ("/a.jpg", "/b.jpg"))
maps = stitch_images(img_a, img_b, cfg).maps
for channels in (1, 2):
    pair = [np.ascontiguousarray(img[:, :, :channels]) for img in maps.rig.pick(img_a, img_b)]
    plan = composite_plan(maps.map_src_input, maps.map_tgt_input, maps.seam_input, (pair[0].shape, pair[1].shape), cfg)
    gains = tuple(np.ones(channels) if k % 2 == 0 else np.zeros(channels) for k in range(4))
    for per_pixel in (False, True):
        composite_image(*pair, plan, FrameState(maps.seam_input.positions, gains), cfg, per_pixel)
print(json.dumps({"before": sorted(before), "warmed": sorted(warmed), "after": sorted(runtime.loaded()),
                  "imported": sorted(m for m in sys.modules if m.startswith("sena_warp.kernels."))}))
"""


def test_a_first_run_loads_the_shipped_builds_and_compiles_nothing(bundled_dir, tmp_path):
    probe = subprocess.run([sys.executable, "-c", PREWARM_PROBE, str(bundled_dir / "udisd_test_000001")],
                           capture_output=True, text=True, check=True,
                           env={**os.environ, "WARP_CACHE_PATH": str(tmp_path)})
    assert list(tmp_path.glob("*/*")) == []  # an empty kernel cache stays empty: nothing was compiled
    seen = json.loads(probe.stdout.strip().splitlines()[-1])
    kernel_files = {path.stem for path in (REPO / "kernels").glob("*.py")} - {"__init__"}
    assert {"composite", "ffd", "gate", "remap", "sampling", "seam"} <= kernel_files
    assert seen["imported"] == sorted(f"sena_warp.kernels.{name}" for name in kernel_files)
    assert seen["before"] == []
    warmed_modules = {name for name, _ in seen["warmed"]}
    for name in kernel_files - {"runtime", "transfer"}:  # where and how kernels run, and what they move: no kernels
        assert any(module.startswith(f"sena_warp.kernels.{name}") for module in warmed_modules), name
    # Nothing the stitch or the planes launched had to be loaded after the prewarm.
    assert seen["after"] == seen["warmed"]


def test_the_shipped_builds_are_those_of_the_kernels_as_they_are():
    """Every kernel module has its CPU object and its sm_75 PTX in ``kernels/built/``, under the name of its
    code as it is now, and nothing else is there: after a change to ``kernels/``, run
    ``.venv/bin/python tools/ship_kernels.py`` (a stale build is never loaded, but a first run compiles).
    The builds are for one Warp version: with another one installed they are not used, and not checked."""
    shipped = sorted(folder.name for folder in runtime.SHIPPED.iterdir())
    if not runtime.BUILT.is_dir():
        pytest.skip(f"the shipped builds are for Warp {', '.join(shipped)}, not the installed {wp.config.version}")
    assert shipped == [runtime.BUILT.name], "builds of another Warp version: run tools/ship_kernels.py"
    wanted = set()
    for module in runtime.kernel_modules("cpu")["cpu"]:
        assert runtime.shipped_build(module, "cpu") is not None, f"{module.name}: run tools/ship_kernels.py"
        cuda_id = module.get_module_identifier(module.options["block_dim"])
        ptx = runtime.BUILT / cuda_id / f"{cuda_id}.sm{runtime.SHIPPED_PTX_ARCH}.ptx"
        assert ptx.is_file() and (runtime.BUILT / cuda_id / f"{cuda_id}.meta").is_file(), f"{module.name}: run " \
                                                                                          "tools/ship_kernels.py"
        wanted |= {module.get_module_identifier(1), cuda_id}
    assert {folder.name for folder in runtime.BUILT.iterdir()} == wanted, "stale builds: run tools/ship_kernels.py"


def test_kernels_are_built_for_any_cpu_of_their_kind():
    """The shipped CPU objects must run on any x86-64 CPU: no -march=native (``kernels/__init__.py``)."""
    for module in runtime.kernel_modules("cpu")["cpu"]:
        assert module.options["cpu_compiler_flags"] == "", module.name


def test_every_kernel_is_built_forward_only():
    """No kernel here is differentiated; Warp's adjoint code would more than double a first run's compile
    (``kernels/__init__.py``). A module that forgets ``enable_backward`` False fails here."""
    import warp as wp

    runtime.prewarm("cpu")
    modules = [module for name, module in sys.modules.items() if name.startswith("sena_warp.kernels.")]
    kernels = [kernel for module in modules for obj in vars(module).values()
               for kernel in (obj.values() if isinstance(obj, dict) else (obj,)) if isinstance(kernel, wp.Kernel)]
    assert len(kernels) >= 20
    for kernel in kernels:
        assert kernel.module.options["enable_backward"] is False, kernel.key


@pytest.mark.parametrize("unwritable", ["WARP_CACHE_PATH", "HOME"])
def test_an_unwritable_kernel_cache_falls_back_to_a_temporary_one_with_one_warning(unwritable, bundled_dir, tmp_path):
    """A WARP_CACHE_PATH that is a file, or a HOME that cannot hold a cache folder: the run goes on with a
    temporary cache (one warning line, exit 0), removed when the process ends."""
    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder")
    env = {k: v for k, v in os.environ.items() if k not in ("WARP_CACHE_PATH", "XDG_CACHE_HOME")}
    env.update({unwritable: str(blocker), "TMPDIR": str(tmp_path)})
    pair = bundled_dir / "udisd_test_000001"
    done = subprocess.run([sys.executable, "-m", "sena_warp.cli", "match", pair / "a.jpg", pair / "b.jpg",
                           "--features", "sift", "-q"], capture_output=True, text=True, env=env, cwd=tmp_path,
                          timeout=300)
    assert done.returncode == 0, done.stderr
    lines = done.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("sena-warp: warning: kernel cache"), lines
    assert "cannot be written" in lines[0] and "WARP_CACHE_PATH" in lines[0]
    assert json.loads(done.stdout)["matches"] > 0
    assert not list(tmp_path.glob("sena-warp-kernels-*"))  # the temporary cache is gone
    assert blocker.read_text() == "not a folder"
