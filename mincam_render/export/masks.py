"""Masks ready to print: 16-bit PNG, OpenEXR, a true-size print sheet and a JSON sidecar.

:func:`export_masks` writes into one directory (``masks/<task>/`` by convention):

* ``mask_KK.png`` -- 16-bit grayscale transmittance, 0..65535 = 0..1, row 0 at
  the top: the mask as seen **from the detector looking out at the scene**
  (``T[detector, row, col]``'s convention; see the README's coordinate frame).
  Printed on a transparency and viewed from the scene side it appears mirrored
  left-right.
* ``masks.exr`` -- the exact float32 transmittance, one channel per mask.
* ``print_sheet.svg`` (and ``print_sheet.pdf``) -- every mask at true physical
  size (``camera.mask_size_m``), laid out as on the board, with cut marks,
  labels and a 10-mm scale bar; transmittance clipped to the printable range.
  Gray level = transmittance (white = clear): a printer's own calibration
  curve (gray level -> film transmittance) must be applied by the user.
* ``masks.json`` -- camera geometry in SI units, units, the printable range,
  the signed pairs (a signed camera's masks ``2j`` and ``2j + 1``: output ``j``
  is the first photodiode's reading minus the second's; null otherwise), and
  the dataset/run that produced the masks.
"""

from __future__ import annotations

import base64
import functools
import io
import os
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from PIL import Image

from mincam_render.core import strict_json
from mincam_render.core.strict_json import JsonObject
from mincam_render.optics.camera import MM, FreeformCamera

if TYPE_CHECKING:
    from matplotlib.collections import PolyCollection

#: Sheet margin around the board layout (mm) and offset/length of cut marks (mm).
SHEET_MARGIN_MM = 12.0
CUT_MARK_OFFSET_MM = 0.8
CUT_MARK_LENGTH_MM = 1.6
LABEL_FONT_MM = 1.8


def _atomic_write(path: Path, data: bytes) -> None:
    from mincam_render.data.dataset import atomic_write_bytes

    atomic_write_bytes(path, data)


def _png16(m: np.ndarray) -> bytes:
    """16-bit grayscale PNG bytes of transmittance ``m[row, col]`` in [0, 1]."""
    arr = np.rint(np.clip(m, 0.0, 1.0) * 65535.0).astype(np.uint16)
    buf = io.BytesIO()
    Image.fromarray(arr).save(buf, format="PNG")
    return buf.getvalue()


def _png8(m: np.ndarray) -> bytes:
    arr = np.rint(np.clip(m, 0.0, 1.0) * 255.0).astype(np.uint8)
    buf = io.BytesIO()
    Image.fromarray(arr, mode="L").save(buf, format="PNG")
    return buf.getvalue()


#: Narrowest sheet (mm): room for the title line above a small camera's masks.
MIN_SHEET_WIDTH_MM = 150.0


def sheet_layout(camera: FreeformCamera) -> tuple[float, float, np.ndarray]:
    """Sheet ``(width_mm, height_mm, corners_mm[K, 2])`` (top-left of each mask, y down)."""
    side = camera.mask_size_m / MM
    xy = np.asarray(camera.layout.positions_m) / MM  # board (x right, y up), as seen from behind
    left = xy[:, 0] - side / 2
    top = -xy[:, 1] - side / 2
    x0, y0 = left.min(), top.min()
    # wide enough for the title line (about 1.9 mm per character at LABEL_FONT_MM)
    width = max((left.max() - x0) + side + 2 * SHEET_MARGIN_MM, MIN_SHEET_WIDTH_MM)
    height = (top.max() - y0) + side + 2 * SHEET_MARGIN_MM
    corners = np.stack([left - x0 + SHEET_MARGIN_MM, top - y0 + SHEET_MARGIN_MM], axis=1)
    return float(width), float(height), corners


def print_sheet_svg(masks: np.ndarray, camera: FreeformCamera, *, title: str = "") -> str:
    """SVG text of the print sheet, sized in millimetres (``width="...mm"``).

    Args:
        masks: ``M[pixel, row, col]`` transmittance, already clipped to the printable range.
        camera: geometry (mask size and board layout).
        title: a line printed at the top.

    """
    w, h, corners = sheet_layout(camera)
    side = camera.mask_size_m / MM
    lo, hi = camera.transmittance_range
    parts = [
        '<?xml version="1.0" encoding="UTF-8"?>',
        f'<svg xmlns="http://www.w3.org/2000/svg" xmlns:xlink="http://www.w3.org/1999/xlink" '
        f'width="{w:.3f}mm" height="{h:.3f}mm" viewBox="0 0 {w:.3f} {h:.3f}">',
        f'<rect x="0" y="0" width="{w:.3f}" height="{h:.3f}" fill="white"/>',
        f'<text x="{SHEET_MARGIN_MM / 2:.2f}" y="{SHEET_MARGIN_MM / 2:.2f}" '
        f'font-family="sans-serif" font-size="{LABEL_FONT_MM}">{title} | '
        f"print at 100% | masks {side:g} mm | transmittance {lo:g}-{hi:g} | "
        "seen from the detector side</text>",
    ]
    o, ln = CUT_MARK_OFFSET_MM, CUT_MARK_LENGTH_MM
    for k, (x, y) in enumerate(corners):
        data = base64.b64encode(_png8(masks[k])).decode()
        parts.append(
            f'<image x="{x:.3f}" y="{y:.3f}" width="{side:.3f}" height="{side:.3f}" '
            f'preserveAspectRatio="none" style="image-rendering:pixelated" '
            f'xlink:href="data:image/png;base64,{data}"/>'
        )
        for cx, sx in ((x, -1), (x + side, 1)):
            for cy, sy in ((y, -1), (y + side, 1)):
                # L-shaped crop marks just outside each corner: the cut lines extended
                parts.append(
                    f'<path d="M {cx + sx * o:.3f} {cy:.3f} h {sx * ln:.3f} '
                    f'M {cx:.3f} {cy + sy * o:.3f} v {sy * ln:.3f}" '
                    'stroke="black" stroke-width="0.1" fill="none"/>'
                )
        parts.append(
            f'<text x="{x + side / 2:.3f}" y="{y + side + o + LABEL_FONT_MM:.3f}" '
            f'text-anchor="middle" font-family="sans-serif" font-size="{LABEL_FONT_MM}">'
            f"pixel {k}</text>"
        )
    bar_y = h - SHEET_MARGIN_MM / 2
    parts.append(
        f'<path d="M {SHEET_MARGIN_MM:.3f} {bar_y:.3f} h 10" stroke="black" stroke-width="0.3"/>'
        f'<text x="{SHEET_MARGIN_MM + 11:.3f}" y="{bar_y + 0.6:.3f}" font-family="sans-serif" '
        f'font-size="{LABEL_FONT_MM}">10 mm</text>'
    )
    parts.append("</svg>")
    return "\n".join(parts) + "\n"


def _texel_rectangles(mask: np.ndarray, x_mm: float, y_mm: float, side_mm: float) -> PolyCollection:
    """A PolyCollection of one square per texel of ``mask`` (grey = transmittance), in mm."""
    from matplotlib.collections import PolyCollection

    rows, cols = mask.shape
    tw, th = side_mm / cols, side_mm / rows
    c, r = np.meshgrid(np.arange(cols), np.arange(rows))
    x0, y0 = x_mm + c.ravel() * tw, y_mm + r.ravel() * th
    squares = np.stack(
        [
            np.stack([x0, y0], 1),
            np.stack([x0 + tw, y0], 1),
            np.stack([x0 + tw, y0 + th], 1),
            np.stack([x0, y0 + th], 1),
        ],
        axis=1,
    )
    grey = np.clip(mask.ravel(), 0.0, 1.0)
    return PolyCollection(
        list(squares),
        facecolors=np.stack([grey, grey, grey], axis=1),
        edgecolors="none",
        linewidths=0,
        antialiased=False,
    )


def print_sheet_pdf(
    masks: np.ndarray, camera: FreeformCamera, path: str | os.PathLike, *, title: str = ""
) -> Path:
    """The same sheet as a PDF at true size (matplotlib; 1 data unit = 1 mm).

    Every texel is a filled vector rectangle (no image, so no resampling by the
    viewer or the printer driver): its edges sit where the design puts them.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    w, h, corners = sheet_layout(camera)
    side = camera.mask_size_m / MM
    fig = plt.figure(figsize=(w / 25.4, h / 25.4))
    ax = fig.add_axes((0, 0, 1, 1))
    ax.set_xlim(0, w)
    ax.set_ylim(h, 0)
    ax.axis("off")
    pt_per_mm = 72 / 25.4
    o, ln = CUT_MARK_OFFSET_MM, CUT_MARK_LENGTH_MM
    for k, (x, y) in enumerate(corners):
        ax.add_collection(_texel_rectangles(masks[k], x, y, side))
        for cx, sx in ((x, -1), (x + side, 1)):
            for cy, sy in ((y, -1), (y + side, 1)):
                ax.plot([cx + sx * o, cx + sx * (o + ln)], [cy, cy], "k-", lw=0.1 * pt_per_mm)
                ax.plot([cx, cx], [cy + sy * o, cy + sy * (o + ln)], "k-", lw=0.1 * pt_per_mm)
        ax.text(
            x + side / 2,
            y + side + o + LABEL_FONT_MM,
            f"pixel {k}",
            ha="center",
            fontsize=LABEL_FONT_MM * pt_per_mm,
        )
    lo, hi = camera.transmittance_range
    ax.text(
        SHEET_MARGIN_MM / 2,
        SHEET_MARGIN_MM / 2,
        f"{title} | print at 100% | masks {side:g} mm | transmittance {lo:g}-{hi:g} | "
        "seen from the detector side",
        fontsize=LABEL_FONT_MM * pt_per_mm,
    )
    ax.plot(
        [SHEET_MARGIN_MM, SHEET_MARGIN_MM + 10],
        [h - SHEET_MARGIN_MM / 2] * 2,
        "k-",
        lw=0.3 * pt_per_mm,
    )
    ax.set_xlim(0, w)
    ax.set_ylim(h, 0)
    ax.set_aspect("auto")
    path = Path(path)
    buf = io.BytesIO()
    fig.savefig(buf, format="pdf")
    plt.close(fig)
    _atomic_write(path, buf.getvalue())
    return path


@dataclass(frozen=True, kw_only=True)
class MaskFiles:
    """The files of one export of masks: names inside its folder, or paths.

    Attributes:
        png: ``mask_NN.png`` of every mask, in mask order.
        exr: ``masks.exr``, every mask unclipped.
        svg: ``print_sheet.svg``.
        pdf: ``print_sheet.pdf``, or None when not written.
        json: ``masks.json``, the sidecar.
    """

    png: tuple[Path, ...]
    exr: Path
    svg: Path
    pdf: Path | None
    json: Path

    def in_folder(self, folder: Path) -> MaskFiles:
        """The same files as paths inside ``folder``."""
        return MaskFiles(
            png=tuple(folder / p for p in self.png),
            exr=folder / self.exr,
            svg=folder / self.svg,
            pdf=None if self.pdf is None else folder / self.pdf,
            json=folder / self.json,
        )

    def as_json(self) -> dict[str, str | list[str]]:
        """``{"png": [paths], "exr", "svg", "pdf" (if written), "json"}`` as strings."""
        out: dict[str, str | list[str]] = {
            "png": [str(p) for p in self.png],
            "exr": str(self.exr),
            "svg": str(self.svg),
        }
        if self.pdf is not None:
            out["pdf"] = str(self.pdf)
        out["json"] = str(self.json)
        return out


def export_masks(
    transmittance: np.ndarray,
    camera: FreeformCamera,
    out_dir: str | os.PathLike,
    *,
    task: str = "",
    provenance: Mapping[str, Any] | None = None,
    pdf: bool = True,
    sheet_note: str = "",
    signed: bool = False,
) -> MaskFiles:
    """Write the printable masks of a camera into ``out_dir``, whole.

    The files are written into a fresh folder that then replaces ``out_dir``
    (:func:`~mincam_render.data.folder_swap.swap_in_folder`): an earlier export
    there is replaced entirely (no stale ``mask_NN.png`` survives), and a folder
    holding anything an export does not write is refused.

    Args:
        transmittance: ``M[pixel, row, col]`` (numpy, 0-1); values outside the
            camera's printable range are clipped to it (and counted in the sidecar).
        camera: geometry and printable range; mask ``k`` goes to board position
            ``k`` (with more masks than positions, a 2-row grid is used).
        out_dir: output directory.
        task: task name for labels.
        provenance: dataset/run information for the sidecar (JSON-ready).
        pdf: also write ``print_sheet.pdf``.
        sheet_note: a warning printed in the print sheet's title line
            (``"UNFINISHED RUN (...)"``); none when empty.
        signed: the masks are signed pairs (plus ``2j``, minus ``2j + 1``), said
            in the sidecar and the print sheet's title.

    Returns:
        The paths of the files written (:class:`MaskFiles`).

    Raises:
        ValueError: wrong shape or non-finite values; an odd number of masks
            signed; ``out_dir`` holds other files.

    """
    from mincam_render.data.folder_swap import swap_in_folder

    m = _checked_transmittance(transmittance)
    if signed and m.shape[0] % 2:
        raise ValueError(f"{m.shape[0]} masks signed: signed pixels are pairs of masks")
    pairs = [[k, k + 1] for k in range(0, m.shape[0], 2)] if signed else None
    layout_cam = _layout_camera(camera, m.shape[0])
    title = f"mincam_render masks: {task}" if task else "mincam_render masks"
    if signed:
        title += " | signed pairs: output j = mask 2j - mask 2j+1"
    if sheet_note:
        title += f" | {sheet_note}"
    write = functools.partial(
        _write_export,
        m,
        layout_cam,
        title=title,
        sidecar=functools.partial(_sidecar, task=task, provenance=provenance, pairs=pairs),
        pdf=pdf,
    )
    out = Path(out_dir)
    return swap_in_folder(out, write, owned=_written_by_an_export).in_folder(out)


def _write_export(
    m: np.ndarray,
    layout_cam: FreeformCamera,
    folder: Path,
    *,
    title: str,
    sidecar: Callable[..., JsonObject],
    pdf: bool,
) -> MaskFiles:
    """Write every file of an export of ``M[pixel, row, col]`` into ``folder``; their names.

    ``sidecar(m, clipped, layout_cam, names=...)`` gives ``masks.json``'s content,
    written last.
    """
    clipped = np.clip(m, *layout_cam.transmittance_range)
    png = tuple(Path(f"mask_{k:02d}.png") for k in range(m.shape[0]))
    for k, name in enumerate(png):
        _atomic_write(folder / name, _png16(clipped[k]))
    exr = Path(_write_exr(m, folder / "masks.exr").name)
    svg = Path("print_sheet.svg")
    _atomic_write(folder / svg, print_sheet_svg(clipped, layout_cam, title=title).encode())
    sheet = None
    if pdf:
        sheet = Path(
            print_sheet_pdf(clipped, layout_cam, folder / "print_sheet.pdf", title=title).name
        )
    names = MaskFiles(png=png, exr=exr, svg=svg, pdf=sheet, json=Path("masks.json"))
    record = sidecar(m, clipped, layout_cam, names=names)
    _atomic_write(folder / names.json, strict_json.dumps(record).encode())
    return names


#: The files an export writes besides its ``mask_NN.png``.
EXPORT_FILES = ("masks.exr", "print_sheet.svg", "print_sheet.pdf", "masks.json")
#: Figures a comparison draws beside the masks it keeps (what they look at,
#: :func:`mincam_render.analysis.mask_structure.plot_mask_views`): an export
#: replaces them with the folder, and the comparison draws them again.
COMPANION_FILES = ("looks_at.png",)


def _written_by_an_export(path: Path) -> bool:
    """Whether ``path`` in a masks folder is a file an export writes (or its temporary)."""
    name = path.name
    png = re.fullmatch(r"mask_\d{2,}\.png", name) is not None
    temporary = name.startswith(".") and name.endswith((".tmp", ".tmp.exr"))
    return path.is_file() and (png or temporary or name in EXPORT_FILES + COMPANION_FILES)


def _checked_transmittance(transmittance: np.ndarray) -> np.ndarray:
    """``M[pixel, row, col]`` as float64; raises ValueError for another shape or NaN/inf."""
    m = np.asarray(transmittance, dtype=np.float64)
    if m.ndim != 3:
        raise ValueError(f"transmittance has shape {m.shape}: expected (pixel, row, col)")
    if not np.all(np.isfinite(m)):
        raise ValueError("transmittance contains NaN or inf")
    return m


def _layout_camera(camera: FreeformCamera, num_masks: int) -> FreeformCamera:
    """The camera with one board position per mask.

    With fewer masks than detectors, the first positions; with more (pixels reusing a
    detector's transport), a 1-row (fewer than 4) or 2-row grid at the mask size + 4 mm pitch.
    """
    if num_masks == camera.num_detectors:
        return camera
    from dataclasses import replace

    from mincam_render.optics.camera import DetectorLayout

    if num_masks < camera.num_detectors:
        layout = DetectorLayout(positions_m=camera.layout.positions_m[:num_masks])
    else:
        rows = 1 if num_masks < 4 else 2
        grid = DetectorLayout.grid(
            rows=rows, cols=-(-num_masks // rows), pitch_m=camera.mask_size_m + 4 * MM
        )
        layout = DetectorLayout(positions_m=grid.positions_m[:num_masks])
    return replace(camera, layout=layout)


def _write_exr(m: np.ndarray, path: Path) -> Path:
    """``M[pixel, row, col]`` as float32 channels ``maskKKKK`` of an EXR at ``path`` (atomic)."""
    import OpenEXR

    channels = {
        f"mask{k:04d}": np.ascontiguousarray(m[k].astype(np.float32)) for k in range(m.shape[0])
    }
    header = {
        "compression": OpenEXR.ZIP_COMPRESSION,
        "type": OpenEXR.scanlineimage,
        "mincam_units": "transmittance (0-1), unclipped",
    }
    tmp_exr = path.parent / f".{path.name}.{os.getpid()}.tmp.exr"
    try:
        OpenEXR.File(header, channels).write(str(tmp_exr))
        _atomic_write(path, tmp_exr.read_bytes())
    finally:
        tmp_exr.unlink(missing_ok=True)
    return path


def _sidecar(
    m: np.ndarray,
    clipped: np.ndarray,
    layout_cam: FreeformCamera,
    *,
    task: str,
    provenance: Mapping[str, Any] | None,
    pairs: list[list[int]] | None,
    names: MaskFiles,
) -> JsonObject:
    """``masks.json``: geometry (SI units, sheet in mm), range, pairs, files, provenance."""
    lo, hi = layout_cam.transmittance_range
    w, h, corners = sheet_layout(layout_cam)
    return {
        "task": task,
        "masks": m.shape[0],
        "mask_resolution": list(m.shape[1:]),
        "units": {
            "lengths": "m",
            "transmittance": "0-1 (fraction of light passed)",
            "png": "uint16, 0..65535 = transmittance 0..1",
            "sheet": "mm, origin top-left",
        },
        "orientation": "row 0 = up side of the view, col 0 = left, seen from the detector "
        "looking out (mirror left-right when viewed from the scene side)",
        "printable_transmittance_range": [lo, hi],
        "texels_clipped_to_printable_range": int(np.count_nonzero(clipped != m)),
        "transmittance_min_max": [float(m.min()), float(m.max())],
        "signed_pairs": pairs,
        "sheet_size_mm": [w, h],
        "mask_corners_on_sheet_mm": corners.tolist(),
        "camera": layout_cam.to_dict(),
        "provenance": dict(provenance or {}),
        "files": {
            "png": [str(p) for p in names.png],
            "exr": "masks.exr",
            "svg": "print_sheet.svg",
            "pdf": None if names.pdf is None else str(names.pdf),
        },
    }
