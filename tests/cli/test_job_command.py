"""``gisroads job``: one job of gisroads.jobs with JSON arguments (QGIS's external-tool mode
for the stages), and the ``path|layername=`` sources the jobs read."""
import json
import subprocess
import sys

import geopandas as gpd
import pytest
import shapely

from gisroads.errors import GisroadsError
from gisroads.jobs import JOBS, job_defaults, run_job
from gisroads.jobs.common import _layer, _map_lines
from gisroads.lidar.hypotheses import DEFAULT_WIDTHS_M
from gisroads.synthetic import make_scene
from gisroads.update import MatchOptions


def _gisroads(*args):
    return subprocess.run([sys.executable, "-m", "gisroads.cli", *map(str, args)],
                          capture_output=True, text=True)


def test_defaults_are_the_jobs_signatures_as_json():
    done = _gisroads("job", "--defaults")
    assert done.returncode == 0, done.stderr
    defaults = json.loads(done.stdout)
    assert set(defaults) == set(JOBS)
    assert defaults["likelihood_job"]["widths_m"] == list(DEFAULT_WIDTHS_M)
    assert "progress" not in defaults["evidence_job"]
    assert defaults == {name: job_defaults(name) for name in JOBS}
    # a job taking an options object lists its fields one by one, not the object
    assert defaults["update_job"]["tolerance_m"] == MatchOptions().tolerance_m
    assert defaults["blocks_job"]["max_edge_m"] == 80.0 and "options" not in defaults["blocks_job"]


def test_a_job_takes_the_fields_of_its_options_object(tmp_path):
    scene = make_scene(seed=2, size_m=(300, 300))
    lines = tmp_path / "lines.gpkg"
    scene.truth.centrelines.to_file(lines, driver="GPKG")
    results = {}
    for name, arguments in (("default", {}), ("short kept", {"min_total_length_m": 0.0})):
        results[name] = run_job("junctions_job", {"lines": str(lines),
                                                  "out_path": str(tmp_path / "n.gpkg"),
                                                  **arguments})
    assert results["default"]["roads"] > 0
    assert results["short kept"]["length_m"] >= results["default"]["length_m"]
    with pytest.raises(GisroadsError, match="takes no options"):
        run_job("junctions_job", {"lines": str(lines), "out_path": "x.gpkg", "options": {}})


def test_a_job_runs_from_json_and_bad_arguments_are_one_line(tmp_path):
    scene = make_scene(seed=2, size_m=(300, 300))
    rectangles = tmp_path / "r.gpkg"
    lines = scene.truth.centrelines
    boxes = gpd.GeoDataFrame(
        {"width_m": lines.width_m.values,
         "theta_rad": [0.0] * len(lines)},
        geometry=shapely.buffer(lines.geometry.values, lines.width_m.values / 2,
                                cap_style="flat"), crs=lines.crs)
    # a GeoPackage of two layers: the job reads the one the source names
    boxes.iloc[:1].to_file(rectangles, layer="other", driver="GPKG")
    boxes.to_file(rectangles, layer="mine", driver="GPKG")
    assert len(_layer(f"{rectangles}|layername=mine", "rectangles")) == len(boxes)
    assert len(_map_lines(f"{rectangles}|layername=other")) == 1
    out = tmp_path / "roads.gpkg"
    done = _gisroads("job", "rectangles_network_job",
                     json.dumps({"rectangles_path": f"{rectangles}|layername=mine",
                                 "out_path": str(out)}), "--json")
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout)
    assert result["roads"] > 0 and result["length_m"] > 100 and out.exists()
    for arguments, message in (('{"out_path": "x.gpkg", "nope": 1}', "takes no nope"),
                               ("[1]", "a JSON object"), ("{x", "not JSON")):
        done = _gisroads("job", "rectangles_network_job", arguments)
        assert done.returncode == 2 and message in done.stderr, done.stderr
    done = _gisroads("job", "no_such_job")
    assert done.returncode == 2 and "no job 'no_such_job'" in done.stderr
    with pytest.raises(GisroadsError, match="takes no nope"):
        run_job("tag_job", {"nope": 1})


def test_likelihood_widths_as_text_are_checked(tmp_path):
    with pytest.raises(GisroadsError, match="widths"):
        run_job("likelihood_job", {"intensity_path": "i.tif", "segments_path": "s.tif",
                                   "likelihood_path": "l.tif",
                                   "hypotheses_path": "h.gpkg", "widths_m": "6,-9"})


def test_linking_refuses_an_image_in_another_crs_and_writes_nothing(tmp_path):
    import numpy as np
    from affine import Affine
    from pyproj import CRS

    from gisroads.geo import GeoRaster
    from gisroads.io.raster import write_geotiff

    parts = gpd.GeoDataFrame(
        {"part_id": [0, 1], "width_m": [6.0, 6.0], "quality": [0.9, 0.9]},
        geometry=[shapely.LineString([(0, 0), (40, 0)]), shapely.LineString([(50, 0), (90, 0)])],
        crs="EPSG:32633")
    parts.to_file(tmp_path / "parts.gpkg", layer="road_parts", driver="GPKG")
    image = GeoRaster(np.zeros((3, 20, 20), np.uint8), Affine(5, 0, -5, 0, -5, 50),
                      CRS("EPSG:32632"))
    write_geotiff(tmp_path / "image.tif", image)
    out = tmp_path / "linked.gpkg"
    with pytest.raises(GisroadsError, match="image is in another CRS than the road parts"):
        run_job("linking_job", {"road_parts": str(tmp_path / "parts.gpkg"),
                                "image_path": str(tmp_path / "image.tif"),
                                "linked_path": str(out)})
    assert not out.exists()
