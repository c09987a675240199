"""The whole-pipeline LiDAR algorithm runs its tiles in parallel from inside QGIS."""
import shapely

from gisroads.io.vector import read_layer


def test_lidar_tiles_on_two_workers_started_from_qgis(qgis_process, scene_dir, tmp_path):
    """Inside QGIS sys.executable is not the embedded interpreter (here the first python3
    on PATH, another installation of 3.11): the workers must start with the embedded
    installation's own, import the plugin's gisroads and give the network of one worker."""
    common = [f"INPUT={scene_dir / 'cloud.laz'}", "CUE=0", "LENGTHS=40,80,150", "TILE=150",
              "OVERLAP=50"]
    runs = {workers: qgis_process("run", "gisroads:lidarroadnetwork", "--", *common,
                                  f"WORKERS={workers}",
                                  f"OUTPUT={tmp_path / f'{workers}.gpkg'}")
            for workers in (1, 2)}
    assert "9 tiles on 2 Dask workers" in runs[2].stdout
    assert "Dask" not in runs[1].stdout and "9 of 9 tiles done" in runs[1].stdout
    for layer in ("road_centrelines", "junctions", "rectangles"):
        one = read_layer(tmp_path / "1.gpkg", layer)
        two = read_layer(tmp_path / "2.gpkg", layer)
        assert len(one) == len(two) > 0
        assert all(shapely.equals_exact(one.geometry.values, two.geometry.values, 1e-9))
