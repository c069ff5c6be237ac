"""SURROGATE-real generation and the sim2real analysis: recovery of injected gains/offsets,
JSON schema, and bad-input errors."""

from __future__ import annotations

import dataclasses
import json
import math
import typing
from pathlib import Path

import numpy as np
import pytest
import torch
from support import REPO

from mincam_render.learn.train_config import TrainConfig
from mincam_render.optics.camera import MM, DetectorLayout, FreeformCamera
from mincam_render.optics.fabrication_fused import fused_fabricated_transmittance
from mincam_render.optics.perturbation import PerturbationModel
from mincam_render.studies.robustness.config import RobustnessConfig
from mincam_render.studies.sim2real import (
    THRESHOLDS,
    GainOffsetFit,
    Sim2RealConfig,
    Sim2RealError,
    SurrogatePerturbations,
    fit_gain_offset,
    load_recording,
    make_surrogate,
    run,
    write_report,
)
from mincam_render.studies.sim2real.surrogate import (
    SURROGATE_PERTURBATION,
    UNIFORM_HALF_RANGE_PER_SIGMA,
    print_masks,
)

#: Only electronics perturbations: real = gain * sim + offset holds exactly.
ELECTRONICS_ONLY = SurrogatePerturbations(
    perturbation=dataclasses.replace(
        PerturbationModel.zero(), gain_mismatch_fraction=0.26, dark_offset_v=0.035
    ),
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
    return rec, run(Sim2RealConfig(recording=rec, spp=4, steps=40, seed=3), root / "out")


def test_fit_recovers_injected_gain_and_offset(electronics_only):
    """Fitted gain/offset equal the injected ones within 5 standard errors.

    With common random numbers the simulated power equals the SURROGATE's, so the
    only differences are the injected per-pixel gain, offset, stray light and dark
    current (an exact affine map) plus read noise (400 uV) and ADC quantization
    (~50 uV): OLS is unbiased and its standard error (from the residuals) bounds
    the estimate; 5 se gives a false-failure rate < 1e-6 per value.
    """
    rec_dir, result = electronics_only
    injected = json.loads((rec_dir / "injected.json").read_text())
    for j, p in enumerate(result.pixels):
        fit, inj = p.fit, p.injected
        assert fit.gain_se > 0 and fit.offset_se_v > 0
        assert inj.injected_offset_v == injected["per_pixel"]["offset_v"][j]
        assert inj.expected_offset_v == injected["expected_fit"]["offset_v"][j]
        assert abs(fit.gain - inj.expected_gain) <= 5 * fit.gain_se, p
        assert abs(fit.offset_v - inj.expected_offset_v) <= 5 * fit.offset_se_v, p
        assert inj.gain_z == pytest.approx((fit.gain - inj.expected_gain) / fit.gain_se)
        assert abs(inj.gain_z) <= 5 and abs(inj.offset_z) <= 5
        assert fit.correlation > 0.99


def test_report_table_separates_injected_and_expected_offsets(electronics_only, tmp_path):
    """Stray light and dark current move the expected offset away from the injected one."""
    _, result = electronics_only
    html = Path(write_report(result, tmp_path)["html"]).read_text()
    for header in ("injected offset (mV)", "expected offset (mV)", "offset − expected (se)"):
        assert f"<th>{header}</th>" in html
    gaps = [abs(p.injected.expected_offset_v - p.injected.injected_offset_v) for p in result.pixels]
    assert max(gaps) > 1e-4  # the two columns differ: stray light and dark current
    for p in result.pixels:
        assert p.injected.explanation.startswith(f"pixel {p.pixel}: fitted gain")
        assert p.injected.explanation in html


def test_geometric_perturbations_explain_a_far_fit(tmp_path, variant):
    """With mask shift and pose error, a fit many se from the expected one says why."""
    injected = {
        "per_pixel": {"gain": [1.0], "offset_v": [0.001]},
        "expected_fit": {"gain": [1.0], "offset_v": [0.002], "exact": False},
    }
    fit = GainOffsetFit(
        gain=1.05,
        gain_se=0.005,
        offset_v=0.002,
        offset_se_v=1e-4,
        correlation=1.0,
        residual_std_v=0,
    )
    from mincam_render.studies.sim2real import injected_comparison

    far = injected_comparison(injected, 0, fit)
    assert far.gain_z == pytest.approx(10.0)
    assert "expected to differ" in far.explanation and "+10.0 se" in far.explanation
    near = injected_comparison(injected, 0, dataclasses.replace(fit, gain=1.001))
    assert "within 3 se" in near.explanation
    exact = dict(injected, expected_fit=dict(injected["expected_fit"], exact=True))
    assert "optimistic" in injected_comparison(exact, 0, fit).explanation


def test_frame_index_is_written_as_integers(electronics_only):
    rec_dir, _ = electronics_only
    rows = (rec_dir / "measurements.csv").read_text().splitlines()[1:]
    assert [r.split(",")[1] for r in rows[:3]] == ["0", "1", "2"]


def _damage_recording(root: Path, name: str) -> None:
    path = root / name
    if name == "masks.npy":
        path.write_bytes(path.read_bytes()[:-7])  # truncated
    elif name == "injected.json":
        path.write_text(path.read_text().replace('"gain"', '"gain" ', 1))
    else:  # one value edited, still a valid CSV
        lines = path.read_text().splitlines()
        cells = lines[5].split(",")
        cells[-1] = repr(float(cells[-1]) + 0.5)
        lines[5] = ",".join(cells)
        path.write_text("\n".join(lines) + "\n")


@pytest.mark.parametrize("name", ["measurements.csv", "labels.csv", "masks.npy", "injected.json"])
def test_a_changed_recording_file_is_refused_naming_it(electronics_only, tmp_path, name):
    rec_dir, _ = electronics_only
    root = _copy_with_meta(rec_dir, tmp_path / "copy")
    _damage_recording(root, name)
    with pytest.raises(Sim2RealError, match=f"{name}: does not match its sha256"):
        load_recording(root)


def test_a_recording_without_checksums_is_read_as_it_is(electronics_only, tmp_path):
    """Recordings written by other tools (a prototype's logger) need no checksums."""
    rec_dir, _ = electronics_only
    root = _copy_with_meta(rec_dir, tmp_path / "theirs", sha256=None)
    np.testing.assert_array_equal(load_recording(root).volts, load_recording(rec_dir).volts)


def test_surrogate_is_labelled(electronics_only):
    rec_dir, result = electronics_only
    meta = json.loads((rec_dir / "recording.json").read_text())
    assert meta["surrogate"] is True and "SURROGATE" in meta["note"]
    assert result.surrogate is True and "SURROGATE" in result.banner
    assert result.verdict.summary.startswith("SURROGATE")


def test_json_schema(electronics_only, tmp_path):
    _, result = electronics_only
    paths = write_report(result, tmp_path)
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
    assert set(data["thresholds"]) == set(THRESHOLDS.as_json())
    assert set(data["recording_sha256"]) == {
        "recording.json",
        "measurements.csv",
        "labels.csv",
        "masks.npy",
        "injected.json",
    }
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
    assert fit.gain == pytest.approx(2.5, rel=1e-9)
    assert fit.offset_v == pytest.approx(-0.3, abs=1e-9)
    assert fit.correlation == pytest.approx(1.0, rel=1e-9)


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
    out = _copy_with_meta(  # a file edited by hand, as another tool would write it
        rec_dir,
        tmp_path / "counts",
        units="counts",
        adc={"bits": 16, "full_scale_v": 3.2},
        sha256=None,
    )
    lines = (out / "measurements.csv").read_text().splitlines()
    conv = [lines[0]]
    for line in lines[1:]:
        vals = line.split(",")
        conv.append(",".join(vals[:2] + [repr(float(v) / (3.2 / 2**16)) for v in vals[2:]]))
    (out / "measurements.csv").write_text("\n".join(conv) + "\n")
    np.testing.assert_allclose(load_recording(out).volts, rec_v.volts, rtol=1e-12)


def test_the_surrogate_draws_its_built_camera_from_the_model_robust_training_uses():
    """One model of a built camera: the SURROGATE's is an optics.perturbation instance."""
    pert = SurrogatePerturbations()
    assert isinstance(pert.perturbation, PerturbationModel)
    # robust training, the robustness report and the SURROGATE declare the same class
    assert typing.get_type_hints(TrainConfig)["perturbation"] == PerturbationModel | None
    assert typing.get_type_hints(RobustnessConfig)["perturbation"] is PerturbationModel
    assert typing.get_type_hints(SurrogatePerturbations)["perturbation"] is PerturbationModel
    assert pert.perturbation is SURROGATE_PERTURBATION and pert.geometric
    assert not ELECTRONICS_ONLY.geometric
    # the former normal spreads, kept as the uniform draws' standard deviations
    assert SURROGATE_PERTURBATION.mask_shift_m / UNIFORM_HALF_RANGE_PER_SIGMA == pytest.approx(
        0.15 * MM, rel=1e-12
    )
    assert pert.to_record()["perturbation"] == SURROGATE_PERTURBATION.to_record()


def test_the_surrogate_prints_masks_as_robust_training_measures_them(rng):
    """print_masks is training's fused mask plane (logits = logit of the design's place)."""
    cam = FreeformCamera(mask_resolution=(8, 8), layout=DetectorLayout.row(count=3, pitch_m=0.02))
    lo, hi = cam.transmittance_range
    fraction = rng.uniform(0.02, 0.98, (3, 8, 8))
    draw = SURROGATE_PERTURBATION.scaled(2.0).draw(3, rng).without_pose()
    printed = print_masks(lo + (hi - lo) * fraction, cam, draw)
    logits = torch.from_numpy(np.log(fraction / (1.0 - fraction)))
    trained = fused_fabricated_transmittance(logits, (lo, hi), draw, cam.texel_size_m)
    np.testing.assert_allclose(printed, trained.numpy(), rtol=1e-12, atol=1e-14)
    assert not np.allclose(printed, lo + (hi - lo) * fraction, atol=1e-3)  # it did perturb


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"perturbation": {"mask_shift_mm": 0.3}}, "SurrogatePerturbations.perturbation"),
        ({"stray_light_fraction": -0.1}, "SurrogatePerturbations.stray_light_fraction"),
        ({"dark_current_a": float("nan")}, "SurrogatePerturbations.dark_current_a"),
    ],
)
def test_bad_surrogate_perturbations_are_refused_naming_the_field(kwargs, field):
    with pytest.raises(ValueError, match=field):
        SurrogatePerturbations(**kwargs)


def test_the_injected_values_are_the_draw_of_the_shared_model(electronics_only):
    rec_dir, _ = electronics_only
    injected = json.loads((rec_dir / "injected.json").read_text())
    record = injected["perturbations"]["perturbation"]
    assert record == ELECTRONICS_ONLY.perturbation.to_record()
    assert record["gain_mismatch_percent"] == pytest.approx(26.0)
    gain = np.asarray(injected["per_pixel"]["gain"])
    assert np.all(np.abs(gain - 1.0) <= 0.26) and np.any(gain != 1.0)
    assert np.all(np.abs(injected["per_pixel"]["offset_v"]) <= 0.035)
    assert injected["per_pixel"]["mask_shift_m"] == [[0.0, 0.0]] * len(gain)
    assert injected["board"]["position_error_m"] == [0.0, 0.0, 0.0]


# -- the study's shape: a frozen config -> run -> a frozen result -> write_report


def test_the_result_reads_back_from_its_json(electronics_only, tmp_path):
    """``sim2real.json`` is the whole result: read back, it is the result, and writes itself."""
    from mincam_render.studies.sim2real import Sim2RealResult

    _, result = electronics_only
    assert Sim2RealResult.from_json(result.as_json()) == result
    on_disk = json.loads(Path(write_report(result, tmp_path)["json"]).read_text())
    again = Sim2RealResult.from_json(on_disk)
    assert again == result
    assert json.loads(Path(write_report(again, tmp_path / "again")["json"]).read_text()) == on_disk


def test_the_kept_benchmark_records_read_back_unchanged():
    """The pixels, thresholds and verdicts of ``sim2real_surrogate.json`` (written before
    the result was typed) are the records :class:`PixelComparison` writes."""
    from mincam_render.studies.sim2real.result import PixelComparison, Thresholds, Verdict

    kept = json.loads((REPO / "benchmarks/results/sim2real_surrogate.json").read_text())
    families = [v for v in kept.values() if "pixels" in v]  # not "machine", "not_run"
    assert families
    for fam in families:
        assert Thresholds.from_json(fam["thresholds"]).as_json() == fam["thresholds"]
        assert dataclasses.asdict(Verdict(**fam["verdict"])) == fam["verdict"]
        for p in fam["pixels"]:
            assert PixelComparison.from_json(p).as_json() == p


def test_run_makes_the_surrogate_it_is_asked_for(tmp_path, variant):
    """``surrogate_family``: the recording is made into ``out/surrogate_input``, then compared."""
    cfg = Sim2RealConfig(surrogate_family="patches", surrogate_frames=20, spp=1, tasks=False)
    result = run(cfg, tmp_path)
    assert Path(result.recording) == (tmp_path / "surrogate_input").resolve()
    assert result.surrogate and result.tasks is None and result.num_samples == 20
    assert set(write_report(result, tmp_path)) == {"json", "html"}
    assert {p.name for p in tmp_path.iterdir()} == {
        "surrogate_input",
        "sim2real.json",
        "sim2real.html",
    }


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({}, "Sim2RealConfig.recording"),
        ({"recording": "r", "surrogate_family": "patches"}, "Sim2RealConfig.surrogate_family"),
        ({"recording": "r", "spp": 0}, "Sim2RealConfig.spp"),
        ({"recording": "r", "steps": 0}, "Sim2RealConfig.steps"),
        ({"recording": "r", "seed": -1}, "Sim2RealConfig.seed"),
        ({"surrogate_family": "patches", "surrogate_frames": 5}, "Sim2RealConfig.surrogate_frames"),
        ({"recording": "r", "spp": 2.0}, "Sim2RealConfig.spp"),
        ({"recording": "r", "tasks": "no"}, "Sim2RealConfig.tasks"),
    ],
)
def test_bad_config_fields_are_refused_naming_the_field(kwargs, field):
    with pytest.raises(ValueError, match=field):
        Sim2RealConfig(**kwargs)
