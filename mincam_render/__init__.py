"""mincam_render: physically-based rendering for designing minimalist cameras."""

from .backend import Backend, BackendUnavailableError, use_variant
from .camera import DetectorElectronics, DetectorLayout, DirectionalResponse, FreeformCamera
from .maskplane import logits_for_transmittance, mask_power, transmittance
from .mitsuba_scene import SceneError, demo_scene, load_scene
from .radiometry import parallel_rectangles_coupling
from .sensor import detector_voltage, leaky_saturation
from .transport import render_transport

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
