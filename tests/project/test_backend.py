"""The backend as explicit state: one variant per process, recorded; the CUDA path.

Tests marked ``gpu`` are deselected by default (``-m gpu`` runs them) and skip
where no CUDA device is usable, or where this process already chose LLVM.
"""

from __future__ import annotations

import numpy as np
import pytest
from support import cli_process

from mincam_render.data import dataset as ds
from mincam_render.data.render_job import RenderRequest, render_dataset
from mincam_render.render import backend


def test_the_variant_is_chosen_once_per_process_and_recorded(variant):
    assert backend.chosen_variant() == variant == backend.use_variant()
    other = next(b for b, v in backend.VARIANTS.items() if v != variant)
    with pytest.raises(backend.VariantConflictError, match=f"already renders with {variant}"):
        backend.use_variant(other)
    assert backend.use_variant(backend.backend_of(variant)) == variant
    assert backend.describe()["variant"] == variant


def test_the_environment_names_the_backend_of_a_new_process(monkeypatch):
    monkeypatch.setattr(backend, "_chosen", None)  # as before the first render
    monkeypatch.setenv(backend.BACKEND_ENV, "gpu")
    with pytest.raises(backend.BackendUnavailableError, match="names no backend"):
        backend.use_variant()
    assert backend.chosen_variant() is None


def test_variant_names_map_to_backends():
    assert {backend.backend_of(v): v for v in backend.VARIANTS.values()} == backend.VARIANTS
    with pytest.raises(ValueError, match="scalar_rgb"):
        backend.backend_of("scalar_rgb")


@pytest.mark.gpu
def test_the_cuda_variant_is_recorded_in_a_dataset(tmp_path, cuda_variant):
    # its own render: the shared tiny_patches is rendered with the default variant
    request = RenderRequest(
        family="patches",
        num_frames=8,
        seed=1,
        overrides={"camera": {"detectors": 2, "mask_resolution": 8}},
        shard_frames=8,
        spp=4,
    )
    summary = render_dataset(request, tmp_path / "gpu", workers=0)
    assert ds.read_manifest(summary.path)["variant"] == cuda_variant == "cuda_ad_mono"
    assert ds.open_dataset(summary.path).verify() == []


@pytest.mark.gpu
def test_cuda_and_llvm_render_the_same_transport(tmp_path, cuda_variant):
    # the same sample sequences on both backends: only the last bits of the
    # floating-point evaluation differ, so per-frame powers agree far below the
    # Monte Carlo noise of 4 spp (1 %); the LLVM render runs in its own process
    args = ["render", "patches", "--frames", "8", "--shard-frames", "8", "--detectors", "2"]
    args += ["--mask-res", "8", "--spp", "4", "--seed", "1", "--no-progress"]
    cpu = cli_process([*args, "--out", str(tmp_path / "cpu")], {backend.BACKEND_ENV: "llvm"})
    _, err = cpu.communicate(timeout=600)
    assert cpu.returncode == 0, err
    gpu = cli_process([*args, "--out", str(tmp_path / "gpu")], {backend.BACKEND_ENV: "cuda"})
    _, err = gpu.communicate(timeout=600)
    assert gpu.returncode == 0, err
    a, b = ds.open_dataset(tmp_path / "cpu"), ds.open_dataset(tmp_path / "gpu")
    assert ds.read_manifest(tmp_path / "gpu")["variant"] == cuda_variant
    power_a = np.asarray(a.frames(0, 8)).sum(axis=(-1, -2))
    power_b = np.asarray(b.frames(0, 8)).sum(axis=(-1, -2))
    np.testing.assert_allclose(power_b, power_a, rtol=1e-2)
