"""One writer per output directory: an advisory lock held for a whole render or training.

``fcntl.flock`` on ``<dir>/.writer.lock`` (standard library, no dependency;
``filelock`` would add Windows support, which Mitsuba's LLVM setup here does
not need). The kernel drops the lock when the holder exits or is killed, so a
killed run never leaves a stale lock behind. The lock file stays in place
(removing it would let two writers lock different files) and stays empty, so
that a resumed dataset is byte-identical to an uninterrupted one. On a network file
system without ``flock`` support the lock may not hold across machines.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
from collections.abc import Iterator
from pathlib import Path

from mincam_render.data.dataset import DatasetError

#: Name of the lock file inside an output directory.
LOCK_NAME = ".writer.lock"


class WriterBusy(DatasetError):
    """Another process is writing into the same output directory."""


@contextlib.contextmanager
def exclusive_writer(directory: str | os.PathLike, what: str) -> Iterator[Path]:
    """Hold the directory's writer lock (creating the directory) for the ``with`` block.

    Args:
        directory: the output directory.
        what: what this writer does (``"render"``, ``"training"``), for messages.

    Raises:
        WriterBusy: another process holds the lock (fails at once, never waits).
        DatasetError: ``directory`` exists and is not a directory.
    """
    out = Path(directory)
    if out.exists() and not out.is_dir():
        raise DatasetError(f"--out {out} exists and is not a directory")
    created = not out.exists()
    out.mkdir(parents=True, exist_ok=True)
    path = out / LOCK_NAME
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise WriterBusy(
                f"{out} is being written by another process; wait for that {what} to finish "
                "or use another --out"
            ) from None
        yield out
    finally:
        os.close(fd)  # releases the lock
        if created and [p.name for p in out.iterdir()] == [LOCK_NAME]:
            path.unlink()  # nothing was written: leave no trace of a failed start
            out.rmdir()
