"""The one place that chooses the Mitsuba variant and checks Dr.Jit's backends.

Every module that needs Mitsuba calls :func:`use_variant` before touching
``mi.*`` types. The variant is chosen once per process, by the first call, and
recorded (:func:`chosen_variant`); later calls return it. The choice is the
backend named by :data:`BACKEND_ENV` when it is set, else CUDA when a GPU driver
is present, else the LLVM (CPU) backend. Monochrome variants are used because a
freeform pixel's photodiode is a single-channel detector.

Why once: a process that rendered part of a dataset or measured a fidelity plan
with one variant must not continue with another (CUDA and LLVM kernels differ
in the last bits, so shards or plans of two variants would mix silently). A
request for another backend after the choice raises
:class:`VariantConflictError`; worker processes are handed the parent's variant
(:mod:`mincam_render.data.render_job.executors`).

Run ``python -m mincam_render.render.backend`` to print the chosen variant and libLLVM.
"""

from __future__ import annotations

import enum
import logging
import os

import drjit as dr
import mitsuba as mi

log = logging.getLogger(__name__)

#: Dr.Jit's LLVM backend aborts with LLVM <= 15 ("Cannot select ... fminimum").
MIN_LLVM_MAJOR = 16


class Backend(enum.Enum):
    """Compute device for Mitsuba and Dr.Jit."""

    AUTO = "auto"
    LLVM = "llvm"
    CUDA = "cuda"


#: The monochrome AD variant of each backend.
VARIANTS = {Backend.LLVM: "llvm_ad_mono", Backend.CUDA: "cuda_ad_mono"}
#: Environment variable naming the backend of a process (``auto``, ``llvm`` or
#: ``cuda``); unset means ``auto``. Worker processes inherit it.
BACKEND_ENV = "MINCAM_RENDER_BACKEND"

#: The variant this process chose (None until the first :func:`use_variant`).
_chosen: str | None = None


class BackendUnavailableError(RuntimeError):
    """No usable Dr.Jit backend (missing/old libLLVM, or no CUDA device)."""


class VariantConflictError(BackendUnavailableError):
    """Another backend was requested after this process chose its variant."""


def chosen_variant() -> str | None:
    """The variant this process chose, or None when nothing has needed Mitsuba yet."""
    return _chosen


def backend_of(variant: str) -> Backend:
    """The :class:`Backend` of a variant name (``"cuda_ad_mono"`` -> ``Backend.CUDA``).

    Raises:
        ValueError: not a variant this package uses.
    """
    for backend, name in VARIANTS.items():
        if name == variant:
            return backend
    raise ValueError(f"variant {variant!r} is none of {sorted(VARIANTS.values())}")


def _requested_backend(backend: Backend) -> Backend:
    """``backend``, or for ``AUTO`` the one :data:`BACKEND_ENV` names (``AUTO`` if unset).

    Raises:
        BackendUnavailableError: the environment variable names no backend.
    """
    if backend is not Backend.AUTO:
        return backend
    name = os.environ.get(BACKEND_ENV, "").strip().lower() or Backend.AUTO.value
    try:
        return Backend(name)
    except ValueError:
        allowed = ", ".join(b.value for b in Backend)
        raise BackendUnavailableError(
            f"{BACKEND_ENV}={name!r} names no backend (allowed: {allowed})"
        ) from None


def _llvm_problem() -> str | None:
    """Describe why the LLVM backend is unusable, or return None when it is fine."""
    if not dr.has_backend(dr.JitBackend.LLVM):
        return (
            "Dr.Jit found no libLLVM. Install one with 'apt-get install -y libllvm19' "
            "(scripts/setup.sh does this) or set DRJIT_LIBLLVM_PATH to a libLLVM >= "
            f"{MIN_LLVM_MAJOR} shared library."
        )
    version = dr.detail.llvm_version()
    if version[0] < MIN_LLVM_MAJOR:
        return (
            f"Dr.Jit loaded libLLVM {'.'.join(map(str, version))}, which miscompiles "
            f"Mitsuba kernels; install libllvm19 and/or set DRJIT_LIBLLVM_PATH to a "
            f"libLLVM >= {MIN_LLVM_MAJOR}."
        )
    return None


def use_variant(backend: Backend = Backend.AUTO) -> str:
    """Select the monochrome AD Mitsuba variant for ``backend`` and return its name.

    The first call of a process chooses and records the variant; later calls
    return the recorded one (and set it again should anything have changed it).

    Args:
        backend: ``AUTO`` takes the process's variant once chosen; before that,
            the backend :data:`BACKEND_ENV` names, else CUDA when a device is
            present, else LLVM.

    Returns:
        The variant name, e.g. ``"llvm_ad_mono"``.

    Raises:
        VariantConflictError: ``backend`` is not the one this process chose.
        BackendUnavailableError: the requested backend cannot run here.

    """
    global _chosen
    backend = Backend(backend)
    if _chosen is not None:
        if backend is not Backend.AUTO and VARIANTS[backend] != _chosen:
            raise VariantConflictError(
                f"backend {backend.value!r} requested, but this process already renders "
                f"with {_chosen} (the variant is chosen once per process; set "
                f"{BACKEND_ENV} before starting it)"
            )
        if mi.variant() != _chosen:
            mi.set_variant(_chosen)
        return _chosen
    variant = _select(_requested_backend(backend))
    _chosen = variant
    log.debug("Mitsuba variant %s chosen for this process", variant)
    return variant


def _select(backend: Backend) -> str:
    """Check that ``backend`` runs here, set its variant in Mitsuba and return its name."""
    want_cuda = backend is Backend.CUDA or (
        backend is Backend.AUTO and dr.has_backend(dr.JitBackend.CUDA)
    )
    if want_cuda:
        if not dr.has_backend(dr.JitBackend.CUDA):
            raise BackendUnavailableError("backend 'cuda' requested but no CUDA device is usable")
        variant = VARIANTS[Backend.CUDA]
    else:
        problem = _llvm_problem()
        if problem is not None:
            raise BackendUnavailableError(problem)
        variant = VARIANTS[Backend.LLVM]
    if not isinstance(mi.logger().appender(0), _MitsubaToLogging):
        _route_mitsuba_log()
    if mi.variant() != variant:
        mi.set_variant(variant)
        log.debug("Mitsuba variant set to %s", variant)
    return variant


#: Mitsuba messages that say nothing to our users (every photodiode is monochrome).
_IRRELEVANT_MITSUBA_MESSAGES = ("Monochrome mode enabled",)


class _MitsubaToLogging(mi.Appender):
    """Mitsuba's log into Python logging (logger ``mitsuba``), irrelevant warnings dropped."""

    def append(self, level: mi.LogLevel, text: str) -> None:
        if any(m in text for m in _IRRELEVANT_MITSUBA_MESSAGES):
            return
        py_level = {mi.LogLevel.Warn: logging.WARNING, mi.LogLevel.Error: logging.ERROR}
        logging.getLogger("mitsuba").log(py_level.get(level, logging.DEBUG), "%s", text.strip())

    def log_progress(
        self, progress: float, name: str, formatted: str, eta: str, ptr: object | None = None
    ) -> None:
        """Mitsuba's own progress bars are not used (our commands draw theirs)."""


def _route_mitsuba_log() -> None:
    logger = mi.logger()
    logger.clear_appenders()
    logger.add_appender(_MitsubaToLogging())


def describe() -> dict[str, str]:
    """Return the chosen variant and library versions (for manifests and benchmarks)."""
    info = {
        "variant": use_variant(),
        "mitsuba": mi.__version__,
        "drjit": dr.__version__,
    }
    if dr.has_backend(dr.JitBackend.LLVM):
        info["libllvm"] = ".".join(map(str, dr.detail.llvm_version()))
    return info


if __name__ == "__main__":
    try:
        for key, value in describe().items():
            print(f"{key}: {value}")
    except BackendUnavailableError as err:
        print(f"error: {err}")
        raise SystemExit(1) from None
