"""Shared fixtures: the bundled test data (tests/data), the wider ../shared/data set (tests marked ``shared``).

A fresh clone has tests/data only: every test marked ``shared`` is then deselected (not skipped),
so the only skips are the ones the machine decides (no CUDA GPU, running as root). A test that
needs ../shared/data must carry the marker: using ``shared_dir`` without it is a collection error,
and ``pair_folder`` refuses a shared pair to an unmarked test.
"""

from __future__ import annotations

from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
BUNDLED = REPO / "tests" / "data"
SHARED = REPO.parent / "shared" / "data"
SHARED_PRESENT = (SHARED / "MANIFEST.md").exists()


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    unmarked = [item.nodeid for item in items
                if "shared_dir" in getattr(item, "fixturenames", ()) and item.get_closest_marker("shared") is None]
    if unmarked:
        raise pytest.UsageError("these tests use shared_dir but are not marked shared: " + ", ".join(unmarked))
    if SHARED_PRESENT:
        return
    shared = [item for item in items if item.get_closest_marker("shared") is not None]
    config.hook.pytest_deselected(items=shared)
    items[:] = [item for item in items if item.get_closest_marker("shared") is None]


@pytest.fixture(scope="session")
def bundled_dir() -> Path:
    return BUNDLED


@pytest.fixture(scope="session")
def udisd_pair(bundled_dir):
    """(img_a, img_b) of the bundled udisd_test_000001 pair: uint8 BGR (512, 512, 3) each, b the left view."""
    from helpers import read_pair

    return read_pair(bundled_dir / "udisd_test_000001")


@pytest.fixture(scope="session")
def shared_dir() -> Path:
    """../shared/data (tests using it are marked ``shared``, so they only run when it is there)."""
    return SHARED


@pytest.fixture
def pair_folder(request: pytest.FixtureRequest):
    """``folder(name)``: a pair's folder, the bundled copy when there is one, else ../shared/data/pairs/name
    (for a test marked ``shared`` only)."""
    def folder(name: str) -> Path:
        if (BUNDLED / name).is_dir():
            return BUNDLED / name
        if request.node.get_closest_marker("shared") is None:
            raise pytest.UsageError(f"{request.node.nodeid} reads the shared pair {name} but is not marked shared")
        return SHARED / "pairs" / name
    return folder


def shared_pairs() -> list[str]:
    """Names of the pair folders in ../shared/data/pairs (empty when absent), for parametrize."""
    root = SHARED / "pairs"
    return sorted(p.name for p in root.iterdir() if p.is_dir()) if root.is_dir() else []


@pytest.fixture(scope="session")
def warp_device() -> str:
    """Warp's CPU device with every kernel module of sena_warp.kernels loaded once for the session."""
    from sena_warp.kernels import runtime

    runtime.prewarm("cpu")
    return "cpu"


@pytest.fixture
def dirs(tmp_path):
    """(input folder, output folder), both empty: tests check that nothing is left in the output one."""
    folder_in, folder_out = tmp_path / "in", tmp_path / "out"
    folder_in.mkdir()
    folder_out.mkdir()
    return folder_in, folder_out
