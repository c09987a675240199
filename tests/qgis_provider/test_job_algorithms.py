"""The stage algorithms that are one job of gisroads.jobs (processing_provider's
JobAlgorithm): one class, run in-process and through the external ``gisroads job``, on
fusa.laz, give the same files and results; the external mode takes its defaults from the
command and says its errors in one line."""
import json
import shutil
import sqlite3
import sys
from pathlib import Path

import geopandas as gpd
import numpy as np
import pytest
import shapely

from gisroads.io.las import read_las
from gisroads.io.raster import read_raster


def _external_gisroads() -> str:
    found = shutil.which("gisroads", path=str(Path(sys.executable).parent))
    assert found, "no gisroads command beside this Python"
    return found


@pytest.fixture(scope="module")
def both_ways(run_algorithm):
    """``run(name, params, folder)``: the algorithm ``name`` run in-process and external,
    each writing the outputs (the Paths of ``params``, by file name) into its own folder
    under ``folder``; ``{mode: (results, its folder)}``."""
    from qgis.core import (QgsApplication, QgsProcessingContext, QgsProcessingFeedback)

    from processing_provider.external import JOB_ALGORITHMS

    registry = QgsApplication.processingRegistry()  # run_algorithm added the provider
    executable = _external_gisroads()

    def run(name, params, folder: Path):
        cls = next(c for c in JOB_ALGORITHMS if c.NAME == name)
        runs = {}
        external = cls(executable)
        external.initAlgorithm()
        for mode, algorithm in (("in-process", registry.createAlgorithmById(f"gisroads:{name}")),
                                ("external", external)):
            out = folder / mode
            out.mkdir(parents=True, exist_ok=True)
            # a Path names an output: each mode writes its own under folder/mode
            these = {k: str(out / v.name) if isinstance(v, Path) else v
                     for k, v in params.items()}
            context, feedback = QgsProcessingContext(), QgsProcessingFeedback()
            assert algorithm.prepare(these, context, feedback)
            runs[mode] = (algorithm.runPrepared(these, context, feedback), out)
        return runs

    return run


def test_the_external_mode_takes_its_defaults_from_the_command(qgis_app):
    """Same parameters, types and defaults whichever way they were read."""
    from processing_provider.external import JOB_ALGORITHMS

    for cls in JOB_ALGORITHMS:
        ours, theirs = cls(), cls(_external_gisroads())
        ours.initAlgorithm()
        theirs.initAlgorithm()
        assert [(p.name(), p.type(), p.defaultValue()) for p in ours.parameterDefinitions()] \
            == [(p.name(), p.type(), p.defaultValue())
                for p in theirs.parameterDefinitions()], cls.NAME


def test_ground_intensity_and_segments_of_fusa_both_ways(both_ways, lidar_dir, tmp_path):
    ground = both_ways("lidargroundintensity",
                       {"INPUT": str(lidar_dir / "fusa.laz"),
                        "OUTPUT": tmp_path / "intensity.tif",
                        "HEIGHTS": tmp_path / "heights.tif"}, tmp_path)
    (ours, here), (theirs, there) = ground["in-process"], ground["external"]
    assert ours["LEVELS"] == theirs["LEVELS"] >= 1 and ours["CELL_M"] == theirs["CELL_M"]
    for name in ("intensity.tif", "heights.tif"):
        np.testing.assert_array_equal(read_raster(here / name).data,
                                      read_raster(there / name).data)
    segments = both_ways("lidarsegmentation",
                         {"INPUT": str(here / "intensity.tif"), "SEGMENTS": 60,
                          "OUTPUT": tmp_path / "segments.tif"}, tmp_path / "segments")
    (ours, here), (theirs, there) = segments["in-process"], segments["external"]
    a = read_raster(here / "segments.tif").data[0]
    b = read_raster(there / "segments.tif").data[0]
    # one NCut; its eigenvectors may differ in the last bits between processes
    assert np.array_equal(a >= 0, b >= 0)
    assert abs(ours["N_SEGMENTS"] - theirs["N_SEGMENTS"]) <= 0.1 * ours["N_SEGMENTS"]
    assert ours["N_SEGMENTS"] >= 60
    # the later stages from one set of inputs (the in-process segments)
    likelihood = both_ways("lidarlikelihood",
                           {"INPUT": str(tmp_path / "in-process" / "intensity.tif"),
                            "SEGMENTS": str(here / "segments.tif"), "LENGTHS": "40,80",
                            "OUTPUT": tmp_path / "likelihood.tif",
                            "HYPOTHESES": tmp_path / "hypotheses.gpkg"}, tmp_path / "maps")
    (ours, here), (theirs, there) = likelihood["in-process"], likelihood["external"]
    assert ours["N_HYPOTHESES"] == theirs["N_HYPOTHESES"] > 0
    np.testing.assert_array_equal(read_raster(here / "likelihood.tif").data,
                                  read_raster(there / "likelihood.tif").data)
    cover = both_ways("lidarmincover",
                      {"INPUT": f"{here / 'hypotheses.gpkg'}|layername=hypotheses",
                       "LIKELIHOOD": str(here / "likelihood.tif"),
                       "OUTPUT": tmp_path / "rectangles.gpkg"}, tmp_path / "cover")
    (ours, here), (theirs, there) = cover["in-process"], cover["external"]
    assert ours["N_RECTANGLES"] == theirs["N_RECTANGLES"] > 0
    assert ours["COVER_COST"] == pytest.approx(theirs["COVER_COST"], rel=1e-12)
    network = both_ways("rectanglestonetwork",
                        {"INPUT": f"{here / 'rectangles.gpkg'}|layername=rectangles",
                         "OUTPUT": tmp_path / "roads.gpkg"}, tmp_path / "network")
    (ours, _), (theirs, _) = network["in-process"], network["external"]
    assert ours["ROADS"] == theirs["ROADS"] > 0
    assert ours["LENGTH_M"] == pytest.approx(theirs["LENGTH_M"], rel=1e-12)


def test_road_evidence_and_tagged_points_of_fusa_both_ways(both_ways, lidar_dir, tmp_path):
    evidence = both_ways("lidarroadevidence", {"INPUT": str(lidar_dir / "fusa.laz"),
                                               "OUTPUT": tmp_path / "evidence.tif"}, tmp_path)
    (ours, here), (theirs, there) = evidence["in-process"], evidence["external"]
    assert ours["CUES"] == theirs["CUES"] and "intensity" in ours["CUES"]
    np.testing.assert_array_equal(read_raster(here / "evidence.tif").data,
                                  read_raster(there / "evidence.tif").data)
    # fusa's digitised road area as the road polygons, on level 0
    polygons = tmp_path / "road_area.gpkg"
    area = gpd.read_file(lidar_dir / "ground_truth" / "fusa" / "road_area.geojson")
    area.assign(level=0).to_file(polygons, layer="road_polygons", driver="GPKG")
    tagged = both_ways("tagroadpoints", {"INPUT": str(lidar_dir / "fusa.laz"),
                                         "POLYGONS": str(polygons),
                                         "OUTPUT": tmp_path / "tagged.laz"},
                       tmp_path / "tagged")
    (ours, here), (theirs, there) = tagged["in-process"], tagged["external"]
    assert ours["TAGGED"] == theirs["TAGGED"] > 10000
    np.testing.assert_array_equal(read_las(here / "tagged.laz").classification,
                                  read_las(there / "tagged.laz").classification)


def _refused_externally(algorithm_class, params: dict, message: str) -> None:
    """The external run of ``algorithm_class`` with ``params`` fails with ``message``."""
    from qgis.core import QgsProcessingContext, QgsProcessingException, QgsProcessingFeedback

    algorithm = algorithm_class(_external_gisroads())
    algorithm.initAlgorithm()
    context, feedback = QgsProcessingContext(), QgsProcessingFeedback()
    assert algorithm.prepare(params, context, feedback)
    with pytest.raises(QgsProcessingException, match=message):
        algorithm.runPrepared(params, context, feedback)


def test_an_external_stage_says_its_error_in_one_line(qgis_app, lidar_dir, tmp_path):
    from processing_provider.algorithms.lidar_ground_intensity import LidarGroundIntensity

    _refused_externally(LidarGroundIntensity, {
        "INPUT": str(tmp_path / "none.laz"), "OUTPUT": str(tmp_path / "i.tif"),
        "HEIGHTS": str(tmp_path / "h.tif")}, "none.laz: no such file")
    assert not list(tmp_path.glob("*.tif"))


def test_gisroads_job_runs_a_job_and_reports_its_defaults(lidar_dir, tmp_path):
    import subprocess

    gisroads = _external_gisroads()
    done = subprocess.run([gisroads, "job", "--defaults"], capture_output=True, text=True)
    defaults = json.loads(done.stdout)
    assert defaults["ground_intensity_job"]["t_planar"] == 0.01      # the paper's
    assert defaults["likelihood_job"]["widths_m"] == [6.0, 9.0, 12.0, 16.0, 20.0, 25.0]
    out = tmp_path / "evidence.tif"
    done = subprocess.run([gisroads, "job", "evidence_job",
                           json.dumps({"cloud_path": str(lidar_dir / "fusa.laz"),
                                       "out_path": str(out)}), "--json"],
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["raster"] == str(out) and out.exists()
    for arguments, message in (('{"cloud_path": 1, "nope": 2}', "evidence_job takes no nope"),
                               ("[1]", "a JSON object"), ("{x", "not JSON")):
        done = subprocess.run([gisroads, "job", "evidence_job", arguments],
                              capture_output=True, text=True)
        assert done.returncode == 2 and message in done.stderr, done.stderr


def test_register_map_of_fusa_both_ways(both_ways, lidar_dir, tmp_path):
    truth = str(lidar_dir / "ground_truth" / "fusa" / "centrelines.geojson")
    runs = both_ways("registerroadmap", {"INPUT": str(lidar_dir / "fusa.laz"), "MAP": truth,
                                         "OUTPUT": tmp_path / "registered.gpkg"}, tmp_path)
    (ours, here), (theirs, there) = runs["in-process"], runs["external"]
    assert ours["ROADS"] == theirs["ROADS"] >= 7
    # a 15 cm support radius at 4.4 points/m2: about one sample in three sees the road
    assert ours["SEEN_FRACTION"] == theirs["SEEN_FRACTION"] > 0.2
    a = gpd.read_file(here / "registered.gpkg", layer="registered_map")
    b = gpd.read_file(there / "registered.gpkg", layer="registered_map")
    assert a.geometry.equals(b.geometry)


def test_curb_attractor_of_fusa_both_ways(both_ways, lidar_dir, tmp_path):
    truth = str(lidar_dir / "ground_truth" / "fusa" / "centrelines.geojson")
    runs = both_ways("curbattractormap", {"INPUT": str(lidar_dir / "fusa.laz"), "MAP": truth,
                                          "OUTPUT": tmp_path / "attractor.tif"}, tmp_path)
    (_, here), (_, there) = runs["in-process"], runs["external"]
    ours = read_raster(here / "attractor.tif").data
    np.testing.assert_array_equal(ours, read_raster(there / "attractor.tif").data)
    assert np.nanmax(ours) > 0.5     # kerbs over the 0.2 extent plateau


def test_evaluate_with_reference_junctions_both_ways(both_ways, lidar_dir, tmp_path):
    """*Evaluate road network* fills its QA sinks from the job's GeoPackage in both modes
    and takes the reference's digitised junctions."""
    truth_dir = lidar_dir / "ground_truth" / "fusa"
    truth = gpd.read_file(truth_dir / "centrelines.geojson")
    shifted = truth.assign(geometry=truth.geometry.translate(2.0, 0.0))
    shifted = shifted[shifted.index != 0]          # one road missed
    shifted.to_file(tmp_path / "extracted.gpkg", layer="road_centrelines")
    runs = both_ways("evaluateroadnetwork", {
        "EXTRACTED": f"{tmp_path / 'extracted.gpkg'}|layername=road_centrelines",
        "REFERENCE": str(truth_dir / "centrelines.geojson"),
        "REFERENCE_JUNCTIONS": str(truth_dir / "junctions.geojson"), "BUFFER": 3.0,
        "EXTRACTED_QA": tmp_path / "e.gpkg", "REFERENCE_QA": tmp_path / "r.gpkg"}, tmp_path)
    (ours, here), (theirs, there) = runs["in-process"], runs["external"]
    assert ours["CORRECTNESS"] == pytest.approx(1.0) == theirs["CORRECTNESS"]
    assert 0.5 < ours["COMPLETENESS"] == theirs["COMPLETENESS"] < 1.0
    report = json.loads(ours["REPORT"])
    assert report == json.loads(theirs["REPORT"])
    assert report["topology"]["junctions_reference"] == len(
        gpd.read_file(truth_dir / "junctions.geojson"))
    for name in ("e.gpkg", "r.gpkg"):
        a, b = gpd.read_file(here / name), gpd.read_file(there / name)
        assert len(a) == len(b) > 0 and a.length.sum() == pytest.approx(b.length.sum())
    missed = gpd.read_file(here / "r.gpkg").query("status == 'FN'").length.sum()
    assert missed == pytest.approx((1 - ours["COMPLETENESS"]) * truth.length.sum(), rel=0.02)


def test_train_lidar_road_model_of_fusa_both_ways(both_ways, lidar_dir, tmp_path):
    """*Train LiDAR road model* (issue 25 item 5 in the toolbox) writes the same model in
    both modes, one that *LiDAR road network* and gisroads read back."""
    from gisroads.lidar.learned import load_evidence_model

    truth = str(lidar_dir / "ground_truth" / "fusa" / "centrelines.geojson")
    runs = both_ways("trainlidarroadmodel", {"INPUT": str(lidar_dir / "fusa.laz"),
                                             "ROADS": truth, "WIDTH": 7.0,
                                             "OUTPUT": tmp_path / "fusa_model.npz"}, tmp_path)
    (ours, here), (theirs, there) = runs["in-process"], runs["external"]
    for key in ("ROAD_CELLS", "OTHER_CELLS", "TREES"):
        assert ours[key] == theirs[key] > 0, key
    assert ours["OTHER_CELLS"] > ours["ROAD_CELLS"] > 5000
    a = load_evidence_model(here / "fusa_model.npz")
    b = load_evidence_model(there / "fusa_model.npz")
    assert a.metadata["road_cells"] == b.metadata["road_cells"] == ours["ROAD_CELLS"]


def test_lidar_road_network_with_a_model_of_the_area_both_ways(run_algorithm, lidar_dir,
                                                              tmp_path):
    """*LiDAR road network* takes a model learned from the area's road layer (issue 25
    item 5), in-process and through 'gisroads lidar --model'."""
    from qgis.core import QgsProcessingContext, QgsProcessingFeedback

    from gisroads.lidar.learned import save_evidence_model
    from gisroads.lidar.pipeline import train_evidence_model
    from processing_provider.external import ExternalLidarRoadNetwork

    truth = gpd.read_file(lidar_dir / "ground_truth" / "fusa" / "centrelines.geojson")
    model = save_evidence_model(train_evidence_model(lidar_dir / "fusa.laz", truth,
                                                     width_field="width_m"),
                                tmp_path / "fusa_model.npz")
    params = {"INPUT": str(lidar_dir / "fusa.laz"), "MODEL": str(model), "WORKERS": 1}
    ours = run_algorithm("lidarroadnetwork", {**params, "OUTPUT": str(tmp_path / "a.gpkg")})
    external = ExternalLidarRoadNetwork(_external_gisroads())
    external.initAlgorithm()
    these = {**params, "OUTPUT": str(tmp_path / "b.gpkg")}
    context, feedback = QgsProcessingContext(), QgsProcessingFeedback()
    assert external.prepare(these, context, feedback)
    theirs = external.runPrepared(these, context, feedback)
    assert ours["ROADS"] == theirs["ROADS"] > 5
    assert ours["LENGTH_M"] == pytest.approx(theirs["LENGTH_M"], rel=1e-9)
    for name in ("a.gpkg", "b.gpkg"):
        lines = gpd.read_file(tmp_path / name, layer="road_centrelines")
        assert "model" in lines.cues.iloc[0].split(",")


def _imagery_stages_both_ways(both_ways, image: Path, folder: Path, n_segments: int) -> dict:
    """The five imagery stages on ``image``, each run both ways from the in-process output of
    the one before (``n_segments`` 0: the stage's own count); asserts that both ways agree
    and returns each stage's in-process results and folder."""
    segments = both_ways("imagesegmentation",
                         {"IMAGE": str(image), "N_SEGMENTS": n_segments,
                          "OUTPUT": folder / "segments.gpkg"}, folder / "segments")
    (ours, here), (theirs, there) = segments["in-process"], segments["external"]
    a, b = (gpd.read_file(f / "segments.gpkg") for f in (here, there))
    assert ours["SEGMENTS"] == len(a) >= 0.75 * (n_segments or 100)
    assert theirs["SEGMENTS"] == len(b)
    # one NCut; its eigenvectors may differ in the last bits between processes
    assert abs(len(a) - len(b)) <= 0.1 * len(a)
    assert a.area.sum() == pytest.approx(b.area.sum()) and str(a.crs) == str(b.crs)
    results = {"segments": (ours, here)}
    grouped = both_ways("segmentgrouping",
                        {"IMAGE": str(image),
                         "SEGMENTS": f"{here / 'segments.gpkg'}|layername=segments",
                         "OUTPUT": folder / "grouped.gpkg"}, folder / "grouped")
    (ours, here), (theirs, there) = grouped["in-process"], grouped["external"]
    results["grouped"] = grouped["in-process"]
    assert ours["SEGMENTS"] == theirs["SEGMENTS"] < len(a)
    a, b = (gpd.read_file(f / "grouped.gpkg") for f in (here, there))
    assert shapely.union_all(a.geometry.values).symmetric_difference(
        shapely.union_all(b.geometry.values)).area < 1.0
    assert a.segment_id.is_unique
    parts = both_ways("roadparts",
                      {"IMAGE": str(image), "SEGMENTS": str(here / "grouped.gpkg"),
                       "OUTPUT_SEGMENTS": folder / "tested.gpkg",
                       "ROAD_PARTS": folder / "parts.gpkg"}, folder / "parts")
    (ours, here), (theirs, there) = parts["in-process"], parts["external"]
    results["parts"] = parts["in-process"]
    assert ours["PARTS"] == theirs["PARTS"] and ours["CUES"] == theirs["CUES"]
    a, b = (gpd.read_file(f / "parts.gpkg") for f in (here, there))
    np.testing.assert_allclose(sorted(a.length), sorted(b.length))
    tested = gpd.read_file(here / "tested.gpkg")
    assert {"passed", "reason", "failures"} <= set(tested.columns)
    assert tested.passed.sum() >= ours["PARTS"]
    linked = both_ways("subgraphlinking",
                       {"ROAD_PARTS": str(here / "parts.gpkg"), "IMAGE": str(image),
                        "GAP_EDGES": folder / "gaps.gpkg",
                        "ROAD_STRINGS": folder / "strings.gpkg"}, folder / "linked")
    (ours, here), (theirs, there) = linked["in-process"], linked["external"]
    results["linked"] = linked["in-process"]
    assert ours["SELECTED"] == theirs["SELECTED"]
    assert ours["STRINGS"] == theirs["STRINGS"] <= len(a)
    network = both_ways("junctionconstruction",
                        {"ROAD_STRINGS": str(here / "strings.gpkg"),
                         "OUTPUT": folder / "roads.gpkg"}, folder / "network")
    (ours, here), (theirs, _) = network["in-process"], network["external"]
    results["network"] = network["in-process"]
    assert ours["ROADS"] == theirs["ROADS"] and ours["CONNECTIONS"] == theirs["CONNECTIONS"]
    assert ours["LENGTH_M"] == pytest.approx(theirs["LENGTH_M"], rel=1e-9)
    with sqlite3.connect(here / "roads.gpkg") as con:
        layers = {row[0] for row in con.execute("SELECT table_name FROM gpkg_contents")}
    assert {"road_centrelines", "junctions", "junction_connections"} <= layers
    return results


def test_the_imagery_stages_both_ways(both_ways, tmp_path):
    """A 100 x 100 m synthetic image (0.5 m): a road across a lawn, a tree crown over its
    middle: two road parts, linked under the crown into one road of the image's width;
    and the grouping's refusal of segments off the image."""
    from affine import Affine
    from pyproj import CRS

    from gisroads.geo import GeoRaster
    from gisroads.io.raster import write_geotiff
    from gisroads.io.vector import write_geopackage
    from processing_provider.algorithms.segment_grouping import SegmentGrouping

    grid = Affine(0.5, 0, 500000.0, 0, -0.5, 4500100.0)
    image = np.empty((3, 200, 200))
    image[:] = np.array([80.0, 112.0, 52.0])[:, None, None]
    image[:, 90:106] = np.array([86.0, 88.0, 91.0])[:, None, None]  # an 8 m road
    image[:, 84:112, 92:108] = np.array([40.0, 90.0, 30.0])[:, None, None]  # a crown
    image += np.random.default_rng(0).normal(0, 4, image.shape)
    write_geotiff(tmp_path / "image.tif", GeoRaster(np.clip(image, 0, 255).astype(np.uint8),
                                                    grid, CRS("EPSG:32633")))
    stages = _imagery_stages_both_ways(both_ways, tmp_path / "image.tif", tmp_path, 40)
    assert stages["grouped"][0]["SEGMENTS"] < stages["segments"][0]["SEGMENTS"] / 2
    assert stages["parts"][0]["PARTS"] >= 2
    assert stages["linked"][0]["SELECTED"] >= 1 and stages["linked"][0]["STRINGS"] == 1
    assert stages["network"][0]["ROADS"] == 1 and stages["network"][0]["LENGTH_M"] > 80.0

    far = gpd.GeoDataFrame({"segment_id": [0]}, geometry=[shapely.box(0, 0, 10, 10)],
                           crs="EPSG:32633")
    write_geopackage(tmp_path / "far.gpkg", {"segments": far})
    _refused_externally(SegmentGrouping, {
        "IMAGE": str(tmp_path / "image.tif"), "SEGMENTS": str(tmp_path / "far.gpkg"),
        "OUTPUT": str(tmp_path / "out.gpkg")}, "no segment polygon overlaps the image")
    assert not (tmp_path / "out.gpkg").exists()


def test_the_imagery_stages_on_a_real_tile_both_ways(both_ways, shared_data, tmp_path):
    """ETH tile satImage_001 (US suburb, 400 x 400 px, 0.6 m assumed) through the five
    stages both ways: the papers' stages find its streets."""
    from gisroads.evaluate import buffer_metrics
    from gisroads.imagery.datasets import load_eth
    from gisroads.io.raster import write_geotiff

    record = load_eth(shared_data / "imagery", stems=["satImage_001"])[0]
    write_geotiff(tmp_path / "image.tif", record.image)
    stages = _imagery_stages_both_ways(both_ways, tmp_path / "image.tif", tmp_path, 0)
    roads = gpd.read_file(stages["network"][1] / "roads.gpkg", layer="road_centrelines")
    scores = buffer_metrics(roads, record.truth, buffer_m=3.0)
    # measured 0.50 / 0.59 (quality 0.37; make bench's papers path: 0.367)
    assert scores.completeness > 0.4 and scores.correctness > 0.5


def test_compare_with_road_database_both_ways(both_ways, lidar_dir, tmp_path):
    """fusa's truth as the road database (GeoJSON: feature ids from 0, which a GeoPackage
    copy cannot keep) against an extraction lacking one of its roads and moving another by
    8 m: the same changes both ways, naming the layer's own feature ids."""
    from qgis.core import QgsVectorLayer

    truth = lidar_dir / "ground_truth" / "fusa" / "centrelines.geojson"
    lines = gpd.read_file(truth)
    extracted = lines.drop(index=0)
    extracted.loc[3, "geometry"] = extracted.loc[[3]].translate(xoff=8.0).iloc[0]
    extracted.to_file(tmp_path / "extracted.gpkg", layer="road_centrelines", driver="GPKG")
    ids = sorted(f.id() for f in QgsVectorLayer(str(truth), "db", "ogr").getFeatures())
    assert ids == list(range(len(lines)))
    sinks = {"CONFIRMED": "confirmed", "MISSING": "missing", "NEW": "new", "MOVED": "moved",
             "PROPOSED_UPDATE": "proposed_update"}
    runs = both_ways("comparewithroaddatabase",
                     {"EXTRACTED": str(tmp_path / "extracted.gpkg"), "DATABASE": str(truth),
                      **{name: tmp_path / f"{layer}.gpkg" for name, layer in sinks.items()}},
                     tmp_path)
    (ours, here), (theirs, there) = runs["in-process"], runs["external"]
    assert {k: v for k, v in ours.items() if k.endswith("_COUNT")} \
        == {k: v for k, v in theirs.items() if k.endswith("_COUNT")}
    changes = {}
    for layer in sinks.values():
        a, b = (gpd.read_file(folder / f"{layer}.gpkg") for folder in (here, there))
        assert list(a.columns) == list(b.columns), layer
        if "db_id" in a:
            assert sorted(a.db_id.dropna()) == sorted(b.db_id.dropna()), layer
        changes[layer] = a
    assert set(changes["missing"].db_id) == {0}        # the road the extraction lacks
    assert set(changes["moved"].db_id) == {3}          # the road moved by 8 m
    assert set(changes["confirmed"].db_id) == set(range(1, len(lines)))
    assert set(changes["confirmed"]["id"]) == set(lines["id"][1:])   # its fields carried
    assert "gisroads_source_fid" not in changes["proposed_update"]
