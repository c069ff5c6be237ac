"""Irradiance on a flat meter placed in a loaded scene, with its Monte Carlo error.

The meter (:func:`mincam_render.render.mitsuba_scene.irradiance_meter`) is not a
shape of the scene: it measures the light arriving at its front face without
shadowing anything. The estimate is the mean of independent batches (different
sampler seeds), so its standard error is measured, not assumed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from mincam_render.core.seeds import stream_seed
from mincam_render.render.backend import use_variant

if TYPE_CHECKING:
    import mitsuba as mi

    from mincam_render.render.mitsuba_scene import MitsubaDict


@dataclass(frozen=True, kw_only=True)
class IrradianceEstimate:
    """A Monte Carlo irradiance estimate.

    Args:
        mean_w_m2: mean irradiance over the meter's face (W/m^2, the renderer's band).
        stderr_w_m2: standard error of the mean over the batches (W/m^2).
        spp: samples in total (batches x samples per batch).
    """

    mean_w_m2: float
    stderr_w_m2: float
    spp: int

    @property
    def relative_error(self) -> float:
        """``stderr / mean`` (0 for a dark meter)."""
        return self.stderr_w_m2 / self.mean_w_m2 if self.mean_w_m2 > 0 else 0.0


def _batch_seed(seed: int, batch: int) -> int:
    """Mitsuba's 32-bit sampler seed of batch ``batch`` under root ``seed``."""
    return stream_seed(seed, "irradiance/batch", batch) % 2**32


def measure_irradiance(
    scene: mi.Scene,
    meter: MitsubaDict,
    *,
    spp: int,
    batches: int = 8,
    seed: int = 0,
) -> IrradianceEstimate:
    """Irradiance on ``meter`` in ``scene`` as the mean of ``batches`` independent renders.

    Args:
        scene: a loaded Mitsuba scene, set to the state to measure.
        meter: a meter dict from :func:`mitsuba_scene.irradiance_meter`.
        spp: samples per batch (>= 1).
        batches: independent renders (>= 2, for the standard error).
        seed: root seed; batch ``b`` renders with ``stream_seed(seed, "irradiance/batch", b)``
            folded to Mitsuba's 32-bit sampler seed.

    Raises:
        ValueError: ``spp < 1`` or ``batches < 2``.
    """
    import mitsuba as mi

    if spp < 1:
        raise ValueError(f"spp = {spp!r}: allowed an integer >= 1")
    if batches < 2:
        raise ValueError(f"batches = {batches!r}: allowed an integer >= 2 (for the error)")
    use_variant()
    shape = mi.load_dict(meter)  # kept alive: its sensor refers back to it
    sensor = shape.sensor()
    values = np.array(
        [
            float(
                np.asarray(
                    mi.render(scene, sensor=sensor, spp=spp, seed=mi.UInt32(_batch_seed(seed, b)))
                ).ravel()[0]
            )
            for b in range(batches)
        ]
    )
    return IrradianceEstimate(
        mean_w_m2=float(values.mean()),
        stderr_w_m2=float(values.std(ddof=1) / math.sqrt(batches)),
        spp=spp * batches,
    )
