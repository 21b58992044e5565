"""Soak run: every image pair in both orders and every video pair through the real CLI, then the hostile
classes, each as a user would meet it, in a process of its own.

Real runs count outcomes by exit code and, above all, unhandled exceptions (anything that is not a
``StitchError`` reaching ``main``). Hostile runs (outputs colliding, existing outputs and -y / -n, the
folder rule, huge inputs, signals and SIGKILL leftovers, damaged and truncated video with and
without --strict, rotated and RGBA and float inputs, a variable frame rate, a full disk, bad
options, misleading failures, eval and bench; then the batch and output ones: batch outputs escaping DIR or
clobbering, -y onto a FIFO or a device node, an output appearing mid-run, names longer than the
file system allows, signals to a batch and its workers, Ray addresses that do not answer, pair
folders that are not ones, and the small ones: CSV byte order mark and repeated columns, control
characters in names, stdout on /dev/full, stderr closed, no key frame, left frames without a
partner, sizes in MP) each check the promise: the expected exit code, exactly the expected stderr
lines (one error, warning or interruption; or warnings then one error), no traceback, nothing left
in the output folder after a failure (no temporary ever, no worker process alive), inputs byte for
byte unchanged. Prints one line per run and a summary; exits 1 if any run raised or broke its promise.

    .venv/bin/python benchmarks/soak.py [--data ../shared/data] [--work DIR] [--only real|hostile] [--named TEXT]
"""

from __future__ import annotations

import argparse
import collections
import contextlib
import hashlib
import io
import json
import os
import resource
import shutil
import signal
import stat
import subprocess
import sys
import tempfile
import time
import traceback
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))

from helpers import (alive, child_processes, claiming_more, damage_the_middle, decoded_frames,  # noqa: E402
                     index_first, joined_ts_files, one_mjpeg_frame, png_claiming, reencode_with_black_start,
                     shortened, truncated, with_orientation, without_key_frames)
from sena_warp.cli import main as cli_main  # noqa: E402
from sena_warp.jobs import INPUT_SUFFIXES  # noqa: E402

FAST_VIDEO = ["--audio", "none", "--crf", "35"]
SIGNAL_WAIT_S = 120.0


def image_runs(data: Path):
    for pair in sorted(p for p in (data / "pairs").iterdir() if p.is_dir()):
        a, b = (next(pair.glob(f"{name}.*")) for name in ("a", "b"))
        yield f"{pair.name} (a,b)", ["image", str(a), str(b)], ".png"
        yield f"{pair.name} (b,a)", ["image", str(b), str(a)], ".png"


def video_runs(data: Path):
    for folder in sorted(p for p in (data / "videos").iterdir() if p.is_dir()):
        left, right = sorted(p for p in folder.iterdir() if p.suffix.lower() in INPUT_SUFFIXES["video"])[:2]
        yield f"{folder.name} static", ["video", str(left), str(right)], ".mp4"
        yield f"{folder.name} moving", ["video", str(left), str(right), "--rig", "moving"], ".mp4"


def run_one(args: list[str], output: Path) -> tuple[int | str, str, float]:
    """(exit code or 'EXCEPTION', last stderr line or traceback tail, seconds)."""
    err = io.StringIO()
    t0 = time.perf_counter()
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            code = cli_main(args + ["-o", str(output), "-y"])
    except Exception:  # the point of the soak: anything escaping main is a bug
        return "EXCEPTION", traceback.format_exc().strip().splitlines()[-1], time.perf_counter() - t0
    lines = [line for line in err.getvalue().splitlines() if line.startswith("sena-warp")]
    return code, lines[-1] if lines else "", time.perf_counter() - t0


@dataclass
class Hostile:
    """One hostile run: ``argv`` after ``sena-warp`` (paths made by the setup), the exit code it must
    give, the last stderr line's kind ("error", "warning", "signal" or "none") and words it must hold,
    ``lines`` stderr lines in all (the others warnings); ``signum``: sent once an output's temporary
    is being written (SIGKILL: the process's workers must die with it); ``appear``: a file made under
    that name in the output folder then instead (kept as it is, not replaced); ``file_limit``:
    RLIMIT_FSIZE in bytes; ``memory_limit``: RLIMIT_AS in bytes; ``env``: variables set for the run;
    ``stdout_full``: stdout on /dev/full; ``stderr_closed``: started with fd 2 closed."""

    name: str
    argv: list
    code: int
    kind: str
    words: tuple[str, ...] = ()
    signum: int | None = None
    file_limit: int | None = None
    lines: int = 1
    appear: str | None = None
    stdout_full: bool = False
    stderr_closed: bool = False
    memory_limit: int | None = None
    env: tuple[tuple[str, str], ...] = ()


def _digest(paths) -> dict[str, str]:
    return {str(p): hashlib.sha256(p.read_bytes()).hexdigest() for p in paths if p.is_file()}


def _in_child(case: Hostile):
    """What the child does before it runs: a file size or memory limit, stderr closed."""
    def apply() -> None:
        if case.memory_limit:
            resource.setrlimit(resource.RLIMIT_AS, (case.memory_limit, resource.getrlimit(resource.RLIMIT_AS)[1]))
        if case.file_limit:
            signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
            resource.setrlimit(resource.RLIMIT_FSIZE, (case.file_limit, resource.getrlimit(resource.RLIMIT_FSIZE)[1]))
        if case.stderr_closed:
            os.close(2)
    return apply


def _gone(pids: list[int], timeout_s: float = 60.0) -> bool:
    t0 = time.perf_counter()
    while any(alive(pid) for pid in pids):
        if time.perf_counter() - t0 > timeout_s:
            return False
        time.sleep(0.05)
    return True


def _writing(folder: Path) -> bool:
    """Some output's temporary in ``folder`` holds data already."""
    with contextlib.suppress(FileNotFoundError):  # renamed meanwhile
        return any(p.name.startswith(".") and p.stat().st_size for p in folder.iterdir())
    return False


def run_hostile(case: Hostile, inputs: Path, out: Path) -> tuple[bool, str, float]:
    """Run ``case`` in a child process; (promise kept, what broke it or the stderr line, seconds)."""
    before_in, before_out = _digest(inputs.rglob("*")), sorted(p.name for p in out.iterdir())
    cmd = [sys.executable, "-m", "sena_warp.cli", *map(str, case.argv), "-q"]  # warnings and errors only
    t0 = time.perf_counter()
    with open("/dev/full" if case.stdout_full else os.devnull, "w") as stdout:
        child = subprocess.Popen(cmd, stdout=stdout, stderr=subprocess.PIPE, text=True, cwd=REPO,
                                 env={**os.environ, **dict(case.env)},
                                 preexec_fn=_in_child(case) if case.file_limit or case.memory_limit
                                 or case.stderr_closed else None)
        workers = []
        if case.signum is not None or case.appear is not None:
            while not _writing(out) and child.poll() is None and time.perf_counter() - t0 < SIGNAL_WAIT_S:
                time.sleep(0.02)
            workers = child_processes(child.pid, "sena_warp.workers")
            if case.appear is not None:
                (out / case.appear).write_bytes(b"mine")
            else:
                child.send_signal(case.signum)
        _, err = child.communicate()
    seconds = time.perf_counter() - t0
    lines = err.splitlines()
    problems = []
    if child.returncode != case.code:
        problems.append(f"exit {child.returncode}, expected {case.code}")
    want = {"error": "sena-warp: error: ", "warning": "sena-warp: warning: ", "signal": "sena-warp: interrupted"}
    if case.kind == "none":
        if lines:
            problems.append(f"stderr not empty: {lines[:2]}")
    elif len(lines) != case.lines or not lines[-1].startswith(want[case.kind]) or not all(
            line.startswith(want["warning"]) for line in lines[:-1]):
        problems.append(f"{len(lines)} stderr lines: {lines[:3]}")
    elif not all(any(word in line for line in lines) for word in case.words):
        problems.append(f"missing {[w for w in case.words if not any(w in line for line in lines)]}")
    if "Traceback" in err:
        problems.append("traceback")
    if not _gone(workers):
        problems.append("worker processes outlived the command")
    if [p for p in out.rglob(".*") if ".part" in p.name]:
        problems.append("temporary left")
    if case.appear is not None and (out / case.appear).read_bytes() != b"mine":
        problems.append(f"{case.appear}, made during the run, was replaced")
    after_out = sorted(p.name for p in out.iterdir() if p.name != case.appear)
    if case.code not in (0, 7) and after_out != before_out:
        problems.append(f"left behind: {sorted(set(after_out) - set(before_out))}")
    if _digest(inputs.rglob("*")) != before_in:
        problems.append("an input changed")
    return not problems, "; ".join(problems) or (lines[-1] if lines else ""), seconds


def hostile_cases(data: Path, work: Path) -> list[tuple[Hostile, object]]:
    """The input, output and signal classes on the shared data: (case, setup), setup() run just before the case (each
    one starts from an empty output folder, plus what the case needs there)."""
    inputs, out = work / "in", work / "out"
    inputs.mkdir()
    out.mkdir()
    pair = data / "pairs" / "rew_footpath"
    a, b = inputs / "a.jpg", inputs / "b.jpg"
    shutil.copy(pair / "a.jpg", a)
    shutil.copy(pair / "b.jpg", b)
    rooftop = data / "videos" / "rooftop_handheld"
    left, right = inputs / "left.mp4", inputs / "right.mp4"
    shutil.copy(rooftop / "left.mp4", left)
    shutil.copy(rooftop / "right.mp4", right)
    office = data / "videos" / "office_static" / "cam1.mp4"
    img_a = cv2.imread(str(a))

    damaged = damage_the_middle(left, inputs / "damaged.mp4", span=64 * 1024)
    cut = truncated(index_first(left, inputs / "whole.mp4"), inputs / "cut.mp4")
    (inputs / "huge.png").write_bytes(png_claiming(25000, 25000))
    turned = inputs / "a_turned.png"
    turned.write_bytes(with_orientation(cv2.imencode(".png", np.rot90(img_a, 1).copy())[1].tobytes(), ".png", 6))
    rgba = cv2.cvtColor(img_a, cv2.COLOR_BGR2BGRA)
    rgba[:, : img_a.shape[1] // 3, 3] = 0
    cv2.imwrite(str(inputs / "a_rgba.png"), rgba)
    cv2.imwrite(str(inputs / "a_float.tiff"), img_a.astype(np.float32))
    cv2.imwrite(str(inputs / "b_small.png"), cv2.resize(cv2.imread(str(b)), None, fx=1 / 20, fy=1 / 20,
                                                        interpolation=cv2.INTER_AREA))
    reencode_with_black_start(left, inputs / "black_start.mp4", 30)
    evaluation = inputs / "eval"
    (evaluation / "ok").mkdir(parents=True)
    shutil.copy(a, evaluation / "ok" / "a.jpg")
    shutil.copy(b, evaluation / "ok" / "b.jpg")
    (evaluation / "only_a").mkdir()
    shutil.copy(a, evaluation / "only_a" / "a.jpg")

    def pano(name="p.png"):
        return out / name

    def clean():
        shutil.rmtree(out)
        out.mkdir()

    def exists(*names):
        def make():
            clean()
            for name in names:
                (out / name).write_bytes(b"old")
        return make

    def folder_with_file(name):
        def make():
            clean()
            (out / name).mkdir()
            (out / name / "old.txt").write_text("old")
        return make

    img = ["image", a, b]
    vid = ["video", left, right]
    cases = [
        # 1. outputs colliding with inputs and each other
        (Hostile("image --report = -o", [*img, "-o", pano(), "--report", pano()], 6, "error", ("name the same path",)),
         clean),
        (Hostile("image --debug = -o", [*img, "-o", pano(), "--debug", pano()], 6, "error", ("name the same path",)),
         clean),
        (Hostile("image -o inside --debug", [*img, "-o", out / "d" / "p.png", "--debug", out / "d"], 6, "error",
                 ("lies inside",)), folder_with_file("d")),
        (Hostile("image -o = input", [*img, "-o", a], 6, "error", ("would overwrite an input",)), clean),
        (Hostile("video --report = -o", [*vid, "-o", pano("v.mp4"), "--report", pano("v.mp4")], 6, "error",
                 ("name the same path",)), clean),
        (Hostile("video -o = input, -y", [*vid, "-o", left, "-y"], 6, "error", ("would overwrite an input",)), clean),
        (Hostile("eval --out = data", ["eval", evaluation, "--out", evaluation], 6, "error", ("overwrite an input",)),
         clean),
        # 16. existing outputs, -y, -n, one folder rule
        (Hostile("image existing -o", [*img, "-o", pano()], 6, "error", ("add -y",)), exists("p.png")),
        (Hostile("image existing --report -n", [*img, "-o", pano(), "--report", pano("r.json"), "-n"], 0, "none"),
         exists("r.json")),
        (Hostile("image existing --debug -y", [*img, "-o", pano(), "--debug", out / "d", "-y"], 0, "none"),
         folder_with_file("d")),
        (Hostile("image -o new/p.png", [*img, "-o", out / "new" / "p.png"], 6, "error", ("does not exist",)), clean),
        (Hostile("image --debug new/nested", [*img, "-o", pano(), "--debug", out / "new" / "nested"], 6, "error",
                 ("does not exist",)), clean),
        (Hostile("video existing --report", [*vid, "-o", pano("v.mp4"), "--report", pano("r.json")], 6, "error",
                 ("add -y",)), exists("r.json")),
        # 2. memory
        (Hostile("image 25000x25000 PNG", ["image", a, inputs / "huge.png", "-o", pano()], 2, "error",
                 ("25000x25000 px", "above the limit")), clean),
        # 3. signals and leftovers
        (Hostile("video SIGTERM", [*vid, "-o", pano("v.mp4"), *FAST_VIDEO], 143, "signal", ("SIGTERM",),
                 signum=signal.SIGTERM), clean),
        (Hostile("video SIGHUP", [*vid, "-o", pano("v.mp4"), *FAST_VIDEO], 129, "signal", ("SIGHUP",),
                 signum=signal.SIGHUP), clean),
        (Hostile("video SIGINT", [*vid, "-o", pano("v.mp4"), *FAST_VIDEO], 130, "signal", signum=signal.SIGINT),
         clean),
        (Hostile("image, 244-character name", [*img, "-o", out / ("p" * 240 + ".png")], 0, "none"), clean),
        # 4. damaged video
        (Hostile("video 64 KB damage", ["video", damaged, right, "-o", pano("v.mp4"), *FAST_VIDEO], 0, "warning",
                 ("damaged frames", "replaced by the last good frame", "1 frame whose time stamp goes back"),
                 lines=2), clean),
        (Hostile("video 64 KB damage --strict", ["video", damaged, right, "-o", pano("v.mp4"), "--strict",
                                                 *FAST_VIDEO], 5, "error", ("--strict",)), clean),
        (Hostile("video cut at 60%", ["video", cut, right, "-o", pano("v.mp4"), *FAST_VIDEO], 0, "warning",
                 ("truncated?",)), clean),
        (Hostile("video cut at 60% --strict", ["video", cut, right, "-o", pano("v.mp4"), "--strict", *FAST_VIDEO],
                 5, "error", ("truncated?", "--strict")), clean),
        # 5, 6. orientation, alpha, float
        (Hostile("image EXIF orientation 6", ["image", turned, b, "-o", pano()], 0, "none"), clean),
        (Hostile("image RGBA, a third transparent", ["image", inputs / "a_rgba.png", b, "-o", pano()], 0, "none"),
         clean),
        (Hostile("image float TIFF 0-255", ["image", inputs / "a_float.tiff", b, "-o", pano()], 0, "none"), clean),
        # 7. a full disk, bad options
        (Hostile("image, disk full", [*img, "-o", pano()], 6, "error", ("cannot write it",), file_limit=64 * 1024),
         clean),
        (Hostile("video, disk full", [*vid, "-o", pano("v.mp4"), *FAST_VIDEO], 6, "error", ("cannot write it",),
                 file_limit=64 * 1024), clean),
        (Hostile("video --offset nan", [*vid, "-o", pano("v.mp4"), "--offset", "nan"], 2, "error", ("offset",)), clean),
        (Hostile("video --offset inf", [*vid, "-o", pano("v.mp4"), "--offset", "inf"], 2, "error", ("offset",)), clean),
        (Hostile("video --crf 99", [*vid, "-o", pano("v.mp4"), "--crf", "99"], 2, "error",
                 ("--crf", "out of range [0, 51]")), clean),
        (Hostile("video --crf -1", [*vid, "-o", pano("v.mp4"), "--crf=-1"], 2, "error",
                 ("--crf", "out of range [0, 51]")), clean),
        (Hostile("video --preset warp9", [*vid, "-o", pano("v.mp4"), "--preset", "warp9"], 2, "error", ("preset",)),
         clean),
        (Hostile("video --reestimate nan", [*vid, "-o", pano("v.mp4"), "--rig", "moving", "--reestimate", "nan"], 2,
                 "error", ("--reestimate", "finite")), clean),
        (Hostile("image -o p.gif", [*img, "-o", pano("p.gif")], 2, "error", ("unsupported output type",)), clean),
        (Hostile("video --crf abc", [*vid, "-o", pano("v.mp4"), "--crf", "abc"], 2, "error", ("invalid int",)), clean),
        # 8. failures that say what is the matter
        (Hostile("video black start", ["video", inputs / "black_start.mp4", right, "-o", pano("v.mp4"),
                                       *FAST_VIDEO], 3, "error", ("blank", "0.00, 0.17")), clean),
        (Hostile("video other camera, other size", ["video", left, office, "-o", pano("v.mp4"), *FAST_VIDEO], 3,
                 "error", ("resolutions differ",)), clean),
        (Hostile("image 20x apart in size", ["image", a, inputs / "b_small.png", "-o", pano()], 3, "error",
                 ("differ 20.0x in size",)), clean),
        # 9. eval and bench
        (Hostile("eval pair without b.*", ["eval", evaluation, "--out", out / "ev"], 0, "none"), clean),
        (Hostile("bench --sizes 17x9", ["bench", "--sizes", "17x9", "--work", out / "bench"], 2, "error",
                 ("17x9",)), clean),
    ]
    return cases + batch_and_output_cases(inputs, out, clean) + input_cases(data, inputs, out, clean)


def _job_list(path: Path, jobs: list[dict], defaults: dict | None = None) -> Path:
    """A TOML job list of ``jobs`` (values as JSON strings and numbers are TOML ones)."""
    tables = [("[defaults]", defaults)] if defaults else []
    tables += [("[[job]]", job) for job in jobs]
    path.write_text("".join(f"{head}\n" + "".join(f"{k} = {json.dumps(v)}\n" for k, v in body.items())
                            for head, body in tables))
    return path


def batch_and_output_cases(inputs: Path, out: Path, clean) -> list[tuple[Hostile, object]]:
    """The batch, output and small reliability classes on the hostile run's inputs: (case, setup)."""
    a, b, left, right = inputs / "a.jpg", inputs / "b.jpg", inputs / "left.mp4", inputs / "right.mp4"
    (inputs / "victim.png").write_bytes(b"victim")  # outside every DIR; checked unchanged as an input
    lists = inputs / "lists"
    lists.mkdir()
    pair = {"a": "../a.jpg", "b": "../b.jpg"}
    escape = _job_list(lists / "escape.toml", [{"name": "one", **pair, "output": "../in/victim.png"}])
    absolute = _job_list(lists / "absolute.toml", [{"name": "one", **pair, "output": str(inputs / "victim.png")}])
    shared = _job_list(lists / "shared.toml", [{"name": "one", **pair, "output": "x.png"},
                                               {"name": "two", **pair, "output": "g/../x.png"}])
    onto = _job_list(lists / "onto.toml", [{"name": "one", **pair, "output": "in.jpg"},
                                           {"name": "two", "a": str(out / "in.jpg"), "b": "../b.jpg"}])
    (lists / "escape.csv").write_text(f"name,a,b,output\none,../a.jpg,../b.jpg,{inputs / 'victim.png'}\n")
    (lists / "bom.csv").write_bytes(b"\xef\xbb\xbfname,a,b\none,../a.jpg,../b.jpg\n")
    (lists / "twice.csv").write_text("name,a,b,name\none,../a.jpg,../b.jpg,two\n")
    fast = {"video_estimate_pairs": 1, "video_audio": "none", "video_crf": 35}
    videos = _job_list(lists / "videos.toml", [{"name": f"v{i}", "left": "../left.mp4", "right": "../right.mp4"}
                                               for i in range(4)], fast)
    pairs = inputs / "pairs"
    for folder, files in {"ok": {"a.jpg": a, "b.jpg": b}, "upper": {"A.JPG": a, "B.JPG": b},
                          "two_a": {"a.jpg": a, "a.png": a, "b.jpg": b}, "typo": {"a.jpg": a, "c.jpg": b},
                          "both": {"a.jpg": a, "b.jpg": b, "left.mp4": left, "right.mp4": right}}.items():
        (pairs / folder).mkdir(parents=True)
        for name, source in files.items():
            shutil.copy(source, pairs / folder / name)
    no_key = without_key_frames(left, inputs / "no_key.mp4")
    short_right = shortened(right, inputs / "short_right.mp4", 250)  # 296 left frames, 250 right
    height, width = cv2.imread(str(a)).shape[:2]

    def with_out(*names, fifo=None, device=None):
        def make():
            clean()
            for name in names:
                shutil.copy(a, out / name)
            if fifo:
                os.mkfifo(out / fifo)
            if device:
                os.mknod(out / device, 0o666 | stat.S_IFCHR, os.makedev(1, 3))  # a private /dev/null
        return make

    img, vid = ["image", a, b], ["video", left, right]
    long_name = "n" * 300
    ray = ["--ray", "local"] if _has_ray() else None
    cases = [
        # 1. batch outputs escaping DIR or clobbering: refused before any job, no DIR made
        (Hostile("batch output ../victim", ["batch", escape, "--out", out / "b"], 2, "error", ("lies outside --out",)),
         clean),
        (Hostile("batch output absolute", ["batch", absolute, "--out", out / "b"], 2, "error", ("lies outside",)),
         clean),
        (Hostile("batch CSV output absolute", ["batch", lists / "escape.csv", "--out", out / "b"], 2, "error",
                 ("lies outside",)), clean),
        (Hostile("batch x.png and g/../x.png", ["batch", shared, "--out", out / "b"], 2, "error",
                 ("have the same output",)), clean),
        (Hostile("batch output onto a job's input", ["batch", onto, "--out", out], 2, "error",
                 ("is an input of job two",)), with_out("in.jpg")),
        # 2. -y never replaces a FIFO or a device node
        (Hostile("image --report FIFO -y", [*img, "-o", out / "p.png", "--report", out / "r.json", "-y"], 6,
                 "error", ("names a device, FIFO or socket",)), with_out(fifo="r.json")),
        # 3. an output that appears while the run works is kept, not replaced (exit 6)
        (Hostile("video -o appears mid-run", [*vid, "-o", out / "v.mp4", *FAST_VIDEO], 6, "error",
                 ("appeared while this run was writing -o",), appear="v.mp4"), clean),
        # 9. names longer than the file system allows
        (Hostile("image 300-byte output name", [*img, "-o", out / f"{long_name}.png"], 6, "error",
                 ("longer than the 255",)), clean),
        (Hostile("image 300-byte input name", ["image", inputs / f"{long_name}.jpg", b, "-o", out / "p.png"], 2,
                 "error", ("File name too long",)), clean),
        # 10. signals to a batch: no job after it, running ones stopped, nothing left, workers die with it
        (Hostile("batch --jobs 2 SIGTERM", ["batch", videos, "--out", out, "--jobs", "2"], 143, "signal",
                 ("SIGTERM",), signum=signal.SIGTERM), clean),
        (Hostile("batch --jobs 2 SIGINT", ["batch", videos, "--out", out, "--jobs", "2"], 130, "signal",
                 signum=signal.SIGINT), clean),
        (Hostile("batch --jobs 2 SIGKILL", ["batch", videos, "--out", out, "--jobs", "2"], -9, "none",
                 signum=signal.SIGKILL), clean),
        # 11. Ray addresses that do not answer: one line at once
        (Hostile("batch --ray closed port", ["batch", escape.parent / "bom.csv", "--out", out / "b", "--ray",
                                             "127.0.0.1:1"], 2, "error", ("cannot reach 127.0.0.1:1",)), clean),
        (Hostile("batch --ray unknown host", ["batch", escape.parent / "bom.csv", "--out", out / "b", "--ray",
                                              "no-such-host.invalid:6379"], 2, "error", ("cannot reach",)), clean),
        # 15. pair folders that are not ones: failed jobs with their reasons; A.JPG/B.JPG a pair
        (Hostile("batch malformed pair folders", ["batch", pairs, "--out", out / "b"], 7, "error",
                 ("3 of 5 jobs failed",), lines=4), clean),
        # 17. small ones
        (Hostile("batch CSV with a byte order mark", ["batch", lists / "bom.csv", "--out", out / "b"], 0, "none"),
         clean),
        (Hostile("batch CSV column twice", ["batch", lists / "twice.csv", "--out", out / "b"], 2, "error",
                 ("'name' appears twice",)), clean),
        (Hostile("image name with a newline", ["image", inputs / "new\nline.jpg", b, "-o", out / "p.png"], 2,
                 "error", ("new\\nline.jpg: file not found",)), clean),
        (Hostile("match, stdout on /dev/full", ["match", a, b], 6, "error", ("stdout: cannot write",),
                 stdout_full=True), clean),
        (Hostile("image, stderr closed", [*img, "-o", out / "p.png"], 0, "none", stderr_closed=True), clean),
        (Hostile("video without key frames", ["video", no_key, right, "-o", out / "v.mp4", *FAST_VIDEO], 5, "error",
                 ("no key frame",)), clean),
        (Hostile("video right ends 46 frames early", ["video", left, short_right, "-o", out / "v.mp4", *FAST_VIDEO],
                 0, "warning", ("the last 46 left frames have no right frame",)), clean),
        (Hostile("image 0.01 MP limit", [*img, "-o", out / "p.png", "--max-megapixels", "0.01"], 2, "error",
                 (f"{width}x{height} px ({width * height / 1e6:.3g} MP)",)), clean),
    ]
    if os.geteuid() == 0:
        cases.append((Hostile("image --report device node -y", [*img, "-o", out / "p.png", "--report", out / "null",
                                                                "-y"], 6, "error", ("names a device",)),
                       with_out(device="null")))
    if ray is not None:
        cases.append((Hostile("batch --ray local SIGTERM", ["batch", videos, "--out", out, *ray, "--jobs", "2"], 143,
                              "signal", ("SIGTERM",), signum=signal.SIGTERM), clean))
    return cases


def input_cases(data: Path, inputs: Path, out: Path, clean) -> list[tuple[Hostile, object]]:
    """The input classes: video time stamps that go back or repeat, a
    resolution change mid-stream, images and a video frame whose header claims a huge size, a run out
    of memory, settings beyond their ranges, an unwritable kernel cache, bench lengths and sizes out of
    range, two noise images: (case, setup)."""
    a, b = inputs / "a.jpg", inputs / "b.jpg"
    clips = REPO / "tests" / "data" / "video"
    left_frames, right_frames = (decoded_frames(clips / name) for name in ("rooftop_left.mp4", "rooftop_right.mp4"))
    (inputs / "ts").mkdir()
    ts = joined_ts_files(left_frames, right_frames, inputs / "ts")
    right_clip = clips / "rooftop_right.mp4"
    small = cv2.imread(str(a))[:48, :70]
    bombs = inputs / "bombs"
    bombs.mkdir()
    for fmt in ("bigtiff", ".gif", ".jp2", ".hdr"):
        (bombs / f"huge_{fmt.strip('.')}.img").write_bytes(claiming_more(fmt, 20000, 20000, small))
    big_mov = one_mjpeg_frame(inputs / "big.mov", 1280, 1024)
    settings = inputs / "settings"
    settings.mkdir()
    for name, value in {"gain_stride": "1000000000", "lattice_nx": "100000", "seam_separation_rows": "1000000000",
                        "flat_patch_px": "100000", "cpu_threads": "100000"}.items():
        (settings / f"{name}.toml").write_text(f"{name} = {value}\n")
    for seed in (1, 2):
        cv2.imwrite(str(inputs / f"noise{seed}.png"), np.random.default_rng(seed).integers(0, 256, (512, 512, 3),
                                                                                            dtype=np.uint8))
    lawn = data / "pairs" / "rew_lawn_2160"
    blocker = inputs / "not_a_folder"
    blocker.write_text("a file where the kernel cache should be")
    vid_out = ["-o", out / "v.mp4", *FAST_VIDEO]
    cases = [
        # 4. time stamps that go back or repeat: dropped and said, or refused with --strict; never squeezed
        (Hostile("video TS time stamps go back", ["video", ts / "back.ts", right_clip, *vid_out], 0, "warning",
                 ("60 frames whose time stamps go back or repeat", "dropped")), clean),
        (Hostile("video TS repeated pts", ["video", ts / "repeated.ts", right_clip, *vid_out], 0, "warning",
                 ("4 frames whose time stamps go back or repeat",)), clean),
        (Hostile("video TS go back --strict", ["video", ts / "back.ts", right_clip, *vid_out, "--strict"], 5, "error",
                 ("frame time stamps", "(--strict)")), clean),
        # 5. a resolution change mid-stream: rescaled to the first size and said
        (Hostile("video resolution change", ["video", ts / "resized.ts", ts / "right_4s.ts", *vid_out], 0, "warning",
                 ("changes resolution from 270x480 to 540x960", "60 frames were rescaled")), clean),
        # 6. formats whose header the decoder would not have read: refused from the header, no decoding
        *[(Hostile(f"image 20000x20000 {path.stem[5:]} bomb", ["image", path, b, "-o", out / "p.png"], 2, "error",
                   ("20000x20000 px (400 MP)", "above the limit of 100 MP")), clean)
          for path in sorted(bombs.iterdir())],
        (Hostile("video .mov frame above --max-megapixels", ["video", big_mov, right_clip, *vid_out,
                                                             "--max-megapixels", "1"], 2, "error",
                 ("a frame is 1280x1024 px (1.31 MP), above the limit of 1 MP",)), clean),
        # 7. out of memory in a native library: one line, exit 1, nothing left
        (Hostile("image 4K pair in 1.4 GB of address space", ["image", *sorted(lawn.glob("[ab].*")), "-o",
                                                               out / "p.png"], 1, "error", ("out of memory",),
                 memory_limit=1400 << 20), clean),
        # 8. settings beyond their ranges, from a settings file and on the command line
        *[(Hostile(f"image {path.stem} beyond its range", [*["image", a, b], "-o", out / "p.png", "--config", path],
                   2, "error", (f"{path.stem} = ", "is out of range")), clean) for path in sorted(settings.iterdir())],
        (Hostile("image --threads 999", ["image", a, b, "-o", out / "p.png", "--threads", "999"], 2, "error",
                 ("--threads", "out of range [0, 256]")), clean),
        # 12. an unwritable kernel cache: a temporary one, said once
        (Hostile("image, WARP_CACHE_PATH a file", ["image", a, b, "-o", out / "p.png"], 0, "warning",
                 ("kernel cache", "cannot be written"), lines=1, env=(("WARP_CACHE_PATH", str(blocker)),)), clean),
        # 13. bench lengths and sizes out of range
        (Hostile("bench --seconds nan", ["bench", "--seconds", "nan", "--work", out / "bench"], 2, "error",
                 ("--seconds",)), clean),
        (Hostile("bench --seconds -5", ["bench", "--seconds", "-5", "--work", out / "bench"], 2, "error",
                 ("--seconds",)), clean),
        (Hostile("bench --sizes 100000x100000", ["bench", "--sizes", "100000x100000", "--work", out / "bench"], 2,
                 "error", ("at most 8192 px a side",)), clean),
        # 14. two noise images: refused as unrelated photos are
        (Hostile("image two noise images", ["image", inputs / "noise1.png", inputs / "noise2.png", "-o",
                                            out / "p.png"], 3, "error", ("check that the images overlap",)), clean),
    ]
    return cases


def _has_ray() -> bool:
    try:
        import ray  # noqa: F401
    except ImportError:
        return False
    return True


def run_real(data: Path, work: Path, counts: collections.Counter) -> int:
    runs = list(image_runs(data)) + list(video_runs(data))
    for i, (name, cli_args, suffix) in enumerate(runs):
        code, message, seconds = run_one(cli_args, work / f"run{i:03d}{suffix}")
        counts[code] += 1
        print(f"{name:32s} exit {code!s:9s} {seconds:6.1f} s  {message}", flush=True)
    return len(runs)


def run_hostile_all(data: Path, work: Path, named: str | None) -> tuple[int, int]:
    cases = [(case, setup) for case, setup in hostile_cases(data, work) if named is None or named in case.name]
    broken = 0
    for case, setup in cases:
        setup()
        ok, said, seconds = run_hostile(case, work / "in", work / "out")
        broken += not ok
        print(f"{case.name:34s} exit {case.code:<4d} {'ok  ' if ok else 'FAIL'} {seconds:6.1f} s  {said}", flush=True)
    return len(cases), broken


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
    parser.add_argument("--work", type=Path, default=None, help="keep outputs here (default: a temp folder)")
    parser.add_argument("--only", choices=("real", "hostile"), help="run one part only")
    parser.add_argument("--named", metavar="TEXT", help="run only the hostile cases whose name holds TEXT")
    args = parser.parse_args()
    if not (args.data / "pairs").is_dir():
        print(f"soak: {args.data} has no pairs/ folder", file=sys.stderr)
        return 2
    counts: collections.Counter = collections.Counter()
    real = hostile = broken = 0
    with tempfile.TemporaryDirectory() as tmp:
        work = args.work or Path(tmp)
        for part in ("real", "hostile"):
            (work / part).mkdir(parents=True, exist_ok=True)
        if args.only in (None, "real"):
            real = run_real(args.data, work / "real", counts)
        if args.only in (None, "hostile"):
            hostile, broken = run_hostile_all(args.data, work / "hostile", args.named)
    exceptions = counts.pop("EXCEPTION", 0)
    summary = ", ".join(f"exit {code}: {n}" for code, n in sorted(counts.items()))
    print(f"soak: {real} real runs ({summary or 'none'}), unhandled exceptions: {exceptions}; {hostile} hostile runs, "
          f"promise broken: {broken}")
    return 1 if exceptions or broken else 0


if __name__ == "__main__":
    sys.exit(main())
