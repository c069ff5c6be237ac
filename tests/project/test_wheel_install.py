"""A wheel installed without -e works from any directory (the README's pip install line).

The wheel is built from a copy of the files a release tarball holds (no git, no
clone), installed with ``pip install --target`` into a fresh folder, and run by
this interpreter with ``-S`` (so the editable install of the checkout is not on
the path) from a directory outside the repository.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
#: what a source tarball of the project holds (tests, docs and benchmarks are not needed)
SOURCES = ("pyproject.toml", "README.md", "mincam_render", "scenes")


@pytest.fixture(scope="module")
def installed(tmp_path_factory) -> Path:
    """The folder the wheel was installed into (``pip install --target``)."""
    work = tmp_path_factory.mktemp("wheel")
    src = work / "mincam_render-src"
    src.mkdir()
    for name in SOURCES:
        copy = shutil.copytree if (REPO / name).is_dir() else shutil.copy2
        copy(REPO / name, src / name, **_ignore(REPO / name))
    pip = [sys.executable, "-m", "pip", "--disable-pip-version-check", "-q"]
    # the build backend of this environment: the test needs no package index
    _run([*pip, "wheel", str(src), "--no-deps", "--no-build-isolation", "-w", str(work)])
    (wheel,) = work.glob("mincam_render-*.whl")
    _check_wheel_ships_the_scene_folder(wheel)
    target = work / "site"
    _run([*pip, "install", "--no-deps", "--target", str(target), str(wheel)])
    return target


def _ignore(path: Path) -> dict:
    return {"ignore": shutil.ignore_patterns("__pycache__")} if path.is_dir() else {}


def _run(cmd: list[str], **kw) -> subprocess.CompletedProcess:
    run = subprocess.run(cmd, capture_output=True, text=True, check=False, **kw)
    assert run.returncode == 0, f"{cmd[2:8]}: {run.stdout[-2000:]}{run.stderr[-3000:]}"
    return run


def _check_wheel_ships_the_scene_folder(wheel: Path) -> None:
    """Every shipped description and plan is in the wheel, byte for byte (one source)."""
    shipped = sorted(REPO.glob("scenes/*.toml")) + sorted(REPO.glob("scenes/plans/*.json"))
    assert len(shipped) >= 8
    with zipfile.ZipFile(wheel) as z:
        for path in shipped:
            name = "mincam_render/scene_data/" + path.relative_to(REPO / "scenes").as_posix()
            assert z.read(name) == path.read_bytes(), name


def _cli(installed: Path, cwd: Path, *args: str) -> subprocess.CompletedProcess:
    """``mincam-render ARGS`` of the installed wheel, run from ``cwd``."""
    deps = sysconfig.get_paths()["purelib"]  # this environment's packages, for the dependencies
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(installed), deps]))
    return _run([sys.executable, "-S", "-m", "mincam_render.cli.main", *args], cwd=cwd, env=env)


def test_the_installed_wheel_reads_its_own_package_data(installed, tmp_path):
    code = (
        "import mincam_render; from mincam_render.core.package_data import shipped_path; "
        "print(mincam_render.__file__); print(shipped_path('workspace.toml'))"
    )
    deps = sysconfig.get_paths()["purelib"]
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(installed), deps]))
    run = _run([sys.executable, "-S", "-c", code], cwd=tmp_path, env=env)
    package, description = run.stdout.split()
    assert Path(package).is_relative_to(installed) and Path(description).is_relative_to(installed)


def test_the_installed_wheel_renders_previews_and_runs_the_pipeline(installed, tmp_path, variant):
    """``render patches``, ``preview workspace`` and a tiny ``pipeline`` outside the repository."""
    _cli(installed, tmp_path, "render", "patches", "--frames", "4", "--shard-frames", "2",
         "--spp", "2", "--workers", "0", "--out", "ds")  # fmt: skip
    manifest = json.loads((tmp_path / "ds" / "manifest.json").read_text())
    assert manifest["complete"] and manifest["family"]["name"] == "patches"
    assert "git_revision" not in manifest["versions"]  # not this checkout's commit

    _cli(installed, tmp_path, "preview", "workspace", "--frames", "1", "--spp", "4",
         "--out", "preview")  # fmt: skip
    assert (tmp_path / "preview" / "preview_workspace.png").read_bytes()[:4] == b"\x89PNG"

    tiny = ["--train-frames", "30", "--train-episodes", "1", "--val-frames", "30",
            "--test-frames", "30", "--test-episodes", "2", "--seeds", "2", "--steps", "10",
            "--workers", "0", "--spp", "1"]  # fmt: skip
    run = _cli(installed, tmp_path, "pipeline", "--family", "patches", *tiny, "--pixels", "2",
               "--baseline-grid", "2x2", "--out", "main")  # fmt: skip
    metrics = json.loads((tmp_path / "main" / "metrics.json").read_text())
    assert set(metrics["designs"]) == {"mincam-2px", "baseline-2x2"}
    assert "trivial" in run.stdout
    assert (tmp_path / "main" / "masks" / "patches" / "mincam-2px" / "masks.json").is_file()
