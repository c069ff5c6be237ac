"""Mask export: true-size print sheet, 16-bit PNGs, EXR, sidecar, printable range."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import OpenEXR
import pytest
from PIL import Image

from mincam_render.export.masks import (
    MIN_SHEET_WIDTH_MM,
    SHEET_MARGIN_MM,
    export_masks,
    sheet_layout,
)
from mincam_render.optics.camera import MM, DetectorLayout, FreeformCamera


@pytest.fixture
def camera() -> FreeformCamera:
    return FreeformCamera(
        mask_resolution=(8, 12), layout=DetectorLayout.grid(rows=2, cols=3, pitch_m=20 * MM)
    )


@pytest.fixture
def exported(tmp_path, camera, rng):
    m = rng.uniform(-0.1, 1.1, (6, 8, 12))  # partly outside the printable range
    return m, export_masks(
        m, camera, tmp_path / "task", task="demo", provenance={"run": "runs/x", "dataset": "data/y"}
    )


def test_sheet_size_in_mm(camera):
    w, h, corners = sheet_layout(camera)
    # the masks span 2 * 20 + 16 mm; the sheet is at least wide enough for its title
    assert w == pytest.approx(max(2 * 20 + 16 + 2 * SHEET_MARGIN_MM, MIN_SHEET_WIDTH_MM))
    assert h == pytest.approx(20 + 16 + 2 * SHEET_MARGIN_MM)
    # detector 0 is top-left on the board (seen from the detector side)
    np.testing.assert_allclose(corners[0], [SHEET_MARGIN_MM, SHEET_MARGIN_MM])
    np.testing.assert_allclose(corners[5] - corners[0], [40.0, 20.0])


def test_svg_true_size_and_masks(exported, camera):
    _, paths = exported
    svg = paths.svg.read_text()
    w, h, _ = sheet_layout(camera)
    head = re.search(
        r'<svg [^>]*width="([\d.]+)mm" height="([\d.]+)mm" viewBox="0 0 ([\d.]+) '
        r'([\d.]+)"',
        svg,
    )
    assert head is not None
    assert float(head.group(1)) == pytest.approx(w) and float(head.group(2)) == pytest.approx(h)
    assert float(head.group(3)) == pytest.approx(w)  # 1 user unit = 1 mm
    sizes = re.findall(r'<image [^>]*width="([\d.]+)" height="([\d.]+)"', svg)
    assert len(sizes) == 6
    assert all(
        float(a) == pytest.approx(16.0) and float(b) == pytest.approx(16.0) for a, b in sizes
    )
    assert svg.count("<path") >= 6 * 4  # cut marks at every corner
    assert "pixel 5" in svg and "0.01-0.67" in svg


def test_png_is_16_bit_within_printable_range(exported, camera):
    m, paths = exported
    lo, hi = camera.transmittance_range
    assert len(paths.png) == 6
    img = Image.open(paths.png[2])
    assert img.mode.startswith("I;16") and img.size == (12, 8)
    a = np.asarray(img).astype(np.float64) / 65535.0
    assert a.min() >= lo - 1e-5 and a.max() <= hi + 1e-5
    np.testing.assert_allclose(a, np.clip(m[2], lo, hi), atol=1 / 65535)


def test_exr_holds_exact_values(exported):
    m, paths = exported
    ch = OpenEXR.File(str(paths.exr)).channels()
    np.testing.assert_allclose(np.asarray(ch["mask0003"].pixels), m[3].astype(np.float32))


def test_sidecar(exported, camera):
    m, paths = exported
    side = json.loads(paths.json.read_text())
    assert side["camera"]["mask_size_m"] == pytest.approx(16 * MM)
    assert side["printable_transmittance_range"] == [0.01, 0.67]
    assert side["texels_clipped_to_printable_range"] == int(
        np.count_nonzero((m < 0.01) | (m > 0.67))
    )
    assert side["provenance"]["dataset"] == "data/y"
    assert side["units"]["lengths"] == "m"


def test_pdf_page_is_true_size(exported, camera):
    _, paths = exported
    raw = paths.pdf.read_bytes()
    box = re.search(rb"/MediaBox \[\s*([\d.]+) ([\d.]+) ([\d.]+) ([\d.]+)\s*\]", raw)
    w, h, _ = sheet_layout(camera)
    assert float(box.group(3)) == pytest.approx(w / 25.4 * 72, rel=1e-3)
    assert float(box.group(4)) == pytest.approx(h / 25.4 * 72, rel=1e-3)


def test_pdf_texels_are_vector_rectangles_where_the_design_puts_them(exported, camera):
    """Issue 18 item 5: every texel's edges in the PDF within 0.01 mm, its grey exact."""
    import pdfplumber

    m, paths = exported
    lo, hi = camera.transmittance_range
    want = np.clip(m, lo, hi)
    _, _, corners = sheet_layout(camera)
    rows, cols = camera.mask_resolution
    texel_mm = camera.mask_size_m / MM / cols, camera.mask_size_m / MM / rows
    mm_per_pt = 25.4 / 72
    with pdfplumber.open(paths.pdf) as pdf:
        page = pdf.pages[0]
        assert page.images == []  # no raster anywhere: nothing a viewer could resample
        found = {
            (round(r["x0"] * mm_per_pt, 2), round(r["top"] * mm_per_pt, 2)): r
            for r in page.rects
            if r["fill"] and r["width"] * mm_per_pt < 5
        }
    assert len(found) == want.size
    for k, (x, y) in enumerate(corners):
        for r in range(rows):
            for c in range(cols):
                key = (round(x + c * texel_mm[0], 2), round(y + r * texel_mm[1], 2))
                rect = found[key]
                assert abs(rect["x0"] * mm_per_pt - (x + c * texel_mm[0])) < 0.01
                assert abs(rect["top"] * mm_per_pt - (y + r * texel_mm[1])) < 0.01
                assert abs(rect["width"] * mm_per_pt - texel_mm[0]) < 0.01
                assert abs(rect["height"] * mm_per_pt - texel_mm[1]) < 0.01
                assert float(np.ravel(rect["non_stroking_color"])[0]) == pytest.approx(
                    want[k, r, c], abs=1e-6
                )


def test_more_masks_than_board_positions(tmp_path, camera):
    paths = export_masks(np.full((8, 8, 12), 0.3), camera, tmp_path, pdf=False)
    assert len(paths.png) == 8
    assert len(json.loads(paths.json.read_text())["mask_corners_on_sheet_mm"]) == 8


def test_bad_input(tmp_path, camera):
    with pytest.raises(ValueError, match="shape"):
        export_masks(np.zeros((8, 12)), camera, tmp_path)
    with pytest.raises(ValueError, match="NaN"):
        export_masks(np.full((1, 8, 12), np.nan), camera, tmp_path)


KEPT = sorted((Path(__file__).parents[2] / "masks").glob("*/*/masks.json"))


@pytest.mark.parametrize("sidecar", KEPT, ids=lambda p: f"{p.parent.parent.name}/{p.parent.name}")
def test_kept_designs_are_complete_and_agree_with_their_sidecar(sidecar):
    side = json.loads(sidecar.read_text())
    folder = sidecar.parent
    lo, hi = side["printable_transmittance_range"]
    ch = OpenEXR.File(str(folder / side["files"]["exr"])).channels()
    assert len(side["files"]["png"]) == side["masks"] == len(ch)
    for k, name in enumerate(side["files"]["png"]):
        png = np.asarray(Image.open(folder / name), np.float64) / 65535.0
        exr = np.asarray(ch[f"mask{k:04d}"].pixels, np.float64)
        assert png.shape == exr.shape == tuple(side["mask_resolution"])
        np.testing.assert_allclose(png, np.clip(exr, lo, hi), atol=1 / 65535)
    err = side["provenance"]["test_error_over_seeds"]
    assert err["ci95"][0] <= err["mean"] <= err["ci95"][1]
    for ep in side["provenance"]["episodes"].values():
        assert len(ep["manifest_sha256"]) == 64
    assert (folder / side["files"]["svg"]).read_text().lstrip().startswith("<")
    import pdfplumber

    with pdfplumber.open(folder / side["files"]["pdf"]) as pdf:  # vector texels, no raster
        page = pdf.pages[0]
        texels = [r for r in page.rects if r["fill"] and r["width"] < 5 / 25.4 * 72]
        assert page.images == [] and len(texels) == side["masks"] * np.prod(side["mask_resolution"])
