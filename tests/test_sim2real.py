"""SURROGATE-real generation and the sim2real analysis: recovery of injected gains/offsets,
JSON schema, and bad-input errors."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from mincam_render.analysis.sim2real import (
    THRESHOLDS,
    Sim2RealError,
    SurrogatePerturbations,
    analyze_sim2real,
    fit_gain_offset,
    load_recording,
    make_surrogate,
    write_sim2real_report,
)

#: Only electronics perturbations: real = gain * sim + offset holds exactly.
ELECTRONICS_ONLY = SurrogatePerturbations(
    mask_shift_m=0.0,
    mask_rotation_deg=0.0,
    printer_gamma=1.0,
    dot_gain=0.0,
    board_position_m=0.0,
    board_rotation_deg=0.0,
    gain_sigma=0.15,
    offset_sigma_v=0.02,
    stray_light_fraction=0.05,
    dark_current_a=2e-10,
    read_noise=True,
    common_random_numbers=True,
)


@pytest.fixture(scope="module")
def electronics_only(tmp_path_factory, variant):
    root = tmp_path_factory.mktemp("s2r")
    rec = make_surrogate(
        "patches",
        root / "in",
        num_frames=60,
        spp=4,
        seed=3,
        perturbations=ELECTRONICS_ONLY,
        mask_resolution=8,
    )
    return rec, analyze_sim2real(rec, spp=4, steps=40, seed=3)


def test_fit_recovers_injected_gain_and_offset(electronics_only):
    """Fitted gain/offset equal the injected ones within 5 standard errors.

    With common random numbers the simulated power equals the SURROGATE's, so the
    only differences are the injected per-pixel gain, offset, stray light and dark
    current (an exact affine map) plus read noise (400 uV) and ADC quantization
    (~50 uV): OLS is unbiased and its standard error (from the residuals) bounds
    the estimate; 5 se gives a false-failure rate < 1e-6 per value.
    """
    _, result = electronics_only
    for p in result["pixels"]:
        assert p["gain_se"] > 0 and p["offset_se_v"] > 0
        assert abs(p["gain"] - p["injected_gain"]) <= 5 * p["gain_se"], p
        assert abs(p["offset_v"] - p["injected_offset_v"]) <= 5 * p["offset_se_v"], p
        assert p["correlation"] > 0.99


def test_surrogate_is_labelled(electronics_only):
    rec_dir, result = electronics_only
    meta = json.loads((rec_dir / "recording.json").read_text())
    assert meta["surrogate"] is True and "SURROGATE" in meta["note"]
    assert result["surrogate"] is True and "SURROGATE" in result["banner"]
    assert result["verdict"]["summary"].startswith("SURROGATE")


def test_json_schema(electronics_only, tmp_path):
    _, result = electronics_only
    paths = write_sim2real_report(result, tmp_path)
    data = json.loads(open(paths["json"]).read())
    required = {
        "surrogate": bool,
        "family": str,
        "num_samples": int,
        "fps": float,
        "thresholds": dict,
        "pixels": list,
        "distribution_gap": dict,
        "verdict": dict,
        "tasks": dict,
        "series": dict,
        "video_simulation_note": str,
    }
    for key, kind in required.items():
        assert isinstance(data[key], kind), key
    assert set(data["thresholds"]) == set(THRESHOLDS)
    pixel_keys = {
        "pixel": int,
        "detector": int,
        "gain": float,
        "gain_se": float,
        "offset_v": float,
        "offset_se_v": float,
        "correlation": float,
        "residual_std_v": float,
        "ks_raw": float,
        "ks_calibrated": float,
        "wasserstein_raw_v": float,
        "wasserstein_calibrated_v": float,
        "residual_percentiles_v": dict,
        "verdict": str,
    }
    for p in data["pixels"]:
        for key, kind in pixel_keys.items():
            assert isinstance(p[key], kind), key
            if kind is float:
                assert math.isfinite(p[key]), key
        assert p["verdict"] in ("agrees", "agrees after gain/offset calibration", "disagrees")
    for key in ("sim_on_sim", "sim_on_real", "sim_head_retrained_on_real", "real_on_real"):
        assert math.isfinite(data["tasks"][key]["error"]), key
    assert data["tasks"]["video_simulation"] is None
    assert {"overall", "counts", "summary", "task"} <= set(data["verdict"])
    n = data["num_samples"]
    assert np.asarray(data["series"]["real_v"]).shape == (n, len(data["pixels"]))


def test_gain_offset_fit_closed_form(rng):
    x = rng.normal(size=500)
    fit = fit_gain_offset(x, 2.5 * x - 0.3)
    assert fit["gain"] == pytest.approx(2.5, rel=1e-9)
    assert fit["offset_v"] == pytest.approx(-0.3, abs=1e-9)
    assert fit["correlation"] == pytest.approx(1.0, rel=1e-9)


def _copy_with_meta(src, dst, **changes):
    """Copy a recording directory, changing fields of its recording.json."""
    dst.mkdir()
    for f in src.iterdir():
        (dst / f.name).write_bytes(f.read_bytes())
    meta = json.loads((dst / "recording.json").read_text())
    meta.update(changes)
    (dst / "recording.json").write_text(json.dumps(meta))
    return dst


def test_bad_recording_names_the_field(electronics_only, tmp_path):
    rec_dir, _ = electronics_only
    bad = _copy_with_meta(rec_dir, tmp_path / "bad", units="mV")
    with pytest.raises(Sim2RealError, match="'units'"):
        load_recording(bad)
    with pytest.raises(Sim2RealError, match="recording.json: missing"):
        load_recording(tmp_path)


def test_counts_are_converted_to_volts(electronics_only, tmp_path):
    rec_dir, _ = electronics_only
    rec_v = load_recording(rec_dir)
    out = _copy_with_meta(
        rec_dir, tmp_path / "counts", units="counts", adc={"bits": 16, "full_scale_v": 3.2}
    )
    lines = (out / "measurements.csv").read_text().splitlines()
    conv = [lines[0]]
    for line in lines[1:]:
        vals = line.split(",")
        conv.append(",".join(vals[:2] + [repr(float(v) / (3.2 / 2**16)) for v in vals[2:]]))
    (out / "measurements.csv").write_text("\n".join(conv) + "\n")
    np.testing.assert_allclose(load_recording(out).volts, rec_v.volts, rtol=1e-12)
