"""GeoRaster: the CRS it is given."""
from dataclasses import replace

import numpy as np
import pytest
from affine import Affine
from pyproj import CRS

from gisroads.geo import GeoRaster
from gisroads.network import raster_to_network


@pytest.mark.parametrize("crs", ["EPSG:32633", 32633, CRS.from_epsg(32633)])
def test_a_crs_given_as_text_or_code_is_a_pyproj_crs(crs):
    mask = np.zeros((100, 100), np.uint8)
    mask[45:55, :] = 1
    raster = GeoRaster(mask, Affine(0.5, 0, 500000, 0, -0.5, 5e6), crs)
    assert isinstance(raster.crs, CRS) and raster.crs.to_epsg() == 32633
    assert replace(raster, nodata=255).crs == raster.crs
    # the stages that check the CRS take it: one 50 m road
    lines = raster_to_network(raster).centrelines
    assert len(lines) == 1 and lines.crs.to_epsg() == 32633


def test_no_crs_stays_none():
    assert GeoRaster(np.zeros((2, 2)), Affine(1, 0, 0, 0, -1, 2), None).crs is None
