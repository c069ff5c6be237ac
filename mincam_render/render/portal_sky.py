r"""Sky and ground seen through a window, sampled through the window (a light portal).

Indoors, daylight reaches the room only through its window. Mitsuba's ``envmap``
samples directions over the whole sphere in proportion to the sky's radiance,
so from a point in the room most of its light samples point at a wall and are
wasted; the sky through a window was the dominant source of noise of the
indoor families (about 85 % of the light and nearly all the variance of the
workspace at 7:30). :class:`PortalSkyEmitter` is an infinite emitter with the
same lat-long radiance map that samples directions through the window opening
instead: a uniform point ``p`` on the window rectangle (area ``A``, outward
normal ``n``), direction ``d = (p - x) / |p - x|``, with solid-angle density

.. math::

    p_\omega(d) = \frac{|p - x|^2}{A \, (d \cdot n)}

and zero for directions that miss the window. Directions that miss the window
reach the sky only through other openings, which indoor scenes here do not
have (the corridor behind the door is closed); rays that escape anyway still
see the sky through :meth:`PortalSkyEmitter.eval` (brute-force paths, MIS weight 1),
so the estimate stays unbiased as long as the sky is visible through the window
only.

The radiance map ``L[row, col]`` (W m^-2 sr^-1) uses the layout of
:func:`mincam_render.scenes.sky.envmap_directions` with its ``to_world``: a world
direction ``(x, y, z)`` (+z up) has ``phi = atan2(x, y)``, ``theta = acos(z)``,
and texel ``(row, col)`` is centred at ``theta = pi (row + 1/2) / H``,
``phi = 2 pi (col + 1/2) / W``. Lookups are bilinear, periodic in ``phi``
and clamped in ``theta``. The map is the ``"<key>.data"`` parameter
(flat ``H*W`` floats), updatable per frame.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import drjit as dr
import mitsuba as mi
import numpy as np

#: Plugin name registered with Mitsuba.
PLUGIN_NAME = "portal_sky"
#: Parameter name of the flat radiance map.
DATA_PARAM = "data"


class PortalSkyEmitter(mi.Emitter):
    """Infinite emitter of a lat-long radiance map, sampled through one rectangle.

    Properties (set by :func:`mincam_render.render.mitsuba_scene.portal_sky`):
        corner: a corner of the window (m, world).
        edge_u, edge_v: the window's two edges from ``corner`` (m, world,
            perpendicular); ``edge_u x edge_v`` points out of the room.
        data: radiance map, ``TensorXf`` of shape (H, W) (W m^-2 sr^-1).
    """

    def __init__(self, props: mi.Properties) -> None:
        super().__init__(props)
        self.m_flags = mi.EmitterFlags.Infinite
        corner = np.asarray(props["corner"], dtype=np.float64)
        eu = np.asarray(props["edge_u"], dtype=np.float64)
        ev = np.asarray(props["edge_v"], dtype=np.float64)
        normal = np.cross(eu, ev)
        area = float(np.linalg.norm(normal))
        if area <= 0 or abs(float(eu @ ev)) > 1e-6 * area:
            raise ValueError(
                f"portal_sky: edges {eu.tolist()} and {ev.tolist()} must be perpendicular "
                "and non-zero (m)"
            )
        tensor = props["data"]
        self.height, self.width = (int(s) for s in tensor.shape[:2])
        self.data = mi.Float(dr.ravel(tensor.array))
        self.area_m2 = area
        self.corner = [float(c) for c in corner]
        self.edge_u = [float(c) for c in eu]
        self.edge_v = [float(c) for c in ev]
        self.normal = [float(c) for c in normal / area]
        self.far_m = 1e4

    # -- Mitsuba interface
    def set_scene(self, scene: mi.Scene) -> None:
        """Place the far end of shadow rays beyond the scene's bounding box."""
        bbox = scene.bbox()
        if bbox.valid():
            self.far_m = float(2.0 * (dr.norm(bbox.extents()) + 1.0))

    def traverse(self, callback: mi.TraversalCallback) -> None:
        """Expose the radiance map as ``data`` (updatable per frame)."""
        callback.put(DATA_PARAM, self.data, mi.ParamFlags.NonDifferentiable)

    def parameters_changed(self, keys: Sequence[str] | None = None) -> None:
        """Check that an updated map keeps its size."""
        if dr.width(self.data) != self.height * self.width:
            raise ValueError(
                f"portal_sky: data has {dr.width(self.data)} values; the map is "
                f"{self.height} x {self.width}"
            )

    def eval(
        self, si: mi.SurfaceInteraction3f, active: bool | dr.auto.ad.Bool = True
    ) -> mi.Spectrum:
        """Radiance arriving along ``-si.wi`` (a ray that escaped the scene)."""
        return mi.Spectrum(self._radiance(-si.wi))

    def sample_direction(
        self, it: mi.Interaction3f, sample: mi.Point2f, active: bool | dr.auto.ad.Bool = True
    ) -> tuple[mi.DirectionSample3f, mi.Spectrum]:
        """A direction through a uniform point of the window; weight = radiance / density."""
        c, eu, ev, n = (
            mi.Vector3f(*v) for v in (self.corner, self.edge_u, self.edge_v, self.normal)
        )
        p = mi.Point3f(c) + eu * sample.x + ev * sample.y
        to_p = p - it.p
        dist2 = dr.squared_norm(to_p)
        dist = dr.sqrt(dist2)
        d = to_p / dist
        cos_w = dr.dot(d, n)
        ok = active & (cos_w > 1e-6)
        pdf = dr.select(ok, dist2 / (self.area_m2 * cos_w), 0.0)
        ds = dr.zeros(mi.DirectionSample3f)
        ds.d = d
        ds.p = it.p + d * self.far_m
        ds.n = -d
        ds.dist = self.far_m
        ds.pdf = pdf
        ds.time = it.time
        ds.delta = mi.Bool(False)
        ds.emitter = mi.EmitterPtr(self)
        value = dr.select(ok, self._radiance(d) / dr.maximum(pdf, 1e-30), 0.0)
        return ds, mi.Spectrum(value)

    def pdf_direction(
        self, it: mi.Interaction3f, ds: mi.DirectionSample3f, active: bool | dr.auto.ad.Bool = True
    ) -> dr.auto.ad.Float:
        """Solid-angle density of :meth:`sample_direction` (0 off the window)."""
        return self._portal_pdf(it.p, ds.d, active)

    def eval_direction(
        self, it: mi.Interaction3f, ds: mi.DirectionSample3f, active: bool | dr.auto.ad.Bool = True
    ) -> mi.Spectrum:
        """Radiance arriving from direction ``ds.d``."""
        return mi.Spectrum(dr.select(active, self._radiance(ds.d), 0.0))

    def sample_ray(
        self,
        time: dr.auto.ad.Float,
        sample1: dr.auto.ad.Float,
        sample2: mi.Point2f,
        sample3: mi.Point2f,
        active: bool | dr.auto.ad.Bool = True,
    ) -> tuple[mi.Ray3f, mi.Spectrum]:
        """Not supported: the portal sky only serves paths traced from the camera."""
        raise NotImplementedError("portal_sky: light tracing is not supported")

    def to_string(self) -> str:
        """Short description."""
        return (
            f"PortalSkyEmitter[window {self.area_m2:.3g} m^2 at {self.corner}, "
            f"map {self.height}x{self.width}]"
        )

    # -- helpers (Dr.Jit arrays)
    def _portal_pdf(self, x: mi.Point3f, d: mi.Vector3f, active: mi.Bool) -> mi.Float:
        """Solid-angle density of :meth:`sample_direction` for direction ``d`` at ``x``."""
        c, eu, ev, n = (
            mi.Vector3f(*v) for v in (self.corner, self.edge_u, self.edge_v, self.normal)
        )
        cos_w = dr.dot(d, n)
        t = dr.dot(mi.Vector3f(c) - mi.Vector3f(x), n) / cos_w
        hit = mi.Vector3f(x) + d * t - c
        a = dr.dot(hit, eu) / dr.squared_norm(eu)
        b = dr.dot(hit, ev) / dr.squared_norm(ev)
        inside = active & (cos_w > 1e-6) & (t > 0) & (a >= 0) & (a <= 1) & (b >= 0) & (b <= 1)
        return dr.select(inside, t * t / (self.area_m2 * cos_w), 0.0)

    def _radiance(self, d: mi.Vector3f) -> mi.Float:
        """Bilinear lookup of the map in world direction ``d`` (unit, +z up)."""
        h, w = self.height, self.width
        phi = dr.atan2(d.x, d.y)
        theta = dr.safe_acos(d.z)
        fu = phi * (w / (2.0 * math.pi)) - 0.5
        fv = theta * (h / math.pi) - 0.5
        u0 = dr.floor(fu)
        v0 = dr.floor(fv)
        tu, tv = fu - u0, fv - v0
        iu0 = mi.Int32(u0)
        iu0 = dr.select(iu0 < 0, iu0 + w, iu0)
        iu0 = dr.select(iu0 >= w, iu0 - w, iu0)
        iu1 = dr.select(iu0 + 1 >= w, iu0 + 1 - w, iu0 + 1)
        iv0 = dr.clip(mi.Int32(v0), 0, h - 1)
        iv1 = dr.clip(mi.Int32(v0) + 1, 0, h - 1)

        def at(iv: mi.Int32, iu: mi.Int32) -> mi.Float:
            return dr.gather(mi.Float, self.data, mi.UInt32(iv * w + iu))

        top = dr.lerp(at(iv0, iu0), at(iv0, iu1), tu)
        bottom = dr.lerp(at(iv1, iu0), at(iv1, iu1), tu)
        return dr.lerp(top, bottom, tv)


def register() -> None:
    """Register the plugin with Mitsuba (idempotent; needs the variant set)."""
    mi.register_emitter(PLUGIN_NAME, lambda props: PortalSkyEmitter(props))
