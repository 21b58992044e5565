"""Shared fixtures: bundled test data, the wider ../shared/data set (skipped when absent)."""

from __future__ import annotations

from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
BUNDLED = REPO / "tests" / "data"
SHARED = REPO.parent / "shared" / "data"


@pytest.fixture(scope="session")
def bundled_dir() -> Path:
    return BUNDLED


@pytest.fixture(scope="session")
def shared_dir() -> Path:
    if not (SHARED / "MANIFEST.md").exists():
        pytest.skip("../shared/data is not present")
    return SHARED


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
