"""``sena-warp batch JOBS --out DIR``: many stitches, on local worker processes or as Ray tasks, resumable.

JOBS is a folder of pair folders (each holding images ``a.*`` + ``b.*`` or videos ``left.*`` +
``right.*``; the folder's name names the job; a folder that tries to be one and is not, such as
``a.jpg`` + ``c.jpg``, is a failed job saying why), or a job list: TOML (``[defaults]`` and
``[[job]]`` tables) or CSV (a header row, one job per row). A job gives its inputs (``a``/``b`` or
``left``/``right``, relative to the list's folder) and optionally ``name``, ``output`` (relative to
DIR, and inside it), ``reference``, ``crop``, ``offset`` (videos: seconds, or "auto" to estimate them)
and any setting of ``sena-warp config``. Settings and these keys apply in this order, the later
winning: defaults, ``--config``, command-line options (``--crop``, ``--offset``, ``--ss``/``--to``,
``--codec``, ...), the list's ``[defaults]``, the job's own. Before any job runs, every output is
resolved (``..``, links) and refused (exit 2) when it lies outside DIR, is any job's input, or is
another job's output; DIR is made only then.

Each job writes ``DIR/NAME.png`` or ``DIR/NAME.mp4`` and then ``DIR/reports/NAME.json`` (its report
with a ``job`` block: status, error, time). A job whose report says "ok" and whose output exists is
complete and skipped by the next run, so an interrupted batch resumes where it stopped; a failed job
is recorded with its error, the others go on, and it is tried again next time (``-y`` runs every job
again, ``-n`` only those whose output does not exist). At the end: a table
on stdout, ``DIR/summary.json``, and exit code 7 when any job failed.

The same job function, :func:`run_entry`, runs in ``--jobs N`` local worker processes
(``sena_warp.workers``: no more workers than jobs; on SIGINT, SIGTERM or SIGHUP no job starts, the
running ones are stopped and leave nothing, and workers die with the parent) or as Ray tasks
(``--ray ADDRESS``, extra ``sena-warp[cluster]``; an address that does not answer within
:data:`RAY_CONNECT_TIMEOUT_S` is refused in one line); a job that asks for ``device = "cuda"`` gets
one GPU per task. On a cluster, inputs and DIR must be on storage every node sees.
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import json
import logging
import os
import signal
import socket
import stat
import sys
import threading
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable, Iterator

from .config import OFFSET_AUTO
from .config_file import check_value, field_types, read_toml, unknown_key_error
from .errors import InputError, StitchError, out_of_memory
from .imageio import input_stat
from .jobs import INPUT_SUFFIXES, OUTPUT_SUFFIXES, PAIR_STEMS, Job, pair_inputs, run_job, summary_line
from .outputs import NAME_MAX_BYTES, atomic_output, make_folder, remove_stale_temps
from .progress import LOGGER, Count, echo, stage
from .workers import STOP_WAIT_S, run_in_workers

# Job keys besides the settings: name -> (type, the kind it applies to or None for both).
JOB_KEYS = {"name": (str, None), "output": (str, None), "reference": (str, None), "crop": (bool, None),
            "offset": (float, "video"), "a": (str, "image"), "b": (str, "image"), "left": (str, "video"),
            "right": (str, "video")}
WORDS = {"offset": (OFFSET_AUTO,)}  # words a number key also takes
REFERENCES = ("auto", "a", "b")
TRUE_WORDS, FALSE_WORDS = ("true", "yes", "1"), ("false", "no", "0")  # CSV cells of a yes/no option
TOML_TABLES = ("defaults", "job")
REPORTS = "reports"  # DIR/reports/NAME.json
SUMMARY = "summary.json"
RAY_LOCAL = "local"
RAY_AUTO = "auto"
RAY_PORTS = {"ray://": 10001, "": 6379}  # Ray Client's port, the GCS's port: where an address names none
RAY_CONNECT_TIMEOUT_S = 5.0  # a cluster address that does not accept a connection this fast is refused


class BatchError(StitchError):
    """The batch ran to its end, but some of its jobs failed (each report says why)."""

    exit_code = 7


@dataclass(frozen=True)
class Entry:
    """One job of a batch: its name, the job, and where its report goes; or, for a pair folder that
    is not one, its name and ``error`` (no job: it is recorded as failed without running)."""

    name: str
    job: Job | None
    report: str
    error: str | None = None


def read_jobs(source: str | os.PathLike, out_dir: str | os.PathLike, settings: dict,
              options: dict | None = None) -> list[Entry]:
    """The batch's jobs from a folder of pair folders or a .toml / .csv list; ``settings``: for every job;
    ``options``: job keys (``crop``, ``offset``) for every job of a kind they apply to, under the list's own.

    Paths come back absolute (a Ray task may run elsewhere); names, outputs and inputs are checked,
    and how the outputs lie against DIR, the inputs and each other.
    """
    source, out_dir = Path(source).resolve(), Path(out_dir).resolve()
    if stat.S_ISDIR(input_stat(source).st_mode):
        defaults: dict = {}
        rows = _folder_rows(source, out_dir)
    elif source.suffix.lower() == ".toml":
        defaults, rows = _toml_rows(source)
    elif source.suffix.lower() == ".csv":
        defaults, rows = {}, _csv_rows(source)
    else:
        raise InputError(f"{source}: a job list is a .toml or .csv file (or give a folder of pair folders)")
    if not rows:
        raise InputError(f"{source}: no jobs found")
    entries = [_refused(where, row, out_dir) if isinstance(row, InputError)
               else _entry({**defaults, **row}, where, source, out_dir, settings, options or {})
               for where, row in rows]
    _check_unique(entries, source)
    _check_outputs(entries, source)
    return entries


def _folder_rows(folder: Path, out_dir: Path) -> list[tuple[str, dict | InputError]]:
    """(where, row) per pair folder of ``folder`` (or ``folder`` itself when it is one); a folder that
    tries to be a pair folder and is not gives (its name, its InputError) instead. ``out_dir`` (DIR,
    whose outputs would look like one) is not looked at."""
    own = _pair_or_error(folder)
    if isinstance(own, tuple):
        return [(str(folder), _pair_row(folder, *own))]
    subs = sorted(p for p in folder.iterdir() if p.is_dir() and not p.name.startswith(".") and p.resolve() != out_dir)
    pairs = [(sub, found) for sub in subs if (found := _pair_or_error(sub)) is not None]
    if not pairs:
        raise own if isinstance(own, InputError) else InputError(
            f"{folder}: no pair folders (sub-folders holding a.* + b.* images or left.* + right.* videos)")
    return [(pair.name, found) if isinstance(found, InputError) else (str(pair), _pair_row(pair, *found))
            for pair, found in pairs]


def _pair_or_error(folder: Path) -> tuple[str, tuple[Path, Path]] | InputError | None:
    """What :func:`~sena_warp.jobs.pair_inputs` says of ``folder``, its InputError returned, not raised."""
    try:
        return pair_inputs(folder)
    except InputError as exc:
        return exc


def _pair_row(folder: Path, kind: str, inputs: tuple[Path, Path]) -> dict:
    return {"name": folder.name, **dict(zip(PAIR_STEMS[kind], map(str, inputs)))}


def _toml_rows(path: Path) -> tuple[dict, list[tuple[str, dict]]]:
    data = read_toml(path)
    for key in data:
        if key not in TOML_TABLES:
            raise unknown_key_error(key, list(TOML_TABLES), str(path))
    jobs = data.get("job", [])
    if not isinstance(jobs, list) or not all(isinstance(j, dict) for j in jobs):
        raise InputError(f"{path}: jobs are [[job]] tables")
    defaults = data.get("defaults", {})
    if not isinstance(defaults, dict):
        raise InputError(f"{path}: defaults is a [defaults] table")
    return defaults, [(f"{path}: job {i + 1}", job) for i, job in enumerate(jobs)]


def _csv_rows(path: Path) -> list[tuple[str, dict]]:
    try:
        with open(path, newline="", encoding="utf-8-sig") as handle:  # -sig: a spreadsheet's byte order mark
            reader = csv.DictReader(handle)
            header = [name.strip() for name in reader.fieldnames or ()]
            table = list(reader)
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise InputError(f"{path}: cannot read it as a CSV job list ({exc})") from exc
    twice = sorted({name for name in header if header.count(name) > 1})
    if twice:
        raise InputError(f"{path}: line 1: the column {twice[0]!r} appears twice; keep one")
    rows = []
    for line_no, cells in enumerate(table, start=2):
        where = f"{path}: line {line_no}"
        if None in cells:
            raise InputError(f"{where}: more cells than the header has names")
        rows.append((where, {key.strip(): _from_text(key.strip(), text.strip(), where)
                             for key, text in cells.items() if text and text.strip()}))
    return rows


def _from_text(key: str, text: str, where: str):
    """A CSV cell as the value its column takes: a number, yes/no, or text; unknown columns pass through."""
    kind = JOB_KEYS[key][0] if key in JOB_KEYS else field_types().get(key, str)
    if text in WORDS.get(key, ()):
        return text
    if kind is bool:
        if text.lower() not in TRUE_WORDS + FALSE_WORDS:
            raise InputError(f"{where}: {key} = {text!r} is not one of {', '.join(TRUE_WORDS + FALSE_WORDS)}")
        return text.lower() in TRUE_WORDS
    if kind in (int, float):
        try:
            return int(text) if kind is int else float(text)
        except ValueError:
            raise InputError(f"{where}: {key} = {text!r} is not {'a whole number' if kind is int else 'a number'}") from None
    return text


def _entry(row: dict, where: str, source: Path, out_dir: Path, settings: dict, given: dict) -> Entry:
    types = field_types()
    for key in row:
        if key not in JOB_KEYS and key not in types:
            raise unknown_key_error(key, [*JOB_KEYS, *types], where)
    kinds = [kind for kind, stems in PAIR_STEMS.items() if any(stem in row for stem in stems)]
    if len(kinds) != 1 or not all(stem in row for stem in PAIR_STEMS[kinds[0]]):
        raise InputError(f"{where}: give the inputs as a and b (images) or left and right (videos)")
    kind = kinds[0]
    options = {**{key: value for key, value in given.items() if JOB_KEYS[key][1] in (None, kind)},
               **{key: _job_value(key, value, kind, where) for key, value in row.items() if key in JOB_KEYS}}
    base = source if source.is_dir() else source.parent
    inputs = tuple(str((base / options[stem]).resolve()) for stem in PAIR_STEMS[kind])
    name = options.get("name") or Path(inputs[0]).parent.name
    _check_name(name, where)
    named = options.get("output", name + OUTPUT_SUFFIXES[kind][0])
    output = Path(os.path.realpath(out_dir / named))  # "g/../x.png" and "x.png" are one output
    if not output.is_relative_to(out_dir) or output == out_dir:
        raise InputError(f"{where}: output = {named!r} lies outside --out {out_dir}; give a name inside it")
    job_settings = {**settings, **{key: check_value(key, value, where) for key, value in row.items() if key in types}}
    # A job still to run replaces what an earlier, unfinished run left (complete jobs are skipped before).
    job = Job(kind, inputs, str(output), job_settings, reference=options.get("reference", "auto"),
              crop=options.get("crop", False), offset_s=options.get("offset", 0.0), overwrite="overwrite")
    return Entry(name, job, str(out_dir / REPORTS / f"{name}.json"))


def _check_name(name: str, where: str) -> None:
    """A job's name names its output and report: a plain file name, short enough for ``NAME.json``."""
    if not name or "/" in name or "\\" in name or name.startswith(".") or not name.isprintable():
        raise InputError(f"{where}: job name {name!r} cannot name a file; give a plain name")
    if len(os.fsencode(f"{name}.json")) > NAME_MAX_BYTES:
        raise InputError(f"{where}: job name {name[:40]!r}... is {len(os.fsencode(name))} bytes, too long for a "
                         f"file name ({NAME_MAX_BYTES} bytes with its .json); give a shorter name")


def _refused(name: str, error: InputError, out_dir: Path) -> Entry:
    """The entry of pair folder ``name`` that is not one: failed from the start, ``error`` its reason."""
    _check_name(name, name)
    return Entry(name, None, str(out_dir / REPORTS / f"{name}.json"), str(error))


def _job_value(key: str, value, kind: str, where: str):
    wanted, applies_to = JOB_KEYS[key]
    if applies_to is not None and applies_to != kind:
        raise InputError(f"{where}: {key} is for {applies_to} jobs; this one is a {kind} job")
    if value in WORDS.get(key, ()):
        return value
    if wanted is float and isinstance(value, int) and not isinstance(value, bool):
        value = float(value)
    if not isinstance(value, wanted) or (wanted is not bool and isinstance(value, bool)):
        words = "".join(f" or {word!r}" for word in WORDS.get(key, ()))
        raise InputError(f"{where}: {key} = {value!r} is not {'yes/no' if wanted is bool else 'a ' + wanted.__name__}"
                         f"{words}")
    if key == "reference" and value not in REFERENCES:
        raise InputError(f"{where}: reference = {value!r} is not one of {', '.join(REFERENCES)}")
    if key in PAIR_STEMS[kind] and Path(value).suffix.lower() not in INPUT_SUFFIXES[kind]:
        raise InputError(f"{where}: {key} = {value!r} is not a {kind} file ({', '.join(INPUT_SUFFIXES[kind])})")
    return value


def _check_unique(entries: list[Entry], source: Path) -> None:
    seen: set[str] = set()
    for entry in entries:
        if entry.name in seen:
            raise InputError(f"{source}: two jobs have the name {entry.name}; give each job its own")
        seen.add(entry.name)


def _check_outputs(entries: list[Entry], source: Path) -> None:
    """No job's output (resolved: links, ``..``) may be another job's output or any job's input."""
    inputs = {path: entry.name for entry in entries if entry.job for path in entry.job.inputs}
    outputs: dict[str, str] = {}
    for entry in entries:
        if entry.job is None:
            continue
        output = entry.job.output
        if output in outputs:
            raise InputError(f"{source}: jobs {outputs[output]} and {entry.name} have the same output {output}; "
                             f"give each job its own")
        if output in inputs:
            raise InputError(f"{source}: the output of job {entry.name}, {output}, is an input of job "
                             f"{inputs[output]}; give it another name")
        outputs[output] = entry.name


def is_complete(entry: Entry) -> bool:
    """Whether an earlier run finished ``entry``: its report says ok (written after the output) and the output is there."""
    try:
        status = json.loads(Path(entry.report).read_text())["job"]["status"]
    except (OSError, ValueError, KeyError, TypeError):
        return False
    return status == "ok" and Path(entry.job.output).is_file()


def run_entry(entry: Entry) -> dict:
    """Run one job here and write its report; its result record (a job's failure is recorded, not raised).

    The function every worker runs, a local process or a Ray task alike.
    """
    t0 = time.perf_counter()
    report: dict = {}
    try:
        report = run_job(entry.job)
        error, exit_code = None, 0
    except StitchError as exc:
        error, exit_code = str(exc), exc.exit_code
    except Exception as exc:  # out of memory, or a bug in one job that must not stop the batch (recorded with its type)
        known = out_of_memory(exc)
        error, exit_code = (str(known), known.exit_code) if known else (f"{type(exc).__name__}: {exc}", 1)
    result = {
        "name": entry.name, "kind": entry.job.kind, "status": "failed" if error else "ok",
        "inputs": list(entry.job.inputs), "output": entry.job.output, "error": error, "exit_code": exit_code,
        "seconds": round(time.perf_counter() - t0, 3), "host": socket.gethostname(),
        "summary": summary_line(entry.job.kind, report) if report else None,
    }
    _write_report(entry.report, {"job": result, **report})
    return result


def _write_report(path: str, data: dict) -> None:
    from .report import write_json

    make_folder(Path(path).parent, "the reports folder")
    write_json(path, data)


def _skipped(entry: Entry) -> dict:
    """The result record of a job not run: its earlier run's record where its report has one."""
    try:
        earlier = json.loads(Path(entry.report).read_text())["job"]
    except (OSError, ValueError, KeyError, TypeError):
        earlier = {**_failed(entry, None), "exit_code": None}
    return {**earlier, "status": "skipped"}


def _failed(entry: Entry, error: str | None, exit_code: int = 1) -> dict:
    """The result record of a job that did not run to a result: a pair folder that is not one, a
    crashed worker process, a lost Ray task."""
    job = entry.job
    return {"name": entry.name, "kind": job.kind if job else None, "status": "failed",
            "inputs": list(job.inputs) if job else [], "output": job.output if job else None, "error": error,
            "exit_code": exit_code, "seconds": None, "host": None, "summary": None}


def _with_threads(entry: Entry, threads: int) -> Entry:
    """``entry`` with ``threads`` as its cpu_threads unless a setting of the batch or the job chose them."""
    return replace(entry, job=replace(entry.job, settings={"cpu_threads": threads, **entry.job.settings}))


def _remove_leftovers(entry: Entry) -> None:
    """Remove the temporaries of ``entry``'s output and report left by a worker that was killed."""
    for path in (entry.job.output, entry.report):
        remove_stale_temps(Path(path))


def _started(entry: Entry) -> None:
    """Say that ``entry`` starts (a batch hands a job to a worker only when one is free to run it)."""
    LOGGER.info("%s: started (%s job: %s)", entry.name, entry.job.kind, Path(entry.job.inputs[0]).parent)


def run_local(entries: list[Entry], workers: int) -> Iterator[dict]:
    """Run ``entries`` in ``workers`` fresh processes sharing the cores, one job per worker at a time (each
    said as it starts); yield each result as its job finishes."""
    share = max((os.cpu_count() or 1) // workers, 1)
    tasks = [_with_threads(entry, share) for entry in entries]
    for entry, result, why in run_in_workers(tasks, workers, f"{__name__}:run_entry", _started, _remove_leftovers):
        yield result if why is None else _failed(entry, f"worker failed: {why}")


def local_runner(workers: int) -> Callable[[list[Entry]], tuple[str, Iterator[dict]]]:
    """A runner for :func:`run_batch`: ``workers`` local processes, no more than there are jobs to run."""
    def runner(todo: list[Entry]) -> tuple[str, Iterator[dict]]:
        count = max(min(workers, len(todo)), 1)
        return f"{count} local worker{'s' if count > 1 else ''}", run_local(todo, count)
    return runner


def ray_runner(address: str, cpus: int) -> Callable[[list[Entry]], tuple[str, Iterator[dict]]]:
    """A runner for :func:`run_batch`: Ray tasks on the cluster at ``address`` (see :func:`run_ray`).
    InputError now, before any work, when Ray is not installed or the address does not answer."""
    try:
        import ray  # noqa: F401
    except ImportError:
        raise InputError("--ray needs Ray: pip install 'sena-warp[cluster]'") from None
    check_reachable(address)
    return lambda todo: (f"ray {address}", run_ray(todo, address, cpus))


def check_reachable(address: str) -> None:
    """InputError unless the Ray cluster at ``address`` accepts a TCP connection within
    :data:`RAY_CONNECT_TIMEOUT_S` (Ray itself retries an unreachable address for minutes, with its
    own log lines). "local" starts a cluster; "auto" is checked where ``RAY_ADDRESS`` names one."""
    if address == RAY_AUTO:
        address = os.environ.get("RAY_ADDRESS", RAY_AUTO)
    if address in (RAY_LOCAL, RAY_AUTO):
        return
    scheme = "ray://" if address.startswith("ray://") else ""
    host, colon, port = address[len(scheme):].rpartition(":")
    if not colon:
        host, port = address[len(scheme):], str(RAY_PORTS[scheme])
    if not host or not port.isdigit():
        raise InputError(f"--ray {address}: not a cluster address; give auto, local, HOST:PORT or ray://HOST:PORT")
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=RAY_CONNECT_TIMEOUT_S).close()
    except OSError as exc:
        why = f"no answer in {RAY_CONNECT_TIMEOUT_S:g} s" if isinstance(exc, TimeoutError) else exc.strerror or str(exc)
        raise InputError(f"--ray {address}: cannot reach {host}:{port} ({why}); check the address and that the "
                         f"cluster is up") from None


@contextlib.contextmanager
def _own_sigterm() -> Iterator[None]:
    """Keep the SIGTERM handler in place across ``ray.init``, which puts its own (exit 15) there."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    handler = signal.getsignal(signal.SIGTERM)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, handler)


@contextlib.contextmanager
def _stderr_to_devnull() -> Iterator[None]:
    """Point file descriptor 2 at /dev/null: Ray's C++ core writes its connection retries there, several
    lines a second, and the processes a local Ray starts inherit it (they log to their own files)."""
    sys.stderr.flush()
    saved, null = os.dup(2), os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(null, 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        os.close(null)


def run_ray(entries: list[Entry], address: str, cpus: int) -> Iterator[dict]:
    """Run ``entries`` as Ray tasks on the cluster at ``address`` (or a Ray started here with ``cpus``);
    yield each result as its job finishes. A task reserves its job's threads as CPUs (one unless a
    setting says otherwise), and a GPU when the job asks for CUDA. Leaving early (a signal)
    cancels every task; a running one ends as Ctrl-C ends a command, leaving nothing."""
    import ray

    quiet = dict(logging_level=logging.ERROR, log_to_driver=False)
    # Ray takes seconds to start or reach: said before, so the wait is not silent.
    stage(f"starting Ray here with {cpus} CPUs" if address == RAY_LOCAL else f"connecting to the Ray cluster at {address}")
    try:
        with _own_sigterm(), _stderr_to_devnull():
            if address == RAY_LOCAL:
                ray.init(num_cpus=cpus, include_dashboard=False, **quiet)
            else:
                ray.init(address=address, **quiet)
    except (ConnectionError, ValueError, RuntimeError) as exc:
        raise InputError(f"--ray {address}: cannot connect ({' '.join(str(exc).split())})") from exc
    pending: dict = {}
    try:
        task = ray.remote(run_entry)
        cluster_cpus = int(ray.cluster_resources().get("CPU", cpus))
        LOGGER.info("Ray: %d CPUs%s", cluster_cpus, "" if address == RAY_LOCAL else f" at {address}")
        waiting = [_with_threads(entry, 1) for entry in reversed(entries)]
        while waiting or pending:
            # Handed to Ray only while the cluster has the CPUs to start them: "started" means started.
            while waiting and (not pending or sum(_task_cpus(e) for e in pending.values()) + _task_cpus(waiting[-1])
                               <= cluster_cpus):
                entry = waiting.pop()
                _started(entry)
                pending[task.options(num_cpus=_task_cpus(entry),
                                     num_gpus=1 if entry.job.settings.get("device") == "cuda" else 0,
                                     max_retries=0).remote(entry)] = entry
            done, _ = ray.wait(list(pending), num_returns=1)
            entry = pending.pop(done[0])
            try:
                yield ray.get(done[0])
            except ray.exceptions.RayError as exc:
                yield _failed(entry, f"Ray task failed: {' '.join(str(exc).split())[:500]}")
    finally:
        for ref in pending:
            ray.cancel(ref)  # a running task gets KeyboardInterrupt: its outputs' temporaries are removed
        if pending:
            ray.wait(list(pending), num_returns=len(pending), timeout=STOP_WAIT_S)
        ray.shutdown()
        if address == RAY_LOCAL:  # its workers are gone now; on a cluster they may still be cleaning up
            for entry in pending.values():
                _remove_leftovers(entry)


def _task_cpus(entry: Entry) -> int:
    """The CPUs a Ray task of ``entry`` reserves: its job's threads."""
    return max(entry.job.settings.get("cpu_threads", 1), 1)


def run_batch(entries: list[Entry], out_dir: str | os.PathLike,
              runner: Callable[[list[Entry]], tuple[str, Iterator[dict]]], overwrite: str = "refuse") -> dict:
    """Record the pair folders that are not ones as failed, run the other entries with ``runner`` (which
    names itself), write ``DIR/summary.json``; the summary.

    ``overwrite`` (``outputs.OVERWRITE_MODES``, as ``-y`` / ``-n`` set it): "refuse" skips the entries an
    earlier run completed (and redoes the others: the batch resumes), "overwrite" runs every entry
    again, "skip" runs only those whose output does not exist.
    """
    t0 = time.perf_counter()
    refused = [e for e in entries if e.error is not None]
    done_before = {"refuse": is_complete, "overwrite": lambda e: False, "skip": lambda e: Path(e.job.output).exists()}
    todo = [e for e in entries if e.error is None and not done_before[overwrite](e)]
    results = {e.name: _skipped(e) for e in entries if e not in todo and e not in refused}
    if results:
        why = "have an output already (-n)" if overwrite == "skip" else "complete from an earlier run"
        LOGGER.info("%d of %d jobs %s: skipped", len(results), len(entries), why)
    for entry in refused:
        results[entry.name] = _failed(entry, entry.error, InputError.exit_code)
        _write_report(entry.report, {"job": results[entry.name]})
        LOGGER.warning("%s: failed: %s", entry.name, entry.error)
    runner_name, stream = runner(todo) if todo else ("no jobs to run", (result for result in ()))  # closable
    count = Count("jobs", len(todo), "jobs/s")
    with contextlib.closing(stream):  # a signal here stops the runner's jobs before it propagates
        for done, result in enumerate(stream, start=1):
            results[result["name"]] = result
            if result["status"] == "ok":
                LOGGER.info("%s: ok (%.1f s)", result["name"], result["seconds"])
            else:
                LOGGER.warning("%s: failed: %s", result["name"], result["error"])
            count.update(done)
    count.close(len(todo))
    wall_s = time.perf_counter() - t0
    ran_ok = sum(r["status"] == "ok" for r in results.values())
    summary = {
        "runner": runner_name, "jobs": len(entries), "ok": ran_ok,
        "failed": sum(r["status"] == "failed" for r in results.values()),
        "skipped": sum(r["status"] == "skipped" for r in results.values()), "wall_s": round(wall_s, 3),
        "jobs_per_hour": round(ran_ok / wall_s * 3600, 1) if ran_ok else 0.0,
        "results": [results[e.name] for e in entries],
    }
    with atomic_output(Path(out_dir) / SUMMARY) as tmp:
        tmp.write_text(json.dumps(summary, indent=2) + "\n")
    return summary


def summary_table(summary: dict) -> str:
    """The summary as a fixed-width text table, one row per job, then the totals."""
    rows = [("job", "kind", "status", "time_s", "result")]
    for r in summary["results"]:
        seconds = "" if r["seconds"] is None else f"{r['seconds']:.1f}"
        rows.append((r["name"], r["kind"] or "-", r["status"], seconds, r["error"] or r["summary"] or ""))
    widths = [max(len(row[i]) for row in rows) for i in range(4)]
    lines = [f"{n:<{widths[0]}}  {k:<{widths[1]}}  {s:<{widths[2]}}  {t:>{widths[3]}}  {res}"
             for n, k, s, t, res in rows]
    lines.append(f"{summary['ok']} ok, {summary['failed']} failed, {summary['skipped']} skipped in "
                 f"{summary['wall_s']:.1f} s ({summary['runner']}, {summary['jobs_per_hour']:g} jobs/h)")
    return "\n".join(lines)


def cmd_batch(args: argparse.Namespace) -> int:
    """``sena-warp batch``: run every job, print the table; BatchError (exit 7) when any failed."""
    # Job keys given on the command line, for every job they apply to (a job list's own win).
    options = {"offset": args.offset, **({"crop": True} if args.crop else {})}
    entries = read_jobs(args.jobs, args.out, args.settings, options)
    runner = ray_runner(args.ray, args.workers or os.cpu_count() or 1) if args.ray else local_runner(args.workers or 1)
    made = not os.path.isdir(args.out)
    out_dir = make_folder(args.out, "--out")  # only once the job list and the runner are known good
    try:
        summary = run_batch(entries, out_dir, runner, args.overwrite)
    except BaseException:
        if made:  # a batch that wrote nothing (Ray refused, a signal before any job ended) leaves no DIR
            with contextlib.suppress(OSError):
                out_dir.rmdir()
        raise
    echo(summary_table(summary))
    if summary["failed"]:
        raise BatchError(f"{summary['failed']} of {summary['jobs']} jobs failed; their reports in "
                         f"{out_dir / REPORTS} say why (run the batch again to retry them)")
    return 0
