"""``sena-warp batch``: pair folders or job lists, worker processes or Ray tasks, resumable, failures recorded."""

from __future__ import annotations

import contextlib
import json
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import cv2
import numpy as np
import pytest

from sena_warp.batch import REPORTS, SUMMARY, local_runner, read_jobs
from sena_warp.cli import main
from sena_warp.errors import InputError
from helpers import alive, assert_one_line_error, child_processes

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


# --- outputs: resolved, inside DIR, never an input, never shared; refused before any job runs (exit 2) ----

def job_list(tmp_path, jobs: list[dict], kind: str = "toml") -> Path:
    """A job list of ``jobs`` (key -> text) beside the copies of a pair in tmp_path/lst/c/."""
    lst = tmp_path / "lst"
    if kind == "toml":
        path = lst / "jobs.toml"
        path.write_text("".join("[[job]]\n" + "".join(f'{k} = "{v}"\n' for k, v in job.items()) for job in jobs))
    else:
        keys = sorted({k for job in jobs for k in job})
        path = lst / "jobs.csv"
        path.write_text(",".join(keys) + "\n" + "".join(",".join(job.get(k, "") for k in keys) + "\n" for job in jobs))
    return path


@pytest.fixture
def lst(bundled_dir, tmp_path):
    """tmp_path/lst/c/{a,b}.jpg; tmp_path/victim.png, a file outside every DIR."""
    shutil.copytree(bundled_dir / PAIRS[0], tmp_path / "lst" / "c")
    (tmp_path / "victim.png").write_bytes(b"victim")
    return tmp_path / "lst"


PAIR = {"a": "c/a.jpg", "b": "c/b.jpg"}
ESCAPES = [  # (jobs, words of the one error line)
    ([{**PAIR, "name": "one", "output": "../victim.png"}], ("output = '../victim.png' lies outside --out",)),
    ([{**PAIR, "name": "one", "output": "{tmp}/victim.png"}], ("lies outside --out",)),
    ([{**PAIR, "name": "one", "output": "g/../../victim.png"}], ("lies outside --out",)),
    ([{**PAIR, "name": "one", "output": "link/x.png"}], ("lies outside --out",)),  # DIR/link -> tmp_path
    ([{**PAIR, "name": "one", "output": "../lst/c/a.jpg"}], ("lies outside --out",)),
    ([{**PAIR, "name": "one", "output": "x.png"}, {**PAIR, "name": "two", "output": "g/../x.png"}],
     ("jobs one and two have the same output", "x.png; give each job its own")),
    ([{**PAIR, "name": "one", "output": "x.png"}, {**PAIR, "name": "two", "output": "./x.png"}],
     ("jobs one and two have the same output",)),
    ([{**PAIR, "name": "one"}, {"a": "../out/one.png", "b": "c/b.jpg", "name": "two"}],
     ("the output of job one,", "is an input of job two; give it another name")),
    ([{**PAIR, "name": "one", "output": "in.jpg"}, {"a": "../out/in.jpg", "b": "c/b.jpg", "name": "two"}],
     ("the output of job one,", "is an input of job two")),
]


@pytest.mark.parametrize("kind", ["toml", "csv"])
@pytest.mark.parametrize("jobs, words", ESCAPES, ids=lambda v: None if isinstance(v, list) else "-".join(v)[:40])
def test_outputs_outside_dir_onto_inputs_or_shared_are_refused_before_any_job(jobs, words, kind, lst, tmp_path,
                                                                              capfd, warp_device):
    jobs = [{k: v.replace("{tmp}", str(tmp_path)) for k, v in job.items()} for job in jobs]
    out = tmp_path / "out"
    out.mkdir()
    (out / "g").mkdir()
    (out / "link").symlink_to(tmp_path)
    (out / "in.jpg").write_bytes((lst / "c" / "a.jpg").read_bytes())
    before = {p: p.read_bytes() for p in (*tmp_path.rglob("*.jpg"), *tmp_path.rglob("*.png")) if p.is_file()}
    rc, stdout, err = batch([job_list(tmp_path, jobs, kind), "--out", out, "-q"], capfd, warp_device)
    assert rc == InputError.exit_code and stdout == []
    assert_one_line_error(err, *words)
    assert sorted(p.name for p in out.iterdir()) == ["g", "in.jpg", "link"]  # no job ran: no report, no summary
    assert {p: p.read_bytes() for p in before} == before


def test_a_batch_refused_on_its_job_list_leaves_no_out_folder(lst, tmp_path, capfd, warp_device):
    jobs = job_list(tmp_path, [{**PAIR, "grid_xx": "2"}])
    rc, _, err = batch([jobs, "--out", tmp_path / "new", "-q"], capfd, warp_device)
    assert rc == InputError.exit_code and "unknown setting 'grid_xx'" in err[0]
    assert not (tmp_path / "new").exists()


def test_a_csv_list_with_a_byte_order_mark_reads_as_without(lst, tmp_path):
    jobs = job_list(tmp_path, [{**PAIR, "name": "one"}], "csv")
    jobs.write_bytes(b"\xef\xbb\xbf" + jobs.read_bytes())  # as spreadsheets save "CSV UTF-8"
    (entry,) = read_jobs(jobs, tmp_path / "out", {})
    assert entry.name == "one" and entry.job.inputs == (str(lst / "c" / "a.jpg"), str(lst / "c" / "b.jpg"))


@pytest.mark.parametrize("header, column", [("name,a,b,name", "name"), ("name,a, b,b ", "b"),
                                            ("name,a,b,grid_x,grid_x", "grid_x")])
def test_a_csv_column_given_twice_is_refused(lst, tmp_path, header, column):
    jobs = lst / "jobs.csv"
    jobs.write_text(f"{header}\none,c/a.jpg,c/b.jpg,{'8,9' if 'grid_x' in header else 'two'}\n")
    with pytest.raises(InputError, match=f"line 1: the column '{column}' appears twice; keep one"):
        read_jobs(jobs, tmp_path / "out", {})


@pytest.mark.parametrize("name", ["a\nb", "tab\there", "x" * 251, "../up", ".hidden"])
def test_a_job_name_that_cannot_name_a_file_is_refused(lst, tmp_path, name):
    jobs = lst / "jobs.toml"
    jobs.write_text(f'[[job]]\nname = {json.dumps(name)}\na = "c/a.jpg"\nb = "c/b.jpg"\n')
    with pytest.raises(InputError, match="job name .* (cannot name a file|too long for a file name)"):
        read_jobs(jobs, tmp_path / "out", {})


# --- pair folders: one that tries to be a pair and is not is a failed job saying why -------------------------

MALFORMED = {  # folder -> (files, the reason in its report)
    "two_a": (("a.jpg", "a.png", "b.jpg"), "2 files for a.* (a.jpg, a.png); keep one"),
    "typo": (("a.jpg", "c.jpg"), "no b.* image (found a.jpg, c.jpg)"),
    "both": (("a.jpg", "b.jpg", "left.mp4", "right.mp4"), "holds both an image pair and a video pair"),
    "one_video": (("left.mp4", "notes.txt"), "no right.* video (found left.mp4, notes.txt)"),
    "unknown": (("x.png", "y.png"), "no a.* and b.* image (found x.png, y.png)"),
}


def test_pair_folders_that_are_not_ones_are_failed_jobs_and_case_variants_are_pairs(bundled_dir, tmp_path, capfd,
                                                                                    warp_device):
    root = tmp_path / "jobs"
    pair, clip = bundled_dir / PAIRS[0], bundled_dir / "video" / "office_cam1.mp4"
    for folder, (files, _) in MALFORMED.items():
        (root / folder).mkdir(parents=True)
        for name in files:
            source = clip if name.endswith(".mp4") else pair / "a.jpg"
            (root / folder / name).write_bytes(source.read_bytes() if not name.endswith(".txt") else b"notes")
    (root / "upper").mkdir()  # A.JPG / B.JPG: a pair, as a camera names its files
    shutil.copy(pair / "a.jpg", root / "upper" / "A.JPG")
    shutil.copy(pair / "b.jpg", root / "upper" / "B.JPG")
    (root / "empty").mkdir()  # no input of either kind: not a pair folder, not a job
    (root / "upper" / ".DS_Store").write_bytes(b"x")
    out = tmp_path / "out"
    rc, _, err = batch([root, "--out", out, "-q"], capfd, warp_device)
    assert rc == 7
    summary = json.loads((out / SUMMARY).read_text())
    status = {r["name"]: (r["status"], r["exit_code"]) for r in summary["results"]}
    assert status == {**{folder: ("failed", InputError.exit_code) for folder in MALFORMED}, "upper": ("ok", 0)}
    for folder, (_, reason) in MALFORMED.items():
        job = json.loads((out / REPORTS / f"{folder}.json").read_text())["job"]
        assert job["error"] == f"{root / folder}: {reason}" or job["error"].startswith(f"{root / folder}: {reason}")
        assert f"{folder}: failed: {root / folder}: {reason}" in "\n".join(err)
    assert sorted(p.name for p in out.iterdir()) == [REPORTS, SUMMARY, "upper.png"]
    assert sorted(p.name for p in (root / "upper").iterdir()) == [".DS_Store", "A.JPG", "B.JPG"]


def test_a_pair_folder_given_itself_that_is_not_one_is_refused(bundled_dir, tmp_path, capfd, warp_device):
    folder = tmp_path / "typo"
    folder.mkdir()
    shutil.copy(bundled_dir / PAIRS[0] / "a.jpg", folder / "a.jpg")
    shutil.copy(bundled_dir / PAIRS[0] / "b.jpg", folder / "c.jpg")
    rc, _, err = batch([folder, "--out", tmp_path / "out", "-q"], capfd, warp_device)
    assert rc == InputError.exit_code
    assert_one_line_error(err, f"{folder}: no b.* image (found a.jpg, c.jpg)")
    assert not (tmp_path / "out").exists()


# --- signals: no job starts after one, running jobs stop and leave nothing, workers die with the parent -----

REPO = Path(__file__).resolve().parents[1]


def start_video_batch(bundled_dir, tmp_path, jobs: int = 6, ray: bool = False) -> tuple[subprocess.Popen, Path]:
    """``sena-warp batch`` of ``jobs`` video jobs (the rooftop clips) on 2 workers (or 2 CPUs of a local
    Ray), as a process of its own."""
    clips = bundled_dir / "video"
    listing = tmp_path / "jobs.toml"
    listing.write_text('[defaults]\nvideo_estimate_pairs = 1\nvideo_audio = "none"\nvideo_crf = 35\n' + "".join(
        f'[[job]]\nname = "v{i}"\nleft = "{clips / "rooftop_left.mp4"}"\nright = "{clips / "rooftop_right.mp4"}"\n'
        for i in range(jobs)))
    out = tmp_path / "out"
    code = "import sys; from sena_warp.cli import main; sys.exit(main(sys.argv[1:]))"
    child = subprocess.Popen([sys.executable, "-c", code, "batch", str(listing), "--out", str(out), "--jobs", "2",
                              *(["--ray", "local"] if ray else []), "--device", "cpu", "-q"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                             cwd=REPO)
    return child, out


def wait_for_a_job_writing(out: Path, child: subprocess.Popen, timeout_s: float = 120.0) -> None:
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout_s:
        with contextlib.suppress(OSError):
            if any(p.name.startswith(".") and ".part" in p.name and p.stat().st_size for p in out.iterdir()):
                return
        assert child.poll() is None, child.communicate()
        time.sleep(0.02)
    raise AssertionError("no job was ever writing its output")


def assert_nothing_half_done(out: Path, running: int) -> None:
    """No temporary anywhere; each output there is a job complete with its ok report; no more of them than
    jobs were running when the batch was stopped (none started after)."""
    assert not [p for p in out.rglob(".*")], sorted(out.rglob("*"))
    outputs = sorted(p.stem for p in out.glob("*.mp4"))
    assert len(outputs) <= running, outputs
    for name in outputs:
        assert json.loads((out / REPORTS / f"{name}.json").read_text())["job"]["status"] == "ok"
    assert sorted(p.stem for p in out.glob(f"{REPORTS}/*.json")) == outputs
    assert not (out / SUMMARY).exists()


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT], ids=lambda s: s.name)  # SIGHUP: the same handler
def test_a_signal_stops_the_batch_at_once_no_job_starts_and_nothing_is_left(signum, bundled_dir, tmp_path):
    child, out = start_video_batch(bundled_dir, tmp_path)
    wait_for_a_job_writing(out, child)
    pids = child_processes(child.pid, "sena_warp.workers")
    child.send_signal(signum)  # Ctrl-C reaches the batch alone: its workers run in sessions of their own
    _, err = child.communicate(timeout=120)
    assert child.returncode == 128 + signum
    assert err.splitlines() == ["sena-warp: interrupted" + ("" if signum == signal.SIGINT else f" by {signum.name}")]
    assert len(pids) == 2 and not any(alive(pid) for pid in pids)
    assert_nothing_half_done(out, running=2)


def test_workers_die_with_a_batch_killed_by_sigkill_and_leave_nothing(bundled_dir, tmp_path):
    child, out = start_video_batch(bundled_dir, tmp_path)
    wait_for_a_job_writing(out, child)
    pids = child_processes(child.pid, "sena_warp.workers")
    child.kill()
    child.communicate()
    t0 = time.monotonic()
    while any(alive(pid) for pid in pids):
        assert time.monotonic() - t0 < 60, "the workers outlived their parent"
        time.sleep(0.05)
    assert len(pids) == 2
    assert_nothing_half_done(out, running=2)


def test_no_more_local_workers_than_jobs_to_run(lst, tmp_path):
    entries = read_jobs(job_list(tmp_path, [{**PAIR, "name": "one"}, {**PAIR, "name": "two"}]), tmp_path / "o", {})
    name, runs = local_runner(1000)(entries)
    runs.close()
    assert name == "2 local workers"


# --- Ray: an address that does not answer is one line at once; a signal stops the tasks like the workers ----

def closed_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


@pytest.mark.parametrize("address, why", [
    ("127.0.0.1:{port}", "cannot reach 127.0.0.1:{port} (Connection refused)"),
    ("ray://127.0.0.1:{port}", "cannot reach 127.0.0.1:{port} (Connection refused)"),
    ("no-such-host.invalid", "cannot reach no-such-host.invalid:6379 ("),
    ("ray://no-such-host.invalid", "cannot reach no-such-host.invalid:10001 ("),
    ("host:port", "not a cluster address; give auto, local, HOST:PORT or ray://HOST:PORT"),
])
def test_a_ray_address_that_does_not_answer_is_one_line_before_ray_starts(address, why, lst, tmp_path, capfd,
                                                                          warp_device, monkeypatch):
    pytest.importorskip("ray", reason="the cluster extra (ray) is not installed")
    import ray

    monkeypatch.setattr(ray, "init", lambda *a, **k: pytest.fail("ray.init ran for an address that does not answer"))
    port = closed_port()
    address, why = address.format(port=port), why.format(port=port)
    rc, stdout, err = batch([job_list(tmp_path, [PAIR]), "--out", tmp_path / "out", "--ray", address, "-q"], capfd,
                            warp_device)
    assert rc == InputError.exit_code and stdout == []
    assert_one_line_error(err, f"--ray {address}: {why}")
    assert not (tmp_path / "out").exists()


def test_ray_connect_timeout_is_said_in_seconds(monkeypatch):
    import sena_warp.batch as batch_module

    def silent(*args, **kwargs):
        raise socket.timeout("timed out")  # what a host that drops the connection gives after the timeout

    monkeypatch.setattr(socket, "create_connection", silent)
    with pytest.raises(InputError, match=r"--ray 192.0.2.1:6379: cannot reach 192.0.2.1:6379 \(no answer in 5 s\)"):
        batch_module.check_reachable("192.0.2.1:6379")


def test_a_signal_stops_a_ray_local_batch_one_line_nothing_left(bundled_dir, tmp_path):
    pytest.importorskip("ray", reason="the cluster extra (ray) is not installed")
    child, out = start_video_batch(bundled_dir, tmp_path, ray=True)
    wait_for_a_job_writing(out, child, timeout_s=300)
    child.send_signal(signal.SIGTERM)
    _, err = child.communicate(timeout=120)
    assert child.returncode == 143 and err.splitlines() == ["sena-warp: interrupted by SIGTERM"]
    assert_nothing_half_done(out, running=2)


def test_dir_inside_the_pair_folders_is_not_taken_for_a_pair_folder(bundled_dir, tmp_path):
    root = tmp_path / "jobs"
    shutil.copytree(bundled_dir / PAIRS[0], root / "one")
    (root / "out").mkdir()
    for name in ("one.png", "two.png"):  # what an earlier run to --out jobs/out left there
        shutil.copy(bundled_dir / PAIRS[0] / "a.jpg", root / "out" / name)
    assert [(e.name, e.error) for e in read_jobs(root, root / "out", {})] == [("one", None)]


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
