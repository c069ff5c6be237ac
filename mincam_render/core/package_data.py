"""Files shipped with the package: scene descriptions, fidelity plans (package data).

They live in the repository's top-level ``scenes/`` folder, the one copy a clone
edits, and are installed as the package ``mincam_render.scene_data``
(``pyproject.toml`` maps the name onto the folder): an editable install reads
the folder itself, a wheel carries it. They are found with
:mod:`importlib.resources`, never relative to this file, so an install works from
any directory.
"""

from __future__ import annotations

import importlib.resources
from pathlib import Path

from mincam_render.core.config import ConfigError

#: The package the shipped descriptions and plans are installed as.
PACKAGE = "mincam_render.scene_data"


def shipped_path(*parts: str) -> Path:
    """The path of a shipped file or folder (``shipped_path("plans")``); may not exist.

    A filesystem path, not only a ``Traversable``: Mitsuba and the plan cache open
    files by name, so an install must unpack its package data (pip does).

    Raises:
        ConfigError: the package data is not installed (an editable install made
            before it existed: run ``bash scripts/setup.sh`` again) or is inside
            a zip archive.
    """
    try:
        root = importlib.resources.files(PACKAGE)
    except ModuleNotFoundError:
        raise ConfigError(
            f"the shipped scene descriptions ({PACKAGE}) are not installed: reinstall "
            "mincam_render (in a clone: bash scripts/setup.sh, or pip install -e .)"
        ) from None
    if not isinstance(root, Path):
        raise ConfigError(f"{PACKAGE} is installed as {root!r}, not as files: install unzipped")
    return root.joinpath(*parts)
