"""Local worker processes for ``sena-warp batch --jobs N``: one task at a time each, stopped at once.

Each worker is a fresh Python (``python -m sena_warp.workers MODULE:FUNCTION``) in a session of its
own, so a terminal's Ctrl-C or hang-up reaches the parent alone, and the parent decides: it hands a
worker its next task only when the last one is done, so after a signal no task starts; it sends
SIGTERM to every worker (a running task ends as Ctrl-C ends a command: ``with`` blocks unwind and
its temporaries are removed), gives them :data:`STOP_WAIT_S`, kills what is left and has the
caller remove what those left. A worker whose parent is gone, even by SIGKILL, sees its task pipe
close and stops the same way.

Tasks and results are pickles behind an 8-byte length, on two pipes per worker (tasks in, results out).
"""

from __future__ import annotations

import contextlib
import importlib
import os
import pickle
import queue
import selectors
import signal
import struct
import subprocess
import sys
import threading
import time
from collections import deque
from dataclasses import dataclass
from typing import Callable, Iterator

STOP_WAIT_S = 10.0  # a worker asked to stop gets this long to clean up before SIGKILL
_LENGTH = struct.Struct("!Q")
_END = object()  # the task pipe closed: no more tasks (or the parent is gone)


def _send(fd: int, obj) -> None:
    body = pickle.dumps(obj)
    data = memoryview(_LENGTH.pack(len(body)) + body)
    while data:
        data = data[os.write(fd, data):]


def _read_exactly(fd: int, size: int) -> bytes | None:
    chunks, left = [], size
    while left:
        chunk = os.read(fd, left)
        if not chunk:
            return None
        chunks.append(chunk)
        left -= len(chunk)
    return b"".join(chunks)


def _receive(fd: int):
    """The next object on pipe ``fd``, or :data:`_END` when the writer closed it."""
    header = _read_exactly(fd, _LENGTH.size)
    body = None if header is None else _read_exactly(fd, _LENGTH.unpack(header)[0])
    return _END if body is None else pickle.loads(body)


@dataclass
class _Worker:
    """A worker process as the parent sees it: its pipes' parent ends and the task it is running."""

    process: subprocess.Popen
    tasks_fd: int | None
    results_fd: int
    task: object = None


def _start(function: str) -> _Worker:
    tasks_r, tasks_w = os.pipe()
    results_r, results_w = os.pipe()
    try:
        process = subprocess.Popen([sys.executable, "-m", __name__, function, str(tasks_r), str(results_w)],
                                   pass_fds=(tasks_r, results_w), start_new_session=True,
                                   stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL)  # stdout: results only
    finally:
        os.close(tasks_r)
        os.close(results_w)
    return _Worker(process, tasks_w, results_r)


def _close_tasks(worker: _Worker) -> None:
    """No more tasks for ``worker``: an idle one exits, a busy one stops its task."""
    if worker.tasks_fd is not None:
        os.close(worker.tasks_fd)
        worker.tasks_fd = None


def _why(process: subprocess.Popen) -> str:
    code = process.wait()
    return f"killed by {signal.Signals(-code).name}" if code < 0 else f"exit code {code}"


def run_in_workers(tasks: list, workers: int, function: str, started: Callable[[object], None],
                   cleanup: Callable[[object], None]) -> Iterator[tuple[object, object, str | None]]:
    """Run ``function`` ("module:name", importable by a fresh Python) on each of ``tasks`` in at most
    ``workers`` processes; yield ``(task, result, None)`` as each finishes, or ``(task, None, why)``
    when its worker died (a replacement takes the remaining tasks).

    ``started(task)`` is called as a task is handed to a worker (free to run it at once);
    ``cleanup(task)`` is called for every task whose worker died or was killed while running it,
    once that process is gone (to remove what it left). Leaving the iteration early (an exception
    in the caller, a signal) stops every worker before it returns.
    """
    waiting = deque(tasks)
    pool: dict[int, _Worker] = {}
    selector = selectors.DefaultSelector()

    def give(worker: _Worker) -> None:
        worker.task = waiting.popleft() if waiting else None
        if worker.task is None:
            _close_tasks(worker)
        else:
            started(worker.task)
            with contextlib.suppress(BrokenPipeError):  # it has just died: its results pipe says so next
                _send(worker.tasks_fd, worker.task)

    def start() -> None:
        worker = _start(function)
        pool[worker.results_fd] = worker
        selector.register(worker.results_fd, selectors.EVENT_READ)
        give(worker)

    try:
        for _ in range(min(workers, len(waiting))):
            start()
        while any(worker.task is not None for worker in pool.values()):
            for key, _ in selector.select():
                worker = pool[key.fd]
                result = _receive(worker.results_fd)
                if result is not _END:
                    task = worker.task
                    give(worker)
                    yield task, result, None
                    continue
                selector.unregister(worker.results_fd)
                os.close(worker.results_fd)
                del pool[key.fd]
                _close_tasks(worker)
                why = _why(worker.process)
                if worker.task is not None:
                    cleanup(worker.task)
                    yield worker.task, None, f"worker process ended ({why})"
                if waiting:
                    start()
    finally:
        _stop(list(pool.values()), cleanup)
        selector.close()


def _stop(pool: list[_Worker], cleanup: Callable[[object], None]) -> None:
    """Stop every worker of ``pool``: SIGTERM, up to :data:`STOP_WAIT_S` to finish, then SIGKILL."""
    for worker in pool:
        _close_tasks(worker)
        if worker.task is not None and worker.process.poll() is None:
            worker.process.send_signal(signal.SIGTERM)
    deadline = time.monotonic() + STOP_WAIT_S
    for worker in pool:
        try:
            worker.process.wait(max(deadline - time.monotonic(), 0.0))
        except subprocess.TimeoutExpired:
            worker.process.kill()
            worker.process.wait()
        os.close(worker.results_fd)
        if worker.task is not None:
            cleanup(worker.task)


def worker_main(function: str, tasks_fd: int, results_fd: int) -> int:
    """A worker: run ``function`` on each task read from ``tasks_fd``, its result to ``results_fd``.

    SIGTERM (from the parent, or from itself when the task pipe closes under a running task) ends
    the running task as Ctrl-C would and the worker with 128 + 15; a closed pipe while idle ends it with 0.
    """
    module, name = function.split(":")
    run = getattr(importlib.import_module(module), name)
    busy = threading.Event()
    inbox: queue.Queue = queue.Queue()

    def stop(signum, frame):
        signal.signal(signal.SIGTERM, signal.SIG_IGN)  # once: the clean-up must not be interrupted again
        raise KeyboardInterrupt

    def read_tasks() -> None:
        while (task := _receive(tasks_fd)) is not _END:
            inbox.put(task)
        inbox.put(_END)
        if busy.is_set():  # the parent is gone while a task runs: stop it as the parent would
            os.kill(os.getpid(), signal.SIGTERM)

    signal.signal(signal.SIGTERM, stop)
    threading.Thread(target=read_tasks, name="tasks", daemon=True).start()
    try:
        while (task := inbox.get()) is not _END:
            busy.set()
            result = run(task)
            busy.clear()
            _send(results_fd, result)
    except KeyboardInterrupt:
        return 128 + signal.SIGTERM
    return 0


if __name__ == "__main__":
    sys.exit(worker_main(sys.argv[1], int(sys.argv[2]), int(sys.argv[3])))
