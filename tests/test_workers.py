"""sena_warp.workers: local worker processes that run one task at a time, replace a worker that dies,
stop at once when the caller stops, and die with their parent (batch's signal classes: test_batch.py)."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from sena_warp import workers
from helpers import alive, child_processes

TESTS = Path(__file__).resolve().parent
TASK = "helpers:worker_task"


@pytest.fixture(autouse=True)
def tests_importable(monkeypatch):
    """A worker is a fresh Python: it finds the tests' task module through PYTHONPATH."""
    monkeypatch.setenv("PYTHONPATH", str(TESTS))


def test_each_task_runs_once_and_a_worker_that_dies_fails_its_task_alone(tmp_path):
    cleaned = []
    tasks = [("double", 1), ("die", 3), ("double", 3), ("double", 4), ("die", 0), ("double", 6)]
    started = []
    results = list(workers.run_in_workers(tasks, 2, TASK, started.append, cleaned.append))
    assert sorted(started) == sorted(tasks)  # each said once, as it was handed out
    assert sorted((task, result, why) for task, result, why in results if why is None) == [
        (("double", 1), 2, None), (("double", 3), 6, None), (("double", 4), 8, None), (("double", 6), 12, None)]
    assert sorted((task, why) for task, _, why in results if why is not None) == [
        (("die", 0), "worker process ended (exit code 0)"), (("die", 3), "worker process ended (exit code 3)")]
    assert sorted(cleaned) == [("die", 0), ("die", 3)]


def test_no_more_workers_than_tasks(monkeypatch):
    started = []
    real = workers._start
    monkeypatch.setattr(workers, "_start", lambda function: started.append(function) or real(function))
    assert [r for _, r, _ in workers.run_in_workers([("double", 5)], 1000, TASK, print, print)] == [10]
    assert len(started) == 1


def test_leaving_early_stops_running_tasks_they_leave_nothing_and_no_task_starts(tmp_path):
    cleaned = []
    hold = ("hold", str(tmp_path))
    started = []
    runs = workers.run_in_workers([("double", 1), hold, hold, ("double", 2), ("double", 3)], 2, TASK, started.append,
                                  cleaned.append)
    assert next(runs) == (("double", 1), 2, None)  # its worker now holds the second "hold"
    wait_for(lambda: len([p for p in tmp_path.iterdir() if p.stat().st_size]) == 2)
    runs.close()  # what a signal does to the caller: it leaves the iteration
    assert list(tmp_path.iterdir()) == []  # each task removed its temporary as Ctrl-C ends a command
    assert cleaned == [hold, hold] and started == [("double", 1), hold, hold]  # no task after the stop


PARENT = """
import sys
from sena_warp.workers import run_in_workers
for _ in run_in_workers([("hold", sys.argv[1])] * 2, 2, "helpers:worker_task", print, print):
    pass
"""


def test_workers_die_with_their_parent_even_by_sigkill_and_leave_nothing(tmp_path):
    parent = subprocess.Popen([sys.executable, "-c", PARENT, str(tmp_path)])
    try:
        wait_for(lambda: len([p for p in tmp_path.iterdir() if p.stat().st_size]) == 2)
        pids = child_processes(parent.pid, "sena_warp.workers")
        assert len(pids) == 2
    finally:
        parent.send_signal(signal.SIGKILL)
        parent.wait()
    wait_for(lambda: not any(alive(pid) for pid in pids))
    assert list(tmp_path.iterdir()) == []


def wait_for(condition, timeout_s: float = 120.0) -> None:
    t0 = time.monotonic()
    while not condition():
        assert time.monotonic() - t0 < timeout_s, "timed out"
        time.sleep(0.05)
