"""Write Mitsuba scene dicts as XML files, so tests can hand the CLI a scene file.

Covers the plugin types of ``mi.cornell_box()`` and our own scene dicts; an
unknown type fails loudly instead of writing a file Mitsuba would misread.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

import mitsuba as mi
import numpy as np

_CATEGORY = {
    **dict.fromkeys(["rectangle", "cube", "sphere", "disk", "obj", "ply"], "shape"),
    **dict.fromkeys(["diffuse", "conductor", "dielectric", "mask"], "bsdf"),
    **dict.fromkeys(["area", "point", "spot", "constant", "directional", "envmap"], "emitter"),
    **dict.fromkeys(["perspective", "irradiancemeter"], "sensor"),
    **dict.fromkeys(["path", "direct"], "integrator"),
    "hdrfilm": "film",
    **dict.fromkeys(["gaussian", "box"], "rfilter"),
    **dict.fromkeys(["independent", "stratified"], "sampler"),
    **dict.fromkeys(["bitmap", "checkerboard"], "texture"),
}


def scene_dict_to_xml(scene: dict, path, *, length_scale: float = 1.0) -> None:
    """Write ``scene`` to ``path``; every ``to_world`` is scaled by ``length_scale`` first.

    ``length_scale`` = 1000 turns a scene in metres into the same scene modelled in
    millimetres (sensor transforms are moved, not scaled, as Mitsuba requires).
    Points are scaled too; scalar lengths (a sphere's radius) are not.
    """
    root = ET.Element("scene", version="3.0.0")
    for key, value in scene.items():
        if key != "type":
            _element(root, key, value, length_scale, top_level=True)
    ET.ElementTree(root).write(path)


def _element(parent, name, value, scale, top_level=False, in_sensor=False):
    if isinstance(value, dict) and value.get("type") == "ref":
        ET.SubElement(parent, "ref", id=value["id"])
    elif isinstance(value, dict) and value.get("type") == "rgb":
        rgb = np.broadcast_to(np.asarray(value["value"], dtype=float), 3)
        ET.SubElement(parent, "rgb", name=name, value=", ".join(f"{v:.9g}" for v in rgb))
    elif isinstance(value, dict):
        plugin = value["type"]
        if plugin not in _CATEGORY:
            raise ValueError(f"mitsuba_xml: no XML tag known for plugin type {plugin!r}")
        attrs = {"type": plugin, "id": name} if top_level else {"type": plugin, "name": name}
        node = ET.SubElement(parent, _CATEGORY[plugin], **attrs)
        for key, inner in value.items():
            if key != "type":
                sensor = in_sensor or _CATEGORY[plugin] == "sensor"
                _element(node, key, inner, scale, in_sensor=sensor)
    elif isinstance(value, mi.ScalarTransform4f):
        matrix = np.array(value.matrix, dtype=np.float64).reshape(4, 4)
        if in_sensor:  # Mitsuba cameras reject scale factors: move, do not scale
            matrix[:3, 3] *= scale
        else:
            matrix = np.diag([scale, scale, scale, 1.0]) @ matrix
        transform = ET.SubElement(parent, "transform", name=name)
        ET.SubElement(transform, "matrix", value=" ".join(f"{v:.9g}" for v in matrix.ravel()))
    elif isinstance(value, list | tuple) and len(value) == 3:  # a point, e.g. a sphere's centre
        x, y, z = (float(v) * (1.0 if in_sensor else scale) for v in value)
        ET.SubElement(parent, "point", name=name, x=f"{x:.9g}", y=f"{y:.9g}", z=f"{z:.9g}")
    elif isinstance(value, bool):
        ET.SubElement(parent, "boolean", name=name, value=str(value).lower())
    elif isinstance(value, int):
        ET.SubElement(parent, "integer", name=name, value=str(value))
    elif isinstance(value, float):
        ET.SubElement(parent, "float", name=name, value=f"{value:.9g}")
    elif isinstance(value, str):
        ET.SubElement(parent, "string", name=name, value=value)
    else:
        raise ValueError(f"mitsuba_xml: cannot write {name} = {value!r}")
