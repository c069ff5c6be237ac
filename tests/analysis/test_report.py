"""HTML reports: embedded figures load in a real headless browser; fidelity rows."""

from __future__ import annotations

import dataclasses
import json
import math
import re
from dataclasses import asdict
from pathlib import Path

import numpy as np
import pytest
from support import chromium, needs_chromium

from mincam_render.analysis.report import Report
from mincam_render.studies.privacy import PrivacyResult


def _page(tmp_path: Path) -> Path:
    from mincam_render.analysis.plots import plt

    page = Report("Test report", banner="SURROGATE test page")
    page.heading("Numbers")
    page.table(["a", "b"], [[1, "<x>"], [2, "y"]], cell_classes=[[None, "pass"], [None, "fail"]])
    for i in range(2):
        fig, ax = plt.subplots(figsize=(3, 2))
        ax.plot(np.arange(5), np.arange(5) ** (i + 1), label="curve")
        ax.set_xlabel("x (s)")
        ax.set_ylabel("y (V)")
        ax.set_title(f"figure {i}")
        ax.legend()
        page.figure(fig, f"caption {i}")
    return page.write(tmp_path / "page.html")


def test_page_is_self_contained_and_escaped(tmp_path):
    text = _page(tmp_path).read_text()
    assert text.count('<img src="data:image/png;base64,') == 2
    assert "&lt;x&gt;" in text and "<x>" not in text
    assert "SURROGATE test page" in text
    assert not re.search(r'src="(?!data:)', text), "external resources would break the page"


@needs_chromium
def test_headless_browser_loads_figures(tmp_path):
    path = _page(tmp_path)
    proc = chromium(tmp_path, "--virtual-time-budget=5000", "--dump-dom", path.as_uri())
    dom = proc.stdout
    assert "<h1>Test report</h1>" in dom, proc.stderr[-2000:]
    loaded = re.search(r'data-figures-loaded="(\d+)"', dom)
    total = re.search(r'data-figures-total="(\d+)"', dom)
    assert loaded and total, f"the page script did not run: {dom[:500]}"
    assert int(total.group(1)) == 2
    assert int(loaded.group(1)) == 2, "some figures failed to decode (naturalWidth == 0)"


@needs_chromium
def test_headless_screenshot_is_not_blank(tmp_path):
    from PIL import Image

    path = _page(tmp_path)
    shot = tmp_path / "shot.png"
    chromium(tmp_path, f"--screenshot={shot}", "--window-size=900,1200", path.as_uri())
    assert shot.is_file()
    img = np.asarray(Image.open(shot).convert("L"), dtype=np.float64)
    # text, tables and plots: many grey levels, not a uniform page
    assert img.std() > 10 and len(np.unique(img)) > 20


def test_fidelity_rows_tiny(variant, tmp_path, monkeypatch):
    from mincam_render.studies.fidelity import (
        KNOBS,
        FidelityBenchConfig,
        FidelityBenchResult,
        run,
        write_report,
    )

    cfg = FidelityBenchConfig(
        families=("patches",),
        num_frames=1,
        sequence_frames=4,
        reference_spp=8,
        base_spp=2,
        spp_levels=(1, 2),
        mask_res_levels=(4,),
        depth_levels=(2,),
        num_masks=2,
        mask_resolution=8,
        include_auto=True,
        signal_seconds=1.0,
    )
    result = run(cfg, tmp_path)
    (res,) = result.families
    assert {r.knob for r in res.rows} == set(KNOBS)
    for r in res.rows:
        e = r.errors
        for key, value in (
            ("error", r.error),
            ("error_random", e.error_random),
            ("error_trained", e.error_trained),
            ("effect", r.effect),
            ("seconds", r.seconds),
        ):
            assert math.isfinite(value) and value >= 0, (r.knob, r.level, key)
        assert r.family == "patches"
        # beside them, relative to the label signal (no single texel at a coarser resolution)
        assert e.signal is not None and math.isfinite(e.signal.random) and e.signal.random >= 0
        assert (e.signal.finest_box is None) == (r.knob == "mask_res")
    # float16 adds at most its rounding (2^-11 relative) to the base render
    base = next(r for r in res.rows if r.knob == "spp" and r.level == 2)
    f16 = next(r for r in res.rows if r.knob == "storage")
    assert abs(f16.error - base.error) < 1e-3
    assert res.statements and all("patches" in s for s in res.statements)
    paths = write_report(result, tmp_path)
    assert Path(paths["html"]).read_text().count("data:image/png;base64,") == 1
    written = json.loads(paths["json"].read_text())
    assert FidelityBenchResult.from_json(written).as_json() == written
    assert FidelityBenchResult.from_json(written).families[0].rows == res.rows
    # the family was kept as it was measured: run again, it is read back, not measured
    import mincam_render.studies.fidelity.study as bench

    def measured(*args, **kwargs):
        raise AssertionError("measured again")

    monkeypatch.setattr(bench, "measure_family", measured)
    assert run(cfg, tmp_path) == result
    with pytest.raises(AssertionError, match="measured again"):  # other sizes: measured
        run(dataclasses.replace(cfg, base_spp=1), tmp_path)


@pytest.fixture(scope="module")
def energy_page(tmp_path_factory, variant):
    from mincam_render.studies.energy import load_energy_config, run, write_report

    config = load_energy_config(
        None,
        {
            "max_pixels": 3,
            "schedule": {"step_min": 120.0},
            "render": {"spp": 16, "batches": 2, "max_depth": 2},
        },
    )
    out = tmp_path_factory.mktemp("energy")
    return Path(write_report(run(config, out, families=["workspace"]), out)["html"])


@needs_chromium
def test_energy_report_loads_its_figures_in_a_headless_browser(tmp_path, energy_page):
    text = energy_page.read_text()
    assert not re.search(r'src="(?!data:)', text), "external resources would break the page"
    proc = chromium(tmp_path, "--virtual-time-budget=5000", "--dump-dom", energy_page.as_uri())
    dom = proc.stdout
    assert "Self-powered budget" in dom, proc.stderr[-2000:]
    loaded = re.search(r'data-figures-loaded="(\d+)"', dom)
    total = re.search(r'data-figures-total="(\d+)"', dom)
    assert loaded and total, f"the page script did not run: {dom[:500]}"
    assert int(total.group(1)) == 3 and int(loaded.group(1)) == 3
    assert "paper: ~600 lx" in dom and "HM01B0" in dom


def _interval(mean: float, half: float) -> dict:
    return {"mean": mean, "ci95": [mean - half, mean + half]}


def _privacy_result() -> PrivacyResult:
    """A privacy audit's result of two designs (as ``privacy.json`` holds it)."""
    from mincam_render.studies.privacy import default_comparison
    from mincam_render.studies.privacy.config import AttackConfig, PrivacyConfig
    from mincam_render.studies.privacy.curve import rederive_verdicts

    conv = {"decoder": {"converged": True}, "reid": {"converged": False}, "decoders": {}}
    image = {
        "fg_psnr_db": _interval(15.0, 0.4),
        "fg_ssim": _interval(0.6, 0.02),
        "psnr_db": _interval(30.0, 0.4),
        "ssim": _interval(0.9, 0.02),
    }
    kept = {"decoder": "conv", "decoder_val_mse": {"mlp": 2.0, "conv": 1.0, "ridge": 3.0},
            "ridge_penalty": 1.0}  # fmt: skip
    scores = {"fg_ssim": 0.6, "psnr_db": 30.0, "ssim": 0.9}
    design = {
        "pixels": 2, "task_state": "converged", "task_seeds": 2, "convergence": [conv] * 3,
        "task_error": _interval(1.0, 0.1), **image, "fg_psnr_db": _interval(14.5, 0.3),
        "fg_psnr_gain_db": _interval(0.1, 0.05), "fg_psnr_over_prior_db": _interval(0.0, 0.05),
        "reid_top1": _interval(0.4, 0.05),
        "per_seed": [{"test-0": {"fg_psnr_db": 14.5, **scores, "reid_top1": 0.4}}] * 3,
        "decoders": [kept, kept, dict(kept, decoder="ridge")],
        "by_decoder": {k: image for k in ("mlp", "conv", "ridge")},
    }  # fmt: skip
    baseline = dict(design, pixels=64, fg_psnr_db=_interval(18.0, 0.4),
                    reid_top1=_interval(0.8, 0.05),
                    per_seed=[{"test-0": {"fg_psnr_db": 18.0, **scores, "reid_top1": 0.8}}] * 3,
                    )  # fmt: skip
    privacy = {
        "task": "workspace", "error_name": "people_count RMSE", "roster": 6,
        "designs": {"mincam-2px": design, "baseline-8x8": baseline},
        "episodes": {"test-0": {"samples": 200}},
        "trivial": {"task_error": _interval(1.6, 0.2), **image, "fg_fraction": 0.04,
                    "reid_top1": _interval(0.35, 0.04), "episodes": {}},
        "prior": {**image, "fg_psnr_gain_db": _interval(0.2, 0.05), "episodes": {}},
        "comparison": "metrics.json", "corner": {},
        "config": json.loads(json.dumps(asdict(PrivacyConfig(
            comparison=default_comparison(), attack=AttackConfig())), default=str)),
    }  # fmt: skip
    return rederive_verdicts(PrivacyResult.from_json(privacy))


@pytest.fixture(scope="module")
def privacy_page(tmp_path_factory):
    from mincam_render.studies.privacy import write_report

    rng = np.random.default_rng(0)
    examples = {
        "frames": np.array([3, 40]),
        "true": rng.uniform(0, 1, (2, 16, 16)).astype(np.float32),
        "background": rng.uniform(0, 1, (2, 16, 16)).astype(np.float32),
        "mask": rng.random((2, 16, 16)) < 0.1,
        "designs": np.array(["mincam-2px", "baseline-8x8"]),
        "recon": rng.uniform(0, 1, (2, 2, 16, 16)).astype(np.float32),
    }
    out = tmp_path_factory.mktemp("privacy")
    return write_report(_privacy_result(), out, examples)


@needs_chromium
def test_privacy_report_loads_its_figures_in_a_headless_browser(tmp_path, privacy_page):
    html = Path(privacy_page["html"])
    assert not re.search(r'src="(?!data:)', html.read_text()), "external resources"
    proc = chromium(tmp_path, "--virtual-time-budget=5000", "--dump-dom", html.as_uri())
    dom = proc.stdout
    assert "Privacy audit" in dom, proc.stderr[-2000:]
    loaded = re.search(r'data-figures-loaded="(\d+)"', dom)
    total = re.search(r'data-figures-total="(\d+)"', dom)
    assert loaded and total, f"the page script did not run: {dom[:500]}"
    assert int(total.group(1)) == 3 and int(loaded.group(1)) == 3
    assert "mincam-2px: in the corner against baseline-8x8" in dom
    assert "trivial (background: sees no one; most frequent person)" in dom
    assert "conv 2, ridge 1" in dom  # the decoder each attacker seed kept
    assert "prior (background + where people usually are; read-out ignored)" in dom
    assert "conv: people PSNR (dB)" in dom  # every decoder's figure
    assert "task-matched baseline" in dom  # the paired differences beside the verdicts
    saved = json.loads(Path(privacy_page["json"]).read_text())
    assert saved["corner"]["mincam-2px"]["in_corner_against"] == ["baseline-8x8"]
    assert Path(privacy_page["png"]).read_bytes()[:4] == b"\x89PNG"
