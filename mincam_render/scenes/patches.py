"""The paper's toy task (Sec. 5): count 0-10 rectangular patches on a plane.

Each frame shows a plane facing the camera and filling its view. On a dark
background, ``count ~ U{0..max_patches}`` axis-aligned rectangles are painted
in random order (later ones occlude earlier ones, so patches may overlap), each
with a uniformly random centre, width, height and brightness within the ranges
of the description. The whole image is multiplied by a smooth sinusoidal
illumination ``1 + A sin(2 pi (x cos(o) + y sin(o)) / P + phi)`` with random
amplitude ``A``, period ``P``, orientation ``o`` and phase ``phi``. Frames are
independent draws (the paper's images were), indexed by time at ``fps``.
Label: the number of patches painted (``count``), including fully occluded ones,
as in the paper's generator.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import mitsuba as mi
import numpy as np

from mincam_render.core.config import Described, check_min_max, spec
from mincam_render.core.labels import LabelKind, LabelSpec
from mincam_render.core.strict_json import JsonObject
from mincam_render.optics.photodiode import DiodeResponse
from mincam_render.render import mitsuba_scene as ms
from mincam_render.render.capabilities import Preview, View
from mincam_render.scenes.base import CameraMount, SceneFamily

if TYPE_CHECKING:
    from mincam_render.optics.camera import FreeformCamera

_PLANE_KEY = "plane"
#: Per-frame parameter, checked against mi.traverse when the scene is built.
PLANE_RADIANCE_PARAM = f"{_PLANE_KEY}.emitter.radiance.data"


@dataclass(frozen=True, kw_only=True)
class PatchesConfig(Described):
    """Description of the patches family (``scenes/patches.toml``)."""

    fps: float = spec(30.0, unit="1/s", range=(1.0, 1000.0), doc="frame rate")
    plane_distance_m: float = spec(1.0, unit="m", range=(0.05, 100.0), doc="camera to plane")
    plane_fov_deg: float = spec(80.0, unit="deg", range=(10.0, 170.0), doc="angle the plane spans")
    image_resolution: int = spec(128, range=(8, 2048), doc="texels per side of the plane image")
    max_patches: int = spec(10, range=(0, 100), doc="count ~ U{0..max_patches}")
    patch_size: tuple[float, float] = spec(
        (0.05, 0.25), range=(0.001, 1.0), doc="min, max side as a fraction of the plane"
    )
    patch_radiance_w_m2_sr: tuple[float, float] = spec(
        (1.0, 10.0), unit="W m^-2 sr^-1", range=(0.0, 1e7), doc="min, max patch radiance"
    )
    background_radiance_w_m2_sr: float = spec(
        0.2, unit="W m^-2 sr^-1", range=(0.0, 1e7), doc="radiance of the empty plane"
    )
    illumination_amplitude: tuple[float, float] = spec(
        (0.0, 0.5), range=(0.0, 1.0), doc="min, max sinusoid amplitude A"
    )
    illumination_period: tuple[float, float] = spec(
        (0.5, 2.0), range=(0.01, 100.0), doc="min, max period P in plane widths"
    )
    camera: CameraMount = spec(
        default_factory=lambda: CameraMount(
            position=(0.0, 0.0, 0.0),
            look_at=(0.0, 0.0, 1.0),
            up=(0.0, 1.0, 0.0),
            detectors=4,
            diode_response=DiodeResponse.COSINE,  # the paper's toy: an ideal diode
        ),
        doc="camera pose; the plane is placed in front of it",
    )

    def __post_init__(self) -> None:
        check_min_max(
            self,
            "patch_size",
            "patch_radiance_w_m2_sr",
            "illumination_amplitude",
            "illumination_period",
        )


class PatchesFamily(SceneFamily, Preview):
    """Counting patches (paper Sec. 5)."""

    name = "patches"
    config_type = PatchesConfig

    def __init__(self, config: PatchesConfig, *, seed: int, num_frames: int) -> None:
        super().__init__(config, seed=seed, num_frames=num_frames)
        self._last_image: tuple[int, tuple[np.ndarray, JsonObject]] | None = None

    @property
    def fps(self) -> float:
        return self.config.fps

    @property
    def labels(self) -> tuple[LabelSpec, ...]:
        return (LabelSpec(name="count", kind=LabelKind.COUNT, median_filter_s=0.0),)

    def camera(self) -> FreeformCamera:
        return self.config.camera.camera()

    def _plane_geometry(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
        cam = self.camera()
        right, up, fwd = cam.frame
        centre = np.asarray(cam.position) + self.config.plane_distance_m * fwd
        side = (
            2.0
            * self.config.plane_distance_m
            * math.tan(math.radians(self.config.plane_fov_deg) / 2)
        )
        return centre, up, np.asarray(cam.position), side

    def image(self, index: int) -> tuple[np.ndarray, JsonObject]:
        """Radiance image ``L[row, col]`` (W m^-2 sr^-1) of frame ``index`` and its parameters.

        The last frame's result is kept: a render asks for it twice (set_frame,
        frame_state). Treat the returned arrays as read-only.
        """
        if self._last_image is not None and self._last_image[0] == index:
            return self._last_image[1]
        result = self._draw_image(index)
        self._last_image = (index, result)
        return result

    def _draw_image(self, index: int) -> tuple[np.ndarray, JsonObject]:
        self.check_index(index)
        c = self.config
        rng = np.random.default_rng([self.seed, index])
        n = c.image_resolution
        # texel centres: xs[col] to the right, ys[row] down, (0, 0) top-left; a
        # rectangle is the outer product of its row and column ranges (the 1-D
        # form gives bit-identical images 5x faster than testing a 2-D grid)
        xs = (np.arange(n) + 0.5) / n
        ys = xs[:, None]
        img = np.full((n, n), c.background_radiance_w_m2_sr, dtype=np.float64)
        count = int(rng.integers(0, c.max_patches + 1))
        patches = []
        for _ in range(count):
            w, h = rng.uniform(c.patch_size[0], c.patch_size[1], size=2)
            cx, cy = rng.uniform(0.0, 1.0, size=2)
            level = rng.uniform(*c.patch_radiance_w_m2_sr)
            cols_in = np.abs(xs - cx) <= w / 2
            rows_in = np.abs(xs - cy) <= h / 2
            img[np.ix_(rows_in, cols_in)] = level
            patches.append({"center": [cx, cy], "size": [w, h], "radiance": level})
        amp = rng.uniform(*c.illumination_amplitude)
        period = rng.uniform(*c.illumination_period)
        orient = rng.uniform(0.0, math.pi)
        phase = rng.uniform(0.0, 2 * math.pi)
        illum = 1.0 + amp * np.sin(
            2 * math.pi * (xs * math.cos(orient) + ys * math.sin(orient)) / period + phase
        )
        state = {
            "count": count,
            "patches": patches,
            "illumination": {
                "amplitude": amp,
                "period": period,
                "orientation_rad": orient,
                "phase_rad": phase,
            },
        }
        return (img * illum).astype(np.float32), state

    def build_scene(self) -> mi.Scene:
        centre, up, cam_pos, side = self._plane_geometry()
        img, _ = self.image(0)
        scene = ms.load_scene(
            ms.scene_dict(
                {
                    _PLANE_KEY: ms.textured_emitter_rectangle(
                        centre, cam_pos, (side, side), img, up=up
                    )
                },
                max_depth=1,
            )
        )
        if PLANE_RADIANCE_PARAM not in mi.traverse(scene):
            raise RuntimeError(f"scene has no parameter {PLANE_RADIANCE_PARAM!r}")
        return scene

    def set_frame(self, scene: mi.Scene, index: int) -> dict[str, np.ndarray]:
        img, state = self.image(index)
        params = mi.traverse(scene)
        params[PLANE_RADIANCE_PARAM] = ms.emitter_image_data(img)
        params.update()
        return {"count": np.array([state["count"]], dtype=np.float32)}

    def frame_state(self, index: int) -> JsonObject:
        return self.image(index)[1]

    def birdseye_view(self) -> View:
        centre, up, cam_pos, side = self._plane_geometry()
        d = np.asarray(centre) - cam_pos
        eye = cam_pos - 0.5 * d + up * side * 1.2
        return View(tuple(eye), tuple(centre), tuple(up), 60.0)
