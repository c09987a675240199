"""Synthetic orthoimage and DSM: georeferencing, NDVI, heights, occlusion, GeoTIFF output."""
import numpy as np
import pytest
import rasterio
import shapely
from affine import Affine
from shapely import affinity

from gisroads.io.raster import read_raster
from gisroads.synthetic import make_scene, render_image, write_image

PIXEL = 0.5


@pytest.fixture(scope="module")
def scene():
    return make_scene(seed=2, size_m=(300.0, 320.0))


@pytest.fixture(scope="module")
def rendered(scene):
    return render_image(scene, pixel_m=PIXEL, seed=0)


def _sample(raster, points):
    xy = shapely.get_coordinates(points)
    row, col = raster.xy_to_rowcol(xy[:, 0], xy[:, 1])
    return raster.data[..., row, col]


def _ndvi(image, points):
    red, nir = _sample(image, points)[[0, 3]].astype(float)
    return (nir - red) / (nir + red)


def _interior_points(geoms, spacing, inset, extent=(0, 0, 1e7, 1e7)):
    """Points on a grid inside the geometries shrunk by ``inset`` metres and the extent."""
    shrunk = shapely.intersection(shapely.union_all(shapely.buffer(geoms, -inset)),
                                  shapely.box(*extent))
    xmin, ymin, xmax, ymax = shapely.bounds(shrunk)
    gx, gy = np.meshgrid(np.arange(xmin, xmax, spacing), np.arange(ymin, ymax, spacing))
    points = shapely.points(gx.ravel(), gy.ravel())
    shapely.prepare(shrunk)  # one polygon against many points: unprepared, GEOS 3.11 crawls
    return points[shapely.contains(shrunk, points)]


def test_georeferencing_matches_the_scene(scene, rendered):
    image, dsm = rendered
    xmin, _, _, ymax = scene.extent
    for raster in (image, dsm):
        assert raster.transform == Affine(PIXEL, 0, xmin, 0, -PIXEL, ymax)
        assert raster.shape == (640, 600)
        assert raster.bounds == scene.extent
        assert raster.crs == scene.crs
    assert image.data.shape == (4, 640, 600) and image.data.dtype == np.uint8
    assert dsm.data.dtype == np.float32 and np.isfinite(dsm.data).all()


def test_same_seed_same_image_other_seed_other_noise(scene, rendered):
    image, dsm = render_image(scene, pixel_m=PIXEL, seed=0)
    assert np.array_equal(image.data, rendered[0].data)
    assert np.array_equal(dsm.data, rendered[1].data)
    other, other_dsm = render_image(scene, pixel_m=PIXEL, seed=1)
    assert not np.array_equal(other.data, image.data)
    assert np.array_equal(other_dsm.data, dsm.data)  # noise is in the colours only


def test_ndvi_separates_vegetation_from_asphalt(scene, rendered):
    image = rendered[0]
    crowns = _interior_points(shapely.buffer(scene.trees.geometry.values,
                                             scene.trees["crown_radius_m"].to_numpy()),
                              1.0, 0.5, scene.extent)
    assert np.median(_ndvi(image, crowns)) > 0.3
    # Bare asphalt: road polygons away from markings, cars, crowns and the deck.
    covered = shapely.union_all(np.concatenate([
        shapely.buffer(scene.markings.geometry.values, 0.5),
        shapely.buffer(scene.cars.geometry.values, 0.5),
        shapely.buffer(scene.trees.geometry.values,
                       scene.trees["crown_radius_m"].to_numpy() + 0.5),
        scene.bridges.geometry.values]))
    asphalt = _interior_points(scene.truth.polygons.geometry.values, 1.0, 0.5, scene.extent)
    shapely.prepare(covered)
    asphalt = asphalt[~shapely.intersects(covered, asphalt)]
    assert len(asphalt) > 1000
    ndvi = _ndvi(image, asphalt)
    assert np.median(ndvi) < 0.1 and np.quantile(ndvi, 0.95) < 0.15


def test_trees_hide_the_roads_beneath(scene, rendered):
    image = rendered[0]
    roads = shapely.union_all(scene.truth.polygons.geometry.values)
    crowns = shapely.buffer(scene.trees.geometry.values,
                            scene.trees["crown_radius_m"].to_numpy() - 0.5)
    over_road = _interior_points(shapely.intersection(crowns, roads), 0.5, 0.0, scene.extent)
    assert len(over_road) > 50
    assert np.median(_ndvi(image, over_road)) > 0.3


def test_dsm_heights(scene, rendered):
    dsm = rendered[1]
    buildings = scene.buildings
    crowns = shapely.union_all(shapely.buffer(scene.trees.geometry.values,
                                              scene.trees["crown_radius_m"].to_numpy()))
    for geom, roof_z, height in zip(buildings.geometry.values, buildings["roof_z"],
                                    buildings["height_m"]):
        points = _interior_points([geom], 1.0, 0.5)
        shapely.prepare(crowns)
        points = points[~shapely.intersects(crowns, points)]
        if len(points) == 0:
            continue
        xy = shapely.get_coordinates(points)
        top = _sample(dsm, points)
        assert np.allclose(top, roof_z, atol=1e-3)
        ground = scene.ground_z(xy[:, 0], xy[:, 1])
        assert np.allclose(top - ground, height, atol=0.6)
    # Open roads: the DSM is the road surface; the deck stands 6-8 m above the road below.
    bridge = scene.bridges.iloc[0]
    row, col = dsm.xy_to_rowcol(bridge.crossing_x, bridge.crossing_y)
    x, y = dsm.transform.c + (col + 0.5) * PIXEL, dsm.transform.f - (row + 0.5) * PIXEL
    deck_top = dsm.data[row, col]
    assert 6.0 <= deck_top - scene.ground_z(x, y) <= 8.0
    assert np.isclose(deck_top, scene.deck_z(x, y), atol=1e-3)


def test_shadows_fall_north_of_buildings(scene, rendered):
    image = rendered[0]
    clutter = shapely.union_all(np.concatenate([
        scene.buildings.geometry.values, scene.truth.polygons.geometry.values,
        shapely.buffer(scene.trees.geometry.values, scene.trees["crown_radius_m"].to_numpy())]))
    open_ground = _interior_points([shapely.difference(shapely.box(*scene.extent), clutter)],
                                   2.0, 1.0)
    lit = np.median(_sample(image, open_ground)[:3].astype(float).mean(axis=0))
    # The sun is due south, 45 degrees up: a 5 m strip north of a tall building is shaded.
    tall = scene.buildings[scene.buildings["height_m"] > 12].geometry.values
    north = shapely.difference(shapely.union_all(
        [affinity.translate(b, 0.0, 5.0) for b in tall]), clutter)
    shaded = np.median(_sample(image, _interior_points([north], 0.5, 0.0))[:3]
                       .astype(float).mean(axis=0))
    assert shaded < 0.7 * lit


def test_write_image_round_trip(scene, rendered, tmp_path):
    image_path, dsm_path = tmp_path / "ortho.tif", tmp_path / "dsm.tif"
    write_image(scene, image_path, dsm_path, pixel_m=PIXEL, seed=0)
    image, dsm = read_raster(image_path), read_raster(dsm_path)
    assert np.array_equal(image.data, rendered[0].data)
    assert np.array_equal(dsm.data[0], rendered[1].data)
    assert image.crs == scene.crs and image.transform == rendered[0].transform
    with rasterio.open(image_path) as src:
        assert list(src.descriptions) == ["red", "green", "blue", "nir"]
