"""'NCut segmentation (imagery)' and 'Segment grouping' through qgis_process on a 300 x 300 px
image with a road crossing a lawn, a grey roof of the road's colour and a DSM."""
import geopandas as gpd
import numpy as np
import pytest
import shapely
from affine import Affine
from pyproj import CRS
from scipy import ndimage

from gisroads.geo import GeoRaster
from gisroads.imagery.segments import frame_to_labels
from gisroads.io.raster import write_geotiff
from gisroads.io.vector import write_geopackage
from gisroads.segmentation.ncut import segment_boundaries

EPSG = "EPSG:32633"
PX = 0.5
X0, Y0 = 500000.0, 4500000.0
GRID = Affine(PX, 0, X0, 0, -PX, Y0 + 150.0)  # 150 x 150 m
SHAPE = (300, 300)


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("segments")
    road = np.zeros(SHAPE, bool)
    road[140:156] = True          # 8 m wide, west to east
    roof = np.zeros(SHAPE, bool)
    roof[40:100, 60:140] = True   # 40 x 30 m, as grey as the road
    image = np.empty((4,) + SHAPE)
    image[:] = np.array([80.0, 112.0, 52.0, 190.0])[:, None, None]   # lawn
    image[:, road | roof] = np.array([86.0, 88.0, 91.0, 92.0])[:, None]
    image += np.random.default_rng(0).normal(0, 4, image.shape)
    write_geotiff(folder / "image.tif",
                  GeoRaster(np.clip(image, 0, 255).astype(np.uint8), GRID, CRS(EPSG)))
    write_geotiff(folder / "dsm.tif",
                  GeoRaster(np.where(roof, 6.0, 0.0).astype(np.float32), GRID, CRS(EPSG)))
    like = GeoRaster(np.zeros(SHAPE), GRID, CRS(EPSG))
    return folder, road, roof, like


def pieces(labels, region):
    return np.unique(labels[region])


def test_segmentation_then_grouping(qgis_process, inputs, tmp_path):
    folder, road, roof, like = inputs
    result = qgis_process.run("imagesegmentation", IMAGE=folder / "image.tif", NIR_BAND=4,
                              N_SEGMENTS=80, OUTPUT=tmp_path / "segments.gpkg")
    segments = gpd.read_file(tmp_path / "segments.gpkg")
    assert result["SEGMENTS"] == len(segments) and 70 <= len(segments) <= 130
    assert segments.crs == CRS(EPSG)
    assert segments.segment_id.is_unique
    assert segments.area.sum() == pytest.approx(150.0 * 150.0)
    labels = frame_to_labels(segments, like)
    assert (labels >= 0).all()
    edge = road ^ ndimage.binary_erosion(road, border_value=1)
    near = ndimage.distance_transform_edt(~segment_boundaries(labels)) <= 1
    assert near[edge].mean() > 0.95
    assert all(road[labels == s].all() for s in pieces(labels, road))  # nothing mixed

    result = qgis_process.run("segmentgrouping", IMAGE=folder / "image.tif",
                              SEGMENTS=f"{tmp_path / 'segments.gpkg'}",
                              DSM=folder / "dsm.tif", NIR_BAND=4,
                              OUTPUT=tmp_path / "grouped.gpkg")
    grouped = gpd.read_file(tmp_path / "grouped.gpkg")
    assert result["SEGMENTS"] == len(grouped) < len(segments) / 3
    assert grouped.area.sum() == pytest.approx(150.0 * 150.0)
    merged = frame_to_labels(grouped, like)
    assert len(pieces(merged, road)) < len(pieces(labels, road)) / 2
    assert all(road[merged == s].all() for s in pieces(merged, road))
    # the roof is as grey as the road but 6 m high: never merged with the lawn or the road
    # (superpixels leave a few lawn pixels at its corners)
    on_roof = merged == merged[70, 100]
    assert roof[on_roof].mean() > 0.97 and on_roof[roof].mean() > 0.95


def test_grouping_refuses_segments_off_the_image(qgis_process, inputs, tmp_path):
    folder, *_ = inputs
    far = gpd.GeoDataFrame({"segment_id": [0]}, geometry=[shapely.box(0, 0, 10, 10)],
                           crs=EPSG)
    write_geopackage(tmp_path / "far.gpkg", {"segments": far})
    run = qgis_process("run", "gisroads:segmentgrouping", "--",
                       f"IMAGE={folder / 'image.tif'}", f"SEGMENTS={tmp_path / 'far.gpkg'}",
                       f"OUTPUT={tmp_path / 'out.gpkg'}", check=False)
    assert run.returncode != 0
    assert "no segment polygon overlaps the image" in run.stdout + run.stderr
