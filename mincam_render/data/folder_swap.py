"""A folder written whole beside its place, then swapped in: nothing stale survives in it.

A writer that owns a folder (an export of printable masks) writes every file
into a fresh hidden sibling, ``.<name>.new-<pid>-<hex>``; only when all are
written does the fresh folder take the folder's place (the old one is renamed
aside, then removed). A reader therefore finds the old folder or the new one,
never a mix: no ``mask_03.png`` of an earlier, larger export beside a
``masks.json`` that lists three masks. A folder holding anything its writer
does not write (files of the user's, other exports' folders) is refused before
anything is written. Siblings left by a killed writer are removed the next time.
"""

from __future__ import annotations

import os
import shutil
import uuid
from collections.abc import Callable
from pathlib import Path
from typing import TypeVar

from mincam_render.data.dataset import fsync_dir

T = TypeVar("T")

#: Infixes of the hidden siblings: the folder being written, the folder being replaced.
_NEW, _OLD = "new", "old"


def swap_in_folder(
    target: str | os.PathLike, write: Callable[[Path], T], owned: Callable[[Path], bool]
) -> T:
    """Write a folder whole with ``write(fresh folder)``, then swap it in for ``target``.

    Args:
        target: the folder to write (its parent is created); an existing one is replaced.
        write: fills the fresh folder it is given; what it returns is returned.
        owned: whether an entry of an existing ``target`` is one this writer
            writes (and may therefore replace).

    Returns:
        What ``write`` returned.

    Raises:
        ValueError: ``target`` is a file, or holds an entry that is not ``owned``
            (nothing is written then).
    """
    target = Path(target)
    if target.exists() and not target.is_dir():
        raise ValueError(f"{target} exists and is not a folder")
    if target.is_dir():
        foreign = sorted(p.name for p in target.iterdir() if not owned(p))
        if foreign:
            shown = ", ".join(foreign[:3]) + (" ..." if len(foreign) > 3 else "")
            raise ValueError(
                f"{target} holds {len(foreign)} entr{'y' if len(foreign) == 1 else 'ies'} "
                f"this writer does not write ({shown}); write into an empty or new folder"
            )
    target.parent.mkdir(parents=True, exist_ok=True)
    _remove_abandoned(target)
    fresh = _sibling(target, _NEW)
    fresh.mkdir()
    try:
        result = write(fresh)
        if target.is_dir():
            old = _sibling(target, _OLD)
            target.rename(old)
            fresh.rename(target)
            shutil.rmtree(old)
        else:
            fresh.rename(target)
    finally:
        if fresh.exists():
            shutil.rmtree(fresh)
    fsync_dir(target.parent)
    return result


def _sibling(target: Path, kind: str) -> Path:
    return target.with_name(f".{target.name}.{kind}-{os.getpid()}-{uuid.uuid4().hex[:8]}")


def _remove_abandoned(target: Path) -> None:
    """Remove the hidden siblings of ``target`` that writers no longer running left."""
    for kind in (_NEW, _OLD):
        for path in target.parent.glob(f".{target.name}.{kind}-*-*"):
            pid = path.name.rsplit("-", 2)[-2]
            if pid.isdigit() and not _alive(int(pid)):
                shutil.rmtree(path, ignore_errors=True)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True  # someone else's
    return True
