"""A new render's estimate: measured before anything is written, refused above its limits."""

from __future__ import annotations

import logging
from collections import namedtuple

import pytest
from click.testing import CliRunner
from support import TINY_PATCHES

from mincam_render.cli.main import main
from mincam_render.data.render_job import JobLimits, JobTooLarge, plan_render, render_dataset
from mincam_render.data.render_job import estimate as est


def test_the_estimate_matches_what_the_render_writes(tmp_path, tiny_patches):
    """The estimate of ``TINY_PATCHES`` against the shards the shared render of it wrote."""
    estimate = est.estimate_job(plan_render(TINY_PATCHES), tmp_path / "ds")
    assert estimate.frames == 24 and estimate.shards == 3 and 0 < estimate.seconds_per_frame < 10
    shards = sorted((tiny_patches / "shards").iterdir())
    per_shard = sum(p.stat().st_size for p in shards) / 3
    assert estimate.bytes_per_shard == pytest.approx(per_shard, rel=0.25)


def test_a_job_above_its_limits_is_refused_before_anything_is_written(
    tmp_path, variant, monkeypatch
):
    # renders its own: a render refused, then confirmed, is what it tests
    out = tmp_path / "ds"
    with pytest.raises(JobTooLarge, match=r"more than 1e-09 h; pass --yes"):
        render_dataset(TINY_PATCHES, out, workers=0, limits=JobLimits(max_hours=1e-9))
    assert not out.exists()
    disk = namedtuple("usage", "total used free")
    monkeypatch.setattr(est.shutil, "disk_usage", lambda path: disk(10**6, 10**6 - 100, 100))
    with pytest.raises(JobTooLarge, match=r"\(100 B free\): more than the free disk"):
        render_dataset(TINY_PATCHES, out, workers=0, limits=JobLimits())
    assert not out.exists()
    render_dataset(TINY_PATCHES, out, workers=0, limits=JobLimits(confirmed=True))  # --yes
    assert (out / "manifest.json").is_file()


def test_render_shows_the_estimate_and_yes_confirms_a_large_job(
    tmp_path, variant, caplog, monkeypatch
):
    disk = namedtuple("usage", "total used free")
    monkeypatch.setattr(est.shutil, "disk_usage", lambda path: disk(10**6, 10**6 - 100, 100))
    args = ["render", "patches", "--frames", "24", "--shard-frames", "8", "--detectors", "2"]
    args += ["--mask-res", "8", "--spp", "2", "--workers", "0", "--no-progress"]
    args += ["--out", str(tmp_path / "ds")]
    res = CliRunner().invoke(main, args)
    errors = [line for line in res.output.splitlines() if line.startswith("Error:")]
    assert res.exit_code == 2 and len(errors) == 1 and "pass --yes" in errors[0]
    assert not (tmp_path / "ds").exists()
    with caplog.at_level(logging.INFO, logger=est.__name__):
        res = CliRunner().invoke(main, [*args, "--yes"])
    assert res.exit_code == 0, res.output
    assert "render estimate: 24 frames x" in caplog.text and "3 shards x" in caplog.text


@pytest.mark.parametrize(
    ("seconds", "text"), [(0.5, "0.5 s"), (90.0, "90 s"), (7200.0, "2 h"), (2.3e7, "266 days")]
)
def test_durations_read_as_people_say_them(seconds, text):
    assert est._duration(seconds) == text


@pytest.mark.parametrize(
    ("n", "text"), [(100, "100 B"), (2650000, "2.65 MB"), (1.03e13, "10.3 TB")]
)
def test_sizes_read_as_people_say_them(n, text):
    assert est._size(n) == text
