"""Self-powered budget: can a minimalist camera run from the light its panel sees?

One concept a module, each importing only those before it: ``config`` (the
description: panel, storage, electronics, camera module, schedule, render),
``consumption`` (frame budgets in joules), ``storage`` (the supercapacitor
stepped through time), ``matching`` (the conventional grid of equal task error
from a study table), ``panel`` (the panel's light rendered in a scene over a
day), ``result`` (:class:`EnergyResult`), ``study`` (:func:`run`), ``figures`` and
``report`` (:func:`write_report`). The study's shape is every study's: a frozen
:class:`EnergyConfig`, ``run(config, out, families=...)``, a frozen
:class:`EnergyResult`, ``write_report(result, out)``. Importing this package loads
numpy, not torch or Mitsuba.
"""

from mincam_render.studies.energy.config import (
    EnergyConfig,
    PanelConfig,
    StorageConfig,
    load_energy_config,
)
from mincam_render.studies.energy.consumption import FrameBudget, head_flops
from mincam_render.studies.energy.report import headline, write_report
from mincam_render.studies.energy.result import EnergyResult
from mincam_render.studies.energy.storage import StorageTrace, simulate_storage
from mincam_render.studies.energy.study import run, threshold_lux

__all__ = [
    "EnergyConfig",
    "EnergyResult",
    "FrameBudget",
    "PanelConfig",
    "StorageConfig",
    "StorageTrace",
    "head_flops",
    "headline",
    "load_energy_config",
    "run",
    "simulate_storage",
    "threshold_lux",
    "write_report",
]
