"""A trained design under fabrication and detector perturbations: error, tolerance, spec.

``config`` (what is measured), ``result`` (the typed curves of a design,
:class:`DesignCurves`), ``study`` (the curves of a trained camera,
pooled over runs, tolerances and specs; ``run`` for run directories),
``report`` (HTML, PNG, JSON) and ``versus`` (nominal against robust training,
what ``benchmarks/bench_robustness.py`` runs; it imports PyTorch, so it is not
re-exported here).
"""

from mincam_render.studies.robustness.config import CURVES, MIX, RobustnessConfig
from mincam_render.studies.robustness.report import write_report
from mincam_render.studies.robustness.result import DesignCurves
from mincam_render.studies.robustness.study import robustness_curves, run

__all__ = [
    "CURVES",
    "MIX",
    "DesignCurves",
    "RobustnessConfig",
    "robustness_curves",
    "run",
    "write_report",
]
