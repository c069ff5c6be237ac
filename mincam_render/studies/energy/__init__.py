"""Self-powered budget: can a minimalist camera run from the light its panel sees?

One concept a module, each importing only those before it: ``config`` (the
description: panel, storage, electronics, camera module, schedule, render),
``consumption`` (frame budgets in joules), ``storage`` (the supercapacitor
stepped through time), ``matching`` (the conventional grid of equal task error
from a study table), ``panel`` (the panel's light rendered in a scene over a
day), ``study`` (:func:`analyze_energy`), ``figures`` and ``report``. Importing
this package loads numpy, not torch or Mitsuba.
"""

from mincam_render.studies.energy.config import (
    EnergyConfig,
    PanelConfig,
    StorageConfig,
    load_energy_config,
)
from mincam_render.studies.energy.consumption import FrameBudget, head_flops
from mincam_render.studies.energy.report import headline, write_energy_report
from mincam_render.studies.energy.result import EnergyResult
from mincam_render.studies.energy.storage import StorageTrace, simulate_storage
from mincam_render.studies.energy.study import analyze_energy, threshold_lux

__all__ = [
    "EnergyConfig",
    "EnergyResult",
    "FrameBudget",
    "PanelConfig",
    "StorageConfig",
    "StorageTrace",
    "analyze_energy",
    "head_flops",
    "headline",
    "load_energy_config",
    "simulate_storage",
    "threshold_lux",
    "write_energy_report",
]
