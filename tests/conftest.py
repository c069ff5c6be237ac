"""Shared fixtures: seeded RNG, backend availability, the tiny datasets and runs of many modules."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from mincam_render.render import backend


@pytest.fixture(autouse=True, scope="session")
def isolated_plan_cache(tmp_path_factory):
    """Fidelity plans of one test session go to a temporary cache, not the user's.

    Session-scoped, so module-scoped fixtures that render are isolated too.
    """
    from mincam_render.data.plan_cache import CACHE_ENV

    with pytest.MonkeyPatch.context() as patch:
        patch.setenv(CACHE_ENV, str(tmp_path_factory.getbasetemp() / "plan-cache"))
        yield


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(12345)


@pytest.fixture(scope="session")
def variant() -> str:
    """The Mitsuba variant in use; skips the test when no Dr.Jit backend works here."""
    try:
        return backend.use_variant()
    except backend.BackendUnavailableError as err:
        pytest.skip(f"no usable Dr.Jit backend: {err}")


@pytest.fixture(scope="session")
def cuda_variant() -> str:
    try:
        return backend.use_variant(backend.Backend.CUDA)
    except backend.BackendUnavailableError as err:
        pytest.skip(f"no CUDA: {err}")


# ---- tiny datasets and runs shared by the test modules ----------------------------------------
# Session-scoped: rendered (or trained) once, read by every module that needs one.
# Users that change a dataset take the ``*_copy`` fixture, a copy in their own
# tmp_path, never the shared folder.


def _render_shared(tmp_path_factory, request, folder: str) -> Path:
    """``request`` rendered once in this process into a fresh ``folder``/ds."""
    from mincam_render.data.render_job import render_dataset

    out = tmp_path_factory.mktemp(folder) / "ds"
    render_dataset(request, out, workers=0)
    return out


@pytest.fixture(scope="session")
def tiny_patches(tmp_path_factory, variant) -> Path:
    """``support.TINY_PATCHES`` rendered in this process: read it, never write into it."""
    from support import TINY_PATCHES

    return _render_shared(tmp_path_factory, TINY_PATCHES, "tiny-patches")


@pytest.fixture
def tiny_patches_copy(tiny_patches, tmp_path) -> Path:
    """A copy of ``tiny_patches`` in this test's tmp_path, to edit, damage or resume."""
    return Path(shutil.copytree(tiny_patches, tmp_path / "ds"))


@pytest.fixture(scope="session")
def differential_dataset(tmp_path_factory, variant) -> Path:
    """``support.TINY_DIFFERENTIAL`` rendered in this process: read it, never write into it."""
    from support import TINY_DIFFERENTIAL

    return _render_shared(tmp_path_factory, TINY_DIFFERENTIAL, "differential")


@pytest.fixture
def differential_dataset_copy(differential_dataset, tmp_path) -> Path:
    """A copy of ``differential_dataset`` in this test's tmp_path, to edit or resume."""
    return Path(shutil.copytree(differential_dataset, tmp_path / "differential"))


@pytest.fixture(scope="session")
def runs_of_each_kind(tmp_path_factory, variant) -> dict:
    """``{kind: (run directory, its metrics, its test split)}``: one finished run of each
    kind of ``support.RUN_KINDS``, trained with ``support.RUN_CONFIG``. Read only."""
    from support import RUN_CONFIG, RUN_KINDS, run_splits

    from mincam_render.learn import train as tr

    root = tmp_path_factory.mktemp("runs")
    out = {}
    for kind, (temporal, kwargs) in RUN_KINDS.items():
        train, val, test = run_splits(temporal)
        metrics = tr.train_run(train, val, test, root / kind, **{"config": RUN_CONFIG, **kwargs})
        out[kind] = (root / kind, metrics, test)
    return out


@pytest.fixture(scope="session")
def finished_run(runs_of_each_kind) -> Path:
    """The finished minimalist run (2 pixels) of ``runs_of_each_kind``: read it or copy it."""
    return runs_of_each_kind["mincam"][0]
