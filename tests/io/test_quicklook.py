"""Quick-looks: cells without data stay blank whatever the matplotlib version."""
import matplotlib.image
import numpy as np
from affine import Affine
from pyproj import CRS

from gisroads.geo import GeoRaster
from gisroads.io.quicklook import write_quicklook


def test_cells_without_data_are_left_blank(tmp_path):
    data = np.full((100, 100), 0.2, np.float32)
    data[:, 50:] = np.nan  # the east half has no data
    raster = GeoRaster(data, Affine(1.0, 0, 0, 0, -1.0, 100.0), CRS.from_epsg(32633))
    write_quicklook(tmp_path / "q.png", [], background=raster)
    image = matplotlib.image.imread(tmp_path / "q.png")[..., :3]
    rows, cols = image.shape[:2]
    middle = image[rows // 2]
    # across the plot: grey over the data, the white page where there is none
    grey = middle[int(cols * 0.3)]
    blank = middle[int(cols * 0.7)]
    assert np.allclose(blank, 1.0) and not np.allclose(grey, 1.0)
