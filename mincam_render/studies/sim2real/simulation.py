"""The scene twin of a recording rendered through a camera: noiseless simulated voltages.

Arrays are numpy float64; powers in watts, voltages in volts.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from mincam_render.core.seeds import stream_seed

if TYPE_CHECKING:
    from mincam_render.optics.camera import FreeformCamera
    from mincam_render.scenes.base import SceneFamily


def simulate_volts(
    family: SceneFamily,
    camera: FreeformCamera,
    frame_index: np.ndarray,
    masks: np.ndarray,
    pixels: np.ndarray,
    *,
    spp: int,
    seed: int,
    stream: int = 0,
    progress: str | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Noiseless simulated voltages ``V[N, P]`` and powers ``P[N, P]`` (W) of a recording.

    Renders the family at each frame index with ``camera`` (one transport per
    distinct frame), applies ``masks[P, row, col]`` to detectors ``pixels``, and
    the electronics without noise (leaky saturation kept). ``progress``: the
    label of a progress bar over the frames, or None for none.
    """
    import torch
    from tqdm import tqdm

    from mincam_render.optics.sensor import detector_voltage

    scene = family.build_scene()
    cache: dict[int, np.ndarray] = {}
    power = np.zeros((len(frame_index), len(pixels)))
    frames = tqdm(frame_index, desc=progress, unit="frame", disable=progress is None)
    for n, i in enumerate(frames):
        i = int(i)
        if i not in cache:
            family.set_frame(scene, i)
            # the family's estimator, as its datasets are rendered (sun-patch sampling)
            t = family.render_transport(
                scene, camera, spp=spp, seed=stream_seed(seed, f"sim2real/{stream}", int(i))
            )
            cache[i] = np.einsum("prc,prc->p", t[pixels].astype(np.float64), masks)
        power[n] = cache[i]
    volts = detector_voltage(torch.from_numpy(power), camera.electronics, noise=False).numpy()
    return volts, power
