"""Worker processes that run tasks, recycled after a few tasks and watched for death and stalls.

Why not :class:`concurrent.futures.ProcessPoolExecutor`: with
``max_tasks_per_child`` it deadlocks on CPython 3.11 (gh-115634: a worker that
exits at its limit is not replaced while a backlog is queued, so the futures
never complete), and ``multiprocessing.Pool`` loses a task silently when its
worker is killed. Here every worker is a process of ours with its own pipe, so
the parent always knows which task each worker holds:

- a worker runs at most ``tasks_per_worker`` tasks and exits; the pool starts a
  fresh one while tasks remain (the memory bound recycling is for);
- a worker that dies holding a task stops the run at once with
  :class:`WorkerDied`, naming the task and the exit code;
- a run in which no worker reports anything (a task's progress or its end) for
  ``max(stall_floor_s, stall_factor x the slowest task so far)`` stops with
  :class:`WorkerStalled` naming the tasks in flight; it never waits forever;
- an exception raised by a task is raised again in the parent.

The initializer's arguments go to each worker through its pipe, not as the
process's arguments: ``spawn`` writes those into a pipe whose read end the parent
keeps open until the write ends, so a worker that died while starting would
leave a large argument (a training set) blocked forever; through the worker's
own pipe its death is a :class:`WorkerDied`.

Workers report progress through a callback ``on_progress(n)`` the task function
receives as a keyword argument; the parent forwards it to its own callback.
"""

from __future__ import annotations

import enum
import logging
import multiprocessing as mp
import os
import signal
import time
import traceback
from collections import deque
from collections.abc import Callable, Hashable, Iterable
from dataclasses import dataclass, field
from multiprocessing.connection import Connection, wait
from typing import Any

from mincam_render.core.checks import check_int

log = logging.getLogger(__name__)

#: A run stalls when no worker reports for this many times the slowest task so far ...
DEFAULT_STALL_FACTOR = 10.0
#: ... and for at least this many seconds (also the bound before any task has finished).
DEFAULT_STALL_FLOOR_S = 900.0
#: Seconds between the parent's checks when no message arrives.
POLL_S = 1.0


class Message(enum.StrEnum):
    """What a worker's message to the parent says: ``(Message, task key, payload)``."""

    PROGRESS = "progress"  # payload: units of the task done since the last report
    ERROR = "error"  # payload: the exception that ended the task (raised again by the parent)
    DONE = "done"  # payload: the task's result


class PoolError(RuntimeError):
    """A task could not finish because of its worker process (see subclasses)."""

    def __init__(self, message: str, tasks: list[Hashable]) -> None:
        super().__init__(message)
        self.tasks = tasks


class WorkerDied(PoolError):
    """A worker process ended while it held a task."""


class WorkerStalled(PoolError):
    """No worker reported progress within the stall bound."""


@dataclass
class _Worker:
    process: Any
    conn: Connection
    task: Hashable | None = None
    started_s: float = 0.0
    tasks_taken: int = 0


@dataclass
class StallWatch:
    """Stops a run in which no worker reported for too long (see the module docstring).

    Args:
        factor: the bound is ``factor`` x the slowest task so far, > 0 ...
        floor_s: ... and at least this many seconds, > 0.
    """

    factor: float = DEFAULT_STALL_FACTOR
    floor_s: float = DEFAULT_STALL_FLOOR_S
    last_report_s: float = field(default_factory=time.monotonic)
    slowest_task_s: float = 0.0

    def __post_init__(self) -> None:
        if not self.factor > 0 or not self.floor_s > 0:
            raise ValueError(
                f"stall_factor = {self.factor!r}, stall_floor_s = {self.floor_s!r} s: "
                "allowed numbers > 0"
            )

    def report(self, task_s: float | None = None) -> None:
        """A worker reported now (a task's progress, or its end after ``task_s`` seconds)."""
        self.last_report_s = time.monotonic()
        if task_s is not None:
            self.slowest_task_s = max(self.slowest_task_s, task_s)

    def check(self, in_flight: list[Hashable]) -> None:
        """Raise :class:`WorkerStalled` if tasks are in flight and the bound has passed."""
        quiet_s = time.monotonic() - self.last_report_s
        bound_s = max(self.floor_s, self.factor * self.slowest_task_s)
        if in_flight and quiet_s > bound_s:
            raise WorkerStalled(
                f"no worker reported for {quiet_s:.3g} s (bound {bound_s:.3g} s: "
                f"{self.factor:g} x the slowest task so far, at least {self.floor_s:g} s) "
                f"while running tasks {in_flight}",
                in_flight,
            )


def threads_per_worker(workers: int) -> int:
    """Threads each of ``workers`` processes may use: the machine's cores shared out, >= 1."""
    return max(1, (os.cpu_count() or 1) // max(1, workers))


def _worker_main(
    conn: Connection,
    fn: Callable[..., Any],
    tasks_per_worker: int,
    initializer: Callable[..., None] | None,
) -> None:
    """Body of a worker process: run up to ``tasks_per_worker`` tasks sent through ``conn``.

    The first message is the initializer's arguments. Ctrl-C (SIGINT, sent to the
    whole terminal's process group) is the parent's to handle: it stops its
    workers itself, so a worker ignores it; a parent that is gone ends the
    worker quietly (:func:`_send`), never with a broken-pipe traceback.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        initargs = conn.recv()
    except EOFError:  # the parent is gone
        return
    if initializer is not None:
        initializer(*initargs)
    for _ in range(tasks_per_worker):
        try:
            message = conn.recv()
        except EOFError:  # the parent is gone
            return
        if message is None:
            return
        key, args = message

        def on_progress(n: int = 1, key: Hashable = key) -> None:
            _send(conn, (Message.PROGRESS, key, n))

        try:
            result = fn(*args, on_progress=on_progress)
        except BaseException as err:  # sent to the parent, which raises it again
            _send(conn, (Message.ERROR, key, _picklable(err)))
            return
        _send(conn, (Message.DONE, key, result))


def _send(conn: Connection, message: tuple) -> None:
    """Send ``message`` to the parent; if the parent is gone, end this worker at once, quietly.

    Nothing a worker holds is worth finishing without its parent (only the parent
    writes files), and an exception here would print a traceback over the
    parent's last line.
    """
    try:
        conn.send(message)
    except OSError:  # BrokenPipeError, ConnectionResetError: the parent ended
        os._exit(0)


def _picklable(err: BaseException) -> BaseException:
    import pickle

    try:
        pickle.dumps(err)
        return err
    except Exception:
        return RuntimeError(f"{type(err).__name__}: {err}\n{traceback.format_exc()}")


def run_tasks(
    fn: Callable[..., Any],
    tasks: Iterable[Hashable],
    args_of: Callable[[Hashable], tuple],
    on_result: Callable[[Hashable, Any], None],
    *,
    workers: int,
    tasks_per_worker: int,
    initializer: Callable[..., None] | None = None,
    initargs: tuple = (),
    on_progress: Callable[[Hashable, int], None] | None = None,
    stall_factor: float = DEFAULT_STALL_FACTOR,
    stall_floor_s: float = DEFAULT_STALL_FLOOR_S,
    context: str = "spawn",
) -> None:
    """Run ``fn(*args_of(task), on_progress=...)`` for every task in worker processes.

    Args:
        fn: a module-level function (it is pickled by reference).
        tasks: task keys, run in this order.
        args_of: the arguments of a task, computed when the task is sent.
        on_result: called in this process with ``(task, result)`` as each task ends.
        workers: worker processes running at once, >= 1.
        tasks_per_worker: tasks a worker runs before it is replaced, >= 1.
        initializer: called once in each new worker, with ``initargs``.
        initargs: the initializer's arguments.
        on_progress: called with ``(task, n)`` when a task reports ``n`` units.
        stall_factor: see the module docstring, > 0.
        stall_floor_s: see the module docstring, seconds > 0.
        context: the multiprocessing start method.

    Raises:
        WorkerDied: a worker ended holding a task.
        WorkerStalled: no report within the stall bound.
        ValueError: invalid arguments.
        Exception: whatever a task raised.
    """
    check_int("workers", workers, 1)
    check_int("tasks_per_worker", tasks_per_worker, 1)
    watch = StallWatch(stall_factor, stall_floor_s)
    ctx: Any = mp.get_context(context)  # BaseContext's stub has no Process
    queued = deque(tasks)
    pool: list[_Worker] = []

    def start() -> _Worker:
        parent, child = ctx.Pipe()
        process = ctx.Process(
            target=_worker_main,
            args=(child, fn, tasks_per_worker, initializer),
            daemon=True,
        )
        process.start()
        child.close()
        return _Worker(process=process, conn=parent)

    try:
        while queued or any(w.task is not None for w in pool):
            started = [start() for _ in range(workers - len(pool))] if queued else []
            pool += started
            for w in started:  # after every start: the workers import at the same time
                _send_initargs(w, initargs)
            for w in pool:
                if w.task is None and queued and w.tasks_taken < tasks_per_worker:
                    w.task, w.started_s = queued.popleft(), time.monotonic()
                    w.tasks_taken += 1
                    w.conn.send((w.task, args_of(w.task)))
            wait([w.conn for w in pool] + [w.process.sentinel for w in pool], timeout=POLL_S)
            for w in list(pool):
                if not _read_messages(w, watch, on_result, on_progress):
                    _retire(w, pool)
            watch.check([w.task for w in pool if w.task is not None])
    finally:
        _shut_down(pool)


def _send_initargs(w: _Worker, initargs: tuple) -> None:
    """Send a new worker its initializer's arguments; :class:`WorkerDied` if it ended first."""
    try:
        w.conn.send(initargs)
    except OSError:  # BrokenPipeError, ConnectionResetError: the worker is gone
        w.process.join()
        raise WorkerDied(
            f"worker process {w.process.pid} ended (exit code {w.process.exitcode}) while starting",
            [],
        ) from None


def _read_messages(
    w: _Worker,
    watch: StallWatch,
    on_result: Callable[[Hashable, Any], None],
    on_progress: Callable[[Hashable, int], None] | None,
) -> bool:
    """Handle every message waiting on a worker's pipe; False once the worker has ended."""
    while True:
        try:
            if not w.conn.poll():
                return w.process.is_alive() or w.conn.poll()
            kind, key, payload = w.conn.recv()
        except (EOFError, OSError):
            return False  # the worker is gone; _retire decides whether that lost a task
        match Message(kind):
            case Message.PROGRESS:
                watch.report()
                if on_progress is not None:
                    on_progress(key, payload)
            case Message.ERROR:
                w.task = None
                raise payload
            case Message.DONE:
                watch.report(time.monotonic() - w.started_s)
                w.task = None
                on_result(key, payload)


def _retire(w: _Worker, pool: list[_Worker]) -> None:
    """Remove an ended worker; raise :class:`WorkerDied` if it held a task."""
    w.process.join()
    w.conn.close()
    pool.remove(w)
    if w.task is not None:
        raise WorkerDied(
            f"worker process {w.process.pid} ended (exit code {w.process.exitcode}) "
            f"while running task {w.task!r}",
            [w.task],
        )


def _shut_down(pool: list[_Worker]) -> None:
    """Ask idle workers to exit; end those holding a task (after an error or an interrupt)."""
    for w in pool:
        try:
            if w.task is None:
                w.conn.send(None)
            else:
                w.process.terminate()
        except (BrokenPipeError, OSError):
            pass
    deadline = time.monotonic() + 5.0
    for w in pool:
        w.process.join(timeout=max(0.0, deadline - time.monotonic()))
        if w.process.is_alive():
            w.process.kill()
            w.process.join(timeout=5.0)
        w.conn.close()
