"""The static backgrounds of a differential job: rendered once, kept as files, loaded per shard.

Components (``backgrounds/component-NNNNN.npy``, converged renders shared
between backgrounds) and each background's ``C``
(``backgrounds/background-NNNNN-same_seed.npy``) are float32 ``[detector, row,
col]`` files (W), written atomically and recorded with their key, seed and
sha256 in the manifest (``background_components``, ``backgrounds``).
"""

from __future__ import annotations

import hashlib
import logging
import time
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from mincam_render.data import dataset as ds
from mincam_render.data.render_job.manifest import _append_log
from mincam_render.data.render_job.scene import _load_family, _render_camera
from mincam_render.render.differential import background_family

if TYPE_CHECKING:
    import mitsuba as mi

    from mincam_render.optics.camera import FreeformCamera
    from mincam_render.render.differential import Background, BackgroundSettings
    from mincam_render.scenes.base import SceneFamily

log = logging.getLogger(__name__)


def background_keys(family: SceneFamily, job: dict) -> list[str]:
    """Background key of every frame of a differential job (frame order)."""
    interval = job["render"]["background"]["interval_s"]
    family_ = background_family(family)
    return [family_.background_key(i, interval) for i in range(job["num_frames"])]


def _first_frames(keys: list[str]) -> dict[str, int]:
    """``{key: first frame}`` of every frame's background key ``keys[frame]``."""
    first_frame: dict[str, int] = {}
    for i, key in enumerate(keys):
        first_frame.setdefault(key, i)
    return first_frame


def _component_path(out: Path, index: int) -> Path:
    return out / ds.BACKGROUND_DIR / f"component-{index:05d}.npy"


def _background_path(out: Path, index: int) -> Path:
    return out / ds.BACKGROUND_DIR / f"background-{index:05d}-same_seed.npy"


def render_backgrounds(
    job: dict, family: SceneFamily, keys: list[str], wanted: list[str]
) -> Iterator[Background]:
    """Render the backgrounds ``wanted`` (keys) of a differential job, in order.

    Args:
        job: the ``job`` section of a manifest.
        family: the job's family (:func:`_load_family`); its scene is built here.
        keys: every frame's background key (:func:`background_keys`).
        wanted: keys to render.

    Yields:
        :class:`~mincam_render.render.differential.Background` per wanted key (components
        shared between them are rendered once).
    """
    from mincam_render.render.differential import BackgroundSettings, render_background

    r = job["render"]
    settings = BackgroundSettings.from_dict(r["background"])
    scene = family.build_scene()
    _, render_cam = _render_camera(job)
    first_frame = _first_frames(keys)
    cache: dict[str, np.ndarray] = {}
    for key in wanted:
        yield render_background(
            background_family(family),
            scene,
            render_cam,
            first_frame[key],
            settings,
            dataset_seed=job["seed"],
            spp=r["spp"],
            max_depth=r["max_depth"] or None,
            component_cache=cache,
        )


def _intact(out: Path, record: dict | None, key: str) -> bool:
    return (
        record is not None
        and record.get("key") == key
        and (out / record["file"]).is_file()
        and ds.sha256_file(out / record["file"]) == record["sha256"]
    )


def _write_array(out: Path, path: Path, array: np.ndarray) -> dict:
    data = ds.npy_bytes(np.asarray(array, dtype="<f4"))
    path.parent.mkdir(parents=True, exist_ok=True)
    ds.atomic_write_bytes(path, data)
    return {"file": f"{ds.BACKGROUND_DIR}/{path.name}", "sha256": hashlib.sha256(data).hexdigest()}


def ensure_backgrounds(
    out: Path, manifest: dict, family: SceneFamily, keys: list[str], *, progress: bool = False
) -> list[str]:
    """Render (in this process) every background file of ``manifest`` missing or corrupt.

    Files and records: see the module docstring; each file is recorded in the
    manifest, which is rewritten, as soon as it is written.

    Args:
        out: dataset directory.
        manifest: its manifest (updated and rewritten after each file).
        family: the job's family.
        keys: every frame's background key (:func:`background_keys`).
        progress: show a progress bar.

    Returns:
        the keys of the components and backgrounds rendered.
    """
    from mincam_render.render.differential import BackgroundSettings

    job = manifest["job"]
    settings = BackgroundSettings.from_dict(job["render"]["background"])
    todo_c, todo_b = _missing_backgrounds(out, manifest)
    if not todo_c and not todo_b:
        return []
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(
            total=len(todo_c) + len(todo_b), unit="render", desc="backgrounds", dynamic_ncols=True
        )
    done: list[str] = []
    try:
        scene = family.build_scene()
        _, render_cam = _render_camera(job)
        for c in todo_c:
            done.append(_render_component(out, manifest, family, scene, render_cam, settings, c))
            if bar is not None:
                bar.update(1)
        first_frame = _first_frames(keys)
        for b in todo_b:
            frame = first_frame[job["backgrounds"][b]]
            done.append(
                _render_same_seed(out, manifest, family, scene, render_cam, settings, b, frame)
            )
            if bar is not None:
                bar.update(1)
    finally:
        if bar is not None:
            bar.close()
    return done


def _missing_backgrounds(out: Path, manifest: dict) -> tuple[list[int], list[int]]:
    """``(components, backgrounds)``: indices whose files are missing or corrupt.

    Logs a warning for each one the manifest records (a file that was written).
    """
    job = manifest["job"]
    components, records = manifest["background_components"], manifest["backgrounds"]
    todo_c = [
        c
        for c, key in enumerate(job["background_components"])
        if not _intact(out, components[c], key)
    ]
    todo_b = [b for b, key in enumerate(job["backgrounds"]) if not _intact(out, records[b], key)]
    for what, todo, table in (("component", todo_c, components), ("background", todo_b, records)):
        for i in todo:
            if table[i] is not None:
                log.warning("%s %d: missing or not matching its sha256; re-rendering it", what, i)
    return todo_c, todo_b


def _render_component(
    out: Path,
    manifest: dict,
    family: SceneFamily,
    scene: mi.Scene,
    render_cam: FreeformCamera,
    settings: BackgroundSettings,
    c: int,
) -> str:
    """Render component ``c``, write its file and record it in the manifest; its key."""
    from mincam_render.render.differential import component_seed, render_component

    job = manifest["job"]
    key = job["background_components"][c]
    array = render_component(
        background_family(family), scene, render_cam, key, settings, dataset_seed=job["seed"]
    )
    record = {"index": c, "key": key, "seed": component_seed(job["seed"], key)}
    components = manifest["background_components"]
    components[c] = record | _write_array(out, _component_path(out, c), array)
    ds.write_manifest(out, manifest)
    return key


def _render_same_seed(
    out: Path,
    manifest: dict,
    family: SceneFamily,
    scene: mi.Scene,
    render_cam: FreeformCamera,
    settings: BackgroundSettings,
    b: int,
    frame: int,
) -> str:
    """Render background ``b``'s ``C`` (first frame ``frame``), write and record it; its key."""
    from mincam_render.render.differential import render_same_seed

    job = manifest["job"]
    r = job["render"]
    key, seed, array = render_same_seed(
        background_family(family),
        scene,
        render_cam,
        frame,
        settings,
        dataset_seed=job["seed"],
        spp=r["spp"],
        max_depth=r["max_depth"] or None,
    )
    record = {"index": b, "key": key, "seed": seed, "components": job["background_parts"][key]}
    records = manifest["backgrounds"]
    records[b] = record | _write_array(out, _background_path(out, b), array)
    ds.write_manifest(out, manifest)
    return key


def load_backgrounds(out: Path, manifest: dict, keys: Iterable[str]) -> dict[str, Background]:
    """``{key: Background}`` for ``keys`` from a dataset's background files."""
    from mincam_render.render.differential import Background, BackgroundSettings

    index = {rec["key"]: rec for rec in manifest["backgrounds"] if rec is not None}
    files = {rec["key"]: rec["file"] for rec in manifest["background_components"] if rec}
    settings = BackgroundSettings.from_dict(manifest["job"]["render"]["background"])
    loaded: dict[str, np.ndarray] = {}
    out_map = {}
    for key in set(keys):
        rec = index.get(key)
        if rec is None or any(part not in files for part in rec["components"]):
            raise ds.DatasetError(f"{out}: background {key!r} has not been rendered")
        for part in rec["components"]:
            if part not in loaded:
                loaded[part] = np.load(out / files[part])
        out_map[key] = Background(
            key=key,
            interval_s=settings.interval_s,
            seed=int(rec["seed"]),
            components={part: loaded[part] for part in rec["components"]},
            same_seed_w=np.load(out / rec["file"]),
            difference_seeds=settings.difference_seeds,
        )
    return out_map


def _shard_backgrounds(out: Path, manifest: dict, progress: bool) -> Callable[[int], dict | None]:
    """``shard -> {key: Background}`` of its frames (rendering missing backgrounds first)."""
    job = manifest["job"]
    if job["render"].get("background") is None:
        return lambda shard: None
    family = _load_family(job)
    keys = background_keys(family, job)
    t0 = time.perf_counter()
    ensure_backgrounds(out, manifest, family, keys, progress=progress)
    _append_log(
        out, {"event": "backgrounds", "seconds": time.perf_counter() - t0, "time": time.time()}
    )
    loaded = load_backgrounds(out, manifest, keys)
    size = job["shard_frames"]

    def of(shard: int) -> dict:
        return {k: loaded[k] for k in set(keys[shard * size : (shard + 1) * size])}

    return of


def converged_backgrounds(out: Path) -> np.ndarray:
    """``B[frame, detector, row, col]`` (W, float32): every frame's converged background.

    The static part of each frame of a differential dataset (the empty room
    with the frame's lights and daylight, from the converged components;
    ``docs/dataset_format.md``), so ``T - B`` is what the frame's people and
    door add, with its render noise. An oracle's input: what a camera could
    read if it knew the background exactly.

    Raises:
        DatasetError: the dataset was not rendered differentially, or a
            background is missing.
    """
    manifest = ds.read_manifest(out)
    job = manifest["job"]
    if job["render"].get("background") is None:
        raise ds.DatasetError(f"{out}: not rendered differentially: no backgrounds to remove")
    family = _load_family(job)
    interval = job["render"]["background"]["interval_s"]
    keys = background_keys(family, job)
    loaded = load_backgrounds(out, manifest, keys)
    components = background_family(family).background_components
    return np.stack(
        [
            loaded[key].converged(components(i, interval)).astype(np.float32)
            for i, key in enumerate(keys)
        ]
    )
