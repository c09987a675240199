"""Fixtures of the tests of tiled LiDAR runs (parallel workers, resumed runs)."""
import pytest

from gisroads.lidar.pipeline import extract_roads


@pytest.fixture(scope="session")
def tiled_network(tiled_cloud):
    """The intensity cue's network of an uninterrupted run, tiles one after another here."""
    return extract_roads(tiled_cloud, cue="intensity")
