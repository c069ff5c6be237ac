"""Worker processes: recycling without deadlock, death and stalls named, errors raised again."""

from __future__ import annotations

import os
import time

import pytest

from mincam_render.data.worker_pool import StallWatch, WorkerDied, WorkerStalled, run_tasks


def _pid_of_task(task: int, *, on_progress) -> tuple[int, int]:
    on_progress(1)
    return task, os.getpid()


def _die_at_3(task: int, *, on_progress) -> int:
    if task == 3:
        os._exit(7)
    return task


def _hang_at_2(task: int, *, on_progress) -> int:
    if task == 2:
        time.sleep(60)
    return task


def _raise_at_1(task: int, *, on_progress) -> int:
    if task == 1:
        raise KeyError(f"task {task} has no data")
    return task


def _run(fn, tasks, **kwargs) -> dict[int, object]:
    results: dict[int, object] = {}
    # fork: a spawned worker imports torch and Dr.Jit (2.4 s each); these tasks are
    # plain Python, and the render tests cover spawned workers
    run_tasks(
        fn,
        tasks,
        lambda t: (t,),
        results.__setitem__,
        **{"workers": 2, "tasks_per_worker": 2, "context": "fork", **kwargs},
    )
    return results


def test_more_tasks_than_workers_times_tasks_per_worker_all_finish_in_recycled_workers():
    # 2 workers x 2 tasks each = 4 < 11: CPython 3.11's ProcessPoolExecutor hangs here
    progress: list[tuple[int, int]] = []
    results = _run(_pid_of_task, range(11), on_progress=lambda t, n: progress.append((t, n)))
    assert sorted(results) == list(range(11))
    assert all(task == key for key, (task, _) in results.items())
    pids = [pid for _, pid in results.values()]
    assert max(pids.count(p) for p in set(pids)) <= 2  # no worker ran more than its quota
    assert len(set(pids)) >= 6  # so at least ceil(11 / 2) processes were started
    assert sorted(progress) == [(t, 1) for t in range(11)]


def test_a_worker_that_dies_is_named_with_its_task_and_exit_code():
    with pytest.raises(WorkerDied, match=r"exit code 7\) while running task 3") as info:
        _run(_die_at_3, range(6))
    assert info.value.tasks == [3]


def test_a_stalled_run_stops_at_the_floor_instead_of_waiting_forever():
    t0 = time.monotonic()
    with pytest.raises(WorkerStalled, match=r"while running tasks \[2\]") as info:
        _run(_hang_at_2, range(3), workers=1, stall_floor_s=3.0)
    assert info.value.tasks == [2]
    assert time.monotonic() - t0 < 30  # the task alone would sleep 60 s


def test_a_task_exception_is_raised_again_in_the_parent():
    with pytest.raises(KeyError, match="task 1 has no data"):
        _run(_raise_at_1, range(4))


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"workers": 0}, r"workers = 0: allowed an integer >= 1"),
        ({"tasks_per_worker": 1.5}, r"tasks_per_worker = 1.5: allowed an integer >= 1"),
        ({"stall_floor_s": 0.0}, r"stall_floor_s = 0.0 s: allowed numbers > 0"),
    ],
)
def test_bad_arguments_are_refused(kwargs, message):
    with pytest.raises(ValueError, match=message):
        _run(_pid_of_task, range(2), **kwargs)


def test_the_stall_bound_is_a_multiple_of_the_slowest_task_above_the_floor():
    watch = StallWatch(factor=2.0, floor_s=0.05)
    watch.report(task_s=0.15)  # bound: max(0.05, 2 x 0.15) = 0.3 s
    time.sleep(0.1)
    watch.check(["a"])  # 0.1 s quiet: within the bound
    watch.check([])  # nothing in flight never stalls
    time.sleep(0.25)
    with pytest.raises(WorkerStalled, match=r"bound 0.3 s: 2 x the slowest task so far") as info:
        watch.check(["a", "b"])
    assert info.value.tasks == ["a", "b"]
    watch.report()  # progress resets the clock
    watch.check(["a"])


def test_a_worker_that_dies_while_starting_is_named_instead_of_blocking_on_its_arguments(
    tmp_path, monkeypatch
):
    """Regression: spawn's start-up pipe blocked for ever on large arguments of a dead worker.

    The worker's task function lives in a module that ends any process importing it
    as a spawned child, so the worker dies before it reads its initializer's 8 MB.
    """
    (tmp_path / "dies_when_spawned.py").write_text(
        "import multiprocessing, os\n"
        "if multiprocessing.current_process().name != 'MainProcess':\n"
        "    os._exit(5)\n"
        "def task(t, *, on_progress):\n"
        "    return t\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    from dies_when_spawned import task

    t0 = time.monotonic()
    with pytest.raises(WorkerDied, match=r"exit code 5\) while starting"):
        _run(task, range(2), context="spawn", initializer=len, initargs=(b"x" * (8 << 20),))
    assert time.monotonic() - t0 < 60
