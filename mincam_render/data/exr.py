"""OpenEXR files of transport images (one float32 channel per detector)."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import OpenEXR

from mincam_render.core import strict_json

_CHANNEL = "detector{:04d}"


def write_transport_exr(path: str | os.PathLike, transport_w: np.ndarray, metadata: dict) -> Path:
    """Write ``T[detector, row, col]`` (W) to ``path`` atomically, one channel per detector.

    ``metadata`` (JSON-serialisable) is stored in the header as ``mincam_metadata``.
    Row 0 of each channel is the top of the image (EXR's convention and ours).
    """
    t = np.asarray(transport_w, dtype=np.float32)
    if t.ndim != 3:
        raise ValueError(f"transport has shape {t.shape}: expected (detector, row, col)")
    path = Path(path)
    header = {
        "compression": OpenEXR.ZIP_COMPRESSION,
        "type": OpenEXR.scanlineimage,
        "mincam_units": "W per unit transmittance",
        "mincam_metadata": strict_json.dumps(metadata, indent=None),
    }
    channels = {_CHANNEL.format(k): np.ascontiguousarray(t[k]) for k in range(t.shape[0])}
    tmp = path.with_name(path.name + ".partial.exr")
    OpenEXR.File(header, channels).write(str(tmp))
    os.replace(tmp, path)
    return path


def read_transport_exr(path: str | os.PathLike) -> tuple[np.ndarray, dict]:
    """Read a file written by :func:`write_transport_exr`: ``(T[detector, row, col], metadata)``."""
    f = OpenEXR.File(str(path))
    channels = f.channels()
    names = sorted(n for n in channels if n.startswith("detector"))
    if not names:
        raise ValueError(f"{path}: no 'detectorNNNN' channels; not a transport image file")
    t = np.stack([np.asarray(channels[n].pixels, dtype=np.float32) for n in names])
    meta = json.loads(f.header().get("mincam_metadata", "{}"))
    return t, meta
