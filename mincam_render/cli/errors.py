"""How the command line reports an error: one line, exit 2 for bad input, 1 for a failure.

A stop signal (SIGTERM, or SIGINT from Ctrl-C) ends any command the same way:
one line, exit code 128 + the signal's number, what was finished kept for the
same command to resume (:func:`stop_on_signals`).
"""

from __future__ import annotations

import errno
import signal
import threading
from types import FrameType

import click


class InputError(click.ClickException):
    """Bad input (an option, a file, a field): exit code 2, like click's own usage errors."""

    exit_code = 2


#: OSError numbers that are the machine's failure, not the user's input.
_MACHINE_ERRNOS = {errno.ENOSPC, errno.EIO, errno.EDQUOT, errno.ENOMEM}


def user_error(err: Exception) -> click.ClickException:
    """One line for an error: bad input (exit 2), or a failure while working (exit 1).

    Bad input: invalid values, files and data (ValueError, KeyError, path errors).
    A failure: a worker or the machine failed (RuntimeError, a full disk, not
    enough memory), or an optional extra is not installed (ImportError).
    """
    if isinstance(err, MemoryError):  # numpy says how much it could not allocate
        return click.ClickException(f"not enough memory: {err}")
    failed = isinstance(err, RuntimeError | ImportError) or (
        isinstance(err, OSError) and err.errno in _MACHINE_ERRNOS
    )
    return click.ClickException(str(err)) if failed else InputError(str(err))


class Stopped(KeyboardInterrupt):
    """A stop signal arrived: raised in the main thread so that every ``finally`` runs.

    A ``KeyboardInterrupt``, so that code written for Ctrl-C (the worker pools'
    shutdown, progress bars, locks) treats SIGTERM alike.
    """

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = signum


#: The signals that stop a command cleanly.
STOP_SIGNALS = (signal.SIGTERM, signal.SIGINT)


def stop_on_signals(ctx: click.Context) -> None:
    """Until ``ctx`` closes, SIGTERM and SIGINT raise :class:`Stopped` (once; then ignored).

    After the first signal the others are ignored while the command unwinds (its
    workers stopped, its files closed), so a second Ctrl-C cannot cut that short.
    Nothing changes outside the main thread, where signals cannot be handled.
    """
    if threading.current_thread() is not threading.main_thread():
        return
    before = {s: signal.getsignal(s) for s in STOP_SIGNALS}

    def stop(signum: int, frame: FrameType | None) -> None:
        for s in STOP_SIGNALS:
            signal.signal(s, signal.SIG_IGN)
        raise Stopped(signum)

    for s in STOP_SIGNALS:
        signal.signal(s, stop)
    ctx.call_on_close(lambda: [signal.signal(s, h) for s, h in before.items()])


def stopped_error(signum: int) -> click.ClickException:
    """The one line of a command ended by signal ``signum`` (exit code 128 + ``signum``)."""
    error = click.ClickException(
        f"stopped by {signal.Signals(signum).name}: what was finished is kept (shards, the "
        "last checkpoint, finished runs); run the same command again to resume"
    )
    error.exit_code = 128 + signum  # type: ignore[misc]  # click declares a class default
    return error
