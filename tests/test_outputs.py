"""sena_warp.outputs: the rules every command's outputs follow, on the plan itself (the CLI classes are
in test_robustness_outputs.py).
"""

from __future__ import annotations

import errno
import os
import stat
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


def make_special(path, kind: str) -> None:
    """A FIFO, a Unix socket or a character device (like /dev/null: root only) at ``path``."""
    if kind == "fifo":
        os.mkfifo(path)
    elif kind == "socket":
        import socket

        with socket.socket(socket.AF_UNIX) as sock:
            sock.bind(str(path))
    else:
        if os.geteuid() != 0:
            pytest.skip("making a device node needs root")
        os.mknod(path, 0o666 | stat.S_IFCHR, os.makedev(1, 3))


@pytest.mark.parametrize("kind", ["fifo", "socket", "device"])
@pytest.mark.parametrize("overwrite", ["refuse", "overwrite", "skip"])
@pytest.mark.parametrize("folder, link", [(False, False), (True, False), (False, True)],
                         ids=["file", "folder", "link-to-it"])
def test_a_device_fifo_or_socket_is_never_an_output_even_with_y(tmp_path, kind, overwrite, folder, link):
    special = tmp_path / "special"
    make_special(special, kind)
    name = special
    if link:
        name = tmp_path / "link"
        name.symlink_to(special)
    before = sorted((p.name, p.lstat().st_mode) for p in tmp_path.iterdir())
    with pytest.raises(OutputError, match="names a device, FIFO or socket, not a file; choose another name"):
        plan_of(tmp_path, (name.name, "--report", folder), overwrite=overwrite).check()
    assert sorted((p.name, p.lstat().st_mode) for p in tmp_path.iterdir()) == before


def test_a_device_made_while_the_command_ran_is_not_replaced_with_y(tmp_path):
    plan = plan_of(tmp_path, ("r.json", "--report", False), overwrite="overwrite")
    plan.check()
    with pytest.raises(OutputError, match="names a device, FIFO or socket"):
        with plan, plan.writing(tmp_path / "r.json") as tmp:
            tmp.write_text("{}")
            os.mkfifo(tmp_path / "r.json")
    assert stat.S_ISFIFO((tmp_path / "r.json").lstat().st_mode) and sorted(os.listdir(tmp_path)) == ["r.json"]


def write_all(plan, tmp_path, appear=None):
    """Write every output of ``plan`` (a file or a folder with one file); ``appear()`` runs just before
    the commit, as another process would."""
    with plan:
        for out in plan.outputs:
            with plan.writing(out.path) as tmp:
                (tmp / "01.jpg" if out.folder else tmp).write_bytes(b"new")
        if appear is not None:
            appear()


OUTS = [("p.png", "-o", False), ("r.json", "--report", False), ("dbg", "--debug", True)]


@pytest.mark.parametrize("overwrite", ["refuse", "skip"])
@pytest.mark.parametrize("taken, made", [("p.png", "file"), ("r.json", "file"), ("r.json", "link"),
                                         ("dbg", "file"), ("dbg", "folder")])
@pytest.mark.parametrize("hard_links", [True, False], ids=["links", "no-hard-links"])
def test_an_output_that_appears_while_the_command_runs_is_never_replaced_without_y(
        tmp_path, monkeypatch, overwrite, taken, made, hard_links):
    if not hard_links:  # a file system without link(2): FAT, some network mounts
        def no_link(*args, **kwargs):
            raise OSError(errno.EPERM, "Operation not permitted")
        monkeypatch.setattr(os, "link", no_link)

    def appear():  # another run to the same output, or a user's file
        path = tmp_path / taken
        if made == "folder":
            path.mkdir()
            (path / "mine.txt").write_text("mine")
        elif made == "link":
            path.symlink_to(tmp_path / "nowhere")
        else:
            path.write_text("mine")

    plan = plan_of(tmp_path, *OUTS, overwrite=overwrite)
    assert plan.check() == []
    with pytest.raises(OutputError, match=f"{taken}: appeared while this run was writing .*nothing written, "
                                          f"add -y to replace it"):
        write_all(plan, tmp_path, appear)
    assert sorted(os.listdir(tmp_path)) == [taken]  # the outputs committed before it are taken back
    path = tmp_path / taken
    if made == "folder":
        assert os.listdir(path) == ["mine.txt"]
    elif made == "link":
        assert os.readlink(path) == str(tmp_path / "nowhere")
    else:
        assert path.read_text() == "mine"


@pytest.mark.parametrize("hard_links", [True, False], ids=["links", "no-hard-links"])
def test_outputs_are_committed_without_y_when_their_names_are_free(tmp_path, monkeypatch, hard_links):
    if not hard_links:
        monkeypatch.setattr(os, "link", lambda *a, **k: (_ for _ in ()).throw(OSError(errno.EOPNOTSUPP, "no")))
    (tmp_path / "dbg").mkdir()  # an empty folder is not an existing output
    write_all(plan_of(tmp_path, *OUTS), tmp_path)
    assert sorted(os.listdir(tmp_path)) == ["dbg", "p.png", "r.json"]
    assert (tmp_path / "p.png").read_bytes() == b"new" and (tmp_path / "dbg" / "01.jpg").read_bytes() == b"new"
    assert (tmp_path / "r.json").stat().st_nlink == 1 and (tmp_path / "p.png").stat().st_mode & 0o777 == (
        0o666 & ~outputs._UMASK)


def test_with_y_an_output_that_appears_while_the_command_runs_is_replaced(tmp_path):
    write_all(plan_of(tmp_path, *OUTS, overwrite="overwrite"), tmp_path,
              lambda: (tmp_path / "p.png").write_text("mine"))
    assert (tmp_path / "p.png").read_bytes() == b"new"


def test_a_link_to_nowhere_is_an_existing_output(tmp_path):
    (tmp_path / "p.png").symlink_to(tmp_path / "gone.png")
    with pytest.raises(OutputError, match="p.png: exists; add -y"):
        plan_of(tmp_path, ("p.png", "-o", False)).check()


@pytest.mark.parametrize("name, folder", [("p" * 252 + ".png", False), ("d" * 256, True),
                                          ("é" * 128 + ".png", False), ("d" * 300 + "/p.png", False)],
                         ids=["file-256", "folder-256", "utf8-260", "parent-300"])
def test_a_name_longer_than_the_file_system_allows_is_refused(tmp_path, name, folder):
    with pytest.raises(OutputError, match=r"has a name of \d+ bytes, longer than the 255 this file system allows"):
        plan_of(tmp_path, (name, "-o", folder)).check()
    with pytest.raises(OutputError, match="longer than the 255"):
        make_folder(tmp_path / name, "--out")
    assert os.listdir(tmp_path) == []


def test_a_path_the_file_system_cannot_look_up_is_one_error(tmp_path):
    (tmp_path / "loop").symlink_to(tmp_path / "loop")
    with pytest.raises(OutputError, match=r"loop/p.png: -o cannot be used \(Too many levels of symbolic links\)"):
        plan_of(tmp_path, ("loop/p.png", "-o", False)).check()
