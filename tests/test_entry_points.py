"""The front door: every name a package exports resolves, and the options objects of the
entry points are frozen, with the defaults the stages read (``stage_default``)."""
import dataclasses
import importlib

import pytest

from gisroads.jobs.common import stage_default

PACKAGES = ["gisroads.evaluate", "gisroads.imagery", "gisroads.io", "gisroads.lidar",
            "gisroads.network", "gisroads.snakes", "gisroads.synthetic", "gisroads.update"]

OPTIONS = [  # (module, options class, the function taking it)
    ("gisroads.lidar.pipeline", "LidarOptions", "extract_roads"),
    ("gisroads.lidar.hypotheses", "HypothesisOptions", "road_hypotheses"),
    ("gisroads.imagery.pipeline", "ImageOptions", "extract_image_roads"),
    ("gisroads.imagery.roadparts", "RoadPartCriteria", "filter_road_parts"),
    ("gisroads.imagery.grouping", "GroupingOptions", "group_segments"),
    ("gisroads.snakes.pipeline", "RibbonOptions", "fit_ribbon"),
    ("gisroads.snakes.pipeline", "RibbonOptions", "extract_map_guided"),
    ("gisroads.snakes.attractor", "AttractorOptions", "attractor_map"),
    ("gisroads.snakes.ribbon", "SnakeOptions", "ribbon_snake"),
    ("gisroads.network.junctions", "NetworkOptions", "strings_to_network"),
    ("gisroads.network.rasters", "PartOptions", "skeleton_parts"),
    ("gisroads.network.subgraph", "ContextOptions", "gap_context"),
    ("gisroads.network.subgraph", "GapOptions", "gap_edges"),
    ("gisroads.network.subgraph", "WeightOptions", "edge_weights"),
    ("gisroads.update.conflate", "MatchOptions", "conflate"),
]


@pytest.mark.parametrize("package", PACKAGES)
def test_every_exported_name_resolves(package):
    module = importlib.import_module(package)
    missing = [name for name in module.__all__ if getattr(module, name, None) is None]
    assert not missing


@pytest.mark.parametrize("module, options, function", OPTIONS,
                         ids=[f"{o}-{f}" for _, o, f in OPTIONS])
def test_options_are_frozen_and_hold_the_stage_defaults(module, options, function):
    module = importlib.import_module(module)
    cls, function = getattr(module, options), getattr(module, function)
    defaults = cls()
    with pytest.raises(dataclasses.FrozenInstanceError):
        setattr(defaults, dataclasses.fields(cls)[0].name, None)
    for field in dataclasses.fields(cls):
        assert stage_default(function, field.name) == getattr(defaults, field.name)
    with pytest.raises(TypeError):
        dataclasses.replace(defaults, no_such_option=1)
