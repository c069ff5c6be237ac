"""The one place that chooses the Mitsuba variant and checks Dr.Jit's backends.

Every module that needs Mitsuba calls :func:`use_variant` before touching
``mi.*`` types. The choice prefers CUDA (when a GPU driver is present) and falls
back to the LLVM (CPU) backend. Monochrome variants are used because a freeform
pixel's photodiode is a single-channel detector.

Run ``python -m mincam_render.render.backend`` to print the chosen variant and libLLVM.
"""

from __future__ import annotations

import enum
import logging

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


class BackendUnavailableError(RuntimeError):
    """No usable Dr.Jit backend (missing/old libLLVM, or no CUDA device)."""


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

    Args:
        backend: ``AUTO`` takes CUDA when a device is present, else LLVM.

    Returns:
        The variant name, e.g. ``"llvm_ad_mono"``.

    Raises:
        BackendUnavailableError: the requested backend cannot run here.

    """
    backend = Backend(backend)
    want_cuda = backend is Backend.CUDA or (
        backend is Backend.AUTO and dr.has_backend(dr.JitBackend.CUDA)
    )
    if want_cuda:
        if not dr.has_backend(dr.JitBackend.CUDA):
            raise BackendUnavailableError("backend 'cuda' requested but no CUDA device is usable")
        variant = "cuda_ad_mono"
    else:
        problem = _llvm_problem()
        if problem is not None:
            raise BackendUnavailableError(problem)
        variant = "llvm_ad_mono"
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
