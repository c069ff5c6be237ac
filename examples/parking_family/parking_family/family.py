"""Occupied parking spaces seen from a lamp pole: a scene family written outside mincam_render.

A row of ``spaces`` parking spaces on asphalt under the sun and a clear sky.
Each space is taken and freed by a two-state Markov process (exponential stays
and gaps); every arriving car has its own paint. Labels: which spaces are taken
(one 0/1 per space) and how many cars are parked.

The family provides what every family must (:class:`SceneFamily`) and one
capability, a bird's-eye :class:`Preview`; it has no differential background,
so the renderer renders its frames plainly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import mitsuba as mi
import numpy as np
import trimesh

from mincam_render.core.config import check_min_max, spec
from mincam_render.core.labels import LabelKind, LabelSpec
from mincam_render.optics.camera import FreeformCamera
from mincam_render.render import mitsuba_scene as ms
from mincam_render.scenes import CameraMount, Preview, SceneFamily, View

#: A car's body (m): width, length, height.
CAR_SIZE_M = (1.8, 4.3, 1.4)
#: Depth of a space (m); spaces are side by side along x, their fronts at y = 0.
SPACE_DEPTH_M = 5.0


@dataclass(frozen=True, kw_only=True)
class ParkingConfig:
    """Description of the parking row (``parking.toml``)."""

    fps: float = spec(1.0, unit="1/s", range=(0.01, 100.0), doc="frame rate")
    spaces: int = spec(4, range=(1, 16), doc="parking spaces in the row")
    space_width_m: float = spec(2.5, unit="m", range=(2.0, 5.0), doc="width of a space")
    mean_parked_s: float = spec(120.0, unit="s", range=(1.0, 1e6), doc="mean stay of a car")
    mean_empty_s: float = spec(60.0, unit="s", range=(1.0, 1e6), doc="mean gap between cars")
    car_albedo: tuple[float, float] = spec(
        (0.05, 0.8), range=(0.0, 1.0), doc="min, max paint albedo, drawn per arriving car"
    )
    sun_irradiance_w_m2: float = spec(
        500.0, unit="W m^-2", range=(0.0, 2000.0), doc="the sun on a surface facing it"
    )
    sky_radiance_w_m2_sr: float = spec(
        30.0, unit="W m^-2 sr^-1", range=(0.0, 1e4), doc="a uniform sky"
    )
    camera: CameraMount = spec(
        default_factory=lambda: CameraMount(
            position=(0.0, -6.0, 6.0), look_at=(0.0, 2.5, 0.0), up=(0.0, 0.0, 1.0),
            detectors=4, mask_resolution=16,
        ),
        doc="the camera on its pole",
    )  # fmt: skip

    def __post_init__(self) -> None:
        check_min_max(self, "car_albedo")


class ParkingFamily(SceneFamily, Preview):
    """Which spaces of a parking row are taken."""

    name = "parking"
    config_type = ParkingConfig

    def __init__(self, config: ParkingConfig, *, seed: int, num_frames: int) -> None:
        super().__init__(config, seed=seed, num_frames=num_frames)
        rng = np.random.default_rng(seed)
        self.taken = _occupancy(rng, num_frames, config)  # [frame, space] bool
        arrivals = self.taken & ~np.vstack([np.zeros((1, config.spaces), bool), self.taken[:-1]])
        paints = rng.uniform(*config.car_albedo, size=self.taken.shape)
        # each car keeps the paint it arrived with
        index = np.maximum.accumulate(np.where(arrivals, np.arange(num_frames)[:, None], 0), 0)
        self.albedo = np.take_along_axis(paints, index, axis=0)
        box = trimesh.creation.box(extents=CAR_SIZE_M)
        self._car_vertices, self._car_faces = np.asarray(box.vertices), np.asarray(box.faces)

    @property
    def fps(self) -> float:
        return self.config.fps

    @property
    def labels(self) -> tuple[LabelSpec, ...]:
        names = tuple(f"space {k + 1}" for k in range(self.config.spaces))
        return (
            LabelSpec(name="taken", kind=LabelKind.BINARY, size=len(names), element_names=names,
                      median_filter_s=0.0),
            LabelSpec(name="cars", kind=LabelKind.COUNT, median_filter_s=0.0),
        )  # fmt: skip

    def camera(self) -> FreeformCamera:
        return self.config.camera.camera()

    def _space_centre(self, k: int) -> np.ndarray:
        c = self.config
        x = (k - (c.spaces - 1) / 2) * c.space_width_m
        return np.array([x, SPACE_DEPTH_M / 2, CAR_SIZE_M[2] / 2])

    def build_scene(self) -> mi.Scene:
        c = self.config
        width = c.spaces * c.space_width_m
        shapes: dict[str, Any] = {
            "sky": ms.constant_environment(c.sky_radiance_w_m2_sr),
            "sun": ms.directional_light((0.3, 0.5, -0.8), c.sun_irradiance_w_m2),
            "asphalt": ms.rectangle((0, 0, 0), (0, 0, 1), (width + 20, 30), ms.diffuse(0.12)),
        }
        for k in range(c.spaces + 1):  # white lines between the spaces
            x = (k - c.spaces / 2) * c.space_width_m
            shapes[f"line{k}"] = ms.rectangle(
                (x, SPACE_DEPTH_M / 2, 0.005), (x, SPACE_DEPTH_M / 2, 1), (0.12, SPACE_DEPTH_M),
                ms.diffuse(0.7),
            )  # fmt: skip
        for k in range(c.spaces):
            shapes[f"car{k}"] = ms.mesh(f"car{k}", self._car_vertices + self._space_centre(k),
                                        self._car_faces, reflectance=0.5)  # fmt: skip
        return ms.load_scene(ms.scene_dict(shapes, max_depth=3))

    def set_frame(self, scene: mi.Scene, index: int) -> dict[str, np.ndarray]:
        self.check_index(index)
        params = mi.traverse(scene)
        for k in range(self.config.spaces):
            # an empty space: the car shrunk to nothing where it would stand
            scale = 1.0 if self.taken[index, k] else 1e-6
            vertices = self._space_centre(k) + scale * self._car_vertices
            params[f"car{k}.vertex_positions"] = mi.Float(vertices.astype(np.float32).ravel())
            params[f"car{k}.bsdf.reflectance.value"] = mi.Float(float(self.albedo[index, k]))
        params.update()
        taken = self.taken[index].astype(np.float32)
        return {"taken": taken, "cars": np.array([taken.sum()], dtype=np.float32)}

    def frame_state(self, index: int) -> dict[str, Any]:
        self.check_index(index)
        return {
            "taken": [bool(v) for v in self.taken[index]],
            "albedo": [round(float(a), 4) for a in self.albedo[index]],
        }

    def birdseye_view(self) -> View:
        height = (self.config.spaces * self.config.space_width_m + 6) / (2 * math.tan(0.5))
        return View((0.0, SPACE_DEPTH_M / 2, height), (0.0, SPACE_DEPTH_M / 2, 0.0),
                    (0.0, 1.0, 0.0), math.degrees(1.0))  # fmt: skip


def _occupancy(rng: np.random.Generator, num_frames: int, c: ParkingConfig) -> np.ndarray:
    """``taken[frame, space]``: a two-state Markov chain per space, started in its steady state."""
    dt = 1.0 / c.fps
    leave, arrive = 1 - math.exp(-dt / c.mean_parked_s), 1 - math.exp(-dt / c.mean_empty_s)
    taken = np.empty((num_frames, c.spaces), dtype=bool)
    taken[0] = rng.random(c.spaces) < c.mean_parked_s / (c.mean_parked_s + c.mean_empty_s)
    for i in range(1, num_frames):
        u = rng.random(c.spaces)
        taken[i] = np.where(taken[i - 1], u >= leave, u < arrive)
    return taken
