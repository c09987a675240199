"""The whole imagery pipeline through qgis_process: the plugin's algorithm, the image's cues."""
import numpy as np
from affine import Affine
from pyproj import CRS

from gisroads.evaluate import buffer_metrics
from gisroads.geo import GeoRaster
from gisroads.io.raster import write_geotiff
from gisroads.io.vector import list_layers, read_layer
from tests.road_layers import assert_empty_road_layers


def test_imagery_road_network_uses_nir_and_dsm(qgis_process, scene_dir, tmp_path):
    result = qgis_process.run("imageryroadnetwork", INPUT=scene_dir / "image.tif", NIR_BAND=4,
                              DSM=scene_dir / "dsm.tif", USE_MODEL="false",
                              OUTPUT=tmp_path / "roads.gpkg")
    assert result["CUES"] == "rgb+nir+dsm" and result["ROADS"] > 0
    assert list_layers(tmp_path / "roads.gpkg")[:4] == ["road_centrelines", "road_polygons",
                                                        "junctions", "segments"]
    lines = read_layer(tmp_path / "roads.gpkg", "road_centrelines")
    truth = read_layer(scene_dir / "truth.gpkg", "road_centrelines")
    # 1 m pixels: a 9 m street is 9 pixels across
    assert buffer_metrics(lines, truth, buffer_m=3.0).correctness > 0.5


def test_imagery_band_the_image_lacks_fails_cleanly(qgis_process, scene_dir, tmp_path):
    result = qgis_process("run", "gisroads:imageryroadnetwork", "--",
                          f"INPUT={scene_dir / 'dsm.tif'}", "NIR_BAND=1", "RED_BAND=3",
                          f"OUTPUT={tmp_path / 'r.gpkg'}", check=False)
    assert result.returncode == 1 and "no red band 3" in result.stdout + result.stderr
    assert not (tmp_path / "r.gpkg").exists()


def test_an_image_without_roads_succeeds_with_empty_layers_and_a_warning(qgis_process,
                                                                        tmp_path):
    rng = np.random.default_rng(0)
    lawn = np.array([80.0, 112.0, 52.0])[:, None, None] + rng.normal(0, 4, (3, 300, 300))
    write_geotiff(tmp_path / "lawn.tif",
                  GeoRaster(lawn.clip(0, 255).astype(np.uint8),
                            Affine(0.5, 0, 500000.0, 0, -0.5, 4500000.0), CRS("EPSG:32633")))
    result = qgis_process("run", "gisroads:imageryroadnetwork", "--",
                          f"INPUT={tmp_path / 'lawn.tif'}", f"OUTPUT={tmp_path / 'r.gpkg'}",
                          check=False)
    assert result.returncode == 0, result.stdout + result.stderr
    assert (f"no road found in {tmp_path / 'lawn.tif'}; wrote empty layers"
            in result.stdout + result.stderr)
    assert "ROADS:\t0" in result.stdout
    assert_empty_road_layers(tmp_path / "r.gpkg")
