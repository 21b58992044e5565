"""Outputs that collide, exist, or cannot be written, and the overwrite rules: every output of every command,
through the CLI.

Each class is tested over every command and output it applies to: the exit code, exactly one
stderr line and no traceback, nothing left in the output folder (no output, no temporary), the
inputs byte for byte as they were. Refusals must come before any work: inputs are never opened.
"""

from __future__ import annotations

import errno
import hashlib
import importlib
import os
import stat
import resource
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import cv2
import pytest

from sena_warp import imageio, outputs
from sena_warp.errors import InputError, OutputError
from sena_warp.video import reader as video_reader
from helpers import assert_one_line_error, decoded_frames, run_cli

FAST_VIDEO = ["--audio", "none", "--crf", "35"]
REPO = Path(__file__).resolve().parents[1]

# command -> its outputs: option -> (name, is a folder); inputs come from the `inputs` fixture
COMMANDS = {
    "image": {"outputs": {"-o": ("pano.png", False), "--report": ("r.json", False), "--debug": ("dbg", True)}},
    "video": {"outputs": {"-o": ("pano.mp4", False), "--report": ("r.json", False)}},
    "match": {"outputs": {"-o": ("m.jpg", False)}},
    "eval": {"outputs": {"--out": ("ev", True)}},
}
SUFFIXED = ("-o",)  # outputs whose extension is checked first: a collision must keep their suffix


def digest(paths) -> list[str]:
    return [hashlib.sha256(Path(p).read_bytes()).hexdigest() for p in paths]


def tree(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


@pytest.fixture
def inputs(bundled_dir, dirs):
    """Per command: its input argv (copies in the input folder, so the output folder starts empty)."""
    folder_in, _ = dirs
    pair = bundled_dir / "udisd_test_000001"
    for name in ("a.jpg", "b.jpg"):
        shutil.copy(pair / name, folder_in / name)
    for name in ("rooftop_left.mp4", "rooftop_right.mp4"):
        shutil.copy(bundled_dir / "video" / name, folder_in / name)
    data = folder_in / "pairs" / "p1"
    data.mkdir(parents=True)
    for name in ("a.jpg", "b.jpg"):
        shutil.copy(pair / name, data / name)
    return {
        "image": [folder_in / "a.jpg", folder_in / "b.jpg"],
        "video": [folder_in / "rooftop_left.mp4", folder_in / "rooftop_right.mp4"],
        "match": [folder_in / "a.jpg", folder_in / "b.jpg"],
        "eval": [folder_in / "pairs"],
    }


@pytest.fixture
def no_work(monkeypatch):
    """Fail the test if any input is opened for reading (images, videos and eval's pair folders)."""
    def refuse(*args, **kwargs):
        raise AssertionError(f"an input was opened before the outputs were checked: {args}")
    monkeypatch.setattr(imageio, "read_image_masked", refuse)
    monkeypatch.setattr(video_reader, "open_input", refuse)
    import sena_warp.evaluation.evaluate as evaluate
    monkeypatch.setattr(evaluate, "pair_folders", refuse)


def argv_for(command: str, ins: list[Path], outs: dict[str, Path]) -> list:
    argv = [command, *ins]
    for option, path in outs.items():
        argv += [option, path]
    return argv + (FAST_VIDEO if command == "video" else [])


def default_outputs(command: str, folder_out: Path) -> dict[str, Path]:
    return {option: folder_out / name for option, (name, _) in COMMANDS[command]["outputs"].items()}


def run_refused(command, outs, ins, folder_out, capfd, warp_device, code, *words, extra=()):
    """Run a command that must be refused; check the code, the one line, nothing left, inputs unchanged."""
    before_out, before_in = tree(folder_out), digest(p for p in ins if os.path.isfile(p))
    rc, err, _ = run_cli([*argv_for(command, ins, outs), *extra], capfd, warp_device)
    assert rc == code, err
    assert_one_line_error(err, *words)
    assert tree(folder_out) == before_out
    assert digest(p for p in ins if os.path.isfile(p)) == before_in


# --- 1. outputs colliding with inputs and with each other: exit 6, before any work -------------------

def collision_cases():
    """(command, case): an output named as an input ("equal"), a folder output holding the inputs
    ("holding"), two outputs on one path ("same"), an output inside a folder output ("inside")."""
    for command, spec in COMMANDS.items():
        options = list(spec["outputs"])
        for i, a in enumerate(options):
            yield command, ("equal", a)
            if spec["outputs"][a][1]:
                yield command, ("holding", a)
                yield from ((command, ("inside", b, a)) for b in options if b != a)
            yield from ((command, ("same", a, b)) for b in options[i + 1:])


@pytest.mark.parametrize("command, case", list(collision_cases()),
                         ids=lambda v: "-".join(v) if isinstance(v, tuple) else v)
def test_outputs_colliding_with_inputs_or_each_other_are_refused_before_work(
        command, case, inputs, dirs, capfd, warp_device, no_work):
    _, folder_out = dirs
    ins = inputs[command]
    outs = default_outputs(command, folder_out)
    kind, option = case[0], case[1]
    if kind == "equal":
        outs[option] = ins[0]
        is_folder, input_is_folder = COMMANDS[command]["outputs"][option][1], ins[0].is_dir()
        words = ("needs a folder and this is a file",) if is_folder and not input_is_folder else (
            f"{option} would overwrite an input",)
    elif kind == "holding":
        outs[option] = ins[0].parent
        words = (f"{option} folder holds the input",)
    elif kind == "same":
        other = case[2]
        outs[option] = outs[other] = outs[option if option in SUFFIXED else other]
        words = (f"{option} and {other} name the same path",)
    else:
        folder = case[2]
        outs[folder].mkdir()
        outs[option] = outs[folder] / outs[option].name
        words = (f"{option} lies inside the {folder} folder",)
    run_refused(command, outs, ins, folder_out, capfd, warp_device, OutputError.exit_code, *words)


# --- 16: existing outputs: refused, skipped with -n, replaced with -y ----------------------------------

EXISTING = [(command, option) for command, spec in COMMANDS.items() for option in spec["outputs"]]


def make_existing(path: Path, folder: bool) -> None:
    if folder:
        path.mkdir()
        (path / "old.txt").write_text("old")
    else:
        path.write_bytes(b"old")


@pytest.mark.parametrize("command, option", EXISTING, ids="-".join)
def test_an_existing_output_is_refused_without_y(command, option, inputs, dirs, capfd, warp_device, no_work):
    _, folder_out = dirs
    outs = default_outputs(command, folder_out)
    make_existing(outs[option], COMMANDS[command]["outputs"][option][1])
    run_refused(command, outs, inputs[command], folder_out, capfd, warp_device, OutputError.exit_code,
                str(outs[option]), "add -y to overwrite it or -n to skip")


@pytest.mark.parametrize("command, option", EXISTING, ids="-".join)
def test_n_skips_the_run_when_an_output_exists(command, option, inputs, dirs, capfd, warp_device, no_work):
    _, folder_out = dirs
    outs = default_outputs(command, folder_out)
    make_existing(outs[option], COMMANDS[command]["outputs"][option][1])
    before = tree(folder_out)
    rc, err, out = run_cli([*argv_for(command, inputs[command], outs), "-n"], capfd, warp_device)
    assert rc == 0 and err == []
    assert out.splitlines() == [f"{outs[option]}: exists, skipped (-n)"]
    assert tree(folder_out) == before


@pytest.mark.parametrize("command", ["image", "video"])
def test_y_replaces_every_existing_output(command, inputs, dirs, capfd, warp_device):
    _, folder_out = dirs
    outs = default_outputs(command, folder_out)
    for option, (_, folder) in COMMANDS[command]["outputs"].items():
        make_existing(outs[option], folder)
    rc, err, _ = run_cli([*argv_for(command, inputs[command], outs), "-y"], capfd, warp_device)
    assert rc == 0 and err == [], err
    for option, (_, folder) in COMMANDS[command]["outputs"].items():
        if folder:
            # The debug pictures of the default (fitted, ungated) warp: six stages, no gate picture.
            assert len(list(outs[option].glob("*.jpg"))) == 6 and (outs[option] / "old.txt").exists()
        else:
            assert outs[option].read_bytes() != b"old"
    assert not [p for p in folder_out.rglob(".*")]  # no temporary left


# --- 2: a device, FIFO or socket is never an output, not even with -y ------------------------------------

@pytest.mark.parametrize("command, option", EXISTING, ids="-".join)
def test_a_fifo_output_is_refused_even_with_y(command, option, inputs, dirs, capfd, warp_device, no_work):
    _, folder_out = dirs
    outs = default_outputs(command, folder_out)
    os.mkfifo(outs[option])
    run_refused(command, outs, inputs[command], folder_out, capfd, warp_device, OutputError.exit_code,
                f"{outs[option]}: {option} names a device, FIFO or socket, not a file", extra=["-y"])
    assert stat.S_ISFIFO(outs[option].lstat().st_mode)


# --- 3: an output that appears while the command works is not replaced without -y -------------------------

WORK = {"image": ("sena_warp.stitch", "stitch_images"), "video": ("sena_warp.video.stitch", "stitch_videos"),
        "match": ("sena_warp.features", "match_images"), "eval": ("sena_warp.evaluation.evaluate", "run_eval")}


@pytest.mark.parametrize("command, option", EXISTING, ids="-".join)
@pytest.mark.parametrize("overwrite", [[], ["-n"]], ids=["refuse", "-n"])
def test_an_output_that_appears_while_the_command_works_is_kept_exit_6(command, option, overwrite, inputs, dirs,
                                                                       capfd, warp_device, monkeypatch):
    _, folder_out = dirs
    outs = default_outputs(command, folder_out)
    module, name = importlib.import_module(WORK[command][0]), WORK[command][1]
    work = getattr(module, name)

    def appear_then_work(*args, **kwargs):  # another run, or a user, takes the name meanwhile
        make_existing(outs[option], COMMANDS[command]["outputs"][option][1])
        return work(*args, **kwargs)

    monkeypatch.setattr(module, name, appear_then_work)
    before_in = digest(inputs[command][:2] if command != "eval" else [])
    rc, err, _ = run_cli([*argv_for(command, inputs[command], outs), *overwrite], capfd, warp_device)
    assert rc == OutputError.exit_code, err
    assert_one_line_error(err, f"{outs[option]}: appeared while this run was writing {option}",
                          "nothing written, add -y to replace it")
    assert tree(folder_out) == (sorted([outs[option].name, f"{outs[option].name}/old.txt"])
                                if COMMANDS[command]["outputs"][option][1] else [outs[option].name])
    assert (outs[option] / "old.txt" if COMMANDS[command]["outputs"][option][1] else outs[option]).read_bytes() == b"old"
    assert digest(inputs[command][:2] if command != "eval" else []) == before_in


def test_two_runs_to_one_output_one_wins_the_other_exits_6(inputs, dirs):
    _, folder_out = dirs
    runs = [start_video(inputs["video"], folder_out / "pano.mp4") for _ in range(2)]
    results = sorted((run.wait(timeout=300), run.communicate()[1]) for run in runs)
    assert [code for code, _ in results] == [0, OutputError.exit_code], results
    err = results[1][1].splitlines()
    assert len(err) == 1 and err[0].startswith(f"sena-warp: error: {folder_out / 'pano.mp4'}: ") and (
        "appeared while this run was writing -o" in err[0] or "exists; add -y" in err[0]), err
    assert os.listdir(folder_out) == ["pano.mp4"] and len(decoded_frames(folder_out / "pano.mp4")) == len(
        decoded_frames(inputs["video"][0]))


# --- 16: one folder rule: an output's folder must exist; an output folder itself is made ---------------

@pytest.mark.parametrize("command, option", EXISTING, ids="-".join)
def test_an_output_in_a_missing_folder_is_refused(command, option, inputs, dirs, capfd, warp_device, no_work):
    _, folder_out = dirs
    outs = default_outputs(command, folder_out)
    outs[option] = folder_out / "new" / outs[option].name
    run_refused(command, outs, inputs[command], folder_out, capfd, warp_device, OutputError.exit_code,
                f"folder {folder_out / 'new'} does not exist; create it first")


# --- 9: bad options exit 2, before any work --------------------------------------------------------------

BAD_OPTIONS = [
    ("video", ["--offset", "nan"], ("offset nan s is not a time",)),
    ("video", ["--offset", "inf"], ("offset inf s is not a time",)),
    ("video", ["--offset=-inf"], ("offset -inf s",)),
    ("video", ["--crf", "-1"], ("--crf: video_crf = -1 is out of range [0, 51]",)),
    ("video", ["--crf", "52"], ("--crf: video_crf = 52 is out of range [0, 51]",)),
    ("video", ["--crf", "99"], ("--crf: video_crf = 99 is out of range [0, 51]",)),
    ("video", ["--crf", "abc"], ("argument --crf: invalid int value",)),
    ("video", ["--preset", "warp9"], ("argument --preset: invalid choice: 'warp9'", "veryfast")),
    ("video", ["--rig", "moving", "--reestimate", "nan"], ("--reestimate: video_reestimate_s = nan must be a finite",)),
    ("video", ["--rig", "moving", "--reestimate", "0"], ("--reestimate: video_reestimate_s = 0.0 is out of range (0, 3600]",)),
    ("video", ["--rig", "moving", "--reestimate", "inf"], ("--reestimate: video_reestimate_s = inf must be a finite",)),
    ("video", ["--rig", "static", "--reestimate", "2"], ("drop --rig static",)),
    ("video", ["--max-megapixels", "0"], ("--max-megapixels: max_input_megapixels = 0.0 is out of range (0, 10000]",)),
    ("image", ["--max-megapixels", "nan"], ("--max-megapixels: max_input_megapixels = nan",)),
    ("image", ["--reference", "c"], ("argument --reference: invalid choice",)),
    ("eval", ["--max-megapixels", "-3"], ("--max-megapixels: max_input_megapixels = -3.0",)),
    ("video", ["--threads", "999"], ("--threads: cpu_threads = 999 is out of range [0, 256]",)),
    ("image", ["--max-megapixels", "1e9"], ("--max-megapixels: max_input_megapixels = 1000000000.0 is out of range",)),
]


@pytest.mark.parametrize("command, extra, words", BAD_OPTIONS,
                         ids=lambda v: " ".join(v) if isinstance(v, list) else None)
def test_bad_option_values_exit_2_before_any_work(command, extra, words, inputs, dirs, capfd, warp_device, no_work):
    _, folder_out = dirs
    run_refused(command, default_outputs(command, folder_out), inputs[command], folder_out, capfd, warp_device,
                InputError.exit_code, *words, extra=extra)


@pytest.mark.parametrize("command, name", [("image", "pano.gif"), ("image", "pano"), ("video", "pano.avi"),
                                           ("video", "pano.gif"), ("match", "m.txt")])
def test_an_unsupported_output_type_is_a_bad_option_exit_2(command, name, inputs, dirs, capfd, warp_device, no_work):
    _, folder_out = dirs
    outs = default_outputs(command, folder_out)
    outs["-o"] = folder_out / name
    run_refused(command, outs, inputs[command], folder_out, capfd, warp_device, InputError.exit_code,
                "unsupported output type for -o")


# --- 7: a full disk while writing any output: exit 6, nothing left ----------------------------------------

@pytest.fixture
def small_files():
    """Files above 16 KiB cannot be written (RLIMIT_FSIZE, SIGXFSZ ignored: EFBIG like a full disk)."""
    limit = 16 * 1024
    soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
    previous = signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (limit, hard))
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))
        signal.signal(signal.SIGXFSZ, previous)


@pytest.mark.parametrize("command", ["image", "video"])
def test_an_output_the_disk_cannot_hold_exit_6_nothing_left(command, inputs, dirs, capfd, warp_device, small_files):
    _, folder_out = dirs
    outs = default_outputs(command, folder_out)
    run_refused(command, outs, inputs[command], folder_out, capfd, warp_device, OutputError.exit_code,
                f"{outs['-o']}: cannot write it (File too large)")


@pytest.mark.parametrize("command", ["image", "video"])
def test_a_report_that_fails_after_the_main_output_leaves_neither(command, inputs, dirs, capfd, warp_device,
                                                                  monkeypatch):
    _, folder_out = dirs
    real = Path.write_text

    def disk_full(self, *args, **kwargs):
        if self.name.endswith(".part.json"):
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(self, *args, **kwargs)

    monkeypatch.setattr(Path, "write_text", disk_full)
    outs = default_outputs(command, folder_out)
    run_refused(command, outs, inputs[command], folder_out, capfd, warp_device, OutputError.exit_code,
                f"{outs['--report']}: cannot write it (No space left on device)")


def _onnxruntime_out_of_memory():
    from onnxruntime.capi.onnxruntime_pybind11_state import Fail

    return Fail("[ONNXRuntimeError] : 1 : FAIL : Non-zero status code returned while running InstanceNormalization "
                "node. Status Message: bfc_arena.cc:360 Failed to allocate memory for requested buffer of size 671088640")


# Where a stitch runs out of memory, and how each library says so (each message as measured under ulimit -v).
OUT_OF_MEMORY = {
    "numpy": ("sena_warp.stitch", "stitch_images", lambda: MemoryError("Unable to allocate 12.5 GiB for an array")),
    "warp": ("sena_warp.stitch", "source_map_canvas",
             lambda: RuntimeError("Failed to allocate 166831664 bytes on device 'cpu'")),
    "onnxruntime": ("sena_warp.features", "detect_xfeat", _onnxruntime_out_of_memory),
    "opencv": ("sena_warp.stitch", "field_from_lattice", lambda: cv2.error(
        "OpenCV(5.1.0) /io/opencv/modules/core/src/alloc.cpp:73: error: (-4:Insufficient memory) Failed to allocate "
        "33922016 bytes in function 'OutOfMemoryError'")),
}


@pytest.mark.parametrize("where", sorted(OUT_OF_MEMORY))
def test_running_out_of_memory_is_one_line_and_leaves_nothing(where, inputs, dirs, capfd, warp_device, monkeypatch):
    """What a 20000x20000 pair allowed by a raised --max-megapixels ends in on a machine without the memory,
    in numpy, in a Warp allocation or in onnxruntime's arena: exit 1, one line, nothing left."""
    import importlib

    module, name, error = OUT_OF_MEMORY[where]

    def no_memory(*args, **kwargs):
        raise error()

    monkeypatch.setattr(importlib.import_module(module), name, no_memory)
    _, folder_out = dirs
    run_refused("image", default_outputs("image", folder_out), inputs["image"], folder_out, capfd, warp_device, 1,
                "out of memory; lower --max-megapixels")


def test_only_a_failed_allocation_reads_as_out_of_memory_and_a_batch_job_records_it(tmp_path, monkeypatch):
    from sena_warp import batch
    from sena_warp.errors import out_of_memory
    from sena_warp.jobs import Job

    assert out_of_memory(RuntimeError("index 3 is out of bounds")) is None  # a bug stays a bug, with its traceback
    assert out_of_memory(ValueError("Failed to allocate")) is None
    assert out_of_memory(_onnxruntime_out_of_memory()).exit_code == 1
    assert out_of_memory(cv2.error("(-215:Assertion failed) !ssize.empty()")) is None
    monkeypatch.setattr(batch, "run_job", lambda job: (_ for _ in ()).throw(RuntimeError("Failed to allocate 8 bytes")))
    entry = batch.Entry("pair", Job("image", ("a.jpg", "b.jpg"), str(tmp_path / "p.png")), str(tmp_path / "r.json"))
    result = batch.run_entry(entry)
    assert (result["error"], result["exit_code"]) == ("out of memory; lower --max-megapixels, downscale the inputs or "
                                                      "free some memory", 1)


# --- 3. SIGTERM, SIGHUP and SIGINT like Ctrl-C; SIGKILL's leftovers cleaned by the next run --------------

def start_video(ins, out: Path) -> subprocess.Popen:
    code = "import sys; from sena_warp.cli import main; sys.exit(main(sys.argv[1:]))"
    return subprocess.Popen([sys.executable, "-c", code, "video", *map(str, ins), "-o", str(out), *FAST_VIDEO,
                             "--preset", "slow", "--device", "cpu", "-q"],  # -q: stderr holds errors only
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=REPO)


def wait_for_temp(folder: Path, child: subprocess.Popen, timeout_s: float = 60.0) -> Path:
    """The output's temporary once the child is writing it."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout_s:
        temps = [p for p in folder.iterdir() if p.name.startswith(".") and ".part" in p.name]
        if temps and temps[0].stat().st_size > 0:
            return temps[0]
        assert child.poll() is None, child.communicate()
        time.sleep(0.02)
    raise AssertionError("the video was never being written")


@pytest.mark.parametrize("signum, code", [(signal.SIGTERM, 143), (signal.SIGHUP, 129)], ids=["SIGTERM", "SIGHUP"])
def test_termination_signals_exit_128_plus_n_one_line_nothing_left(signum, code, inputs, dirs):
    """A real signal to a real process (SIGINT takes the same handler; Ctrl-C in-process: test_robustness_video)."""
    _, folder_out = dirs
    before = digest(inputs["video"])
    child = start_video(inputs["video"], folder_out / "pano.mp4")
    wait_for_temp(folder_out, child)
    child.send_signal(signum)
    _, err = child.communicate(timeout=60)
    assert child.returncode == code
    assert err.splitlines() == [f"sena-warp: interrupted by {signal.Signals(signum).name}"]
    assert list(folder_out.iterdir()) == []
    assert digest(inputs["video"]) == before


def test_a_later_run_removes_what_a_killed_run_left(inputs, dirs, capfd, warp_device):
    _, folder_out = dirs
    child = start_video(inputs["video"], folder_out / "pano.mp4")
    left = wait_for_temp(folder_out, child)
    child.kill()
    child.wait()
    assert left.exists()
    rc, err, _ = run_cli(["video", *inputs["video"], "-o", folder_out / "pano.mp4", *FAST_VIDEO], capfd, warp_device)
    assert rc == 0, err
    assert [p.name for p in folder_out.iterdir()] == ["pano.mp4"]


def test_an_output_name_of_244_characters_is_written(inputs, dirs, capfd, warp_device):
    _, folder_out = dirs
    name = "p" * 240 + ".png"
    rc, err, _ = run_cli(["image", *inputs["image"], "-o", folder_out / name], capfd, warp_device)
    assert rc == 0, err
    assert [p.name for p in folder_out.iterdir()] == [name]


def test_outputs_module_names_fit_the_file_system(tmp_path):
    assert os.pathconf(tmp_path, "PC_NAME_MAX") >= outputs.NAME_MAX_BYTES


# --- 9: names longer than the file system allows: one line, exit 2 for an input, 6 for an output ---------

LONG = "n" * 300
LONG_OUTPUTS = [(command, option, how) for command, spec in COMMANDS.items() for option in spec["outputs"]
                for how in ("name", "folder")] + [("batch", "--out", "name"), ("batch", "--out", "folder")]


@pytest.mark.parametrize("command, option, how", LONG_OUTPUTS, ids=lambda v: str(v))
def test_an_output_name_longer_than_the_file_system_allows_is_refused_before_work(
        command, option, how, inputs, dirs, capfd, warp_device, no_work):
    _, folder_out = dirs
    ins = inputs["eval" if command == "batch" else command]
    outs = default_outputs(command, folder_out) if command in COMMANDS else {"--out": folder_out / "b"}
    name = outs[option].name
    outs[option] = folder_out / (LONG + Path(name).suffix) if how == "name" else folder_out / LONG / name
    run_refused(command, outs, ins, folder_out, capfd, warp_device, OutputError.exit_code,
                f"{option} has a name of 30", "bytes, longer than the 255 this file system allows")


LONG_INPUTS = [(command, 0) for command in COMMANDS] + [("video", 1), ("batch", 0), ("image", "--config")]


@pytest.mark.parametrize("command, where", LONG_INPUTS, ids=lambda v: str(v))
def test_an_input_name_longer_than_the_file_system_allows_is_one_line_exit_2(command, where, inputs, dirs, capfd,
                                                                            warp_device):
    folder_in, folder_out = dirs
    ins = list(inputs["eval" if command == "batch" else command])
    outs = default_outputs(command, folder_out) if command in COMMANDS else {"--out": folder_out / "b"}
    extra = []
    if where == "--config":
        extra = ["--config", folder_in / (LONG + ".toml")]
    else:
        ins[where] = folder_in / (LONG + ins[where].suffix)
    run_refused(command, outs, ins, folder_out, capfd, warp_device, InputError.exit_code, "File name too long",
                extra=extra)
