"""Map-guided road extraction with ribbon snakes (Boyko & Funkhouser 2011).

Stages, each callable alone: map registration in 3D (:mod:`.registration`), subclouds per
road patch (:mod:`.subclouds`), then the attractor map, its gradient vector flow and the
ribbon snakes fitted to it.
"""
