"""The task-level check of a fidelity plan: task figures against samples, noise against signal."""

from mincam_render.studies.task_fidelity.config import (
    CHECK_DESIGNS,
    SampleLevel,
    TaskFidelityConfig,
)
from mincam_render.studies.task_fidelity.noise import NoiseFigures, noise_figures
from mincam_render.studies.task_fidelity.report import write_report
from mincam_render.studies.task_fidelity.study import (
    Acceptance,
    CrossFigures,
    LevelFigures,
    TaskFidelityResult,
    level_requests,
    render_level,
    run,
)

__all__ = [
    "CHECK_DESIGNS",
    "Acceptance",
    "CrossFigures",
    "LevelFigures",
    "NoiseFigures",
    "SampleLevel",
    "TaskFidelityConfig",
    "TaskFidelityResult",
    "level_requests",
    "noise_figures",
    "render_level",
    "run",
    "write_report",
]
