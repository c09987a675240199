"""Wide paved areas (car parks, plazas) in a road raster: the network stage draws the roads
through them and beside them, not the car park's outline and aisles."""
import numpy as np
import pytest
import shapely
from affine import Affine
from pyproj import CRS
from shapely import LineString, box

from gisroads.geo import GeoRaster
from gisroads.network import raster_to_network
from gisroads.network.areas import lines_in_wide_areas, wide_paved_areas

PIXEL_M = 0.5
STREET_Y = (112.0, 120.0)
"""The street's edges, metres north (rows 60-76 of the 150 m raster)."""


def _raster(probability: np.ndarray) -> GeoRaster:
    height = probability.shape[0] * PIXEL_M
    return GeoRaster(probability, Affine(PIXEL_M, 0, 0, 0, -PIXEL_M, height),
                     CRS.from_epsg(32633))


def _street_with_car_park(*, access: bool) -> GeoRaster:
    """A 150 m square at 0.5 m: an east-west street 8 m wide, and south of it a car park
    of 70 x 50 m with three rows of parked cars, joined to the street by a 4 m access or
    lying right against it."""
    p = np.full((300, 300), 0.05, np.float32)
    p[60:76, :] = 0.9
    if access:
        p[76:84, 140:156] = 0.9
        p[84:184, 80:220] = 0.8
    else:
        p[76:184, 80:220] = 0.8
    for row in (100, 130, 160):
        p[row:row + 10, 90:210] = 0.2
    return _raster(p)


def _on_street(lines) -> float:
    """Share of the lines' length within the street (2 m of slack)."""
    street = box(-1, STREET_Y[0] - 2, 151, STREET_Y[1] + 2)
    total = lines.length.sum()
    return float(shapely.length(shapely.intersection(lines.geometry.values, street)).sum()
                 / total) if total else 0.0


def test_a_car_park_off_a_street_gives_the_street_alone():
    raster = _street_with_car_park(access=True)
    plain = raster_to_network(raster)
    assert len(plain.centrelines) >= 5 and _on_street(plain.centrelines) < 0.5  # the ladder
    network = raster_to_network(raster, wide_areas=True)
    lines = network.centrelines
    assert len(lines) == 1 and _on_street(lines) == pytest.approx(1.0)
    assert lines.length.sum() > 135
    rejected = network.qa["rejected"].query("reason == 'wide paved area'")
    assert rejected.length.sum() > 250


def test_a_street_right_against_a_car_park_stays_whole():
    network = raster_to_network(_street_with_car_park(access=False), wide_areas=True)
    lines = network.centrelines
    street = shapely.union_all(lines.geometry.values)
    # it still runs from one side of the raster to the other, and little else is drawn
    assert street.bounds[0] < 5 and street.bounds[2] > 145
    assert lines.length.sum() < 200


def test_a_road_across_a_plaza_is_kept():
    p = np.full((400, 400), 0.05, np.float32)
    p[185:201, :] = 0.9                 # the road, 8 m wide
    p[140:260, 140:260] = 0.9           # an open square of 60 m
    raster = _raster(p)
    assert wide_paved_areas(raster, 0.5).area > 2500
    network = raster_to_network(raster, wide_areas=True)
    assert network.centrelines.length.sum() == pytest.approx(
        raster_to_network(raster).centrelines.length.sum())
    assert network.centrelines.length.sum() > 190


def test_roads_wider_than_an_area_are_not_areas():
    # a freeway of 50 m with its shoulders, 200 m long: long, so a road
    p = np.full((400, 400), 0.05, np.float32)
    p[150:250, :] = 0.9
    assert wide_paved_areas(_raster(p), 0.5).is_empty
    # two 30 m roads crossing: the crossing is wide, and its four arms stay
    p = np.full((400, 400), 0.05, np.float32)
    p[170:230, :] = 0.9
    p[:, 170:230] = 0.9
    raster = _raster(p)
    assert not wide_paved_areas(raster, 0.5).is_empty
    network = raster_to_network(raster, wide_areas=True)
    assert len(network.centrelines) == 4 and network.centrelines.length.sum() > 330


def test_a_roundabout_keeps_its_ring_and_arms():
    rows, cols = np.mgrid[:400, :400]
    radius_m = np.hypot(rows - 200, cols - 200) * PIXEL_M
    p = np.full((400, 400), 0.05, np.float32)
    p[190:210, :] = 0.9
    p[:, 190:210] = 0.9
    p[radius_m <= 22] = 0.9
    p[radius_m <= 5] = 0.05           # a small island: the roundabout is a wide area
    raster = _raster(p)
    assert not wide_paved_areas(raster, 0.5).is_empty
    plain = raster_to_network(raster)
    network = raster_to_network(raster, wide_areas=True)
    assert len(network.centrelines) == len(plain.centrelines)
    assert network.centrelines.length.sum() == pytest.approx(
        plain.centrelines.length.sum())


def test_a_road_entering_an_area_from_past_the_data_is_a_way_through():
    # a road from the raster's west edge across a car park to a north-south street in the
    # east; the car park's outline round it
    lines = [LineString([(0, 50), (40, 50)]), LineString([(40, 50), (80, 50)]),
             LineString([(80, 50), (120, 50)]),
             LineString([(40, 50), (40, 70), (80, 70), (80, 50)]),
             LineString([(120, 0), (120, 50)]), LineString([(120, 50), (120, 100)])]
    car_park = box(-1, 25, 85, 75)
    extent = box(0, 0, 200, 100)
    taken = lines_in_wide_areas(lines, car_park, extent=extent)
    assert taken.tolist() == [False, False, False, True, False, False]
    # without the data's edge the road ends in the car park: it is the car park's access
    taken = lines_in_wide_areas(lines, car_park)
    assert taken.tolist() == [True, True, True, True, False, False]


def test_no_area_takes_nothing():
    lines = [LineString([(0, 0), (10, 0)])]
    assert not lines_in_wide_areas(lines, shapely.Polygon()).any()
    assert not lines_in_wide_areas([], box(0, 0, 1, 1)).any()
