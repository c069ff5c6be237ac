"""The design protocol: per-task cameras, recipes by measurement, learning curves, references."""

from mincam_render.studies.design_protocol.config import (
    DesignProtocolConfig,
    Floor,
    RecipeVariant,
    default_recipes,
    recipes_named,
)
from mincam_render.studies.design_protocol.report import write_report
from mincam_render.studies.design_protocol.study import (
    DesignProtocolResult,
    FloorCheck,
    FloorVerdict,
    run,
)

__all__ = [
    "DesignProtocolConfig",
    "DesignProtocolResult",
    "Floor",
    "FloorCheck",
    "FloorVerdict",
    "RecipeVariant",
    "default_recipes",
    "recipes_named",
    "run",
    "write_report",
]
