"""Every output of a command, planned and checked before any work, written to temporaries and
committed together at the end.

One :class:`OutputPlan` per command holds its outputs (files such as ``-o`` and ``--report``,
folders such as ``--debug`` and ``eval --out``). ``check()`` applies the rules below to all of them
before anything is read or computed; inside ``with plan:`` each output is written to a temporary
name beside it (``plan.writing(path)``), and only when the whole block succeeds are they all
given their names. A failure or an interruption anywhere (the report after the panorama, a full
disk, SIGTERM) leaves none of them, and replaces no existing file.

The rules (also in the README, "Outputs"):

- **Folders**: an output goes into a folder that exists. An output folder itself is created when
  missing, but never its parents: ``-o new/p.png`` and ``--debug new/nested`` are both refused
  while ``new`` does not exist.
- **Overwriting**, as ffmpeg does it: an existing output (a file, a link, or a folder that is not
  empty) is refused with ``overwrite="refuse"``, replaced with ``"overwrite"`` (``-y``); with
  ``"skip"`` (``-n``) ``check()`` reports it and the command does nothing. Files written into an
  existing output folder replace those of the same name; other files there are left alone.
- **Commit without replacing**: without ``-y`` an output is given its name by a hard link (a file)
  or a rename (a folder, onto nothing or an empty folder), which fail when something took the name
  while the command ran (another run to the same output, a file made meanwhile): OutputError, and
  the outputs this commit had already placed are taken back.
- **Only files and folders**: a device, FIFO or socket is never an output, not even with ``-y``
  (``--report /dev/null -y`` would otherwise replace the device node with a file).
- **Names**: a name longer than its file system allows (``PC_NAME_MAX``, 255 bytes on most) is
  refused before any work.
- **Collisions**: no output may be an input (also through links), lie inside another output, hold
  another output or hold an input. Even ``-y`` never overwrites an input.
- **Temporaries** are named ``.NAME.TAG.PID.RANDOM.part.EXT`` (``NAME`` shortened so the whole fits
  in 255 bytes; ``TAG`` a hash of the output's full name). A later run for the same output removes
  those left by a process that no longer exists (killed with SIGKILL, or a machine that crashed).
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import os
import re
import shutil
import stat
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Iterator

from .errors import InputError, OutputError

OVERWRITE_MODES = ("refuse", "overwrite", "skip")
NAME_MAX_BYTES = 255  # longest file name on the usual file systems (ext4, xfs, btrfs, tmpfs, APFS)
SUFFIX_MAX_BYTES = 16  # a longer output extension is left off its temporary's name (no encoder needs it)
NO_HARD_LINKS = (errno.EPERM, errno.EOPNOTSUPP, errno.ENOTSUP, errno.EMLINK)  # link(2) on FAT, some network mounts
TAKEN = (errno.EEXIST, errno.ENOTEMPTY, errno.ENOTDIR)  # link(2) / rename(2): something else has the name
RANDOM_CHARS = 8  # what tempfile.mkstemp / mkdtemp put between prefix and suffix: [a-z0-9_]
_TEMP_NAME = re.compile(r"\.(?P<tag>[0-9a-f]{8})\.(?P<pid>\d+)\.[a-z0-9_]{%d}\.part(\.[^.]*)?$" % RANDOM_CHARS)


def _process_umask() -> int:
    """The process's umask (read once at import, before any thread: os.umask can only swap it)."""
    mask = os.umask(0)
    os.umask(mask)
    return mask


_UMASK = _process_umask()


@dataclass(frozen=True)
class Output:
    """One planned output: its path as given, the option that named it (for messages), its kind."""

    path: Path
    option: str
    folder: bool


def _real(path: Path) -> Path:
    """The absolute path with links resolved as far as the path exists."""
    return Path(os.path.realpath(path))


def _same_file(a: Path, b: Path) -> bool:
    if _real(a) == _real(b):
        return True
    try:
        return os.path.samefile(a, b)
    except OSError:  # either one missing, or a name the file system refuses (checked on its own)
        return False


def _inside(inner: Path, outer: Path) -> bool:
    """``inner`` lies inside folder ``outer`` (not equal to it)."""
    inner, outer = _real(inner), _real(outer)
    return inner != outer and inner.is_relative_to(outer)


def _exists(output: Output) -> bool:
    if output.folder:
        return output.path.is_dir() and any(output.path.iterdir())
    return os.path.lexists(output.path)  # a link whose target is gone still holds the name


def _kind(path: Path, option: str) -> str:
    """What ``path`` names, following links: "missing", "file", "folder" or "other" (a device, FIFO or
    socket); OutputError when the file system refuses to look (a name too long, a loop of links)."""
    try:
        mode = os.stat(path).st_mode
    except (FileNotFoundError, NotADirectoryError):
        return "missing"
    except OSError as exc:
        raise OutputError(f"{path}: {option} cannot be used ({exc.strerror}); choose another name") from exc
    return "file" if stat.S_ISREG(mode) else "folder" if stat.S_ISDIR(mode) else "other"


def _check_name_lengths(path: Path, option: str) -> None:
    """OutputError when a name in ``path`` is longer than its file system takes (asked of the deepest
    folder of ``path`` that exists; 255 bytes where it cannot say)."""
    existing = next((p for p in (path.absolute(), *path.absolute().parents) if os.path.isdir(p)), None)
    try:
        limit = os.pathconf(existing, "PC_NAME_MAX") if existing is not None else NAME_MAX_BYTES
    except (OSError, ValueError):
        limit = NAME_MAX_BYTES
    for name in path.parts:
        if len(os.fsencode(name)) > limit:
            raise OutputError(f"{path}: {option} has a name of {len(os.fsencode(name))} bytes, longer than the "
                              f"{limit} this file system allows; choose a shorter name")


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's process
        return True
    return True


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        with contextlib.suppress(FileNotFoundError):
            path.unlink()


def _tag(path: Path) -> str:
    """8 hex digits naming output ``path`` in its temporaries, whatever its length."""
    return hashlib.sha256(os.fsencode(path.name)).hexdigest()[:8]


def temp_affixes(path: Path, folder: bool) -> tuple[str, str]:
    """(prefix, suffix) of the temporaries of output ``path``: with tempfile's random part between
    them the name fits in :data:`NAME_MAX_BYTES` for any output name (the name is shortened)."""
    ext = "" if folder or len(os.fsencode(path.suffix)) > SUFFIX_MAX_BYTES else path.suffix
    tail, suffix = f".{_tag(path)}.{os.getpid()}.", f".part{ext}"
    room = NAME_MAX_BYTES - len(os.fsencode(f".{tail}{suffix}")) - RANDOM_CHARS
    stem = os.fsdecode(os.fsencode(path.name[:len(path.name) - len(ext)])[:room])
    return f".{stem}{tail}", suffix


def remove_stale_temps(path: Path) -> list[Path]:
    """Remove the temporaries of output ``path`` left by processes that are gone; returns them."""
    tag, removed = _tag(path), []
    with contextlib.suppress(OSError):
        for entry in path.parent.iterdir():
            found = _TEMP_NAME.search(entry.name)
            if entry.name.startswith(".") and found and found["tag"] == tag and not _alive(int(found["pid"])):
                _remove(entry)
                removed.append(entry)
    return removed


class OutputPlan:
    """The outputs of one command: checked together before any work, committed together at the end.

    ``inputs``: the command's input files or folders (no output may be, hold or overwrite one).
    ``overwrite``: one of :data:`OVERWRITE_MODES` ("refuse": ``-y`` not given; "overwrite": ``-y``;
    "skip": ``-n``). Use: ``add`` every output, ``check()``, then ``with plan:`` and
    ``with plan.writing(path) as tmp:`` for each output written.
    """

    def __init__(self, inputs: Iterable[str | os.PathLike] = (), overwrite: str = "refuse"):
        if overwrite not in OVERWRITE_MODES:
            raise InputError(f"overwrite mode {overwrite!r} unknown; use one of {', '.join(OVERWRITE_MODES)}")
        self.inputs = [Path(p) for p in inputs]
        self.overwrite = overwrite
        self.outputs: list[Output] = []
        self._temps: dict[Path, Path] = {}
        self._open = False

    def add(self, path: str | os.PathLike, option: str, folder: bool = False,
            suffixes: tuple[str, ...] | None = None) -> Path:
        """Plan output ``path`` (a file, or a folder when ``folder``), named by ``option`` in messages.

        ``suffixes``: the file extensions this output can be written as; another one is a bad
        option (InputError), refused here, before any other check.
        """
        path = Path(path)
        if suffixes is not None and path.suffix.lower() not in suffixes:
            raise InputError(f"{path}: unsupported output type for {option}; use one of {', '.join(suffixes)}")
        self.outputs.append(Output(path, option, folder))
        return path

    def check(self) -> list[Path]:
        """Apply the module's rules to every output; OutputError for the first that breaks one.

        Returns the outputs that exist already: empty unless ``overwrite`` is "skip", in which case a
        non-empty list means the command should do nothing.
        """
        for i, out in enumerate(self.outputs):
            self._check_place(out)
            for src in self.inputs:
                if _same_file(out.path, src):
                    raise OutputError(f"{out.path}: {out.option} would overwrite an input; choose another name")
                if out.folder and _inside(src, out.path):
                    raise OutputError(f"{out.path}: {out.option} folder holds the input {src}; choose another folder")
            for other in self.outputs[:i]:
                if _same_file(out.path, other.path):
                    raise OutputError(f"{out.path}: {other.option} and {out.option} name the same path; "
                                      f"give each output its own name")
                for inner, outer in ((out, other), (other, out)):
                    if outer.folder and _inside(inner.path, outer.path):
                        raise OutputError(f"{inner.path}: {inner.option} lies inside the {outer.option} folder "
                                          f"{outer.path}; put it elsewhere")
        existing = [out for out in self.outputs if _exists(out)]
        if existing and self.overwrite == "refuse":
            out = existing[0]
            what = "folder exists and is not empty" if out.folder else "exists"
            raise OutputError(f"{out.path}: {what}; add -y to overwrite it or -n to skip the run")
        return [out.path for out in existing] if self.overwrite == "skip" else []

    @staticmethod
    def _check_place(out: Output) -> None:
        """The folder rule, and a file where a folder is needed (or the reverse)."""
        path = out.path
        _check_name_lengths(path, out.option)
        kind = _kind(path, out.option)
        if kind == "other":
            raise OutputError(f"{path}: {out.option} names a device, FIFO or socket, not a file; choose another name")
        if out.folder and kind == "file":
            raise OutputError(f"{path}: {out.option} needs a folder and this is a file; choose another name")
        if not out.folder and kind == "folder":
            raise OutputError(f"{path}: is a folder; give {out.option} a file name")
        parent = path.parent
        parent_kind = _kind(parent, out.option)
        if parent_kind == "missing":
            raise OutputError(f"{path}: folder {parent} does not exist; create it first")
        if parent_kind != "folder":
            raise OutputError(f"{path}: {parent} is not a folder")
        if not os.access(parent, os.W_OK):
            raise OutputError(f"{path}: folder {parent} is not writable")

    def _output(self, path: str | os.PathLike) -> Output:
        path = Path(path)
        for out in self.outputs:
            if out.path == path:
                return out
        raise ValueError(f"{path} is not an output of this plan")

    def __enter__(self) -> "OutputPlan":
        self._open = True
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self._open = False
        try:
            if exc_type is None:
                self._commit()
        finally:
            for tmp in self._temps.values():
                _remove(tmp)
            self._temps.clear()

    def temp(self, path: str | os.PathLike) -> Path:
        """The temporary that output ``path`` is written to (made on first use: an empty file or folder).

        Made beside the output; stale temporaries of the same output are removed first.
        """
        out = self._output(path)
        if not self._open:
            raise RuntimeError("OutputPlan.temp outside its with block")
        if out.path not in self._temps:
            remove_stale_temps(out.path)
            prefix, suffix = temp_affixes(out.path, out.folder)
            folder = out.path.parent
            try:
                if out.folder:
                    tmp = tempfile.mkdtemp(prefix=prefix, suffix=suffix, dir=folder)
                else:
                    fd, tmp = tempfile.mkstemp(prefix=prefix, suffix=suffix, dir=folder)
                    os.close(fd)
            except OSError as exc:
                raise OutputError(f"{out.path}: cannot create a file in {folder} ({exc.strerror}); "
                                  f"choose another folder") from exc
            self._temps[out.path] = Path(tmp)
        return self._temps[out.path]

    @contextlib.contextmanager
    def writing(self, path: str | os.PathLike) -> Iterator[Path]:
        """Yield the temporary to write output ``path`` into; an OSError inside (a full disk, a
        removed folder) becomes an OutputError naming the output."""
        tmp = self.temp(path)
        try:
            yield tmp
        except OSError as exc:
            raise OutputError(f"{path}: cannot write it ({exc.strerror or exc}); free some space or choose "
                              f"another folder") from exc

    def _commit(self) -> None:
        """Give every written output its name: replacing what is there with -y, else only where the name
        is still free (all or none: what this commit placed is taken back when a later output fails)."""
        replace = self.overwrite == "overwrite"
        placed: list[Path] = []
        written = [(out, self._temps[out.path]) for out in self.outputs if out.path in self._temps]
        try:
            for out, tmp in written:
                if replace and out.folder and out.path.is_dir():
                    _merge_folder(tmp, out.path)
                    continue
                os.chmod(tmp, (0o777 if out.folder else 0o666) & ~_UMASK)  # mkstemp/mkdtemp: 0600/0700
                if replace:
                    if _kind(out.path, out.option) == "other":  # made while the command ran
                        raise OutputError(f"{out.path}: {out.option} names a device, FIFO or socket, not a "
                                          f"file; choose another name")
                    os.replace(tmp, out.path)
                elif out.folder:
                    os.rename(tmp, out.path)  # onto nothing or an empty folder only
                else:
                    _link_new(tmp, out.path)
                placed.append(out.path)
        except BaseException as exc:
            for path in placed if not replace else ():
                _remove(path)
            if isinstance(exc, OSError) and exc.errno in TAKEN and not replace:
                raise OutputError(f"{out.path}: appeared while this run was writing {out.option} (another run to "
                                  f"the same output?); nothing written, add -y to replace it") from exc
            if isinstance(exc, OSError):
                raise OutputError(f"{out.path}: cannot write it ({exc.strerror}); choose another name") from exc
            raise


def _link_new(tmp: Path, path: Path) -> None:
    """Give file ``tmp`` the name ``path`` too, or FileExistsError when ``path`` is taken (never replaced).

    Where the file system has no hard links, the name is claimed by an exclusive create and the file
    renamed onto the claim.
    """
    try:
        os.link(tmp, path)
    except OSError as exc:
        if exc.errno not in NO_HARD_LINKS:
            raise
        os.close(os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600))
        os.replace(tmp, path)


def make_folder(path: str | os.PathLike, option: str) -> Path:
    """Folder ``path``, created when missing by the folder rule (its parent must exist, it is not made);
    OutputError saying why when it cannot be. For folders that are not outputs, such as a cache."""
    out = Output(Path(path), option, folder=True)
    OutputPlan._check_place(out)
    try:
        out.path.mkdir(exist_ok=True)
    except OSError as exc:
        raise OutputError(f"{out.path}: cannot create this folder ({exc.strerror}); choose another folder") from exc
    return out.path


def _merge_folder(src: Path, dst: Path) -> None:
    """Move everything in folder ``src`` into the existing folder ``dst``, replacing files of the same name."""
    for entry in src.iterdir():
        target = dst / entry.name
        if entry.is_dir() and target.is_dir():
            _merge_folder(entry, target)
        else:
            os.replace(entry, target)


@contextlib.contextmanager
def staged(plan: OutputPlan | None, path: str | os.PathLike, inputs: Iterable[str | os.PathLike] = (),
           folder: bool = False, overwrite: str = "overwrite") -> Iterator[OutputPlan]:
    """``plan`` itself (entered by its owner, who commits it) or, without one, an entered plan of the
    single output ``path`` (a file, or a folder when ``folder``): checked now (an existing output as
    ``overwrite`` says, one of ``OVERWRITE_MODES``; one of the ``inputs`` refused) and committed when
    the block succeeds."""
    if plan is not None:
        yield plan
        return
    own = OutputPlan(inputs, overwrite=overwrite)
    own.add(path, "the output", folder=folder)
    own.check()
    with own:
        yield own


@contextlib.contextmanager
def atomic_output(path: str | os.PathLike, inputs: Iterable[str | os.PathLike] = (),
                  plan: OutputPlan | None = None) -> Iterator[Path]:
    """Yield a temporary path to write output file ``path`` into, renamed to ``path`` when the block
    succeeds (with ``plan``: when that plan commits, with its other outputs); see :func:`staged`."""
    with staged(plan, path, inputs) as plan, plan.writing(path) as tmp:
        yield tmp
