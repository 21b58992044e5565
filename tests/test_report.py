"""The reports say what ran (tool, device, settings) and docs/report.md explains every key they hold."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from sena_warp import __version__
from sena_warp.jobs import Job, run_job

DOC = (Path(__file__).resolve().parents[1] / "docs" / "report.md").read_text()
DOCUMENTED = set(re.findall(r"`([a-z0-9_]+)`", DOC)) | {name for path in re.findall(r"`([a-z0-9_.]+)`", DOC)
                                                        for name in path.split(".")}


def keys(value, prefix=""):
    """Every key of a report, as dotted paths (lists of dicts by their first element)."""
    if isinstance(value, list) and value and isinstance(value[0], dict):
        value = value[0]
    if isinstance(value, dict):
        for key, item in value.items():
            yield f"{prefix}{key}"
            yield from keys(item, f"{prefix}{key}.")


@pytest.fixture(scope="module")
def reports(bundled_dir, tmp_path_factory, warp_device):
    out = tmp_path_factory.mktemp("reports")
    pair = bundled_dir / "udisd_test_000001"
    image = run_job(Job("image", (str(pair / "a.jpg"), str(pair / "b.jpg")), str(out / "p.png"),
                        {"device": warp_device, "grid_x": 4}, crop=True))
    clips = bundled_dir / "video"
    video = run_job(Job("video", (str(clips / "rooftop_left.mp4"), str(clips / "rooftop_right.mp4")),
                        str(out / "v.mp4"), {"device": warp_device, "video_estimate_pairs": 1, "video_crf": 30}))
    return image, video


def test_the_run_block_names_tool_device_detector_and_every_changed_setting(reports, warp_device):
    image, video = reports
    assert image["run"] == {"tool": "sena-warp", "version": __version__, "device": warp_device, "detector": "xfeat",
                            "threads": 0, "settings": {"grid_x": 4}}
    assert video["run"]["settings"] == {"video_crf": 30, "video_estimate_pairs": 1}
    assert video["output"]["encoder"]["crf"] == 30 and video["output"]["encoder"]["codec"] == "libx264"
    assert image["output"]["width"] == image["canvas"]["crop_xywh"][2]


def test_a_video_report_has_one_timing_block(reports):
    _, video = reports
    assert "timing_s" not in video["stitch"]
    assert {"load_kernels", "compositor_setup", "composite", "encode", "reestimate", "maps_upload", "total"} <= set(
        video["timing_s"])


def test_docs_report_md_explains_every_key(reports):
    image, video = reports
    for report, stages in ((image, "timing_s."), (video, None)):  # an image's stage times: SENA's step names
        paths = {p for p in keys(report) if not p.startswith("run.settings.")  # Config field names
                 and (stages is None or not p.startswith(stages))}
        assert sorted(p for p in paths if p.split(".")[-1] not in DOCUMENTED) == []
