"""sena_warp.outputs: the rules every command's outputs follow, on the plan itself (the CLI classes are
in test_robustness_outputs.py).
"""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from sena_warp import outputs
from sena_warp.errors import InputError, OutputError
from sena_warp.outputs import NAME_MAX_BYTES, OutputPlan, atomic_output, make_folder, remove_stale_temps, temp_affixes


def plan_of(tmp_path, *outs, inputs=(), overwrite="refuse") -> OutputPlan:
    plan = OutputPlan(inputs, overwrite)
    for name, option, folder in outs:
        plan.add(tmp_path / name, option, folder=folder)
    return plan


def dead_pid() -> int:
    """The id of a process that has just exited (so no process has it for a while)."""
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    return child.pid


def test_outputs_are_committed_together_only_when_the_block_succeeds(tmp_path):
    plan = plan_of(tmp_path, ("p.png", "-o", False), ("r.json", "--report", False), ("dbg", "--debug", True))
    assert plan.check() == []
    with plan:
        with plan.writing(tmp_path / "p.png") as tmp:
            tmp.write_bytes(b"png")
        with plan.writing(tmp_path / "dbg") as folder:
            (folder / "01.jpg").write_bytes(b"jpg")
        assert sorted(p.name for p in tmp_path.iterdir() if not p.name.startswith(".")) == []
        with plan.writing(tmp_path / "r.json") as tmp:
            tmp.write_text("{}")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dbg", "p.png", "r.json"]
    assert (tmp_path / "dbg" / "01.jpg").read_bytes() == b"jpg"
    assert (tmp_path / "p.png").stat().st_mode & 0o777 == 0o666 & ~outputs._UMASK


@pytest.mark.parametrize("error", [OSError(28, "No space left on device"), KeyboardInterrupt()])
def test_a_failure_of_the_last_output_leaves_none(tmp_path, error):
    (tmp_path / "p.png").write_bytes(b"old")  # -y: the old panorama must survive a failed run
    plan = plan_of(tmp_path, ("p.png", "-o", False), ("r.json", "--report", False), overwrite="overwrite")
    plan.check()
    with pytest.raises(OutputError if isinstance(error, OSError) else KeyboardInterrupt):
        with plan:
            with plan.writing(tmp_path / "p.png") as tmp:
                tmp.write_bytes(b"new")
            with plan.writing(tmp_path / "r.json"):
                raise error
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p.png"]
    assert (tmp_path / "p.png").read_bytes() == b"old"


@pytest.mark.parametrize("outs, words", [
    ([("x", "-o", False), ("x", "--report", False)], ("-o and --report name the same path",)),
    ([("x", "-o", False), ("x", "--debug", True)], ("-o and --debug name the same path",)),
    ([("d/p.png", "-o", False), ("d", "--debug", True)], ("lies inside the --debug folder",)),
    ([("d", "--debug", True), ("d/e", "--out", True)], ("lies inside the --debug folder",)),
])
def test_outputs_that_collide_are_refused(tmp_path, outs, words):
    (tmp_path / "d").mkdir()
    with pytest.raises(OutputError) as caught:
        plan_of(tmp_path, *outs).check()
    assert all(w in str(caught.value) for w in words), str(caught.value)


def test_inputs_are_never_overwritten_nor_held_even_with_y(tmp_path):
    src = tmp_path / "in" / "a.png"
    src.parent.mkdir()
    src.write_bytes(b"a")
    os.link(src, tmp_path / "hard.png")
    (tmp_path / "soft.png").symlink_to(src)
    for name, folder, words in (("in/a.png", False, "would overwrite an input"),
                                ("hard.png", False, "would overwrite an input"),
                                ("soft.png", False, "would overwrite an input"),
                                ("in", True, "holds the input")):
        with pytest.raises(OutputError, match=words):
            plan_of(tmp_path, (name, "-o", folder), inputs=(src,), overwrite="overwrite").check()


def test_overwrite_modes(tmp_path):
    (tmp_path / "p.png").write_bytes(b"old")
    (tmp_path / "empty").mkdir()
    outs = [("p.png", "-o", False), ("empty", "--debug", True)]
    with pytest.raises(OutputError, match="p.png: exists; add -y to overwrite it or -n to skip the run"):
        plan_of(tmp_path, *outs).check()
    assert plan_of(tmp_path, *outs, overwrite="skip").check() == [tmp_path / "p.png"]
    assert plan_of(tmp_path, *outs, overwrite="overwrite").check() == []
    assert plan_of(tmp_path, ("empty", "--debug", True)).check() == []  # an empty folder is not "existing"
    (tmp_path / "empty" / "keep.txt").write_text("mine")
    with pytest.raises(OutputError, match="folder exists and is not empty"):
        plan_of(tmp_path, ("empty", "--debug", True)).check()
    with pytest.raises(InputError, match="overwrite mode"):
        OutputPlan((), "ask")


def test_y_into_an_existing_folder_replaces_same_names_and_keeps_the_rest(tmp_path):
    folder = tmp_path / "dbg"
    (folder / "sub").mkdir(parents=True)
    (folder / "keep.txt").write_text("mine")
    (folder / "01.jpg").write_bytes(b"old")
    plan = plan_of(tmp_path, ("dbg", "--debug", True), overwrite="overwrite")
    plan.check()
    with plan, plan.writing(folder) as tmp:
        (tmp / "01.jpg").write_bytes(b"new")
        (tmp / "sub").mkdir()
        (tmp / "sub" / "s.png").write_bytes(b"s")
    assert (folder / "01.jpg").read_bytes() == b"new" and (folder / "keep.txt").read_text() == "mine"
    assert (folder / "sub" / "s.png").read_bytes() == b"s"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dbg"]


@pytest.mark.parametrize("name, folder", [("new/p.png", False), ("new/nested", True)])
def test_one_folder_rule_parents_are_never_made(tmp_path, name, folder):
    with pytest.raises(OutputError, match="folder .*new does not exist; create it first"):
        plan_of(tmp_path, (name, "--x", folder)).check()
    with pytest.raises(OutputError, match="does not exist"):
        make_folder(tmp_path / name, "--work")
    assert list(tmp_path.iterdir()) == []
    assert make_folder(tmp_path / "made", "--work").is_dir()


@pytest.mark.parametrize("name", ["p" * 240 + ".png", "p" * 251 + ".png", "é" * 125 + ".png",
                                  "x" * 200 + "." + "y" * 50])
def test_temporary_names_fit_in_255_bytes_for_any_output_name(tmp_path, name):
    assert len(os.fsencode(name)) <= NAME_MAX_BYTES
    prefix, suffix = temp_affixes(tmp_path / name, folder=False)
    assert len(os.fsencode(prefix + "abcdefgh" + suffix)) <= NAME_MAX_BYTES
    with atomic_output(tmp_path / name) as tmp:
        tmp.write_bytes(b"data")
    assert (tmp_path / name).read_bytes() == b"data"


def temp_name(out, pid: int, random: str = "abcdefgh"):
    """The name a temporary of output ``out`` made by process ``pid`` has."""
    prefix, suffix = temp_affixes(out, folder=False)
    return out.parent / (prefix.replace(f".{os.getpid()}.", f".{pid}.") + random + suffix)


def test_stale_temporaries_of_gone_processes_are_removed_and_live_ones_kept(tmp_path):
    out = tmp_path / "pano.mp4"
    live = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        stale, stale_dir = temp_name(out, dead_pid()), temp_name(out, dead_pid(), "stuvwxyz")
        alive, other = temp_name(out, live.pid), temp_name(tmp_path / "other.mp4", dead_pid())
        for path in (stale, alive, other):
            path.write_bytes(b"partial")
        stale_dir.mkdir()
        assert sorted(remove_stale_temps(out)) == sorted([stale, stale_dir])
        assert alive.exists() and other.exists()  # a run still going; another output's
        with atomic_output(out) as tmp:  # every new temporary of the output cleans up first
            tmp.write_bytes(b"video")
        assert sorted(p.name for p in tmp_path.iterdir()) == sorted([alive.name, other.name, "pano.mp4"])
    finally:
        live.kill()
        live.wait()
