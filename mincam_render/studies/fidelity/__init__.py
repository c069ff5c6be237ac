"""The fidelity benchmark: error against run time of every rendering knob."""

from mincam_render.studies.fidelity.config import KNOBS, FidelityBenchConfig
from mincam_render.studies.fidelity.report import (
    fidelity_statements,
    pareto_front,
    pareto_table,
    plot_pareto,
    write_report,
)
from mincam_render.studies.fidelity.result import (
    BaseRun,
    BenchCamera,
    DetectorModel,
    FamilyFidelity,
    FidelityBenchResult,
    FidelityRow,
    KnobErrors,
    KnobSettings,
    Machine,
    ReferenceRun,
    RenderSharing,
    SignalErrors,
)
from mincam_render.studies.fidelity.study import measure_family, run

__all__ = [
    "KNOBS",
    "BaseRun",
    "BenchCamera",
    "DetectorModel",
    "FamilyFidelity",
    "FidelityBenchConfig",
    "FidelityBenchResult",
    "FidelityRow",
    "KnobErrors",
    "KnobSettings",
    "Machine",
    "ReferenceRun",
    "RenderSharing",
    "SignalErrors",
    "fidelity_statements",
    "measure_family",
    "pareto_front",
    "pareto_table",
    "plot_pareto",
    "run",
    "write_report",
]
