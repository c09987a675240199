"""Road rectangles as the minimum cover gives them, for the tests of their conversion."""
import math

import geopandas as gpd
import shapely
from shapely import LineString

UTM = "EPSG:32633"
EAST, NORTH = 0.0, math.pi / 2


def rectangles(boxes, thetas, width_m=10.0, score=1.0):
    return gpd.GeoDataFrame({"width_m": width_m, "theta_rad": thetas, "score": score},
                            geometry=list(boxes), crs=UTM)


def along(line_xy, width_m):
    """Rectangle of a segment: (polygon, theta_rad)."""
    (x0, y0), (x1, y1) = line_xy
    return (LineString(line_xy).buffer(width_m / 2, cap_style="flat"),
            math.atan2(y1 - y0, x1 - x0))


def coords(geom):
    return shapely.get_coordinates(geom)
