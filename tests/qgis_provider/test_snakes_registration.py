"""'Register road map to point cloud' run by the real qgis_process.bin on a synthetic scene."""
import numpy as np
import pytest
import shapely

from gisroads.io.las import read_las
from gisroads.io.vector import list_layers, read_layer, write_geopackage
from tests.qgis_provider.map_scenes import cloud_and_map, map_inputs


@pytest.fixture(scope="module")
def overpass(tmp_path_factory):
    """A bridge and a cliff road at 5 points/m2, and a map of its edges shifted 2.5 m."""
    return cloud_and_map(tmp_path_factory.mktemp("register"), seed=2,
                         features=("bridge", "cliff"), density_per_m2=5.0)


def test_registered_vertices_lie_on_the_surface(qgis_process, overpass, tmp_path):
    scene, folder = overpass
    result = qgis_process.run("registerroadmap", **map_inputs(folder), SNAP=7.0,
                              OUTPUT=tmp_path / "registered.gpkg")
    assert list_layers(tmp_path / "registered.gpkg") == ["registered_map"]
    lines = read_layer(tmp_path / "registered.gpkg", "registered_map")
    assert lines.crs == read_las(folder / "cloud.laz").crs
    assert result["ROADS"] == len(lines) == len(scene.truth_edges)
    assert 0.2 < result["SEEN_FRACTION"] < 0.5  # 5 points/m2: 30 % of 15 cm discs hold one
    assert shapely.has_z(lines.geometry.values).all()
    xyz, index = shapely.get_coordinates(lines.geometry.values, include_z=True,
                                         return_index=True)
    bridge = int(scene.bridges["road_id"].iloc[0])
    on_bridge = lines["map_road_id"].to_numpy()[index] == bridge
    truth = scene.ground_z(xyz[:, 0], xyz[:, 1])
    truth[on_bridge] = scene.relief.road_z(xyz[on_bridge, 0], xyz[on_bridge, 1], bridge)
    dz = np.abs(xyz[:, 2] - truth)
    assert np.percentile(dz, 95) <= 0.10
    assert np.median(dz) <= 0.05
    # The avenue passes under the deck on the ground.
    deck = scene.deck_z(xyz[:, 0], xyz[:, 1])
    under = ~on_bridge & np.isfinite(deck)
    assert under.any() and (xyz[under, 2] < deck[under] - 5).all()


def test_a_map_beside_the_cloud_is_refused(qgis_process, overpass, tmp_path):
    scene, folder = overpass
    far = scene.truth_edges.copy()
    far.geometry = far.geometry.translate(5000.0, 0.0)
    write_geopackage(tmp_path / "far.gpkg", {"far": far})
    result = qgis_process("run", "gisroads:registerroadmap", "--",
                          f"INPUT={folder / 'cloud.laz'}", f"MAP={tmp_path / 'far.gpkg'}",
                          f"OUTPUT={tmp_path / 'out.gpkg'}", check=False)
    assert result.returncode != 0
    assert "no point lies along the map" in result.stdout + result.stderr
    assert not (tmp_path / "out.gpkg").exists()
