"""Map-guided road extraction with ribbon snakes (Boyko & Funkhouser 2011).

The entry point is :func:`extract_map_guided`: a LAS/LAZ file and an approximate road map
to road polygons, kerb to kerb. Stages, each callable alone: map registration in 3D
(:func:`register_map`), subclouds per road patch (:mod:`.subclouds`), then the attractor
map (:func:`curb_attractor` over a whole map), its gradient vector flow and the ribbon
snake fitted to it (:func:`fit_ribbon`).

The names are imported from their modules on first use, so that ``import gisroads.snakes``
stays cheap.
"""
from typing import TYPE_CHECKING

from .. import _lazy_exports

__all__ = [
    "MapGuidedRoads", "Ribbon", "RibbonOptions", "curb_attractor", "extract_map_guided",
    "fit_ribbon", "map_patches", "register_map",
]

__getattr__, __dir__ = _lazy_exports(__name__, {
    **dict.fromkeys(["MapGuidedRoads", "Ribbon", "RibbonOptions", "curb_attractor",
                     "extract_map_guided", "fit_ribbon", "map_patches"], ".pipeline"),
    "register_map": ".registration",
})

if TYPE_CHECKING:
    from .pipeline import (MapGuidedRoads, Ribbon, RibbonOptions, curb_attractor,
                           extract_map_guided, fit_ribbon, map_patches)
    from .registration import register_map
