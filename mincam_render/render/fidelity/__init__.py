"""Fidelity planning: render settings chosen from measured errors (see :mod:`.plan`)."""

from mincam_render.render.fidelity.budget import round_up_spp, split_noise_budget, spp_for
from mincam_render.render.fidelity.constants import PILOT_SPP
from mincam_render.render.fidelity.plan import Fidelity, FidelityPlan, decide_fidelity
from mincam_render.render.fidelity.probes import depth_map_m, nearest_depth_m

__all__ = [
    "PILOT_SPP",
    "Fidelity",
    "FidelityPlan",
    "decide_fidelity",
    "depth_map_m",
    "nearest_depth_m",
    "round_up_spp",
    "spp_for",
    "split_noise_budget",
]
