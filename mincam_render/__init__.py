"""mincam_render: physically-based rendering for designing minimalist cameras.

The public names below are imported on first use (PEP 562), so that
``mincam-render --help`` and other light commands start without loading
PyTorch, Mitsuba and Dr.Jit.
"""

from __future__ import annotations

import importlib
from typing import Any

#: public name -> the module that defines it
_EXPORTS = {
    "Backend": "mincam_render.render.backend",
    "BackendUnavailableError": "mincam_render.render.backend",
    "use_variant": "mincam_render.render.backend",
    "DetectorElectronics": "mincam_render.optics.camera",
    "DetectorLayout": "mincam_render.optics.camera",
    "DirectionalResponse": "mincam_render.optics.camera",
    "FreeformCamera": "mincam_render.optics.camera",
    "logits_for_transmittance": "mincam_render.optics.maskplane",
    "mask_power": "mincam_render.optics.maskplane",
    "transmittance": "mincam_render.optics.maskplane",
    "parallel_rectangles_coupling": "mincam_render.optics.radiometry",
    "detector_voltage": "mincam_render.optics.sensor",
    "leaky_saturation": "mincam_render.optics.sensor",
    "SceneError": "mincam_render.render.mitsuba_scene",
    "demo_scene": "mincam_render.render.mitsuba_scene",
    "load_scene": "mincam_render.render.mitsuba_scene",
    "render_transport": "mincam_render.render.transport",
    "render_transport_with_noise": "mincam_render.render.transport",
    "check_scene": "mincam_render.render.user_scene",
    "check_transport": "mincam_render.render.user_scene",
    "rescale_scene": "mincam_render.render.user_scene",
    "sensor_pose": "mincam_render.render.user_scene",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    if name not in _EXPORTS:
        raise AttributeError(f"module 'mincam_render' has no attribute {name!r}")
    value = getattr(importlib.import_module(_EXPORTS[name]), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
