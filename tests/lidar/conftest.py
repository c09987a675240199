"""Fixtures shared by the tests of tiled runs (parallel workers, resumed runs)."""
import pytest

from gisroads.lidar.pipeline import extract_roads
from gisroads.synthetic import make_scene, write_cloud


@pytest.fixture(scope="session")
def tiled_cloud(tmp_path_factory):
    """A 700 x 500 m scene of every feature at 2 pulses/m2: six tiles of 300 m."""
    scene = make_scene(seed=1, size_m=(700.0, 500.0))
    path = tmp_path_factory.mktemp("tiled") / "cloud.laz"
    write_cloud(scene, path, density_per_m2=2.0, seed=1)
    return path


@pytest.fixture(scope="session")
def tiled_network(tiled_cloud):
    """The intensity cue's network of an uninterrupted run, tiles one after another here."""
    return extract_roads(tiled_cloud, cue="intensity")
