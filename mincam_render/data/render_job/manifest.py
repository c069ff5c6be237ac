"""A render's directory: its manifest reopened or planned, its shards checked, its log.

An existing directory must hold a manifest of the *same* request (compared
field by field), whose plan is then reused as is, so a resumed render is
identical to an uninterrupted one. It must also have been rendered with this
process's Mitsuba variant: shards of two variants (CPU and GPU kernels differ in
the last bits) must not mix in one dataset. Intact shards are kept; corrupted or
truncated ones are marked for re-rendering.
"""

from __future__ import annotations

import json
import logging
import time
from pathlib import Path

from mincam_render.core import strict_json
from mincam_render.data import dataset as ds
from mincam_render.data.render_job.estimate import JobLimits, check_job, estimate_job
from mincam_render.data.render_job.planning import _describe_family, package_versions, plan_render
from mincam_render.data.render_job.request import RenderRequest
from mincam_render.data.writer_lock import LOCK_NAME

log = logging.getLogger(__name__)


def _append_log(out: Path, entry: dict) -> None:
    with open(out / ds.LOG_NAME, "a") as f:
        f.write(strict_json.dumps(entry, indent=None) + "\n")


def _open_or_plan(
    request: RenderRequest,
    out: Path,
    use_plan_cache: bool,
    progress: bool = False,
    limits: JobLimits | None = None,
) -> dict:
    """Reuse the manifest of ``out`` if it is the same request; plan a new one if empty.

    A new job is estimated and checked against ``limits`` (None: neither) before
    its manifest is written (:mod:`.estimate`).

    Raises:
        JobTooLarge: a new job above ``limits``, not confirmed (nothing written).
    """
    if out.exists() and not out.is_dir():
        raise ds.DatasetError(f"--out {out} exists and is not a directory")
    if (out / ds.MANIFEST_NAME).is_file():
        return _reopen(request, out)
    if out.is_dir() and any(p.name != LOCK_NAME for p in out.iterdir()):
        raise ds.DatasetError(
            f"{out} is not empty and holds no {ds.MANIFEST_NAME}; refusing to render into it"
        )
    t0 = time.perf_counter()
    manifest = plan_render(request, use_cache=use_plan_cache, progress=progress)
    if limits is not None:
        check_job(estimate_job(manifest, out), limits, out)
    (out / ds.SHARD_DIR).mkdir(parents=True, exist_ok=True)
    ds.write_manifest(out, manifest)
    _append_log(out, {"event": "planned", "seconds": time.perf_counter() - t0, "time": time.time()})
    return manifest


def _reopen(request: RenderRequest, out: Path) -> dict:
    """The manifest of ``out``, checked to be of this format and of ``request``.

    Raises:
        DatasetError: another format version, another Mitsuba variant, or another
            configuration.
    """
    manifest = ds.read_manifest(out)
    if manifest.get("format_version", 0) != ds.FORMAT_VERSION:
        raise ds.DatasetError(
            f"{out} was rendered by another mincam_render (dataset format version "
            f"{manifest.get('format_version', 0)}, this one writes {ds.FORMAT_VERSION}); "
            "it can be read but not resumed: render into another --out directory"
        )
    _check_variant(out, manifest)
    _, description, _ = _describe_family(request)
    identity = request.identity(description)
    if manifest["request"] != identity:
        diffs = _identity_diff(manifest["request"], identity)
        raise ds.DatasetError(
            f"{out} holds a dataset rendered with a different configuration "
            f"({'; '.join(diffs[:3])}{' ...' if len(diffs) > 3 else ''}); "
            "render into another --out directory or delete this one"
        )
    return manifest


def warn_of_other_versions(out: Path, manifest: dict, shards: list[int]) -> None:
    """Warn when ``shards`` of ``out`` are to be rendered with other package versions.

    A finished dataset opened again renders nothing, so it is not warned about
    (a protocol run opens tens of finished episodes).
    """
    versions = package_versions()
    if shards and versions != manifest["versions"]:
        log.warning(
            "resuming %s (%d of %d shards to render) with other package versions than it "
            "was started with: %s (now %s)",
            out,
            len(shards),
            manifest["num_shards"],
            manifest["versions"],
            versions,
        )


def _check_variant(out: Path, manifest: dict) -> None:
    """Refuse to resume ``out`` with another Mitsuba variant than the one it was rendered with.

    Raises:
        DatasetError: the manifest's ``variant`` is not this process's.
    """
    from mincam_render.render import backend

    now = backend.use_variant()
    if manifest.get("variant") != now:
        raise ds.DatasetError(
            f"{out} was rendered with Mitsuba variant {manifest.get('variant')!r}, this "
            f"process renders with {now!r}; shards of two variants must not mix: set "
            f"{backend.BACKEND_ENV}={_backend_name(manifest.get('variant'))} to resume it, "
            "or render into another --out directory"
        )


def _backend_name(variant: object) -> str:
    """The :data:`~mincam_render.render.backend.BACKEND_ENV` value of ``variant`` (or ``...``)."""
    from mincam_render.render import backend

    try:
        return backend.backend_of(str(variant)).value
    except ValueError:
        return "..."


def _identity_diff(old: dict, new: dict, prefix: str = "") -> list[str]:
    diffs = []
    for key in sorted(set(old) | set(new)):
        a, b = old.get(key, "<absent>"), new.get(key, "<absent>")
        if isinstance(a, dict) and isinstance(b, dict):
            diffs += _identity_diff(a, b, f"{prefix}{key}.")
        elif a != b:
            diffs.append(f"{prefix}{key}: {a!r} (on disk) != {b!r} (now)")
    return diffs


def _check_shards(out: Path, manifest: dict) -> tuple[list[int], list[int], list[int]]:
    """``(kept, repaired, todo)`` shards of ``out``, recording what changed in the manifest.

    A shard is kept when its files match its sha256 (and, if the manifest does
    not record it, belong to this job); a recorded or damaged one that does not
    is repaired; every shard not kept is to do. The manifest is rewritten when
    a record changed or its ``complete`` flag is stale.
    """
    kept, repaired, todo = [], [], []
    changed = False
    for i in range(manifest["num_shards"]):
        rec = manifest["shards"][i]
        found, reason = _verify_shard(out, manifest["job"], i, rec)
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
    return kept, repaired, todo


def _verify_shard(out: Path, job: dict, i: int, rec: dict | None) -> tuple[dict | None, str]:
    """``(record or None, reason)`` of shard ``i``; one the manifest lacks must be ``job``'s.

    See :func:`~mincam_render.data.dataset.verify_shard`.
    """
    found, reason = ds.verify_shard(out, i, rec)
    if found is not None and rec is None:
        # finished by a previous run that was killed before updating the manifest
        meta = json.loads(ds.shard_paths(out, i)[1].read_text())
        if meta.get("request_sha256") != job["request_sha256"]:
            found, reason = None, "belongs to another configuration"
    return found, reason
