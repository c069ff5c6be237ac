"""How the command line reports an error: one line, exit 2 for bad input, 1 for a failure."""

from __future__ import annotations

import errno

import click


class InputError(click.ClickException):
    """Bad input (an option, a file, a field): exit code 2, like click's own usage errors."""

    exit_code = 2


#: OSError numbers that are the machine's failure, not the user's input.
_MACHINE_ERRNOS = {errno.ENOSPC, errno.EIO, errno.EDQUOT, errno.ENOMEM}


def user_error(err: Exception) -> click.ClickException:
    """One line for an error: bad input (exit 2), or a failure while working (exit 1).

    Bad input: invalid values, files and data (ValueError, KeyError, path errors).
    A failure: a worker or the machine failed (RuntimeError, a full disk), or an
    optional extra is not installed (ImportError).
    """
    failed = isinstance(err, RuntimeError | ImportError) or (
        isinstance(err, OSError) and err.errno in _MACHINE_ERRNOS
    )
    return click.ClickException(str(err)) if failed else InputError(str(err))
