"""Shared fixtures: seeded RNG, backend availability, small cameras."""

from __future__ import annotations

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
