"""Full views of a rendered dataset: what an attacker would like to recover from its frames.

For every frame of a dataset, a pinhole image from the camera's pose (its
board centre, looking where it looks, with the masks' field of view) of the
frame's scene state: ``view[frame, row, col]``, luminance radiance
(W/(m^2 sr)), row 0 toward the camera's ``up``. The scene is rebuilt from the
dataset's manifest, so the views show exactly the episode the transport images
were rendered from. Written as ``views_<width>.npy`` plus a JSON sidecar
(settings, sha256) into a directory of the caller's choosing; a finished file
is reused, not rendered again.

With ``people=False`` the same frames are rendered with their people removed
(the door, lights and daylight kept): each frame's *background*, written as
``background_<width>.npy``. Each frame's background is rendered with the same
sampler seed as its view, so a pixel whose light paths never meet a person is
bit-identical in both: the difference view - background is what the people add
(themselves, their shadows, their light on the room) plus the Monte Carlo noise
of the paths that do meet them, not the independent noise of two renders.
"""

from __future__ import annotations

import json
import logging
import os
from pathlib import Path
from typing import Any, NotRequired, TypedDict

import numpy as np

from mincam_render.core.checks import check_int
from mincam_render.data import dataset as ds
from mincam_render.render.capabilities import PeopleRemoval

log = logging.getLogger(__name__)


def view_paths(out_dir: str | os.PathLike, width: int, *, people: bool = True) -> tuple[Path, Path]:
    """``(.npy, sidecar .json)`` of views ``width`` pixels wide in ``out_dir``.

    ``people=False``: of the backgrounds (the frames with their people removed).
    """
    out, stem = Path(out_dir), "views" if people else "background"
    return out / f"{stem}_{width}.npy", out / f"{stem}_{width}.json"


class ViewSettings(TypedDict):
    """What a views sidecar records of how they were made, checked when they are reused.

    ``people`` is ``"removed"`` for backgrounds; views keep the sidecars of
    before backgrounds existed, without it.
    """

    width: int
    spp: int
    dataset_manifest_sha256: str
    people: NotRequired[str]


def _check_settings(width: int, spp: int) -> None:
    check_int("width", width, 1, 1024, unit="px")
    check_int("spp", spp, 1, 1 << 16)


def render_views(
    dataset_dir: str | os.PathLike,
    out_dir: str | os.PathLike,
    *,
    width: int = 64,
    spp: int = 16,
    progress: bool = False,
    people: bool = True,
) -> np.ndarray:
    """Render (or reuse) ``view[frame, row, col]`` (W/(m^2 sr)) of every frame of a dataset.

    Args:
        dataset_dir: a complete dataset (:func:`~mincam_render.data.dataset.open_dataset`).
        out_dir: where ``views_<width>.npy`` and its sidecar go (created).
        width: pixels per side of the square view, [1, 1024].
        spp: samples per pixel, [1, 65536]; the scene's own integrator (its
            ``max_depth``) renders them.
        progress: a progress bar on stderr.
        people: False renders each frame's background instead (module
            docstring), into ``background_<width>.npy``.

    Returns:
        float32 ``[frame, width, width]``; memory-mapped when reused from disk.

    Raises:
        ValueError: bad ``width`` or ``spp``; a sidecar of other settings or
            dataset; ``people=False`` for a family that cannot remove its people.
    """
    _check_settings(width, spp)
    data = ds.open_dataset(dataset_dir)
    npy, meta = view_paths(out_dir, width, people=people)
    settings: ViewSettings = {
        "width": width,
        "spp": spp,
        "dataset_manifest_sha256": ds.sha256_file(Path(dataset_dir) / ds.MANIFEST_NAME),
    }
    if not people:  # views keep their sidecars of before backgrounds existed
        settings["people"] = "removed"
    if npy.is_file() and meta.is_file():
        kept = json.loads(meta.read_text())
        if {k: kept.get(k) for k in settings} != settings:
            raise ValueError(f"{meta}: views of other settings or another dataset; remove them")
        if ds.sha256_file(npy) == kept["sha256"]:
            return np.load(npy, mmap_mode="r")
        log.warning("%s: checksum mismatch; rendering the views again", npy)
    views = _render_all(data, width, spp, progress, people)
    npy.parent.mkdir(parents=True, exist_ok=True)
    ds.atomic_write_bytes(npy, ds.npy_bytes(views))
    record = {**settings, "sha256": ds.sha256_file(npy), "unit": "W/(m^2 sr)",
              "axes": "view[frame, row, col], row 0 toward the camera's up"}  # fmt: skip
    ds.atomic_write_bytes(meta, ds.json_bytes(record))
    return views


def _render_all(data: Any, width: int, spp: int, progress: bool, people: bool) -> np.ndarray:
    """Every frame's view (or background) of ``data`` (numpy float32), the family rebuilt."""
    import mitsuba as mi
    from tqdm import tqdm

    from mincam_render.data.render_job import _load_family
    from mincam_render.render import mitsuba_scene as ms

    family = _load_family(data.manifest["job"])
    remover = family if isinstance(family, PeopleRemoval) else None
    if not (people or remover):
        raise ValueError(f"family {family.name!r} cannot remove its people: no backgrounds")
    camera = data.camera
    scene = family.build_scene()
    sensor = ms.perspective_sensor(
        camera.position, camera.look_at, camera.up, camera.fov_deg, width, width
    )
    views = np.empty((data.num_frames, width, width), np.float32)
    desc = "views" if people else "backgrounds"
    for i in tqdm(range(data.num_frames), desc=desc, unit="frame", disable=not progress):
        if remover is None or people:
            family.set_frame(scene, i)
        else:
            remover.set_frame_without_people(scene, i)
        # the frame's seed for both: untouched paths give bit-identical pixels
        views[i] = np.asarray(mi.render(scene, sensor=sensor, spp=spp, seed=i))[..., 0]
    return views
