"""A job's scene family and camera, rebuilt from its manifest (in the parent and in workers)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from mincam_render.data import dataset as ds

if TYPE_CHECKING:
    from mincam_render.optics.camera import FreeformCamera
    from mincam_render.scenes.base import SceneFamily


def _load_family(job: dict) -> SceneFamily:
    """The scene family of a job, rebuilt from the manifest's resolved description."""
    from mincam_render.core.config import parse
    from mincam_render.scenes.registry import family_class, load_family

    fam = job["family"]
    if fam.get("rebuild_from_description", True):
        cls = family_class(fam["name"])
        config: Any = parse(cls.config_type, fam["description"], source="manifest")
        return cls(config, seed=job["seed"], num_frames=job["num_frames"])
    return load_family(
        fam["source"], seed=job["seed"], num_frames=job["num_frames"], overrides=fam["overrides"]
    )


def _render_camera(job: dict) -> tuple[FreeformCamera, FreeformCamera]:
    """``(camera of the dataset, camera actually rendered)``; they differ for shared renders."""
    camera = ds.camera_from_dict(job["camera"])
    # shared: one representative detector at the board centre, replicated to all K
    return camera, camera.rendered_camera(bool(job["render"]["shared_render"]))
