"""The one place that builds Mitsuba scene dicts and loads user scenes.

Everything here is in SI units: metres, and radiance in W m^-2 sr^-1 in the
detector's band (monochrome variants). Dicts are built by small functions so
scene families can compose them; :func:`load_scene` accepts what users bring.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, Union

import mitsuba as mi

from mincam_render.render.backend import use_variant

if TYPE_CHECKING:
    import numpy as np
    from numpy.typing import ArrayLike

    from mincam_render.optics.camera import FreeformCamera

#: A Mitsuba scene dictionary, the form ``mi.load_dict`` takes: ``{"type": plugin,
#: ...}`` with nested plugin dicts, numbers, strings and Mitsuba objects (transforms,
#: bitmaps) as values. Mitsuba's format, not ours: typed only as far as Mitsuba types it.
MitsubaDict = dict[str, Any]

#: What :func:`load_scene` accepts.
SceneInput = Union[MitsubaDict, str, os.PathLike, "mi.Scene"]


class SceneError(ValueError):
    """A scene could not be loaded or described."""


def load_scene(scene: SceneInput, *, optimize: bool = True) -> mi.Scene:
    """Return an ``mi.Scene`` from a scene dict, an XML file path, or a loaded scene.

    ``optimize=False`` keeps every shape of an XML file as it is: Mitsuba's
    optimizations merge meshes that share a BSDF, ids and all.

    Raises:
        SceneError: the file is missing or unreadable, or Mitsuba rejects the scene.

    """
    use_variant()
    if isinstance(scene, mi.Scene):
        return scene
    if isinstance(scene, dict):
        if scene.get("type") != "scene":
            raise SceneError(
                f"scene dict has type = {scene.get('type')!r}: a Mitsuba scene dict needs "
                "type = 'scene'"
            )
        try:
            return mi.load_dict(scene)
        except Exception as err:  # Mitsuba raises RuntimeError/TypeError variants
            raise SceneError(f"Mitsuba rejected the scene dict: {_first_line(err)}") from err
    if isinstance(scene, str | os.PathLike):
        path = Path(scene)
        if not path.is_file():
            raise SceneError(f"scene file {str(path)!r} does not exist or is not a file")
        try:
            return mi.load_file(str(path), optimize=optimize)
        except Exception as err:
            raise SceneError(f"Mitsuba could not load {str(path)!r}: {_first_line(err)}") from err
    raise SceneError(
        f"scene of type {type(scene).__name__} is not supported: pass a Mitsuba scene dict, "
        "a path to a Mitsuba XML file, or an mi.Scene"
    )


def _first_line(err: Exception) -> str:
    text = str(err).strip().splitlines()
    return text[-1] if text else type(err).__name__


def _to_world(
    position: Sequence[float] | np.ndarray,
    look_at: Sequence[float] | np.ndarray | None = None,
    up: Sequence[float] | np.ndarray = (0.0, 1.0, 0.0),
    scale: Sequence[float] | np.ndarray | None = None,
) -> mi.ScalarTransform4f:
    use_variant()
    t = mi.ScalarTransform4f()
    if look_at is not None:
        t = t.look_at(origin=list(position), target=list(look_at), up=list(up))
    else:
        t = t.translate(list(position))
    if scale is not None:
        t = t @ mi.ScalarTransform4f().scale(list(scale))
    return t


def diffuse(reflectance: float) -> MitsubaDict:
    """A Lambertian BSDF of albedo ``reflectance`` (0-1)."""
    return {"type": "diffuse", "reflectance": {"type": "rgb", "value": float(reflectance)}}


def constant_environment(radiance_w_m2_sr: float) -> MitsubaDict:
    """A uniform environment emitter of radiance ``radiance_w_m2_sr`` (W m^-2 sr^-1)."""
    return {"type": "constant", "radiance": {"type": "rgb", "value": float(radiance_w_m2_sr)}}


def rectangle(
    center_m: Sequence[float] | np.ndarray,
    facing_m: Sequence[float] | np.ndarray,
    size_m: Sequence[float] | np.ndarray,
    bsdf: MitsubaDict | None = None,
    radiance_w_m2_sr: float | None = None,
    up: Sequence[float] | np.ndarray = (0.0, 1.0, 0.0),
) -> MitsubaDict:
    """A ``(width, height)`` rectangle centred at ``center_m``, front facing ``facing_m``.

    With ``radiance_w_m2_sr`` it is an area emitter (one-sided, W m^-2 sr^-1).
    """
    w, h = size_m
    shape: MitsubaDict = {
        "type": "rectangle",
        # Mitsuba's rectangle spans [-1, 1]^2 in z = 0 with normal +z; look_at
        # points +z at the target.
        "to_world": _to_world(center_m, facing_m, up, (w / 2.0, h / 2.0, 1.0)),
        "bsdf": bsdf if bsdf is not None else diffuse(0.0),
    }
    if radiance_w_m2_sr is not None:
        shape["emitter"] = {"type": "area", "radiance": {"type": "rgb", "value": radiance_w_m2_sr}}
    return shape


def sphere(
    center_m: Sequence[float] | np.ndarray,
    radius_m: float,
    bsdf: MitsubaDict | None = None,
    radiance_w_m2_sr: float | None = None,
) -> MitsubaDict:
    """A sphere; an area emitter when ``radiance_w_m2_sr`` is given (W m^-2 sr^-1)."""
    shape: MitsubaDict = {
        "type": "sphere",
        "center": list(map(float, center_m)),
        "radius": float(radius_m),
        "bsdf": bsdf if bsdf is not None else diffuse(0.0),
    }
    if radiance_w_m2_sr is not None:
        shape["emitter"] = {"type": "area", "radiance": {"type": "rgb", "value": radiance_w_m2_sr}}
    return shape


def scene_dict(shapes: dict[str, MitsubaDict | mi.Mesh], *, max_depth: int = 4) -> MitsubaDict:
    """Wrap named shape/emitter dicts into a scene with a path integrator."""
    d: MitsubaDict = {"type": "scene", "integrator": {"type": "path", "max_depth": max_depth}}
    d.update(shapes)
    return d


def demo_scene() -> MitsubaDict:
    """A small room-like demo scene for the default camera (board at the origin, facing +z).

    A grey back wall 2 m away, a floor, a lit bright panel up and right, a
    diffuse sphere, and a dim sky-like environment (~100 lux indoors).
    """
    return scene_dict(
        {
            "sky": constant_environment(5.0),
            "back_wall": rectangle((0.0, 0.0, 2.0), (0.0, 0.0, 0.0), (4.0, 3.0), diffuse(0.6)),
            "floor": rectangle(
                (0.0, -1.0, 1.0), (0.0, 0.0, 1.0), (4.0, 4.0), diffuse(0.3), up=(0.0, 0.0, 1.0)
            ),
            # world -x is the camera's right (board looks along +z with +y up)
            "lamp": rectangle(
                (-0.6, 0.5, 1.95),
                (-0.6, 0.5, 0.0),
                (0.4, 0.3),
                diffuse(0.0),
                radiance_w_m2_sr=200.0,
            ),
            "ball": sphere((0.4, -0.6, 1.2), 0.3, diffuse(0.8)),
        }
    )


def _irradiance_sensor() -> MitsubaDict:
    """Mitsuba's irradiance meter on the shape holding it: one luminance value (W/m^2)."""
    return {
        "type": "irradiancemeter",
        "film": {
            "type": "hdrfilm",
            "width": 1,
            "height": 1,
            "rfilter": {"type": "box"},
            "pixel_format": "luminance",
        },
    }


def with_mask_geometry(
    scene: MitsubaDict,
    camera: FreeformCamera,
    detector: int,
    transmittance: ArrayLike,
    *,
    max_depth: int,
) -> MitsubaDict:
    """Copy of ``scene`` with one freeform pixel built as geometry, for validation.

    Adds, around detector ``detector`` of ``camera``: the mask as a thin sheet
    whose pass-through probability is ``transmittance[row, col]`` (Mitsuba's
    ``mask`` BSDF over a black diffuse), an opaque black housing from the board
    to the mask edges, and an ``irradiancemeter`` on the diode's active area.
    Rendering it measures the detector's irradiance (W/m^2) through the mask,
    independently of :mod:`mincam_render.render.transport`. The pass through the
    sheet is one extra path vertex, so the integrator depth is ``max_depth + 1``.
    """
    import numpy as np

    use_variant()
    right, up, fwd = camera.frame
    centre = camera.detector_centers_m[detector]
    # local x = -right keeps the frame proper (det +1), so the diode's front is +fwd
    rot = np.column_stack([-right, up, fwd])

    def placed(
        offset_local: Sequence[float] | np.ndarray,
        scale: Sequence[float] | np.ndarray,
        extra: np.ndarray | None = None,
    ) -> mi.ScalarTransform4f:
        m = np.eye(4)
        m[:3, :3] = rot @ (extra if extra is not None else np.eye(3)) @ np.diag(scale)
        m[:3, 3] = centre + rot @ np.asarray(offset_local, dtype=np.float64)
        return mi.ScalarTransform4f(m)

    w, d, a = camera.mask_size_m, camera.mask_distance_m, camera.detector_size_m
    m = np.asarray(transmittance, dtype=np.float32)
    # bitmap rows run along local +y from the bottom and columns along local +x
    # (= camera left): flip both so our row 0 (top) / col 0 (left) land right.
    opacity = np.ascontiguousarray(1.0 - m[::-1, ::-1])[..., None]
    rot_y90 = np.array([[0, 0, 1], [0, 1, 0], [-1, 0, 0]], dtype=np.float64)
    rot_x90 = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]], dtype=np.float64)
    out = dict(scene)
    out["integrator"] = {"type": "path", "max_depth": max_depth + 1}
    out["_mincam_mask"] = {
        "type": "rectangle",
        "to_world": placed((0, 0, d), (w / 2, w / 2, 1)),
        "bsdf": {
            "type": "mask",
            "opacity": {
                "type": "bitmap",
                "data": mi.TensorXf(opacity),
                "raw": True,
                "filter_type": "nearest",
                "wrap_mode": "clamp",
            },
            "bsdf": diffuse(0.0),
        },
    }
    for name, offset, extra, scale in (
        ("_mincam_wall_px", (w / 2, 0, d / 2), rot_y90, (d / 2, w / 2, 1)),
        ("_mincam_wall_nx", (-w / 2, 0, d / 2), rot_y90, (d / 2, w / 2, 1)),
        ("_mincam_wall_py", (0, w / 2, d / 2), rot_x90, (w / 2, d / 2, 1)),
        ("_mincam_wall_ny", (0, -w / 2, d / 2), rot_x90, (w / 2, d / 2, 1)),
    ):
        out[name] = {
            "type": "rectangle",
            "to_world": placed(offset, scale, extra),
            "bsdf": diffuse(0.0),
        }
    out["_mincam_diode"] = {
        "type": "rectangle",
        "to_world": placed((0, 0, 0), (a / 2, a / 2, 1)),
        "sensor": _irradiance_sensor() | {"id": "_mincam_irradiancemeter"},
    }
    return out


def irradiance_meter(
    center_m: Sequence[float] | np.ndarray,
    normal: Sequence[float] | np.ndarray,
    tangent: Sequence[float] | np.ndarray,
    size_m: tuple[float, float],
) -> MitsubaDict:
    """A flat rectangular ``irradiancemeter`` (a panel or a lux meter), not part of any scene.

    Rendered with ``mi.render(scene, sensor=loaded.sensor())`` it measures the mean
    irradiance (W/m^2) over its front face: cosine-weighted rays into the
    hemisphere around ``normal``. It casts no shadow (it is not in the scene).

    Args:
        center_m: centre of the rectangle (m, world), shape (3,).
        normal: direction the front face looks toward (world), shape (3,), any length.
        tangent: direction of the first side (world), not parallel to ``normal``.
        size_m: ``(width, height)`` (m) along ``tangent`` and ``normal x tangent``.

    Raises:
        ValueError: a side <= 0, or ``tangent`` parallel to ``normal``.
    """
    import numpy as np

    use_variant()
    width, height = (float(v) for v in size_m)
    if not (width > 0 and height > 0):
        raise ValueError(f"size_m = {size_m!r}: both sides must be > 0 (m)")
    z = np.asarray(normal, dtype=np.float64)
    z = z / np.linalg.norm(z)
    t = np.asarray(tangent, dtype=np.float64)
    x = t - (t @ z) * z
    if np.linalg.norm(x) < 1e-9 * max(1.0, float(np.linalg.norm(t))):
        raise ValueError(f"tangent {list(t)} is parallel to normal {list(z)}")
    x = x / np.linalg.norm(x)
    m = np.eye(4)
    # rectangle: [-1, 1]^2 in local x, y, front face toward local +z
    m[:3, :3] = np.column_stack([x * width / 2, np.cross(z, x) * height / 2, z])
    m[:3, 3] = np.asarray(center_m, dtype=np.float64)
    return {
        "type": "rectangle",
        "to_world": mi.ScalarTransform4f(m),
        "sensor": _irradiance_sensor(),
    }


#: Name of a mesh's per-vertex albedo attribute (see :func:`mesh`).
VERTEX_ALBEDO = "vertex_albedo"


def mesh(
    name: str,
    vertices_m: ArrayLike,
    faces: ArrayLike,
    *,
    reflectance: ArrayLike,
    radiance_w_m2_sr: float | None = None,
) -> mi.Mesh:
    """A triangle mesh object (e.g. from trimesh) with a diffuse BSDF, for a scene dict.

    Its ``vertex_positions`` can be updated per frame with ``mi.traverse``
    (key ``"<dict key>.vertex_positions"``), keeping the face count fixed.

    Args:
        name: Mitsuba object id.
        vertices_m: ``(V, 3)`` vertex positions (m).
        faces: ``(F, 3)`` vertex indices.
        reflectance: diffuse albedo, 0-1: one number, or one per vertex (``(V,)``,
            interpolated over faces; updatable via ``"<dict key>.vertex_albedo"``).
        radiance_w_m2_sr: makes the mesh an area emitter (W m^-2 sr^-1).
    """
    import numpy as np

    use_variant()
    v = np.asarray(vertices_m, dtype=np.float32)
    f = np.asarray(faces, dtype=np.uint32)
    albedo = np.asarray(reflectance, dtype=np.float32)
    if albedo.ndim and albedo.shape != (len(v),):
        raise ValueError(
            f"mesh {name!r}: reflectance of shape {albedo.shape}: allowed a number or one "
            f"per vertex ({len(v)},)"
        )
    props = mi.Properties()
    props["bsdf"] = mi.load_dict(
        {"type": "diffuse", "reflectance": {"type": "mesh_attribute", "name": VERTEX_ALBEDO}}
        if albedo.ndim
        else diffuse(float(albedo))
    )
    if radiance_w_m2_sr is not None:
        props["emitter"] = mi.load_dict(
            {"type": "area", "radiance": {"type": "rgb", "value": float(radiance_w_m2_sr)}}
        )
    m = mi.Mesh(
        name,
        vertex_count=len(v),
        face_count=len(f),
        has_vertex_normals=False,
        has_vertex_texcoords=False,
        props=props,
    )
    if albedo.ndim:
        m.add_attribute(VERTEX_ALBEDO, 1, mi.Float(albedo))
    params = mi.traverse(m)
    params["vertex_positions"] = mi.Float(v.ravel())
    params["faces"] = mi.UInt32(f.ravel())
    params.update()
    return m


def environment_map(
    radiance_w_m2_sr: ArrayLike, to_world: mi.ScalarTransform4f | None = None
) -> MitsubaDict:
    """An environment emitter from a lat-long map ``L[row, col]`` (W m^-2 sr^-1).

    Row 0 is the zenith of the map's frame (Mitsuba's +y up by default).
    The map can be updated per frame via the ``"<key>.data"`` parameter.
    """
    import numpy as np

    use_variant()
    data = np.ascontiguousarray(np.asarray(radiance_w_m2_sr, dtype=np.float32))[..., None]
    d: MitsubaDict = {"type": "envmap", "bitmap": mi.Bitmap(data)}
    if to_world is not None:
        d["to_world"] = to_world
    return d


def portal_sky(
    radiance_w_m2_sr: ArrayLike,
    corner_m: Sequence[float] | np.ndarray,
    edge_u_m: Sequence[float] | np.ndarray,
    edge_v_m: Sequence[float] | np.ndarray,
) -> MitsubaDict:
    """Sky and ground seen through one window, sampled through it (a light portal).

    ``radiance_w_m2_sr`` is a lat-long map ``L[row, col]`` in the layout of
    :func:`mincam_render.scenes.sky.envmap_directions` (W m^-2 sr^-1); the
    window is the rectangle ``corner_m + a edge_u_m + b edge_v_m``, ``a, b`` in
    [0, 1] (m, world), with ``edge_u_m x edge_v_m`` pointing out of the room.
    See :mod:`mincam_render.render.portal_sky`; update the map per frame via
    ``"<key>.data"`` with :func:`portal_sky_data`.
    """
    import numpy as np

    from mincam_render.render import portal_sky as ps

    use_variant()
    ps.register()
    data = np.ascontiguousarray(np.asarray(radiance_w_m2_sr, dtype=np.float32))
    return {
        "type": ps.PLUGIN_NAME,
        "corner": mi.ScalarPoint3f(*map(float, corner_m)),
        "edge_u": mi.ScalarVector3f(*map(float, edge_u_m)),
        "edge_v": mi.ScalarVector3f(*map(float, edge_v_m)),
        "data": mi.TensorXf(data),
    }


def sun_patch_integrator(
    corner_m: Sequence[float] | np.ndarray,
    edge_u_m: Sequence[float] | np.ndarray,
    edge_v_m: Sequence[float] | np.ndarray,
    *,
    max_depth: int = -1,
) -> MitsubaDict:
    """The :mod:`~mincam_render.render.sun_patch` path tracer as an integrator dict (``mi.render``).

    The window is the rectangle ``corner_m + a edge_u_m + b edge_v_m``, ``a, b``
    in [0, 1] (m, world), ``edge_u_m x edge_v_m`` pointing out of the room;
    ``max_depth`` in path segments (-1: no limit). Render inside
    :func:`mincam_render.render.sun_patch.sun_sampled_apart`.
    """
    from mincam_render.render import sun_patch as sp

    use_variant()
    sp.register()
    return {
        "type": sp.PLUGIN_NAME,
        "corner": mi.ScalarPoint3f(*map(float, corner_m)),
        "edge_u": mi.ScalarVector3f(*map(float, edge_u_m)),
        "edge_v": mi.ScalarVector3f(*map(float, edge_v_m)),
        "max_depth": int(max_depth),
    }


def portal_sky_data(radiance_w_m2_sr: ArrayLike) -> mi.Float:
    """Flat value of a :func:`portal_sky`'s ``"<key>.data"`` from ``L[row, col]``."""
    import numpy as np

    use_variant()
    return mi.Float(np.ascontiguousarray(np.asarray(radiance_w_m2_sr, dtype=np.float32)).ravel())


def directional_light(
    direction: Sequence[float] | np.ndarray, irradiance_w_m2: float
) -> MitsubaDict:
    """A distant light (e.g. the sun) travelling along ``direction``, irradiance in W/m^2."""
    return {
        "type": "directional",
        "direction": list(map(float, direction)),
        "irradiance": {"type": "rgb", "value": float(irradiance_w_m2)},
    }


def textured_emitter_rectangle(
    center_m: Sequence[float] | np.ndarray,
    facing_m: Sequence[float] | np.ndarray,
    size_m: Sequence[float] | np.ndarray,
    radiance_w_m2_sr: ArrayLike,
    up: Sequence[float] | np.ndarray = (0.0, 1.0, 0.0),
) -> MitsubaDict:
    """A rectangle emitting a radiance image ``L[row, col]`` (W m^-2 sr^-1), nearest filtered.

    Row 0 of the image is the ``up`` edge and column 0 the left edge as seen by
    a viewer the rectangle faces. Update per frame via ``"<key>.emitter.radiance.data"``
    with :func:`emitter_image_data`.
    """
    import numpy as np

    use_variant()
    w, h = size_m
    data = emitter_image_data(np.asarray(radiance_w_m2_sr, dtype=np.float32))
    return {
        "type": "rectangle",
        "to_world": _to_world(center_m, facing_m, up, (w / 2.0, h / 2.0, 1.0)),
        "bsdf": diffuse(0.0),
        "emitter": {
            "type": "area",
            "radiance": {
                "type": "bitmap",
                "bitmap": mi.Bitmap(data.numpy()),
                "raw": True,
                "filter_type": "nearest",
            },
        },
    }


def emitter_image_data(radiance_w_m2_sr: ArrayLike) -> mi.TensorXf:
    """Tensor for a textured rectangle's ``radiance.data`` from ``L[row, col]``.

    Mitsuba's bitmap rows start at the rectangle's local -y (bottom) edge, so the
    image is flipped vertically; columns already run left to right for a viewer
    the rectangle faces (checked by ``tests/scenes/test_scenes.py``).
    """
    import numpy as np

    use_variant()
    img = np.asarray(radiance_w_m2_sr, dtype=np.float32)
    return mi.TensorXf(np.ascontiguousarray(img[::-1, :])[..., None])


def perspective_sensor(
    position_m: Sequence[float] | np.ndarray,
    look_at_m: Sequence[float] | np.ndarray,
    up: Sequence[float] | np.ndarray,
    fov_deg: float,
    width: int,
    height: int,
) -> mi.Sensor:
    """A pinhole camera (loaded ``mi.Sensor``) for previews: ``fov_deg`` is horizontal."""
    use_variant()
    return mi.load_dict(
        {
            "type": "perspective",
            "to_world": _to_world(position_m, look_at_m, up),
            "fov": float(fov_deg),
            "fov_axis": "x",
            "film": {
                "type": "hdrfilm",
                "width": int(width),
                "height": int(height),
                "rfilter": {"type": "box"},
                "pixel_format": "luminance",
            },
        }
    )


def directional_light_to_world(direction: Sequence[float] | np.ndarray) -> mi.ScalarTransform4f:
    """``to_world`` of a distant light travelling along ``direction``, for per-frame updates.

    Set it as ``"<key>.to_world"`` of a :func:`directional_light` (e.g. the sun
    moving over a day); the light's local +z becomes ``direction``.
    """
    import numpy as np

    use_variant()
    d = np.asarray(direction, dtype=np.float64)
    d = d / np.linalg.norm(d)
    up = (0.0, 1.0, 0.0) if abs(d[2]) > 0.99 else (0.0, 0.0, 1.0)
    return mi.ScalarTransform4f().look_at(origin=[0.0, 0.0, 0.0], target=list(d), up=list(up))


def environment_map_data(radiance_w_m2_sr: ArrayLike) -> mi.TensorXf:
    """Tensor for an :func:`environment_map`'s ``"<key>.data"`` from a lat-long map ``L[row, col]``.

    Mitsuba stores the map with one wrap-around column on each side and three
    channels (also in monochrome variants); the new map must have the size the
    emitter was built with.
    """
    import numpy as np

    use_variant()
    m = np.asarray(radiance_w_m2_sr, dtype=np.float32)
    padded = np.concatenate([m[:, -1:], m, m[:, :1]], axis=1)
    return mi.TensorXf(np.ascontiguousarray(np.repeat(padded[..., None], 3, axis=-1)))
