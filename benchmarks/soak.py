"""Soak run (issues 7 and 15): every image pair in both orders and every video pair through the real CLI,
then the hostile classes of issue 15, each as a user would meet it, in a process of its own.

Real runs count outcomes by exit code and, above all, unhandled exceptions (anything that is not a
``StitchError`` reaching ``main``). Hostile runs (outputs colliding, existing outputs and -y / -n, the
folder rule, huge inputs, signals and SIGKILL leftovers, damaged and truncated video with and
without --strict, rotated and RGBA and float inputs, a variable frame rate, a full disk, bad
options, misleading failures, eval and bench) each check the promise: the expected exit code, exactly
one stderr line (an error, or a warning when it should warn), no traceback, nothing left in the
output folder after a failure (no temporary ever), inputs byte for byte unchanged. Prints one line
per run and a summary; exits 1 if any run raised or broke its promise.

    .venv/bin/python benchmarks/soak.py [--data ../shared/data] [--work DIR] [--only real|hostile]
"""

from __future__ import annotations

import argparse
import collections
import contextlib
import hashlib
import io
import resource
import shutil
import signal
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

from helpers import (damage_the_middle, index_first, png_claiming, reencode_with_black_start,  # noqa: E402
                     truncated, with_orientation)
from sena_warp.cli import main as cli_main  # noqa: E402

FAST_VIDEO = ["--audio", "none", "--crf", "35"]
SIGNAL_WAIT_S = 120.0


def image_runs(data: Path):
    for pair in sorted(p for p in (data / "pairs").iterdir() if p.is_dir()):
        a, b = (next(pair.glob(f"{name}.*")) for name in ("a", "b"))
        yield f"{pair.name} (a,b)", ["image", str(a), str(b)], ".png"
        yield f"{pair.name} (b,a)", ["image", str(b), str(a)], ".png"


def video_runs(data: Path):
    for folder in sorted(p for p in (data / "videos").iterdir() if p.is_dir()):
        left, right = sorted(folder.glob("*.mp4"))[:2]
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
    give, the stderr line's kind ("error", "warning" or "none") and words it must hold; ``signum``:
    sent once the output's temporary is being written; ``file_limit``: RLIMIT_FSIZE in bytes."""

    name: str
    argv: list
    code: int
    kind: str
    words: tuple[str, ...] = ()
    signum: int | None = None
    file_limit: int | None = None


def _digest(paths) -> dict[str, str]:
    return {str(p): hashlib.sha256(p.read_bytes()).hexdigest() for p in paths if p.is_file()}


def _limit_files(limit: int):
    def apply() -> None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, resource.getrlimit(resource.RLIMIT_FSIZE)[1]))
    return apply


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
    child = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=REPO,
                             preexec_fn=_limit_files(case.file_limit) if case.file_limit else None)
    if case.signum is not None:
        while not _writing(out) and child.poll() is None and time.perf_counter() - t0 < SIGNAL_WAIT_S:
            time.sleep(0.02)
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
    elif len(lines) != 1 or not lines[0].startswith(want[case.kind]):
        problems.append(f"{len(lines)} stderr lines: {lines[:3]}")
    elif not all(word in lines[0] for word in case.words):
        problems.append(f"missing {[w for w in case.words if w not in lines[0]]}")
    if "Traceback" in err:
        problems.append("traceback")
    if [p for p in out.iterdir() if ".part" in p.name and p.name.startswith(".")]:
        problems.append("temporary left")
    if case.code not in (0,) and sorted(p.name for p in out.iterdir()) != before_out:
        problems.append(f"left behind: {sorted(set(p.name for p in out.iterdir()) - set(before_out))}")
    if _digest(inputs.rglob("*")) != before_in:
        problems.append("an input changed")
    return not problems, "; ".join(problems) or (lines[0] if lines else ""), seconds


def hostile_cases(data: Path, work: Path) -> list[tuple[Hostile, object]]:
    """The issue 15 classes on the shared data: (case, setup), setup() run just before the case (each
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
                 ("damaged frames", "replaced by the last good frame")), clean),
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
        (Hostile("video --crf 99", [*vid, "-o", pano("v.mp4"), "--crf", "99"], 2, "error", ("--crf", "<= 51")), clean),
        (Hostile("video --crf -1", [*vid, "-o", pano("v.mp4"), "--crf=-1"], 2, "error", ("--crf", ">= 0")), clean),
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
    return cases


def run_real(data: Path, work: Path, counts: collections.Counter) -> int:
    runs = list(image_runs(data)) + list(video_runs(data))
    for i, (name, cli_args, suffix) in enumerate(runs):
        code, message, seconds = run_one(cli_args, work / f"run{i:03d}{suffix}")
        counts[code] += 1
        print(f"{name:32s} exit {code!s:9s} {seconds:6.1f} s  {message}", flush=True)
    return len(runs)


def run_hostile_all(data: Path, work: Path) -> tuple[int, int]:
    cases = hostile_cases(data, work)
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
            hostile, broken = run_hostile_all(args.data, work / "hostile")
    exceptions = counts.pop("EXCEPTION", 0)
    summary = ", ".join(f"exit {code}: {n}" for code, n in sorted(counts.items()))
    print(f"soak: {real} real runs ({summary or 'none'}), unhandled exceptions: {exceptions}; {hostile} hostile runs, "
          f"promise broken: {broken}")
    return 1 if exceptions or broken else 0


if __name__ == "__main__":
    sys.exit(main())
