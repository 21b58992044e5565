"""``sena-warp batch``: pair folders or job lists, worker processes or Ray tasks, resumable, failures recorded."""

from __future__ import annotations

import json
import shutil

import cv2
import numpy as np
import pytest

from sena_warp.batch import REPORTS, SUMMARY, read_jobs
from sena_warp.cli import main
from sena_warp.errors import InputError

PAIRS = ("udisd_test_000001", "graf_gt")
VARYING = {"seconds", "host", "timing_s", "decode_wait_s", "decode_s", "output_fps", "summary"}  # differ run to run


@pytest.fixture
def jobs_dir(bundled_dir, tmp_path):
    """Two image pairs, one video pair (the office clips as left/right) and a pair whose b image is broken."""
    root = tmp_path / "jobs"
    for name in PAIRS:
        shutil.copytree(bundled_dir / name, root / name)
    (root / "office").mkdir()
    for side, clip in (("left", "office_cam1.mp4"), ("right", "office_cam2.mp4")):
        shutil.copy(bundled_dir / "video" / clip, root / "office" / f"{side}.mp4")
    (root / "broken").mkdir()
    shutil.copy(bundled_dir / PAIRS[0] / "a.jpg", root / "broken" / "a.jpg")
    (root / "broken" / "b.jpg").write_bytes((bundled_dir / PAIRS[0] / "b.jpg").read_bytes()[:300])
    (root / "not_a_pair").mkdir()
    return root


@pytest.fixture
def fast(tmp_path):
    path = tmp_path / "fast.toml"
    path.write_text("video_estimate_pairs = 1\nvideo_audio = \"none\"\n")
    return str(path)


def batch(argv, capfd, warp_device) -> tuple[int, list[str], list[str]]:
    """(exit code, stdout lines, stderr lines) of ``sena-warp batch argv``."""
    capfd.readouterr()
    rc = main(["batch", *map(str, argv), "--device", warp_device])
    captured = capfd.readouterr()
    return rc, captured.out.splitlines(), captured.err.splitlines()


def stable(value):
    """A report without what changes from run to run (times, host names)."""
    if isinstance(value, dict):
        return {k: stable(v) for k, v in value.items() if k not in VARYING}
    if isinstance(value, list):
        return [stable(v) for v in value]
    return value


def test_a_folder_of_pairs_runs_on_two_workers_records_the_failure_and_resumes(jobs_dir, fast, tmp_path, capfd,
                                                                                bundled_dir, warp_device):
    out = tmp_path / "out"
    rc, stdout, err = batch([jobs_dir, "--out", out, "--jobs", 2, "--config", fast], capfd, warp_device)
    # Not a terminal: plain lines, one per finished job (a warning for the failed one), then the error.
    assert rc == 7 and "\x1b" not in "".join(err) and err[-1] == (
        f"sena-warp: error: 1 of 4 jobs failed; their reports in {out / REPORTS} say why "
        "(run the batch again to retry them)")
    assert [line for line in err if ": warning: " in line] == [
        f"sena-warp: warning: broken: failed: {jobs_dir / 'broken' / 'b.jpg'}: not a readable image (corrupt, "
        "truncated or unsupported format)"]
    assert sum(line.startswith("sena-warp: ") and ": ok (" in line for line in err) == 3
    # Each job is said as it starts (before its result), and the jobs' count ends once on 4/4.
    for name in ("broken", "graf_gt", "office", "udisd_test_000001"):
        started = [i for i, line in enumerate(err) if line.startswith(f"sena-warp: {name}: started (")]
        ended = [i for i, line in enumerate(err) if line.startswith((f"sena-warp: {name}: ok (",
                                                                   f"sena-warp: warning: {name}: failed"))]
        assert len(started) == len(ended) == 1 and started[0] < ended[0]
    assert sum(line.startswith("sena-warp: 4/4 jobs") for line in err) == 1
    summary = json.loads((out / SUMMARY).read_text())
    status = {r["name"]: r["status"] for r in summary["results"]}
    assert status == {"broken": "failed", "graf_gt": "ok", "office": "ok", "udisd_test_000001": "ok"}
    assert summary["runner"] == "2 local workers" and summary["jobs_per_hour"] > 0
    broken = json.loads((out / REPORTS / "broken.json").read_text())["job"]
    assert broken["exit_code"] == 2 and "not a readable image" in broken["error"]
    video = json.loads((out / REPORTS / "office.json").read_text())
    assert video["job"]["status"] == "ok" and video["frames_out"] == 48 and (out / "office.mp4").is_file()
    assert video["run"]["threads"] == 1  # two workers on the cores: each job gets its share
    image = json.loads((out / REPORTS / "graf_gt.json").read_text())
    assert image["global_affine"]["inliers"] > 100 and cv2.imread(str(out / "graf_gt.png")).shape[:2] == (
        image["output"]["height"], image["output"]["width"])
    assert stdout[0].split() == ["job", "kind", "status", "time_s", "result"] and len(stdout) == 6
    assert stdout[-1].startswith("3 ok, 1 failed, 0 skipped in ")

    # Fixed, then run again: only the failed job runs; the others are complete and skipped.
    shutil.copy(bundled_dir / PAIRS[0] / "b.jpg", jobs_dir / "broken" / "b.jpg")
    before = (out / "office.mp4").stat().st_mtime_ns
    rc, stdout, err = batch([jobs_dir, "--out", out, "--config", fast, "-q"], capfd, warp_device)
    summary = json.loads((out / SUMMARY).read_text())
    assert rc == 0 and err == [] and stdout == [] and (summary["ok"], summary["skipped"], summary["failed"]) == (1, 3, 0)
    assert (out / "office.mp4").stat().st_mtime_ns == before and (out / "broken.png").is_file()


def test_a_toml_list_gives_per_job_options_and_settings(bundled_dir, tmp_path, capfd, warp_device):
    data = tmp_path / "data"
    shutil.copytree(bundled_dir / PAIRS[0], data / "u")
    jobs = tmp_path / "jobs.toml"
    jobs.write_text('[defaults]\ngrid_x = 4\n\n'
                    '[[job]]\nname = "cropped"\na = "data/u/a.jpg"\nb = "data/u/b.jpg"\ncrop = true\n'
                    'output = "c.jpg"\ngrid_y = 3\n\n'
                    '[[job]]\nname = "plain"\na = "data/u/a.jpg"\nb = "data/u/b.jpg"\nfeatures = "sift"\n')
    out = tmp_path / "out"
    rc, _, err = batch([jobs, "--out", out, "--threads", 2, "-q"], capfd, warp_device)
    assert rc == 0 and err == []
    cropped = json.loads((out / REPORTS / "cropped.json").read_text())
    assert cropped["run"]["settings"] == {"grid_x": 4, "grid_y": 3, "cpu_threads": 2}
    assert cropped["canvas"]["crop_xywh"] is not None and (out / "c.jpg").is_file()
    plain = json.loads((out / REPORTS / "plain.json").read_text())
    assert plain["run"]["detector"] == "sift" and plain["canvas"]["crop_xywh"] is None


def test_a_csv_list_reads_each_cell_as_its_column_takes_it(bundled_dir, tmp_path):
    jobs = tmp_path / "jobs.csv"
    videos = f"{bundled_dir / 'video/office_cam1.mp4'},{bundled_dir / 'video/office_cam2.mp4'}"
    jobs.write_text("name,a,b,left,right,crop,grid_x,offset,reference\n"
                    f"one,{bundled_dir / PAIRS[0] / 'a.jpg'},{bundled_dir / PAIRS[0] / 'b.jpg'},,,yes,8,,b\n"
                    f"two,,,{videos},,,0.5,\nthree,,,{videos},,,auto,\n")
    one, two, three = read_jobs(jobs, tmp_path / "out", {"cpu_threads": 1})
    assert three.job.offset_s == "auto"
    assert (one.job.kind, one.job.crop, one.job.reference, one.job.settings) == ("image", True, "b",
                                                                                 {"cpu_threads": 1, "grid_x": 8})
    assert (two.job.kind, two.job.offset_s, two.job.output) == ("video", 0.5, str(tmp_path / "out" / "two.mp4"))
    assert one.report == str(tmp_path / "out" / REPORTS / "one.json")


@pytest.mark.parametrize("text, message", [
    ('[[job]]\na = "x.jpg"\nb = "y.jpg"\ngrid_xx = 2\n', "unknown setting 'grid_xx'; did you mean 'grid_x' or 'grid_y'?"),
    ('[[job]]\na = "x.jpg"\n', "give the inputs as a and b (images) or left and right (videos)"),
    ('[[job]]\na = "x.jpg"\nb = "y.jpg"\noffset = 0.5\n', "offset is for video jobs; this one is a image job"),
    ('[[job]]\na = "x.jpg"\nb = "y.jpg"\ngrid_x = 0\n', "grid_x = 0 is out of range \\[1, 64\\]"),
    ('[[job]]\na = "x.mp4"\nb = "y.jpg"\n', "a = 'x.mp4' is not a image file"),
    ('[[job]]\nname="n"\na = "x.jpg"\nb = "y.jpg"\n[[job]]\nname="n"\na = "x.jpg"\nb = "z.jpg"\n',
     "two jobs have the name n"),
    ('[jobs]\n', "unknown setting 'jobs'; did you mean 'job'?"),
    ('[[job]]\nleft = "x.mp4"\nright = "y.mp4"\noffset = "soon"\n', "offset = 'soon' is not a float or 'auto'"),
])
def test_a_bad_job_list_is_refused_before_any_work(text, message, tmp_path):
    jobs = tmp_path / "jobs.toml"
    jobs.write_text(text)
    with pytest.raises(InputError, match=message.replace("?", r"\?").replace("(", r"\(").replace(")", r"\)")):
        read_jobs(jobs, tmp_path / "out", {})


def test_ray_tasks_give_the_local_run_s_results(jobs_dir, fast, tmp_path, capfd, warp_device):
    pytest.importorskip("ray", reason="the cluster extra (ray) is not installed")
    shutil.rmtree(jobs_dir / "office")  # images only: the comparison is about the job function, not video
    results = {}
    for runner, argv in (("local", []), ("ray", ["--ray", "local", "--jobs", 2])):
        out = tmp_path / runner
        rc, _, err = batch([jobs_dir, "--out", out, "--config", fast, "--threads", 1, *argv], capfd, warp_device)
        assert rc == 7, err  # the broken pair fails in both
        assert sum(": started (image job: " in line for line in err) == 3
        summary = json.loads((out / SUMMARY).read_text())
        results[runner] = {r["name"]: (r["status"], r["exit_code"], r["error"]) for r in summary["results"]}
        results[runner, "reports"] = {name: stable(json.loads((out / REPORTS / f"{name}.json").read_text()))
                                      for name in PAIRS}
    assert summary["runner"] == "ray local"
    assert err[0] == "sena-warp: starting Ray here with 2 CPUs"  # said before the seconds Ray takes to start
    assert results["ray"] == results["local"]
    for name in PAIRS:
        local, ray = results["local", "reports"][name], results["ray", "reports"][name]
        assert {k: v for k, v in ray.items() if k not in ("job", "output")} == \
               {k: v for k, v in local.items() if k not in ("job", "output")}
        np.testing.assert_array_equal(cv2.imread(str(tmp_path / "ray" / f"{name}.png"), cv2.IMREAD_UNCHANGED),
                                      cv2.imread(str(tmp_path / "local" / f"{name}.png"), cv2.IMREAD_UNCHANGED))


def test_a_video_job_can_estimate_its_offset_and_a_bad_output_type_fails_that_job_alone(bundled_dir, tmp_path,
                                                                                        capfd, warp_device):
    clips, pair = bundled_dir / "video", bundled_dir / PAIRS[0]
    jobs = tmp_path / "jobs.toml"
    # The bundled clips last 2 s: the default 3 s of shared signal would refuse any offset.
    jobs.write_text(f'[[job]]\nname = "synced"\nleft = "{clips / "rooftop_left.mp4"}"\n'
                    f'right = "{clips / "rooftop_right.mp4"}"\noffset = "auto"\nsync_min_overlap_s = 0.75\n'
                    f'video_estimate_pairs = 1\nvideo_audio = "none"\n\n'
                    f'[[job]]\nname = "gif"\na = "{pair / "a.jpg"}"\nb = "{pair / "b.jpg"}"\noutput = "p.gif"\n')
    out = tmp_path / "out"
    rc, _, err = batch([jobs, "--out", out, "-q"], capfd, warp_device)
    assert rc == 7, err
    synced = json.loads((out / REPORTS / "synced.json").read_text())
    assert synced["job"]["status"] == "ok" and synced["sync"]["method"] == "audio"
    assert -11 < synced["sync"]["offset_ms"] < -8  # the two phones' own offset, as test_video_sync measures it
    assert synced["inputs"]["right"]["offset_s"] == pytest.approx(synced["sync"]["offset_ms"] / 1000, abs=1e-4)
    gif = json.loads((out / REPORTS / "gif.json").read_text())["job"]
    assert (gif["status"], gif["exit_code"]) == ("failed", InputError.exit_code)
    assert "unsupported output type" in gif["error"] and not (out / "p.gif").exists()


def test_the_max_megapixels_option_reaches_every_job(bundled_dir, tmp_path, capfd, warp_device):
    out = tmp_path / "out"
    rc, _, _ = batch([bundled_dir / PAIRS[0], "--out", out, "--max-megapixels", "0.01", "-q"], capfd, warp_device)
    job = json.loads((out / REPORTS / f"{PAIRS[0]}.json").read_text())["job"]
    assert rc == 7 and job["exit_code"] == InputError.exit_code and "--max-megapixels" in job["error"]


def test_a_folder_s_jobs_take_the_command_line_s_job_options(bundled_dir, tmp_path, capfd, warp_device):
    root, out = tmp_path / "jobs", tmp_path / "out"
    shutil.copytree(bundled_dir / PAIRS[0], root / "photos")
    (root / "rooftop").mkdir()
    for side in ("left", "right"):
        shutil.copy(bundled_dir / "video" / f"rooftop_{side}.mp4", root / "rooftop" / f"{side}.mp4")
    options = ["--crop", "--ss", "0.5", "--to", "1.5", "--codec", "libx265", "--offset", "0.05",
               "--audio", "none", "-q"]
    rc, _, err = batch([root, "--out", out, *options], capfd, warp_device)
    assert rc == 0, err
    video = json.loads((out / REPORTS / "rooftop.json").read_text())
    assert video["frames_out"] == 30 and video["stitch"]["canvas"]["crop_xywh"] is not None
    assert video["output"]["encoder"]["codec"] == "libx265" and video["sync"]["offset_ms"] == 50
    photos = json.loads((out / REPORTS / "photos.json").read_text())
    assert photos["canvas"]["crop_xywh"] is not None  # --crop for the image job too; --offset not for it

    # -n: a job whose output exists is left alone, complete or not (its report lost: the default redoes it).
    (out / REPORTS / "photos.json").unlink()
    before = {name: (out / name).stat().st_mtime_ns for name in ("rooftop.mp4", "photos.png")}
    rc, _, _ = batch([root, "--out", out, *options, "-n"], capfd, warp_device)
    assert rc == 0 and json.loads((out / SUMMARY).read_text())["skipped"] == 2
    assert {name: (out / name).stat().st_mtime_ns for name in before} == before
    # -y: every job runs again.
    rc, _, _ = batch([root, "--out", out, *options, "-y"], capfd, warp_device)
    summary = json.loads((out / SUMMARY).read_text())
    assert rc == 0 and (summary["ok"], summary["skipped"]) == (2, 0)
    assert all((out / name).stat().st_mtime_ns != before[name] for name in before)


def test_a_video_job_in_a_list_can_crop(bundled_dir, tmp_path):
    clips = bundled_dir / "video"
    jobs = tmp_path / "jobs.toml"
    jobs.write_text(f'[[job]]\nleft = "{clips / "rooftop_left.mp4"}"\nright = "{clips / "rooftop_right.mp4"}"\n'
                    f'crop = true\nvideo_start_s = 1.0\nvideo_max_width = 200\noutput = "check.png"\n')
    (entry,) = read_jobs(jobs, tmp_path / "out", {}, {"crop": False, "offset": 0.25})
    assert (entry.job.kind, entry.job.crop, entry.job.offset_s) == ("video", True, 0.25)
    assert entry.job.settings == {"video_start_s": 1.0, "video_max_width": 200}
    assert entry.job.output == str(tmp_path / "out" / "check.png")  # a still of the frame at 1 s
