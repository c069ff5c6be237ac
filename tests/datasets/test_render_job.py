"""Rendering datasets: resume after SIGKILL, repair, refusal, fidelity choices, Ray."""

from __future__ import annotations

import dataclasses
import difflib
import json
import logging
import os
import re
import signal
import time
from pathlib import Path

import numpy as np
import pytest
from support import TINY_PATCHES, cli_process

from mincam_render.core.seeds import frame_seed
from mincam_render.data import dataset as ds
from mincam_render.data.render_job import (
    FRAME_DELAY_ENV,
    RenderRequest,
    plan_render,
    render_dataset,
)

TINY = {"camera": {"detectors": 2, "mask_resolution": 8}}
CLI_TINY = [
    "render",
    "patches",
    "--frames",
    "40",
    "--shard-frames",
    "8",
    "--detectors",
    "2",
    "--mask-res",
    "8",
    "--spp",
    "4",
    "--seed",
    "5",
    "--no-progress",
]


def _files(root: Path) -> dict[str, bytes]:
    return {
        str(p.relative_to(root)): p.read_bytes()
        for p in sorted(root.rglob("*"))
        if p.is_file() and p.name != ds.LOG_NAME
    }


def _log(root: Path) -> list[dict]:
    return [json.loads(line) for line in (root / ds.LOG_NAME).read_text().splitlines()]


def test_frame_seed_is_deterministic_and_distinct():
    seeds = {frame_seed(0, i) for i in range(1000)} | {frame_seed(1, i) for i in range(1000)}
    assert len(seeds) == 2000 and all(0 <= s < 2**63 for s in seeds)
    assert frame_seed(7, 3) == frame_seed(7, 3)


def test_resume_after_sigkill_is_byte_identical(tmp_path, variant):
    ref, killed = tmp_path / "ref", tmp_path / "killed"
    # uninterrupted reference, rendered in the CLI's own process
    p = cli_process([*CLI_TINY, "--out", str(ref), "--workers", "0"])
    out, err = p.communicate(timeout=240)
    assert p.returncode == 0, err

    # the same command in a worker process, slowed down, killed mid-way
    p = cli_process(
        [*CLI_TINY, "--out", str(killed), "--workers", "1"],
        env={FRAME_DELAY_ENV: "0.1"},
        start_new_session=True,
    )
    deadline = time.monotonic() + 240
    while len(list((killed / ds.SHARD_DIR).glob("shard-*.json"))) < 2:
        assert p.poll() is None, p.communicate()[1]
        assert time.monotonic() < deadline, "render produced no shards in time"
        time.sleep(0.02)
    os.killpg(p.pid, signal.SIGKILL)  # the CLI and its worker, at an arbitrary moment
    p.wait(timeout=30)
    finished = sorted((killed / ds.SHARD_DIR).glob("shard-*.json"))
    assert 2 <= len(finished) < 5
    before = {
        q.name: (q.stat().st_ino, q.stat().st_mtime_ns)
        for f in finished
        for q in (f, f.with_suffix(".npy"))
    }

    # resumed with the default workers: chosen by job size (this tiny job: this process)
    p = cli_process([*CLI_TINY, "--out", str(killed)])
    out, err = p.communicate(timeout=240)
    assert p.returncode == 0, err
    log = [json.loads(line) for line in (killed / ds.LOG_NAME).read_text().splitlines()]
    assert [e["workers"] for e in log if e["event"] == "start"][-1] is None
    assert [e["workers"] for e in log if e["event"] == "workers"][-1] == 0
    got, want = _files(killed), _files(ref)
    assert sorted(got) == sorted(want)
    for name in want:
        assert got[name] == want[name], f"{name} differs:\n" + "\n".join(
            difflib.unified_diff(
                want[name].decode(errors="replace").splitlines(),
                got[name].decode(errors="replace").splitlines(),
                "uninterrupted",
                "resumed",
                lineterm="",
                n=2,
            )
        )
    after = {
        n: (
            (killed / ds.SHARD_DIR / n).stat().st_ino,
            (killed / ds.SHARD_DIR / n).stat().st_mtime_ns,
        )
        for n in before
    }
    assert after == before  # finished shards were not rewritten
    last_start = [e for e in _log(killed) if e["event"] == "start"][-1]
    kept = {int(f.stem.split("-")[1]) for f in finished}
    assert kept <= set(last_start["kept"]) and not kept & set(last_start["todo"])
    assert ds.open_dataset(killed).verify() == []


def test_corrupted_and_truncated_shards_are_re_rendered(tiny_patches_copy, variant):
    out = tiny_patches_copy
    good = _files(out)
    npy1, _ = ds.shard_paths(out, 1)
    data = bytearray(npy1.read_bytes())
    data[200] ^= 0x01
    npy1.write_bytes(bytes(data))
    npy2, json2 = ds.shard_paths(out, 2)
    json2.write_bytes(json2.read_bytes()[:50])  # truncated metadata
    summary = render_dataset(TINY_PATCHES, out, workers=0)
    assert summary.shards_repaired == [1, 2] and summary.shards_rendered == [1, 2]
    assert summary.shards_kept == [0]
    assert _files(out) == good


def test_shard_finished_but_not_in_manifest_is_kept(tiny_patches_copy, variant):
    out = tiny_patches_copy
    good = _files(out)
    m = ds.read_manifest(out)  # as if killed between writing shard 2 and the manifest
    m["shards"][2] = None
    m["complete"] = False
    ds.write_manifest(out, m)
    summary = render_dataset(TINY_PATCHES, out, workers=0)
    assert summary.shards_rendered == [] and summary.shards_kept == [0, 1, 2]
    assert _files(out) == good


def test_mismatched_configuration_is_refused(tiny_patches_copy, variant):
    from click.testing import CliRunner

    from mincam_render.cli.main import main

    out = tiny_patches_copy
    other = dataclasses.replace(TINY_PATCHES, seed=2)
    with pytest.raises(ds.DatasetError, match=r"different configuration.*seed: 1 .* != 2"):
        render_dataset(other, out, workers=0)
    res = CliRunner().invoke(
        main, ["render", "patches", "--out", str(out), "--frames", "24", "--spp", "8"]
    )
    assert res.exit_code != 0
    assert "different configuration" in res.output and "Traceback" not in res.output


def test_dataset_of_an_older_format_is_read_but_not_resumed(tiny_patches_copy, variant):
    out = tiny_patches_copy
    m = ds.read_manifest(out)
    m["format_version"] = ds.FORMAT_VERSION - 1
    m["shards"][2], m["complete"] = None, False
    ds.write_manifest(out, m)
    assert ds.read_manifest(out)["format_version"] == ds.FORMAT_VERSION - 1
    with pytest.raises(ds.DatasetError, match="can be read but not resumed"):
        render_dataset(TINY_PATCHES, out, workers=0)


def test_a_dataset_of_another_variant_is_not_resumed(tiny_patches_copy, variant):
    from mincam_render.render.backend import VARIANTS

    out = tiny_patches_copy
    other = next(v for v in VARIANTS.values() if v != variant)
    m = ds.read_manifest(out)  # as if started on a host with the other backend
    m["variant"] = other
    m["shards"][2], m["complete"] = None, False
    ds.write_manifest(out, m)
    shards = _files(out)
    with pytest.raises(ds.DatasetError) as err:
        render_dataset(TINY_PATCHES, out, workers=0)
    message = str(err.value)
    assert f"rendered with Mitsuba variant {other!r}" in message
    assert f"renders with {variant!r}" in message and "\n" not in message
    assert _files(out) == shards  # nothing was rendered into it


def test_non_empty_directory_without_manifest_is_refused(tmp_path):
    (tmp_path / "notes.txt").write_text("mine")
    with pytest.raises(ds.DatasetError, match="not empty"):
        render_dataset(TINY_PATCHES, tmp_path, workers=0)


@pytest.mark.parametrize(("bound", "expected"), [(1e-9, "float32"), (1e-2, "float16")])
def test_dtype_chosen_by_error_bound(bound, expected, variant):
    req = dataclasses.replace(TINY_PATCHES, dtype=None, dtype_error_bound=bound)
    m = plan_render(req)
    decision = m["fidelity"]["dtype"]
    assert decision["value"] == expected == m["job"]["render"]["dtype"]
    assert decision["source"] == "auto"
    assert 0 < decision["float16_error"]["max"] < 1e-2  # the measured figure is recorded


def _tiny_patches(**fields) -> RenderRequest:
    """16 patches frames in two shards, 2 detectors at 8x8: planning takes about a second."""
    return RenderRequest(
        family="patches", num_frames=16, seed=0, overrides=TINY, shard_frames=8, **fields
    )


def test_auto_fidelity_records_measured_decisions(tmp_path, variant):
    m = plan_render(_tiny_patches(target_error=0.2))
    f = m["fidelity"]
    for key in (
        "shared_render",
        "max_depth",
        "spp",
        "dtype",
        "mask_resolution",
        "temporal_history",
        "variant",
    ):
        assert key in f and "reason" in f[key] and "value" in f[key]
    # patches: a plane 1 m away, detectors 10 mm off centre -> 0.057 texel of parallax
    assert f["shared_render"]["parallax_texels"] == pytest.approx(0.057, rel=0.01)
    assert f["shared_render"]["value"] is True
    assert f["spp"]["source"] == "auto" and "error_vs_reference" in f["spp"]
    assert f["temporal_history"]["value"] is False


def test_shared_render_replicates_the_centre_render(tmp_path, variant):
    # its own render: tiny_patches renders each detector, this is the shared render
    req = RenderRequest(
        family="patches",
        num_frames=8,
        seed=0,
        overrides=TINY,
        shard_frames=8,
        spp=4,
        shared_render=True,
        dtype="float32",
    )
    d = ds.open_dataset(render_dataset(req, tmp_path / "ds", workers=0).path)
    t = d.transport("train")
    np.testing.assert_array_equal(t[:, 0], t[:, 1])
    assert d.manifest["fidelity"]["shared_render"]["source"] == "flag"


@pytest.fixture(scope="module")
def many_shards(tmp_path_factory):
    """A dataset of 13 one-frame shards rendered in this process: the reference."""
    request = RenderRequest(  # what the command line below asks for
        family="patches",
        num_frames=13,
        seed=2,
        overrides={"camera": {"detectors": 2}},
        mask_res=8,
        shard_frames=1,
        spp=1,
    )
    out = tmp_path_factory.mktemp("many") / "ds"
    render_dataset(request, out, workers=0)
    return request, out


def test_more_shards_than_workers_times_shards_per_worker_finish(tmp_path, many_shards, variant):
    # 13 shards > 2 workers x 4 shards: the pool must replace its workers (gh-115634 hung here)
    request, reference = many_shards
    p = cli_process(
        [
            *["render", "patches", "--frames", "13", "--shard-frames", "1", "--spp", "1"],
            *["--detectors", "2", "--mask-res", "8", "--seed", "2", "--workers", "2"],
            *["--no-progress", "--out", str(tmp_path / "ds")],
        ]
    )
    try:
        _, err = p.communicate(timeout=240)
    finally:
        p.kill()
    assert p.returncode == 0, err
    assert _files(tmp_path / "ds") == _files(reference)
    pids = [e["pid"] for e in _log(tmp_path / "ds") if e["event"] == "shard"]
    assert len(pids) == 13


def _worker_pids(pid: int) -> list[int]:
    """Render worker processes among the children of ``pid`` (not the resource tracker)."""
    children = Path(f"/proc/{pid}/task/{pid}/children").read_text().split()
    return [
        int(c)
        for c in children
        if b"resource_tracker" not in Path(f"/proc/{c}/cmdline").read_bytes()
    ]


@pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="needs Linux /proc")
def test_a_killed_worker_stops_the_render_naming_its_shard(tmp_path, many_shards, variant):
    _, reference = many_shards
    args = [
        *["render", "patches", "--frames", "13", "--shard-frames", "1", "--spp", "1"],
        *["--detectors", "2", "--mask-res", "8", "--seed", "2", "--no-progress"],
        *["--out", str(tmp_path / "ds")],
    ]
    # 2 s a frame: the worker found after the first shard still holds a task (it is
    # recycled after 4 shards, 6 s later); at 0.5 s a loaded machine noticed the shard
    # late and killed a worker that had just finished its last task (the render then
    # ended well: failures at load 8-12, and once in a fresh-clone run)
    p = cli_process([*args, "--workers", "1"], env={FRAME_DELAY_ENV: "2.0"})
    deadline = time.monotonic() + 120
    while not list((tmp_path / "ds" / ds.SHARD_DIR).glob("shard-*.json")):
        assert p.poll() is None and time.monotonic() < deadline, p.communicate()
        time.sleep(0.05)
    (worker,) = _worker_pids(p.pid)
    os.kill(worker, signal.SIGKILL)
    _, err = p.communicate(timeout=60)
    assert p.returncode != 0
    line = err.strip().splitlines()[-1]
    assert re.search(r"exit code -9\) while running task \d+: shard \d+ did not finish", line)
    assert "run the same command again to resume" in line
    p = cli_process([*args, "--workers", "2"])  # and it does
    _, err = p.communicate(timeout=240)
    assert p.returncode == 0, err
    assert _files(tmp_path / "ds") == _files(reference)


def test_ray_local_mode_renders_many_shards_like_local_workers(tmp_path, many_shards, variant):
    # Ray runs 2 CPUs x max_calls 4 per worker process: 13 tasks recycle its workers too
    pytest.importorskip("ray")
    request, reference = many_shards
    summary = render_dataset(request, tmp_path / "ray", ray_address="local")
    assert summary.shards_rendered == list(range(13))
    assert _files(summary.path) == _files(reference)


def _assert_reasons_match_values(f: dict, req: RenderRequest) -> None:
    """Each automatic knob's recorded figure agrees with its bound and its choice."""
    shared = f["shared_render"]
    if "error_shared_vs_per_detector" in shared:
        err, bound = shared["error_shared_vs_per_detector"]["rms"], shared["error_bound"]
        noise = shared["noise_floor_two_seeds"]["rms"]
        geometric = shared["parallax_texels"] < req.parallax_fraction and err <= noise
        assert shared["value"] == (err < bound or geometric)
        assert (f"{err:.3g} rms < bound" in shared["reason"]) == (err < bound)
    depth = f["max_depth"]
    if "change_vs_reference" in depth:
        kept = depth["change_vs_reference"].get(str(depth["value"]), {"rms": 0.0})["rms"]
        assert kept < req.indirect_fraction
    spp = f["spp"]
    if spp["source"] == "auto" and "predicted_error_rms" in spp:
        met = spp["predicted_error_rms"] <= req.target_error
        assert ("meets target" in spp["reason"]) == met
    dtype = f["dtype"]
    if dtype["source"] == "auto":
        assert (dtype["value"] == "float16") == (
            dtype["float16_error"]["max"] < req.dtype_error_bound
        )


@pytest.mark.parametrize("target", [0.2, 0.02])
def test_recorded_fidelity_reasons_agree_with_values_and_bounds(target, variant):
    req = _tiny_patches(target_error=target)
    f = plan_render(req)["fidelity"]
    _assert_reasons_match_values(f, req)
    assert f["achieved"]["met"] == (f["achieved"]["error_rms"] <= target)


def test_a_missed_error_target_warns_and_names_the_knob(variant, caplog):
    """Regression: `render --spp 4` recorded 16 % error against a 1 % target silently."""
    req = _tiny_patches(target_error=0.01, spp=1)
    with caplog.at_level(logging.WARNING):
        f = plan_render(req)["fidelity"]
    achieved = f["achieved"]
    assert not achieved["met"] and achieved["error_rms"] > 0.01
    assert "--spp " in achieved["advice"] and "drop --spp" in achieved["advice"]
    assert "rms off the reference, target 0.01" in caplog.text and achieved["advice"] in caplog.text
    _assert_reasons_match_values(f, req)


@pytest.mark.parametrize("break_even_s", [0.0, 1e9])
def test_automatic_workers_follow_the_work_left(
    tmp_path, many_shards, variant, monkeypatch, break_even_s
):
    """workers=None: the first shard here, the rest in a pool only if it is long enough."""
    from mincam_render.data.render_job import executors

    request, reference = many_shards
    monkeypatch.setattr(executors, "POOL_BREAK_EVEN_S", break_even_s)
    render_dataset(request, tmp_path / "ds", workers=None)
    assert _files(tmp_path / "ds") == _files(reference)
    (chosen,) = [e["workers"] for e in _log(tmp_path / "ds") if e["event"] == "workers"]
    assert chosen == ((os.cpu_count() or 1) if break_even_s == 0.0 else 0)


def test_the_plan_reports_each_detectors_error_against_the_reference(variant):
    """Item 4 of issue 17: the per-detector figure after a render, not only the pooled one."""
    shared = plan_render(_tiny_patches(target_error=0.2, shared_render=True))["fidelity"]
    own = plan_render(_tiny_patches(target_error=0.2, shared_render=False))["fidelity"]
    same = shared["achieved"]["per_detector_error_rms"]
    apart = own["achieved"]["per_detector_error_rms"]
    assert len(same) == len(apart) == 2
    assert same[0] == same[1]  # one render replicated: the same error on both detectors
    assert apart[0] != apart[1]  # each detector its own render and its own noise
    pooled = own["achieved"]["error_rms"]
    assert all(0.25 * pooled < e < 4 * pooled for e in apart), (apart, pooled)


def test_ray_ships_the_package_root_to_its_workers():
    """Ray imports a shipped directory under its own name: it must be mincam_render/."""
    import mincam_render
    from mincam_render.data.ray_cluster import ray_runtime_env

    (shipped,) = ray_runtime_env()["py_modules"]
    assert Path(shipped) == Path(mincam_render.__file__).resolve().parent
