import numpy as np

from gisroads.evaluate import buffer_metrics
from gisroads.io.las import concatenate
from gisroads.lidar.baseline import baseline_roads, lowest_point_grid
from gisroads.io.las import PointCloud
from gisroads.synthetic import make_scene, render_cloud


def test_lowest_point_grid_takes_the_lowest_point_of_each_cell():
    xyz = np.array([[0.2, 0.2, 5.0], [0.7, 0.3, 2.0], [1.5, 0.5, 9.0]])
    cloud = PointCloud(xyz, np.array([10, 20, 30], np.uint16), *np.zeros((3, 3), np.uint8))
    z, intensity, transform = lowest_point_grid(cloud, cell_m=1.0)
    assert transform.c == 0.0 and transform.f == 1.0
    assert z[0, 0] == 2.0 and intensity[0, 0] == 20
    assert z[0, 1] == 9.0 and intensity[0, 1] == 30


def test_baseline_finds_roads_of_a_synthetic_scene():
    scene = make_scene(seed=5, size_m=(400.0, 400.0))
    cloud = concatenate(list(render_cloud(scene, density_per_m2=4.0, seed=0)))
    net = baseline_roads(cloud)
    scores = buffer_metrics(net.centrelines, scene.truth.centrelines, buffer_m=3.0)
    # a baseline: it finds much of the network, with false roads in lots and verges
    assert scores.completeness > 0.55  # measured 0.67
    assert scores.correctness > 0.6  # measured 0.76
