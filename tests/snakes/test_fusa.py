"""Map-guided snakes on real data: fusa.laz (4.4 points/m2) with its hand-digitised centre
lines shifted 3 m and jittered 0.5 m as the map, scored against the digitised road area."""
import geopandas as gpd
import shapely

from gisroads.evaluate import area_metrics
from gisroads.snakes.pipeline import extract_map_guided
from gisroads.synthetic.perturb import perturb_lines


def test_fusa_road_area_from_a_shifted_map(lidar_dir):
    truth = lidar_dir / "ground_truth" / "fusa"
    lines = gpd.read_file(truth / "centrelines.geojson")
    road_area = gpd.read_file(truth / "road_area.geojson")
    road_map = perturb_lines(lines.to_crs("EPSG:32754"), shift_m=3.0, jitter_m=0.5, seed=1)
    roads = extract_map_guided(lidar_dir / "fusa.laz", road_map.to_crs("EPSG:4326"))
    tile = shapely.box(277750.0, 6122250.0, 278000.0, 6122500.0)
    metrics = area_metrics(roads.network.polygons, road_area, valid_area=[tile])
    print("fusa, map 3 m off:", metrics.as_dict())
    # Measured 0.775 / 0.951 / 0.745, spill 1.0 m outwards (0.70 / 0.97 / 0.68 and 1.5 m
    # with the paper's curb term alone: at this density the normals barely see a kerb, the
    # ground steps do)
    assert metrics.recall >= 0.9
    assert metrics.quality >= 0.72
    assert metrics.spill_direction > 0
    assert roads.network.polygons.crs.to_epsg() == 32754
    assert sum(r.converged for r in roads.ribbons) >= 0.7 * len(roads.ribbons)
    # better than the map line two lanes wide (the paper's starting ribbon, 0.61) and than
    # the shifted map buffered by the true widths (0.69)
    start = shapely.buffer(road_map.geometry.values, 3.66, cap_style="flat")
    assert area_metrics(start, road_area, valid_area=[tile]).quality < metrics.quality - 0.05
    widths = shapely.buffer(road_map.geometry.values, road_map["width_m"].to_numpy() / 2,
                            cap_style="flat")
    assert area_metrics(widths, road_area, valid_area=[tile]).quality < metrics.quality
