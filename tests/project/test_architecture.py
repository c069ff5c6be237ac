"""The package's shape: layers import only downward, no import cycles, lint-clean code."""

import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import grimp
import networkx as nx
import pytest

REPO = Path(__file__).resolve().parents[2]


def _tool(name: str) -> str:
    path = Path(sys.executable).parent / name
    if not path.exists():
        found = shutil.which(name)
        if found is None:
            pytest.fail(f"{name} is not installed: run bash scripts/setup.sh --dev")
        return found
    return str(path)


def test_layer_contracts_of_pyproject_hold():
    run = subprocess.run(
        [_tool("lint-imports")], cwd=REPO, capture_output=True, text=True, check=False
    )
    assert run.returncode == 0, run.stdout[-3000:]
    assert "0 broken" in run.stdout


def test_no_module_imports_itself_through_others():
    # every import counts, those under TYPE_CHECKING and a package's __init__
    # re-exporting its modules too: a module that imports its own package's
    # __init__ (which imports it back) is a circle; no cache, so the graph is
    # of the files as they are now (grimp takes well under a second)
    graph = grimp.build_graph("mincam_render", cache_dir=None)
    edges = nx.DiGraph()
    for module in graph.modules:
        for imported in graph.find_modules_directly_imported_by(module):
            edges.add_edge(module, imported)
    cycles = list(nx.simple_cycles(edges))
    assert cycles == [], f"import cycles: {cycles[:5]}"


def test_layers_are_the_subpackages_of_the_package():
    layers = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["importlinter"][
        "contracts"
    ][0]["layers"]
    packages = {p.parent.name for p in (REPO / "mincam_render").glob("*/__init__.py")}
    assert set(layers) == packages, "every subpackage belongs to exactly one layer"
    assert not [p.name for p in (REPO / "mincam_render").glob("*.py") if p.name != "__init__.py"]


def test_every_study_is_in_the_contract_that_keeps_studies_apart():
    contracts = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["importlinter"][
        "contracts"
    ]
    (studies,) = [c for c in contracts if c.get("containers") == ["mincam_render.studies"]]
    named = {name.strip() for layer in studies["layers"] for name in layer.split("|")}
    packages = {p.parent.name for p in (REPO / "mincam_render" / "studies").glob("*/__init__.py")}
    assert named == packages, "every study is a sibling, or the comparison they build on"
    assert not [
        p.name for p in (REPO / "mincam_render" / "studies").glob("*.py") if p.name != "__init__.py"
    ]


def test_the_wheel_lists_every_package_and_maps_the_scene_folder():
    """pyproject lists the packages (find cannot add the mapped scenes/): none forgotten."""
    tool = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]
    on_disk = {
        ".".join(p.parent.relative_to(REPO).parts)
        for p in (REPO / "mincam_render").rglob("__init__.py")
    }
    assert set(tool["packages"]) == on_disk | {"mincam_render.scene_data"}
    assert tool["package-dir"] == {"mincam_render.scene_data": "scenes"}


def test_ruff_finds_nothing():
    run = subprocess.run(
        [_tool("ruff"), "check", "mincam_render", "tests", "benchmarks", "scripts", "examples"],
        cwd=REPO,
        capture_output=True,
        text=True,
        check=False,
    )
    assert run.returncode == 0, run.stdout[-3000:]


def test_mypy_finds_nothing():
    """The package type-checks (settings in pyproject.toml's [tool.mypy])."""
    run = subprocess.run([_tool("mypy")], cwd=REPO, capture_output=True, text=True, check=False)
    assert run.returncode == 0, run.stdout[-3000:]


def test_the_command_line_starts_without_torch_or_mitsuba():
    """Regression: every command, --help included, took ~7 s importing torch first."""
    code = (
        "import sys; from click.testing import CliRunner; from mincam_render.cli.main import main; "
        "r = CliRunner().invoke(main, ['render', '--help']); assert r.exit_code == 0, r.output; "
        "print(sorted(m for m in ('torch', 'mitsuba', 'drjit') if m in sys.modules))"
    )
    run = subprocess.run(
        [sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, check=True
    )
    assert run.stdout.strip() == "[]", run.stdout + run.stderr


def test_runs_are_read_back_through_one_restore_path():
    """A trained camera comes back from its run directory in one place (learn/restore).

    Restore written three times behaved three ways (a privacy run's adversary kept
    by one, a TCN head lost by another): every checkpoint read is the resumable
    state's (learn/checkpoint) or the restore path's.
    """
    readers = {
        path.relative_to(REPO).as_posix()
        for path in (REPO / "mincam_render").rglob("*.py")
        if "load_checkpoint(" in path.read_text() or "torch.load(" in path.read_text()
    }
    assert readers == {"mincam_render/learn/checkpoint.py", "mincam_render/learn/restore.py"}


def test_the_mitsuba_variant_is_set_in_one_place():
    """The backend is explicit state: only render/backend sets Mitsuba's variant.

    A second ``mi.set_variant`` elsewhere could switch a process between CPU and
    GPU under a dataset's feet; ``backend.use_variant`` chooses once and records
    it, and a resumed dataset of another variant is refused.
    """
    setters = {
        path.relative_to(REPO).as_posix()
        for path in (REPO / "mincam_render").rglob("*.py")
        if "set_variant(" in path.read_text()
    }
    assert setters == {"mincam_render/render/backend.py"}
