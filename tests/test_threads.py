"""``--threads N`` reaches every pool a run uses: Warp's CPU row bands, onnxruntime, the decoders, the encoder."""

from __future__ import annotations

import json
import os

import pytest

from sena_warp import xfeat
from sena_warp.cli import main
from sena_warp.config import Config
from sena_warp.kernels import runtime

THREADS = 1  # FFmpeg and x264 choose more by themselves (cores + 1, 1.5 x cores), onnxruntime one per core


def test_threads_reach_warp_onnxruntime_decoders_and_encoder(bundled_dir, tmp_path, monkeypatch, capfd,
                                                             warp_device):
    launches = []
    for name in ("launch_rows", "launch_row_loops"):
        real = getattr(runtime, name)

        def spy(kernel, height, width, inputs, device, threads=0, real=real):
            launches.append(threads)
            real(kernel, height, width, inputs, device, threads)

        monkeypatch.setattr(runtime, name, spy)
    sessions = []
    real_session = xfeat.xfeat_session
    monkeypatch.setattr(xfeat, "xfeat_session",
                        lambda threads, spins: sessions.append((threads, spins)) or real_session(threads, spins))
    clips = bundled_dir / "video"
    settings = tmp_path / "s.toml"
    settings.write_text("video_estimate_pairs = 1\n")
    rc = main(["video", str(clips / "office_cam1.mp4"), str(clips / "office_cam2.mp4"), "-o", str(tmp_path / "o.mp4"),
               "--report", str(tmp_path / "r.json"), "--config", str(settings), "--threads", str(THREADS),
               "--device", warp_device, "-q"])
    assert rc == 0, capfd.readouterr().err
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["run"]["threads"] == THREADS and report["run"]["settings"]["cpu_threads"] == THREADS
    assert len(launches) > 48 and set(launches) == {THREADS}  # the estimate's kernels and every frame's
    assert sessions and set(sessions) == {(THREADS, False)}
    options = real_session(THREADS, False).get_session_options()
    assert options.intra_op_num_threads == THREADS
    assert options.get_session_config_entry("session.intra_op.allow_spinning") == "0"
    assert [report["inputs"][side]["decoder_threads"] for side in ("left", "right")] == [THREADS, THREADS]
    assert report["output"]["encoder"]["threads"] == THREADS


def test_without_threads_each_library_chooses(bundled_dir):
    options = xfeat.xfeat_session(0, True).get_session_options()
    assert options.intra_op_num_threads == 0
    with pytest.raises(RuntimeError):  # left as onnxruntime has it
        options.get_session_config_entry("session.intra_op.allow_spinning")


def test_the_onnxruntime_pool_spins_only_for_a_moving_rig_with_a_thread_per_core():
    cores = os.cpu_count() or 1
    assert xfeat.pool_spins(Config(video_rig="moving"))
    assert xfeat.pool_spins(Config(video_rig="moving", cpu_threads=cores))
    assert not xfeat.pool_spins(Config())  # images, and a static rig's only estimate
    if cores > 1:  # sharing the machine
        assert not xfeat.pool_spins(Config(video_rig="moving", cpu_threads=1))
    options = xfeat.xfeat_session(0, False).get_session_options()
    assert options.get_session_config_entry("session.intra_op.allow_spinning") == "0"
