r"""Camera pose error as a resampling of the mask plane (numpy; the torch side is in fabrication).

A built camera is screwed to the wall a little off its designed pose: turned by
``(pan, tilt, roll)`` and moved by ``t = (right, up, forward)`` in the designed
camera's frame. Its transport images differ from the rendered ones; this module
approximates them from the rendered ones instead of rendering again.

**The model.** Texel ``p`` of a detector's mask plane sees the scene along one
direction from the detector (its pinhole), in tangent coordinates
``(a, b) = (right, up) / mask_distance``. The transport of the texel is its
angular weight times the radiance from that direction,
``T(p) = G(p) L(p)`` with ``G = cos^4(theta) f(theta)`` (solid angle per unit
mask area, ``cos^3``, times the diode's cosine and its directional response
``f``, as :mod:`mincam_render.render.transport` integrates them). The moved
camera's texel ``p`` sees the scene point that the designed camera saw at
``h(p)``, with ``h`` the homography

.. math::  h(p) \simeq (I - t n^T / D)^{-1} R \, (a_p, b_p, 1)^T, \qquad n = (0, 0, 1)

of a scene plane at depth ``D`` facing the camera: exact for the rotation ``R``
at any depth (a camera turned about its pinhole sees the same rays), exact for
the offset ``t`` on that plane only; content at depth ``z`` is off by the
parallax ``|t| (1/z - 1/D)`` (rad). Given the view's depth map instead of one
``D``, every texel's content moves by its own parallax (``R x + t / z``).
Radiance is carried along rays, so

.. math::  T'(p) = G(p)\, L(h(p)) \approx G(p) \sum_q B(q; h(p))\, T(q) / G(q)

with ``B`` the bilinear weights of the rendered texels ``q`` around ``h(p)``.
The measurement ``P' = sum_p T'(p) M(p)`` is then a measurement of the rendered
transport through an effective mask, the splat (adjoint of the bilinear
lookup) of ``G M`` onto the rendered texels:

.. math::  M_{eff}(q) = \frac{1}{G(q)} \sum_p B(q; h(p))\, G(p)\, M(p)

so a pose error costs a few thousand multiply-adds per mask, linear and
differentiable in ``M``, and every detector takes the same splat (the board is
rigid; a detector ``b`` off the board centre also moves by ``(R - I) b``,
~1.7 mm for 5 cm at 2 deg, not modelled).

**What is missing.** Where ``h(p)`` falls outside the rendered field, the
moved camera sees content no render holds; the lookup then takes the nearest
rendered texel (border replication), a guess. :meth:`PoseWarp.extrapolated_fraction`
is the share of the moved camera's angular weight that is guessed this way:
for the prototype's masks 0.026 for a 2-deg pan (a strip ``11.4 mm x tan 2 deg
/ cos^2 35 deg = 0.6 mm`` wide along one 16-mm edge), 0.046 for 2 deg about
all three axes, 0.005 for a 2-cm move at the 2-m plane.
``benchmarks/bench_pose_error.py`` measures the approximation against real
re-renders.

Conventions (``docs/robustness.md``): pan turns the view right, tilt up, roll
clockwise as seen from the camera (like a mask rotation), applied in that order
about the camera's own axes; the camera turns about its board origin.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, replace

import numpy as np

from mincam_render.optics.camera import FreeformCamera


def _check_pose(
    rotation_rad: object, offset_m: object, depth_m: float | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """``(rotation, offset)`` as float64 vectors, else a ValueError naming the value."""
    try:
        rot = np.asarray(rotation_rad, dtype=np.float64)
        off = np.asarray(offset_m, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"pose {rotation_rad!r} rad, {offset_m!r} m: need numbers") from None
    if rot.shape != (3,) or not np.isfinite(rot).all():
        raise ValueError(
            f"pose rotation {rotation_rad!r} rad: need 3 finite angles (pan, tilt, roll)"
        )
    if off.shape != (3,) or not np.isfinite(off).all():
        raise ValueError(f"pose offset {offset_m!r} m: need 3 finite numbers (right, up, forward)")
    if depth_m is not None:
        if not (isinstance(depth_m, int | float) and math.isfinite(depth_m) and depth_m > 0):
            raise ValueError(f"pose depth {depth_m!r} m is invalid: allowed a finite depth > 0")
        if off[2] >= depth_m:
            raise ValueError(f"pose offset forward {off[2]:g} m reaches the depth {depth_m:g} m")
    return rot, off


def pose_rotation(rotation_rad: object) -> np.ndarray:
    """``R`` (3x3): the moved camera's axes in the designed camera's ``(right, up, forward)``.

    Column ``i`` is the moved camera's axis ``i``: pan (turning forward toward
    right), then tilt (forward toward up), then roll (up toward right:
    clockwise as seen from the camera), each about the camera's current axes.
    """
    pan, tilt, roll = np.asarray(rotation_rad, dtype=np.float64).tolist()
    cp, sp, ct, st, cr, sr = (f(x) for x in (pan, tilt, roll) for f in (math.cos, math.sin))
    # R_pan R_tilt R_roll multiplied out (one small array per training draw), with
    # R_pan = [[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]], R_tilt = [[1, 0, 0], [0, ct, st],
    # [0, -st, ct]], R_roll = [[cr, sr, 0], [-sr, cr, 0], [0, 0, 1]]
    a, b = sp * st, cp * st  # row 0 and row 2 of R_pan R_tilt: (cp, -a, sp ct), (-sp, -b, cp ct)
    return np.array(
        [
            [cp * cr + a * sr, cp * sr - a * cr, sp * ct],
            [-ct * sr, ct * cr, st],
            [b * sr - sp * cr, -sp * sr - b * cr, cp * ct],
        ]
    )


def content_homography(rotation_rad: object, offset_m: object, depth_m: float) -> np.ndarray:
    """``H`` (3x3): a moved camera's direction ``(a, b, 1)`` -> the designed camera's.

    Both in their own ``(right, up, forward)`` coordinates, for scene points on
    the plane ``forward = depth_m`` of the designed camera (any depth when the
    offset is 0).
    """
    rot, off = _check_pose(rotation_rad, offset_m, depth_m)
    r = pose_rotation(rot)
    # (I - t n^T / D)^-1 = I + t n^T / (D - t_z) (Sherman-Morrison), n the forward axis
    return r + np.outer(off / (depth_m - off[2]), r[2])


def texel_directions(camera: FreeformCamera) -> tuple[np.ndarray, np.ndarray]:
    """Tangent coordinates ``(a, b)`` of the texel centres, each ``[rows, cols]``.

    ``a`` along right, ``b`` along up, in units of the mask distance (row 0 up).
    """
    rows, cols = camera.mask_resolution
    th, tw = camera.texel_size_m
    d = camera.mask_distance_m
    a = ((np.arange(cols) + 0.5) * tw - 0.5 * camera.mask_size_m) / d
    b = (0.5 * camera.mask_size_m - (np.arange(rows) + 0.5) * th) / d
    aa, bb = np.broadcast_arrays(a[None, :], b[:, None])
    return aa, bb


def angular_weight(camera: FreeformCamera, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``G = cos^4(theta) f(theta)`` of directions ``(a, b)``: transport per unit radiance.

    Up to a constant factor (detector area, texel area, ``1 / d^2``), which
    cancels in every ratio this module takes.
    """
    cos_theta = 1.0 / np.sqrt(1.0 + a * a + b * b)
    g = cos_theta**4
    if camera.directional_response is not None:
        g = g * camera.directional_response(np.arccos(np.clip(cos_theta, 0.0, 1.0)))
    return g


@functools.lru_cache(maxsize=8)
def _texel_rays(camera: FreeformCamera) -> tuple[np.ndarray, np.ndarray]:
    """``(rays[3, texel], G[rows, cols])`` of a camera: its texel directions ``(a, b, 1)``.

    Cached per camera (a frozen dataclass): every draw of a training run reuses
    them. Read-only arrays.
    """
    a, b = texel_directions(camera)
    rays = np.stack([a.ravel(), b.ravel(), np.ones(a.size)])
    g = angular_weight(camera, a, b)
    rays.setflags(write=False)
    g.setflags(write=False)
    return rays, g


@dataclass(frozen=True)
class PoseWarp:
    """Where a moved camera's texels look on the rendered mask plane (numpy).

    The effective mask is ``M_eff = splat(G M, grid) / G``
    (:func:`mincam_render.optics.fabrication.posed_masks`): each moved texel
    ``p``'s ``G(p) M(p)`` spread bilinearly onto the rendered texels around
    ``grid[p]``, the border texels standing in beyond the field.

    Attributes:
        grid: ``[rows, cols, 2]`` ``(x, y)`` of ``h(p)`` in ``grid_sample``'s units
            (-1 and 1 at the edges of the field, ``align_corners=False``; y down);
            content behind the designed camera is put far outside.
        angular_weight: ``G[rows, cols]`` of the texels (see :func:`angular_weight`).
        ahead: ``[rows, cols]`` 1.0 where ``h(p)`` is in front of the designed
            camera, else 0.0 (no render holds that content; it is dropped).
    """

    grid: np.ndarray
    angular_weight: np.ndarray
    ahead: np.ndarray

    def extrapolated_fraction(self) -> float:
        """Share of the moved camera's angular weight whose content lies outside the field.

        Each texel counts by the share of its width beyond the field (content
        behind the designed camera counts whole): what the border stands in for.
        """
        rows, cols = self.angular_weight.shape
        col = ((self.grid[..., 0] + 1.0) * cols - 1.0) / 2.0
        row = ((self.grid[..., 1] + 1.0) * rows - 1.0) / 2.0
        inside = _inside(row, rows) * _inside(col, cols) * self.ahead
        g = self.angular_weight
        return float((g * (1.0 - inside)).sum() / g.sum())


def _inside(index: np.ndarray, n: int) -> np.ndarray:
    """Share of a texel around continuous index ``index`` that lies within ``[-0.5, n - 0.5]``."""
    beyond = np.clip(np.abs(index - (n - 1) / 2.0) - (n - 1) / 2.0, 0.0, 1.0)
    return 1.0 - beyond


def _content_directions(
    rays: np.ndarray, rotation_rad: object, offset_m: object, depth_m: float | np.ndarray
) -> np.ndarray:
    """``x[3, texel]``: the designed camera's direction of what each moved texel sees.

    A scalar depth: the plane homography (:func:`content_homography`). A depth
    map: each texel's content at its own depth, the designed view's depth at
    that texel less the forward offset (exact for a pure offset wherever the
    depth varies slowly; with a rotation too, the depth is taken at the
    unrotated texel).
    """
    if np.ndim(depth_m) == 0:
        return content_homography(rotation_rad, offset_m, float(depth_m)) @ rays
    rot, off = _check_pose(rotation_rad, offset_m)
    z = np.asarray(depth_m, dtype=np.float64).ravel()
    if z.size != rays.shape[1] or np.isnan(z).any() or not np.all(z > max(off[2], 0.0)):
        raise ValueError(
            f"pose depth map of shape {np.shape(depth_m)}: need one depth (m) per texel, "
            f"beyond the forward offset {off[2]:g} m (inf for misses)"
        )
    return pose_rotation(rot) @ rays + off[:, None] / (z - off[2])  # the ray scaled by 1/depth


def pose_warp(
    camera: FreeformCamera,
    rotation_rad: object,
    offset_m: object,
    depth_m: float | np.ndarray,
) -> PoseWarp:
    """The :class:`PoseWarp` of a camera moved by ``rotation_rad`` and ``offset_m``.

    Args:
        camera: mask geometry (size, distance, texels) and directional response.
        rotation_rad: ``(pan, tilt, roll)`` (rad).
        offset_m: ``(right, up, forward)`` (m), in the designed camera's frame.
        depth_m: depth of the scene plane the offset is exact for (m), > 0; or
            the designed view's depth map ``[rows, cols]`` (m, ``inf`` where a
            ray misses), each texel's content moved by its own parallax.

    Raises:
        ValueError: not 3 finite angles or offsets, depth not > 0, an offset
            forward reaching the plane, or a depth map of another shape.
    """
    rows, cols = camera.mask_resolution
    rays, g = _texel_rays(camera)
    x = _content_directions(rays, rotation_rad, offset_m, depth_m)
    ahead = x[2] > 0
    # tangent coordinates over the half field (a_max = w / 2d), y down: grid_sample's units
    half = 0.5 * camera.mask_size_m / camera.mask_distance_m
    xy = x[:2] * np.array([[1.0 / half], [-1.0 / half]])
    if ahead.all():
        grid = xy / x[2]
    else:  # content behind the designed camera: far outside
        grid = np.where(ahead, xy / np.where(ahead, x[2], 1.0), 3.0)
    return PoseWarp(
        grid=np.ascontiguousarray(grid.T).reshape(rows, cols, 2),  # grid_sample's layout
        angular_weight=g,
        ahead=ahead.astype(np.float64).reshape(rows, cols),
    )


def posed_camera(camera: FreeformCamera, rotation_rad: object, offset_m: object) -> FreeformCamera:
    """``camera`` turned by ``rotation_rad`` about its board origin and moved by ``offset_m``.

    The offset ``(right, up, forward)`` (m) is in the designed camera's frame.
    What :func:`pose_warp` approximates; renders of it are the reference.
    """
    rot, off = _check_pose(rotation_rad, offset_m)
    frame = camera.frame  # rows: right, up, forward (world)
    axes = frame.T @ pose_rotation(rot)  # columns: the moved camera's axes (world)
    position = np.asarray(camera.position) + frame.T @ off
    return replace(
        camera,
        position=tuple(position),
        look_at=tuple(position + axes[:, 2]),
        up=tuple(axes[:, 1]),
    )
