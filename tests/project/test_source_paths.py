"""What the package knows of where it is: its git revision, its shipped files."""

from __future__ import annotations

import logging
import shutil
import subprocess
import sys
from pathlib import Path

from mincam_render.core.package_data import shipped_path
from mincam_render.data import plan_cache
from mincam_render.data.render_job import package_versions, source_revision
from mincam_render.studies.energy import config as energy_config

REPO = Path(__file__).resolve().parents[2]


def test_a_checkout_records_its_own_revision():
    head = subprocess.run(
        ["git", "-C", str(REPO), "rev-parse", "HEAD"], capture_output=True, text=True, check=True
    ).stdout.strip()
    assert source_revision() == head == package_versions()["git_revision"]


def test_a_package_installed_inside_another_work_tree_records_no_revision_of_it(tmp_path):
    """Regression: the revision was that of whatever repository held the installed package."""
    other = tmp_path / "project"
    subprocess.run(["git", "init", "-q", str(other)], check=True)
    subprocess.run(
        ["git", "-C", str(other), "-c", "user.email=a@b", "-c", "user.name=a",
         "commit", "-q", "--allow-empty", "-m", "other project"],
        check=True,
    )  # fmt: skip
    site = other / ".venv" / "site-packages"  # untracked, as a virtual environment is
    shutil.copytree(REPO / "mincam_render", site / "mincam_render")
    code = (
        "import mincam_render; from mincam_render.data.render_job import package_versions as v;"
        " print(mincam_render.__file__, v())"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=other,
        env={"PYTHONPATH": str(site), "PATH": "/usr/bin:/bin"}, check=True,
    )  # fmt: skip
    assert done.stdout.startswith(str(site))  # the installed copy ran
    assert "git_revision" not in done.stdout and "'mincam_render'" in done.stdout


def test_the_energy_description_is_found_among_the_shipped_files(tmp_path, monkeypatch):
    shipped = tmp_path / "scene_data"
    shipped.mkdir()
    text = shipped_path(energy_config.ENERGY_TOML).read_text()
    (shipped / "energy.toml").write_text(text.replace("area_m2 = 0.016872", "area_m2 = 0.5"))
    monkeypatch.setattr(energy_config, "shipped_path", lambda *parts: shipped.joinpath(*parts))
    assert energy_config.load_energy_config().panel.area_m2 == 0.5


def test_missing_shipped_plans_are_said_once(tmp_path, monkeypatch, caplog):
    monkeypatch.setattr(plan_cache, "shipped_dir", lambda: tmp_path / "not-installed")
    monkeypatch.setenv(plan_cache.CACHE_ENV, str(tmp_path / "cache"))
    plan_cache.shipped_plans_missing.cache_clear()
    fields = {
        "family_name": "patches",
        "planner_version": plan_cache.PLANNER_VERSION,
        "renderer": {"variant": "llvm_ad_mono"},
    }
    with caplog.at_level(logging.WARNING, logger=plan_cache.__name__):
        assert plan_cache.find_plan(fields) is None
        assert plan_cache.find_plan(fields) is None
    plan_cache.shipped_plans_missing.cache_clear()
    warnings = [r.getMessage() for r in caplog.records]
    assert len(warnings) == 1 and "shipped fidelity plans are missing" in warnings[0]
