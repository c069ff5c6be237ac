"""Rendering a dataset: planning shards, worker processes or Ray, resume, progress.

A render is described by a :class:`RenderRequest` (scene family, frames, seed,
sharding, fidelity settings). :func:`render_dataset` turns it into a dataset
directory (format: :mod:`mincam_render.data.dataset`):

1. **Plan.** A new directory gets a manifest with the resolved configuration,
   the fidelity decisions (measured once, :mod:`mincam_render.render.fidelity`) and one
   empty record per shard. An existing directory must hold a manifest of the
   *same* request (compared field by field), whose plan is then reused as is, so
   a resumed render is identical to an uninterrupted one.
2. **Check.** Every shard is verified against its sha256: intact shards are kept
   (never re-rendered); corrupted or truncated ones are re-rendered.
3. **Render.** Missing shards are rendered by worker processes
   (:mod:`mincam_render.data.worker_pool`: ``spawn``; each replaced after a few shards
   so Mitsuba/Dr.Jit memory cannot accumulate; each limited to
   ``cores / workers`` Dr.Jit threads; a worker that dies or stalls stops the
   render with an error naming its shard), in-process (``workers=0``), or
   as Ray tasks (``ray_address``). Workers return arrays; only this process
   writes files, each atomically, then updates the manifest.

Frame ``i`` is rendered with seed :func:`frame_seed` ``(seed, i)`` and the family's
scene state ``i`` (a pure function of ``i``), so any frame re-renders
bit-identically whatever the order, worker count or interruption.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import logging
import math
import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from mincam_render.core.seeds import frame_seed
from mincam_render.data import dataset as ds
from mincam_render.data.writer_lock import LOCK_NAME, exclusive_writer
from mincam_render.render import precision
from mincam_render.render.fidelity import Fidelity, FidelityPlan

log = logging.getLogger(__name__)

#: Shards a local worker process renders before it is replaced by a fresh one.
DEFAULT_SHARDS_PER_WORKER = 4
#: Test hook: seconds to sleep after each frame (slows renders so a test can kill
#: one mid-way). Read by workers from the environment; unset in normal use.
FRAME_DELAY_ENV = "MINCAM_RENDER_TEST_FRAME_DELAY_S"


class RenderError(RuntimeError):
    """A render could not run (worker crash, Ray unavailable)."""


@dataclass(frozen=True, kw_only=True)
class RenderRequest:
    """What to render; equal requests give byte-identical datasets.

    Args:
        family: a family name (``"patches"``) or a scene TOML path.
        num_frames: frames of the sequence, >= 1.
        seed: dataset seed (scene trajectories and frame render seeds), >= 0.
        overrides: nested dict replacing values of the scene description.
        shard_frames: frames per shard file, >= 1.
        splits: train/val/test fractions of the sequence (contiguous).
        fidelity: AUTO measures each choice below that is None; FULL takes the
            expensive option (per-detector, scene integrator, float32, 64 spp).
        spp: samples per texel, or None to decide.
        max_depth: path depth (2 = direct light), 0 = the scene's integrator, or
            None to decide.
        shared_render: one render for all detectors, or None to decide.
        mask_res: mask texels per side, or None for the family camera's.
        dtype: ``"float16"``/``"float32"`` storage, or None to decide.
        target_error: target relative measurement error (Monte Carlo) for spp.
        dtype_error_bound: largest relative measurement error float16 may add.
        indirect_fraction: drop indirect light when it changes measurements less.
        parallax_fraction: share one render when parallax is below this many texels.
        differential: render frames as a converged static background plus the
            change the movers make (:mod:`mincam_render.render.differential`), or None
            to decide (families with a static background only).
        background_interval_s: scene time (s) one background's daylight stands for.
        background_spp: samples per texel of the backgrounds, or None to decide.
        shared_difference: render the movers' change once from the board centre
            for all detectors, or None to decide (differential rendering).
    """

    family: str
    num_frames: int
    seed: int = 0
    overrides: dict | None = None
    shard_frames: int = 256
    splits: tuple[float, float, float] = (0.7, 0.15, 0.15)
    fidelity: Fidelity = Fidelity.AUTO
    spp: int | None = None
    max_depth: int | None = None
    shared_render: bool | None = None
    mask_res: int | None = None
    dtype: str | None = None
    target_error: float = 0.01
    dtype_error_bound: float = 1e-3
    indirect_fraction: float = 0.005
    parallax_fraction: float = 0.25
    differential: bool | None = None
    background_interval_s: float = 60.0
    background_spp: int | None = None
    shared_difference: bool | None = None

    def __post_init__(self) -> None:
        def bad(name: str, allowed: str) -> ValueError:
            return ValueError(
                f"RenderRequest.{name} = {getattr(self, name)!r} is invalid: allowed {allowed}"
            )

        def is_int(v: Any) -> bool:
            return isinstance(v, int) and not isinstance(v, bool)

        if not is_int(self.num_frames) or self.num_frames < 1:
            raise bad("num_frames", "an integer >= 1")
        if not is_int(self.seed) or not 0 <= self.seed < 2**63:
            raise bad("seed", "an integer in [0, 2^63)")
        if not is_int(self.shard_frames) or not 1 <= self.shard_frames <= 1 << 20:
            raise bad("shard_frames", "an integer in [1, 2^20]")
        ds.split_ranges(self.num_frames, self.splits)
        object.__setattr__(self, "splits", tuple(float(f) for f in self.splits))
        object.__setattr__(self, "fidelity", Fidelity(self.fidelity))
        if self.spp is not None and (not is_int(self.spp) or not 1 <= self.spp <= 1 << 20):
            raise bad("spp", "None or an integer in [1, 2^20]")
        if self.max_depth is not None and (
            not is_int(self.max_depth) or not 0 <= self.max_depth <= 64
        ):
            raise bad("max_depth", "None, 0 (scene integrator) or an integer in [1, 64]")
        if self.mask_res is not None and (
            not is_int(self.mask_res) or not 1 <= self.mask_res <= 4096
        ):
            raise bad("mask_res", "None or an integer in [1, 4096]")
        if self.background_spp is not None and (
            not is_int(self.background_spp) or not 1 <= self.background_spp <= 1 << 20
        ):
            raise bad("background_spp", "None or an integer in [1, 2^20]")
        for name in ("differential", "shared_difference"):
            if getattr(self, name) is not None and not isinstance(getattr(self, name), bool):
                raise bad(name, "None, True or False")
        if self.dtype is not None and self.dtype not in precision.DTYPES:
            raise bad("dtype", f"None or one of {', '.join(precision.DTYPES)}")
        for name, lo, hi in (
            ("target_error", 1e-6, 1.0),
            ("dtype_error_bound", 1e-9, 1.0),
            ("indirect_fraction", 0.0, 1.0),
            ("parallax_fraction", 0.0, 100.0),
            ("background_interval_s", 1e-3, 1e6),
        ):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | float) or not lo <= v <= hi:
                raise bad(name, f"a number in [{lo:g}, {hi:g}]")

    def identity(self, description: dict) -> dict:
        """JSON-ready identity: the request with the *resolved* scene description.

        Two renders into one directory must have equal identities; the resolved
        description (not the file name) makes an edited TOML count as different.
        """
        d = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        d["family"] = str(self.family)
        d["fidelity"] = self.fidelity.value
        d["splits"] = list(self.splits)
        d["overrides"] = self.overrides or {}
        d["description"] = description
        return json.loads(json.dumps(d, sort_keys=True, default=ds._json_default))


@dataclass
class RenderSummary:
    """What a call of :func:`render_dataset` did."""

    path: Path
    num_frames: int
    shards_total: int
    shards_rendered: list[int]
    shards_kept: list[int]
    shards_repaired: list[int]
    seconds: float
    frames_per_s: float


def package_versions() -> dict[str, str]:
    """Versions of the packages that determine the output, and the git revision."""
    import importlib.metadata as md
    import subprocess

    out = {}
    for name in ("mitsuba", "drjit", "torch", "numpy", "mincam_render"):
        try:
            out[name] = md.version(name)
        except md.PackageNotFoundError:
            out[name] = "not installed"
    try:
        repo = Path(__file__).resolve().parents[1]
        rev = subprocess.run(
            ["git", "-C", str(repo), "rev-parse", "HEAD"],
            capture_output=True,
            text=True,
            timeout=10,
            check=True,
        ).stdout.strip()
        out["git_revision"] = rev or "unknown"
    except (OSError, subprocess.SubprocessError):
        out["git_revision"] = "unknown"
    return out


# ---- family construction (parent and workers) ----------------------------------------


def _load_family(job: dict):
    """The scene family of a job, rebuilt from the manifest's resolved description."""
    from mincam_render.core.config import parse
    from mincam_render.scenes.registry import family_class, load_family

    fam = job["family"]
    if fam.get("rebuild_from_description", True):
        cls = family_class(fam["name"])
        config = parse(cls.config_type, fam["description"], source="manifest")
        return cls(config, seed=job["seed"], num_frames=job["num_frames"])
    return load_family(
        fam["source"], seed=job["seed"], num_frames=job["num_frames"], overrides=fam["overrides"]
    )


def _render_camera(job: dict):
    """``(camera of the dataset, camera actually rendered)``; they differ for shared renders."""
    camera = ds.camera_from_dict(job["camera"])
    if job["render"]["shared_render"]:
        # one representative detector at the board centre, replicated to all K
        return camera, camera.centre_camera()
    return camera, camera


# ---- worker side -----------------------------------------------------------------------

_WORKER: dict[str, Any] = {"parent": None, "cache": {}}


def _worker_init(threads: int, parent_pid: int | None) -> None:
    """Initializer of a worker process: limit Dr.Jit threads, remember the parent."""
    import drjit as dr

    from mincam_render.render.backend import use_variant

    use_variant()
    dr.set_thread_count(max(1, int(threads)))
    _WORKER["parent"] = parent_pid


def render_shard(
    job: dict,
    shard: int,
    backgrounds: dict | None = None,
    on_progress: Callable[[int], None] | None = None,
) -> tuple[int, np.ndarray, dict, float]:
    """Render one shard of a job (in whatever process calls it).

    Args:
        job: the ``job`` section of a manifest (family, camera, render settings).
        shard: shard number.
        backgrounds: for differentially rendered jobs, ``{key: Background}``
            covering the shard's frames (see :func:`load_backgrounds`).
        on_progress: called with 1 after each frame.

    Returns:
        ``(shard, stored T[frame, detector, row, col], shard metadata, seconds)``.

    Raises:
        ValueError: a differential job without the shard's backgrounds.
    """
    from mincam_render.render.backend import use_variant
    from mincam_render.render.differential import render_frame

    use_variant()
    t0 = time.perf_counter()
    key = job["request_sha256"]
    cached = _WORKER["cache"].get(key)
    if cached is None:
        _WORKER["cache"].clear()  # one job per process: free the previous scene
        family = _load_family(job)
        cached = (family, family.build_scene(), *_render_camera(job))
        _WORKER["cache"][key] = cached
    family, scene, camera, render_cam = cached
    r = job["render"]
    start = shard * job["shard_frames"]
    stop = min(job["num_frames"], start + job["shard_frames"])
    max_depth = r["max_depth"] or None
    delay = float(os.environ.get(FRAME_DELAY_ENV, "0") or 0)
    k = camera.num_detectors
    frames, images = [], []
    labels: dict[str, list] = {s.name: [] for s in family.labels}
    for i in range(start, stop):
        if _WORKER["parent"] is not None and os.getppid() != _WORKER["parent"]:
            os._exit(1)  # the render was killed: do not linger as an orphan
        background = None
        if r.get("background") is not None:
            key = family.background_key(i, r["background"]["interval_s"])
            background = (backgrounds or {}).get(key)
            if background is None:
                raise ValueError(f"frame {i}: background {key!r} was not given to render_shard")
            t, lab = render_frame(
                family, scene, render_cam, i, background, spp=r["spp"], max_depth=max_depth
            )
            seed = background.seed
        else:
            lab = family.set_frame(scene, i)
            seed = frame_seed(job["seed"], i)
            t = family.render_transport(
                scene, render_cam, spp=r["spp"], seed=seed, max_depth=max_depth
            )
        if r["shared_render"]:
            t = np.repeat(t, k, axis=0)
        images.append(t)
        for name in labels:
            labels[name].append(np.asarray(lab[name], dtype=np.float32).reshape(-1).tolist())
        record = {"index": i, "time_s": family.time_s(i), "seed": seed}
        if background is not None:
            record["background"] = background.key
        frames.append(dict(record, state=family.frame_state(i)))
        if on_progress is not None:
            on_progress(1)
        if delay:
            time.sleep(delay)
    stored, scales = precision.encode_transport(np.stack(images), r["dtype"])
    for f, s in zip(frames, scales, strict=True):
        f["scale"] = float(s)
    meta = {
        "format": ds.FORMAT_NAME,
        "format_version": ds.FORMAT_VERSION,
        "request_sha256": key,
        "shard": shard,
        "start": start,
        "stop": stop,
        "dtype": r["dtype"],
        "shape": list(stored.shape),
        "frames": frames,
        "labels": labels,
    }
    # JSON round trip now, so the parent writes exactly what a reader will parse
    meta = json.loads(json.dumps(meta, default=ds._json_default))
    return shard, stored, meta, time.perf_counter() - t0


def _ray_render_shard(job: dict, shard: int, threads: int, backgrounds: dict | None):
    import drjit as dr

    from mincam_render.render.backend import use_variant

    use_variant()
    dr.set_thread_count(max(1, int(threads)))
    return render_shard(job, shard, backgrounds)


# ---- backgrounds (differential rendering) ------------------------------------------------


def background_keys(family, job: dict) -> list[str]:
    """Background key of every frame of a differential job (frame order)."""
    interval = job["render"]["background"]["interval_s"]
    return [family.background_key(i, interval) for i in range(job["num_frames"])]


def _component_path(out: Path, index: int) -> Path:
    return out / ds.BACKGROUND_DIR / f"component-{index:05d}.npy"


def _background_path(out: Path, index: int) -> Path:
    return out / ds.BACKGROUND_DIR / f"background-{index:05d}-same_seed.npy"


def render_backgrounds(job: dict, family, keys: list[str], wanted: list[str]):
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
    first_frame: dict[str, int] = {}
    for i, key in enumerate(keys):
        first_frame.setdefault(key, i)
    cache: dict[str, np.ndarray] = {}
    for key in wanted:
        yield render_background(
            family,
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
    out: Path, manifest: dict, family, keys: list[str], *, progress: bool = False
) -> list[str]:
    """Render (in this process) every background file of ``manifest`` missing or corrupt.

    Components (``backgrounds/component-NNNNN.npy``, converged renders shared
    between backgrounds) and each background's ``C``
    (``backgrounds/background-NNNNN-same_seed.npy``) are float32 ``[detector,
    row, col]`` files written atomically and recorded with their key, seed and
    sha256 in ``manifest["background_components"]`` and
    ``manifest["backgrounds"]``.

    Args:
        out: dataset directory.
        manifest: its manifest (updated and rewritten after each file).
        family: the job's family.
        keys: every frame's background key (:func:`background_keys`).
        progress: show a progress bar.

    Returns:
        the keys of the components and backgrounds rendered.
    """
    from mincam_render.render.differential import (
        BackgroundSettings,
        component_seed,
        render_component,
        render_same_seed,
    )

    job = manifest["job"]
    r = job["render"]
    settings = BackgroundSettings.from_dict(r["background"])
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
    if not todo_c and not todo_b:
        return []
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(
            total=len(todo_c) + len(todo_b), unit="render", desc="backgrounds", dynamic_ncols=True
        )
    done = []
    try:
        scene = family.build_scene()
        _, render_cam = _render_camera(job)
        for c in todo_c:
            key = job["background_components"][c]
            array = render_component(
                family, scene, render_cam, key, settings, dataset_seed=job["seed"]
            )
            record = {"index": c, "key": key, "seed": component_seed(job["seed"], key)}
            components[c] = record | _write_array(out, _component_path(out, c), array)
            ds.write_manifest(out, manifest)
            done.append(key)
            if bar is not None:
                bar.update(1)
        first_frame: dict[str, int] = {}
        for i, key in enumerate(keys):
            first_frame.setdefault(key, i)
        for b in todo_b:
            key, seed, array = render_same_seed(
                family,
                scene,
                render_cam,
                first_frame[job["backgrounds"][b]],
                settings,
                dataset_seed=job["seed"],
                spp=r["spp"],
                max_depth=r["max_depth"] or None,
            )
            record = {
                "index": b,
                "key": key,
                "seed": seed,
                "components": job["background_parts"][key],
            }
            records[b] = record | _write_array(out, _background_path(out, b), array)
            ds.write_manifest(out, manifest)
            done.append(key)
            if bar is not None:
                bar.update(1)
    finally:
        if bar is not None:
            bar.close()
    return done


def load_backgrounds(out: Path, manifest: dict, keys) -> dict:
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
        )
    return out_map


# ---- planning ----------------------------------------------------------------------------


def _describe_family(request: RenderRequest):
    """``(family, description dict, rebuild flag)`` for a request."""
    from mincam_render.core.config import parse, to_dict
    from mincam_render.scenes.registry import load_family

    family = load_family(
        request.family,
        seed=request.seed,
        num_frames=request.num_frames,
        overrides=request.overrides,
    )
    description = json.loads(json.dumps(to_dict(family.config), default=ds._json_default))
    try:
        rebuilt = parse(type(family.config), description, source="manifest")
        rebuild = rebuilt == family.config
    except ValueError:
        rebuild = False
    return family, description, rebuild


def plan_render(
    request: RenderRequest, *, use_cache: bool = True, ship: bool = False, progress: bool = False
) -> dict:
    """The manifest of a new render: configuration, fidelity decisions, empty shards.

    The fidelity plan comes from :mod:`mincam_render.data.plan_cache` when one is kept
    for the request's description, camera, targets and frame count; otherwise it is
    measured (a few small renders of the planning episode) and kept in the user's
    cache. Writes nothing else.

    Args:
        request: what to render.
        use_cache: look up and keep plans; False always measures (and keeps nothing).
        ship: measure the plan and write it among the shipped plans
            (``scenes/plans/``, :mod:`mincam_render.data.plan_cache`).
        progress: show a progress bar while the plan is measured.
    """
    from mincam_render.render import backend
    from mincam_render.render.differential import background_parts

    backend.use_variant()
    family, description, rebuild = _describe_family(request)
    identity = request.identity(description)
    request_sha = hashlib.sha256(ds.json_bytes(identity)).hexdigest()
    base_camera = family.camera()
    if request.mask_res is not None:
        base_camera = dataclasses.replace(
            base_camera, mask_resolution=(request.mask_res, request.mask_res)
        )
    plan = _fidelity_plan(
        request, family.name, identity, base_camera, use_cache and not ship, ship, progress
    )
    camera = base_camera
    num_shards = -(-request.num_frames // request.shard_frames)
    job = {
        "request_sha256": request_sha,
        "family": {
            "name": family.name,
            "source": str(request.family),
            "overrides": request.overrides or {},
            "description": description,
            "rebuild_from_description": rebuild,
        },
        "seed": request.seed,
        "num_frames": request.num_frames,
        "shard_frames": request.shard_frames,
        "camera": ds.camera_to_dict(camera),
        "render": {
            "spp": plan.spp,
            "max_depth": plan.max_depth,
            "shared_render": plan.shared_render,
            "mask_resolution": plan.mask_resolution,
            "dtype": plan.dtype,
            "background": plan.background,
        },
    }
    backgrounds = components = None
    if plan.background is not None:
        parts = background_parts(family, job["num_frames"], plan.background["interval_s"])
        job["backgrounds"] = list(parts)
        job["background_parts"] = parts
        job["background_components"] = list(dict.fromkeys(c for p in parts.values() for c in p))
        backgrounds = [None] * len(job["backgrounds"])
        components = [None] * len(job["background_components"])
    info = backend.describe()
    return {
        "format": ds.FORMAT_NAME,
        "format_version": ds.FORMAT_VERSION,
        "request": identity,
        "family": {
            "name": family.name,
            "fps": float(family.fps),
            "needs_history": bool(family.needs_history),
            "description": description,
        },
        "num_frames": request.num_frames,
        "shard_frames": request.shard_frames,
        "num_shards": num_shards,
        "splits": {
            k: list(v) for k, v in ds.split_ranges(request.num_frames, request.splits).items()
        },
        "camera": job["camera"],
        "label_specs": [ds.label_spec_to_dict(s) for s in family.labels],
        "fidelity": plan.decisions,
        "job": job,
        "transport": {
            "units": "W per unit transmittance",
            "axes": "T[frame, detector, row, col]; row 0 = up side of the view, col 0 = left",
            "stored_as": "stored * scale = T, scale a per-frame power of two (frames[i].scale)",
            "dtype": plan.dtype,
        },
        "frame_seed": "splitmix64(splitmix64(seed) ^ index) & (2^63 - 1)",
        "variant": info["variant"],
        "versions": package_versions(),
        "shards": [None] * num_shards,
        "backgrounds": backgrounds,
        "background_components": components,
        "complete": False,
    }


def _fidelity_plan(
    request: RenderRequest,
    family_name: str,
    identity: dict,
    camera,
    use_cache: bool,
    ship: bool,
    progress: bool,
) -> FidelityPlan:
    """The fidelity plan of a request: kept, or measured on the planning episode."""
    from mincam_render.data import plan_cache
    from mincam_render.render import backend
    from mincam_render.render.fidelity import decide_fidelity

    info = backend.describe()
    versions = package_versions()
    renderer = {"variant": info["variant"], **{k: versions[k] for k in ("mitsuba", "drjit")}}
    fields = plan_cache.plan_fields(identity, family_name, renderer)
    found = plan_cache.find_plan(fields) if use_cache else None
    if found is not None:
        plan, where = found
        log.info("fidelity plan %s (%s)", plan_cache.plan_key(fields)[:12], where)
        return FidelityPlan.from_dict(plan["settings"], plan["decisions"])
    t0 = time.perf_counter()
    plan_request = dataclasses.replace(request, seed=plan_cache.PLAN_SEED)
    family, _, _ = _describe_family(plan_request)
    measured = decide_fidelity(family, camera, plan_request, progress=progress)
    decisions = measured.decisions
    decisions["planning_episode"] = {"seed": plan_cache.PLAN_SEED, "frames": request.num_frames}
    # measured figures are reported to 6 significant digits: last-bit differences
    # of floating-point sums between two planning runs must not change the bytes
    # of otherwise identical manifests; the JSON round trip makes a fresh plan
    # equal to a kept one
    plan = json.loads(
        json.dumps({"settings": measured.settings(), "decisions": _rounded(decisions)})
    )
    seconds = time.perf_counter() - t0
    log.info("fidelity planned in %.1f s", seconds)
    if use_cache or ship:
        try:
            plan_cache.store_plan(fields, plan, seconds, plan_cache.SHIPPED_DIR if ship else None)
        except OSError as err:
            log.warning("could not keep the fidelity plan in %s: %s", plan_cache.cache_dir(), err)
    return FidelityPlan.from_dict(plan["settings"], plan["decisions"])


def _identity_diff(old: dict, new: dict, prefix: str = "") -> list[str]:
    diffs = []
    for key in sorted(set(old) | set(new)):
        a, b = old.get(key, "<absent>"), new.get(key, "<absent>")
        if isinstance(a, dict) and isinstance(b, dict):
            diffs += _identity_diff(a, b, f"{prefix}{key}.")
        elif a != b:
            diffs.append(f"{prefix}{key}: {a!r} (on disk) != {b!r} (now)")
    return diffs


def _rounded(obj: Any, digits: int = 6) -> Any:
    """``obj`` with every float rounded to ``digits`` significant digits (recursively)."""
    if isinstance(obj, float):
        return float(f"{obj:.{digits}g}") if math.isfinite(obj) else obj
    if isinstance(obj, dict):
        return {k: _rounded(v, digits) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return type(obj)(_rounded(v, digits) for v in obj)
    return obj


def _open_or_plan(
    request: RenderRequest, out: Path, use_plan_cache: bool, progress: bool = False
) -> dict:
    """Reuse the manifest of ``out`` if it is the same request; plan a new one if empty."""
    manifest_path = out / ds.MANIFEST_NAME
    if out.exists() and not out.is_dir():
        raise ds.DatasetError(f"--out {out} exists and is not a directory")
    if manifest_path.is_file():
        manifest = ds.read_manifest(out)
        if manifest.get("format_version", 0) != ds.FORMAT_VERSION:
            raise ds.DatasetError(
                f"{out} was rendered by another mincam_render (dataset format version "
                f"{manifest.get('format_version', 0)}, this one writes {ds.FORMAT_VERSION}); "
                "it can be read but not resumed: render into another --out directory"
            )
        _, description, _ = _describe_family(request)
        identity = request.identity(description)
        if manifest["request"] != identity:
            diffs = _identity_diff(manifest["request"], identity)
            raise ds.DatasetError(
                f"{out} holds a dataset rendered with a different configuration "
                f"({'; '.join(diffs[:3])}{' ...' if len(diffs) > 3 else ''}); "
                "render into another --out directory or delete this one"
            )
        versions = package_versions()
        if versions != manifest["versions"]:
            log.warning(
                "resuming a dataset started with other package versions %s (now %s)",
                manifest["versions"],
                versions,
            )
        return manifest
    if out.is_dir() and any(p.name != LOCK_NAME for p in out.iterdir()):
        raise ds.DatasetError(
            f"{out} is not empty and holds no {ds.MANIFEST_NAME}; refusing to render into it"
        )
    t0 = time.perf_counter()
    manifest = plan_render(request, use_cache=use_plan_cache, progress=progress)
    (out / ds.SHARD_DIR).mkdir(parents=True, exist_ok=True)
    ds.write_manifest(out, manifest)
    _append_log(out, {"event": "planned", "seconds": time.perf_counter() - t0, "time": time.time()})
    return manifest


# ---- running -----------------------------------------------------------------------------


def _append_log(out: Path, entry: dict) -> None:
    with open(out / ds.LOG_NAME, "a") as f:
        f.write(json.dumps(entry, default=ds._json_default) + "\n")


#: A worker pool pays off when the shards left would take this process longer than
#: this (s). Measured on 2 cores (benchmarks/bench_workers.py, first run with 20 s):
#: a pool renders about 1.6x faster but costs 1.6 s (patches) to 3.5 s (workspace) to
#: start, so it wins beyond about 2.7x its start-up: 4 s (patches), 9 s (workspace).
POOL_BREAK_EVEN_S = 10.0


def _first_shard_then_choose(
    job, todo, frames_of, finish, bar, backgrounds_of
) -> tuple[int, list[int]]:
    """Render ``todo[0]`` here, then ``(workers, rest)``: a pool only for long remainders.

    The time per frame is taken from the shard's frames after its first (which
    pays for compiling the kernels) when it has more than one.
    """
    stamps = []

    def on_frame(n: int) -> None:
        stamps.append(time.perf_counter())
        if bar is not None:
            bar.update(n)

    first, rest = todo[0], list(todo[1:])
    t0 = time.perf_counter()
    finish(render_shard(job, first, backgrounds_of(first), on_frame), True)
    per_frame = (
        (stamps[-1] - stamps[0]) / (len(stamps) - 1)
        if len(stamps) > 1
        else time.perf_counter() - t0
    )
    left_s = per_frame * sum(frames_of[i] for i in rest)
    workers = (os.cpu_count() or 1) if left_s > POOL_BREAK_EVEN_S and len(rest) > 1 else 0
    log.info(
        "workers: %.3g s per frame, about %.0f s left in this process -> %s",
        per_frame,
        left_s,
        f"{workers} worker processes" if workers else "this process",
    )
    return workers, rest


def _threads_per_worker(workers: int) -> int:
    cores = os.cpu_count() or 1
    return max(1, cores // max(1, workers))


def render_dataset(
    request: RenderRequest,
    out: str | os.PathLike,
    *,
    workers: int | None = 1,
    ray_address: str | None = None,
    progress: bool = False,
    shards_per_worker: int = DEFAULT_SHARDS_PER_WORKER,
    use_plan_cache: bool = True,
) -> RenderSummary:
    """Render (or finish) the dataset of ``request`` into directory ``out``.

    Args:
        request: what to render.
        out: dataset directory; created, or resumed if it holds the same request.
        workers: local worker processes (>= 1), 0 to render in this process, or None to
            choose by job size: the first shard renders in this process, and a pool of
            one worker per core takes the rest only if this process would need more than
            :data:`POOL_BREAK_EVEN_S` for it (:func:`_first_shard_then_choose`).
        ray_address: run shards as Ray tasks on this cluster (``"local"`` starts a
            single-node cluster, ``"auto"`` joins the running one); needs the
            ``ray`` extra. ``workers`` is then ignored.
        progress: show a tqdm progress bar (frames/s, ETA) on stderr.
        shards_per_worker: shards a worker process renders before it is replaced.
        use_plan_cache: reuse a kept fidelity plan of the same description, camera,
            targets and frame count (:mod:`mincam_render.data.plan_cache`), and keep a
            new one; False measures the plan again.

    Returns:
        A :class:`RenderSummary`.

    Raises:
        DatasetError: ``out`` holds another configuration or is not a dataset.
        RenderError: a worker died or Ray is unavailable.
        ValueError: invalid arguments.
    """
    if workers is not None and (
        isinstance(workers, bool) or not isinstance(workers, int) or not 0 <= workers <= 256
    ):
        raise ValueError(f"workers = {workers!r}: allowed None (auto) or an integer in [0, 256]")
    if not isinstance(shards_per_worker, int) or shards_per_worker < 1:
        raise ValueError(f"shards_per_worker = {shards_per_worker!r}: allowed an integer >= 1")
    with exclusive_writer(out, "render") as out:
        t_start = time.perf_counter()
        manifest = _open_or_plan(request, out, use_plan_cache, progress)
        for tmp in ds.remove_stale_temporaries(out):
            log.info("removed %s, left by a killed render", tmp)
        (out / ds.SHARD_DIR).mkdir(parents=True, exist_ok=True)
        job = manifest["job"]
        num_shards = manifest["num_shards"]

        kept, repaired, todo = [], [], []
        changed = False
        for i in range(num_shards):
            rec = manifest["shards"][i]
            found, reason = ds.verify_shard(out, i, rec)
            if found is not None and rec is None:
                # finished by a previous run that was killed before updating the manifest
                meta = json.loads(ds.shard_paths(out, i)[1].read_text())
                if meta.get("request_sha256") != job["request_sha256"]:
                    found, reason = None, "belongs to another configuration"
            if found is not None:
                kept.append(i)
                if rec != found:
                    manifest["shards"][i] = found
                    changed = True
                continue
            if rec is not None or reason != "missing":
                log.warning("shard %d: %s; re-rendering it", i, reason)
                repaired.append(i)
                manifest["shards"][i] = None
                changed = True
            todo.append(i)
        if changed or (not todo and not manifest["complete"]):
            manifest["complete"] = not todo
            ds.write_manifest(out, manifest)

        frames_of = {
            i: min(job["num_frames"], (i + 1) * job["shard_frames"]) - i * job["shard_frames"]
            for i in range(num_shards)
        }
        backgrounds_of = _shard_backgrounds(out, manifest, progress) if todo else (lambda i: None)
        done_frames = sum(frames_of[i] for i in kept)
        _append_log(
            out,
            {
                "event": "start",
                "pid": os.getpid(),
                "time": time.time(),
                "kept": kept,
                "repaired": repaired,
                "todo": todo,
                "workers": workers,
                "ray": ray_address,
            },
        )
        bar = None
        if progress and todo:
            from tqdm import tqdm

            bar = tqdm(
                total=job["num_frames"],
                initial=done_frames,
                unit="frame",
                desc=f"render {out.name}",
                dynamic_ncols=True,
                smoothing=0.1,
            )

        rendered: list[int] = []

        def finish(result: tuple[int, np.ndarray, dict, float], per_frame_progress: bool) -> None:
            shard, stored, meta, seconds = result
            record = ds.write_shard(out, shard, stored, meta)
            manifest["shards"][shard] = record
            manifest["complete"] = all(s is not None for s in manifest["shards"])
            ds.write_manifest(out, manifest)
            rendered.append(shard)
            _append_log(
                out,
                {
                    "event": "shard",
                    "shard": shard,
                    "frames": [meta["start"], meta["stop"]],
                    "seconds": seconds,
                    "pid": os.getpid(),
                    "time": time.time(),
                },
            )
            if bar is not None and not per_frame_progress:
                bar.update(meta["stop"] - meta["start"])

        try:
            if not todo:
                pass
            elif ray_address is not None:
                _run_ray(ray_address, job, todo, finish, shards_per_worker, backgrounds_of)
            else:
                if workers is None:
                    workers, todo = _first_shard_then_choose(
                        job, todo, frames_of, finish, bar, backgrounds_of
                    )
                    _append_log(out, {"event": "workers", "workers": workers, "time": time.time()})
                if workers == 0:
                    on_frame = None if bar is None else bar.update
                    for i in todo:
                        shard = render_shard(job, i, backgrounds_of(i), on_frame)
                        finish(shard, on_frame is not None)
                elif todo:
                    _run_processes(
                        job, todo, finish, workers, shards_per_worker, bar, backgrounds_of
                    )
        finally:
            if bar is not None:
                bar.close()
        seconds = time.perf_counter() - t_start
        n_rendered = sum(frames_of[i] for i in rendered)
        _append_log(
            out,
            {
                "event": "end",
                "pid": os.getpid(),
                "time": time.time(),
                "rendered": rendered,
                "seconds": seconds,
            },
        )
        return RenderSummary(
            path=out,
            num_frames=job["num_frames"],
            shards_total=num_shards,
            shards_rendered=sorted(rendered),
            shards_kept=kept,
            shards_repaired=repaired,
            seconds=seconds,
            frames_per_s=n_rendered / seconds if seconds > 0 else 0.0,
        )


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


def _run_processes(
    job: dict,
    todo: list[int],
    finish: Callable[[tuple, bool], None],
    workers: int,
    shards_per_worker: int,
    bar,
    backgrounds_of: Callable[[int], dict | None],
) -> None:
    from mincam_render.data.worker_pool import PoolError, run_tasks

    workers = min(workers, len(todo))  # and the cores go to the workers that run
    try:
        run_tasks(
            render_shard,
            todo,
            lambda shard: (job, shard, backgrounds_of(shard)),
            lambda shard, result: finish(result, True),
            workers=workers,
            tasks_per_worker=shards_per_worker,
            initializer=_worker_init,
            initargs=(_threads_per_worker(workers), os.getpid()),
            on_progress=None if bar is None else lambda shard, n: bar.update(n),
        )
    except PoolError as err:
        raise RenderError(
            f"{err}: shard {', '.join(map(str, err.tasks))} did not finish; finished shards "
            "are kept: run the same command again to resume"
        ) from None


def _run_ray(
    address: str,
    job: dict,
    todo: list[int],
    finish: Callable[[tuple, bool], None],
    shards_per_worker: int,
    backgrounds_of: Callable[[int], dict | None],
) -> None:
    try:
        import ray
    except ImportError:
        raise RenderError(
            "--ray needs the optional dependency ray: pip install 'mincam_render[ray]'"
        ) from None
    from mincam_render.data.worker_pool import POLL_S, StallWatch, WorkerStalled

    pkg_dir = str(Path(__file__).resolve().parent)
    init_kwargs: dict[str, Any] = {
        "ignore_reinit_error": True,
        "log_to_driver": False,
        "include_dashboard": False,
        # ship this package to the workers (other nodes may not have it installed)
        "runtime_env": {"py_modules": [pkg_dir], "excludes": ["__pycache__"]},
    }
    if address != "local":
        init_kwargs["address"] = address
    started = not ray.is_initialized()
    try:
        ray.init(**init_kwargs)
    except Exception as err:  # ray raises ConnectionError, RuntimeError, ValueError ...
        raise RenderError(f"could not connect to Ray at {address!r}: {err}") from None
    try:
        cpus = int(ray.cluster_resources().get("CPU", 1))
        # one Dr.Jit thread per task: Ray runs as many tasks as the cluster has CPUs
        task = ray.remote(num_cpus=1, max_calls=shards_per_worker)(_ray_render_shard)
        job_ref = ray.put(job)
        shard_of = {task.remote(job_ref, i, 1, backgrounds_of(i)): i for i in todo}
        pending = list(shard_of)
        log.info("Ray: %d shard tasks on %d CPUs", len(pending), cpus)
        # tasks wait for a CPU, so the time between two results stands for a task's
        watch, last_s = StallWatch(), time.monotonic()
        while pending:
            done, pending = ray.wait(pending, num_returns=1, timeout=POLL_S)
            if not done:
                try:
                    watch.check(sorted(shard_of[r] for r in pending))
                except WorkerStalled as err:
                    for ref in pending:
                        ray.cancel(ref, force=True)
                    raise RenderError(f"Ray: {err}; run the same command again to resume") from None
                continue
            try:
                result = ray.get(done[0])
            except Exception as err:
                raise RenderError(f"a Ray render task failed: {err}") from None
            watch.report(time.monotonic() - last_s)
            last_s = time.monotonic()
            finish(result, False)
    finally:
        if started:
            ray.shutdown()
