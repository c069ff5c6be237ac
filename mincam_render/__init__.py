"""mincam_render: physically-based rendering for designing minimalist cameras."""

from mincam_render.optics.camera import (
    DetectorElectronics,
    DetectorLayout,
    DirectionalResponse,
    FreeformCamera,
)
from mincam_render.optics.maskplane import logits_for_transmittance, mask_power, transmittance
from mincam_render.optics.radiometry import parallel_rectangles_coupling
from mincam_render.optics.sensor import detector_voltage, leaky_saturation
from mincam_render.render.backend import Backend, BackendUnavailableError, use_variant
from mincam_render.render.mitsuba_scene import SceneError, demo_scene, load_scene
from mincam_render.render.transport import render_transport

__all__ = [
    "Backend",
    "BackendUnavailableError",
    "DetectorElectronics",
    "DetectorLayout",
    "DirectionalResponse",
    "FreeformCamera",
    "SceneError",
    "demo_scene",
    "detector_voltage",
    "leaky_saturation",
    "load_scene",
    "logits_for_transmittance",
    "mask_power",
    "parallel_rectangles_coupling",
    "render_transport",
    "transmittance",
    "use_variant",
]
