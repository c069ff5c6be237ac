"""Independent checks of the transport renderer with plain Mitsuba renders."""

from __future__ import annotations

import mitsuba as mi
import numpy as np

from mincam_render.optics.camera import FreeformCamera
from mincam_render.render.backend import use_variant
from mincam_render.render.mitsuba_scene import load_scene, with_mask_geometry


def render_through_mask_geometry(
    scene: dict,
    camera: FreeformCamera,
    detector: int,
    transmittance: np.ndarray,
    *,
    spp: int,
    seed: int = 0,
    max_depth: int,
) -> float:
    """Power (W) on one detector with its mask present as geometry in ``scene``.

    An irradiance meter on the diode, behind a ``mask``-BSDF sheet and an
    opaque housing (see :func:`mitsuba_scene.with_mask_geometry`), rendered by
    Mitsuba's own sensor code: no part of :mod:`transport` is involved. The
    result should equal ``sum(T[detector] * transmittance)`` within Monte Carlo
    error when ``T`` was rendered with the same ``max_depth``.

    Args:
        scene: a Mitsuba scene dict (not a loaded scene: geometry is added).
        camera: the camera whose detector is simulated.
        detector: detector index, 0 <= detector < K.
        transmittance: ``M[row, col]`` in [0, 1], the camera's mask resolution.
        spp: samples of the irradiance meter.
        seed: Mitsuba sampler seed.
        max_depth: path depth of the transport render being checked.

    """
    use_variant()
    m = np.asarray(transmittance, dtype=np.float64)
    if m.shape != camera.mask_resolution or np.any(m < 0) or np.any(m > 1):
        raise ValueError(
            f"transmittance has shape {m.shape}, range [{m.min():g}, {m.max():g}]: expected "
            f"{camera.mask_resolution} within [0, 1]"
        )
    if not 0 <= detector < camera.num_detectors:
        raise ValueError(f"detector = {detector} is out of range [0, {camera.num_detectors})")
    full = with_mask_geometry(scene, camera, detector, m, max_depth=max_depth)
    loaded = load_scene(full)
    meter = next(s for s in loaded.sensors() if s.id() == "_mincam_irradiancemeter")
    img = mi.render(loaded, sensor=meter, spp=spp, seed=seed)
    irradiance = float(np.asarray(img).ravel()[0])
    return irradiance * camera.detector_size_m**2
