"""The provider's algorithms in this process (pytest-qgis): cancel, conversions, errors."""
from pathlib import Path

import geopandas as gpd
import psutil
import pytest
import shapely
from qgis.core import QgsProcessingException, QgsProcessingFeedback, QgsVectorLayer, QgsWkbTypes

from gisroads.synthetic import make_scene, write_cloud
from gisroads.synthetic.image import write_image
from processing_provider.convert import source_to_frame, to_pyproj, to_qgis

STYLES = Path(__file__).resolve().parents[2] / "styles"


def test_cancel_before_start_writes_nothing(run_algorithm, tmp_path):
    feedback = QgsProcessingFeedback()
    feedback.cancel()
    with pytest.raises(QgsProcessingException, match="cancelled"):
        run_algorithm("syntheticroadscene",
            {"WIDTH": 300, "HEIGHT": 300, "DENSITY": 1, "PIXEL": 2.0,
             "OUTPUT_FOLDER": str(tmp_path / "out")}, feedback)
    assert not list((tmp_path / "out").glob("*"))


def test_cancel_while_writing_the_cloud_leaves_no_partial_file(run_algorithm, tmp_path):
    feedback = QgsProcessingFeedback()
    feedback.progressChanged.connect(lambda percent: percent > 20 and feedback.cancel())
    with pytest.raises(QgsProcessingException, match="cancelled"):
        run_algorithm("syntheticroadscene",
            {"WIDTH": 400, "HEIGHT": 400, "DENSITY": 4, "PIXEL": 2.0,
             "OUTPUT_FOLDER": str(tmp_path / "out")}, feedback)
    # truth.gpkg is complete before the cloud starts; the cloud is absent, not partial
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["truth.gpkg"]


def test_cancel_while_tiles_run_on_dask_workers_stops_them_and_writes_nothing(
        run_algorithm, tmp_path):
    scene = make_scene(seed=3, size_m=(300.0, 300.0))
    write_cloud(scene, tmp_path / "cloud.laz", density_per_m2=2.0, seed=3)
    class CancelAfterFirstTile(QgsProcessingFeedback):
        texts = []

        def setProgressText(self, text):  # noqa: N802
            self.texts.append(text)
            if text.startswith("1 of ") and " tiles done" in text:  # not the reading pass
                self.cancel()
            super().setProgressText(text)
    feedback = CancelAfterFirstTile()
    texts = feedback.texts
    children_before = set(psutil.Process().children(recursive=True))
    with pytest.raises(QgsProcessingException, match="cancelled"):
        run_algorithm("lidarroadnetwork", {"INPUT": str(tmp_path / "cloud.laz"), "TILE": 150,
                                           "OVERLAP": 50, "WORKERS": 2, "CUE": 0,
                                           "OUTPUT": str(tmp_path / "roads.gpkg")}, feedback)
    assert "9 tiles on 2 Dask workers" in texts
    assert not any(t.startswith("2 of ") and " tiles done" in t for t in texts)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cloud.laz"]
    # the local cluster is closed: its worker processes are gone (multiprocessing's
    # resource tracker stays for the life of this process, as it does for any spawn)
    _, alive = psutil.wait_procs(
        set(psutil.Process().children(recursive=True)) - children_before, timeout=30)
    assert [p for p in alive if "resource_tracker" not in " ".join(p.cmdline())] == []


def test_cancel_during_the_imagery_pipeline_leaves_no_output(run_algorithm, tmp_path):
    write_image(make_scene(seed=1, size_m=(300.0, 300.0)), tmp_path / "image.tif",
                tmp_path / "dsm.tif", pixel_m=2.0)
    feedback = QgsProcessingFeedback()
    percents = []
    feedback.progressChanged.connect(
        lambda percent: (percents.append(percent), percent > 45 and feedback.cancel()))
    with pytest.raises(QgsProcessingException, match="cancelled"):
        run_algorithm("imageryroadnetwork", {"INPUT": str(tmp_path / "image.tif"),
                                             "OUTPUT": str(tmp_path / "roads.gpkg")}, feedback)
    assert 45 < max(percents) < 100
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dsm.tif", "image.tif"]


class RecordedFeedback(QgsProcessingFeedback):
    """Feedback that keeps the warnings an algorithm pushes."""

    def __init__(self):
        super().__init__()
        self.warnings = []

    def pushWarning(self, text):  # noqa: N802
        self.warnings.append(text)
        super().pushWarning(text)


def test_a_forest_plot_succeeds_with_empty_typed_layers_and_a_warning(run_algorithm,
                                                                      lidar_dir, tmp_path):
    forest = lidar_dir / "Megaplot.laz"
    feedback = RecordedFeedback()
    result = run_algorithm("lidarroadnetwork", {"INPUT": str(forest), "CUE": 0,  # intensity
                                                "OUTPUT": str(tmp_path / "roads.gpkg")},
                           feedback)
    assert (result["ROADS"], result["LENGTH_M"], result["JUNCTIONS"]) == (0, 0, 0)
    assert feedback.warnings == [f"no road found in {forest}; wrote empty layers"]
    for name, geometry in (("road_centrelines", QgsWkbTypes.LineGeometry),
                           ("road_polygons", QgsWkbTypes.PolygonGeometry),
                           ("junctions", QgsWkbTypes.PointGeometry),
                           ("rectangles", QgsWkbTypes.PolygonGeometry),
                           ("hypotheses", QgsWkbTypes.PolygonGeometry)):
        layer = QgsVectorLayer(f"{tmp_path / 'roads.gpkg'}|layername={name}", name, "ogr")
        assert layer.isValid() and layer.featureCount() == 0, name
        assert layer.isSpatial() and layer.geometryType() == geometry, name


def test_layer_to_frame_keeps_geometry_attributes_nulls_and_crs(qgis_app, tmp_path):
    frame = gpd.GeoDataFrame(
        {"road_id": [1, 2], "width_m": [7.5, None], "kind": ["road", "service"]},
        geometry=[shapely.LineString([(0, 0), (10, 0)]), shapely.LineString([(0, 5), (3, 9)])],
        crs="EPSG:32754")
    frame.to_file(tmp_path / "l.gpkg", layer="lines")
    layer = QgsVectorLayer(f"{tmp_path / 'l.gpkg'}|layername=lines", "lines", "ogr")
    assert layer.isValid()
    back = source_to_frame(layer)
    assert back.crs.to_epsg() == 32754
    assert back.road_id.tolist() == [1, 2] and back.kind.tolist() == ["road", "service"]
    assert back.width_m.iloc[0] == 7.5 and back.width_m.isna().iloc[1]
    assert all(a.equals(b) for a, b in zip(back.geometry, frame.geometry))


def test_crs_round_trip(qgis_app):
    assert to_pyproj(to_qgis("EPSG:2154")).to_epsg() == 2154
    assert to_pyproj(to_qgis(None)) is None


@pytest.mark.parametrize("fields, values, labels", [
    ("field=passed:boolean", (True, False, None),
     ["road part (passed)", "rejected (see reason)", "segment"]),
    ("field=segment_id:integer", (7,), ["segment"]),  # a plain segmentation layer
])
def test_segments_style_tells_road_parts_from_rejected_segments(qgis_app, fields, values,
                                                                 labels):
    from qgis.core import QgsFeature, QgsGeometry, QgsRenderContext
    layer = QgsVectorLayer(f"Polygon?crs=EPSG:32633&{fields}", "segments", "memory")
    assert layer.loadNamedStyle(str(STYLES / "segments.qml"))[1]
    features = []
    for value in values:
        feature = QgsFeature(layer.fields())
        feature.setGeometry(QgsGeometry.fromWkt("POLYGON((0 0, 1 0, 1 1, 0 0))"))
        feature[0] = value
        features.append(feature)
    layer.dataProvider().addFeatures(features)
    context = QgsRenderContext()
    renderer = layer.renderer().clone()
    renderer.startRender(context, layer.fields())
    matched = [[rule.label() for rule in renderer.rootRule().rulesForFeature(f, context)]
               for f in layer.getFeatures()]
    renderer.stopRender(context)
    assert matched == [[label] for label in labels]


FUSA_LAYERS = {"fusa – road centre lines": True, "fusa – road polygons": True,
               "fusa – junctions": True, "fusa – service ways": True,
               "fusa – bridged gaps (QA)": False, "fusa – junction connections (QA)": False,
               "fusa – rejected parts (QA)": False, "fusa – ground intensity": True}
"""The layers a LiDAR road network run on fusa adds to the project (with the background
raster, as the dialog writes it by default), and whether each is ticked."""


def test_a_run_loads_its_layers_named_after_the_input_with_the_qa_layers_hidden(
        run_and_load, lidar_dir, tmp_path):
    """What the toolbox dialog does when the algorithm ends: the layers are named after
    the input, styled, the road network ticked and the QA layers unticked, the cloud's
    ground intensity beneath them and above what the project held."""
    from qgis.core import QgsApplication, QgsProject, QgsVectorLayer

    algorithm = QgsApplication.processingRegistry().createAlgorithmById(
        "gisroads:lidarroadnetwork")
    basemap = QgsVectorLayer("Polygon?crs=EPSG:3044", "basemap", "memory")
    ticked = run_and_load(algorithm, {"INPUT": str(lidar_dir / "fusa.laz"),
                                      "OUTPUT": str(tmp_path / "roads.gpkg"),
                                      "BACKGROUND": "TEMPORARY_OUTPUT"}, existing=[basemap])
    assert ticked == {**FUSA_LAYERS, "basemap": True}
    assert list(ticked)[-2:] == ["fusa – ground intensity", "basemap"]
    intensity = QgsProject.instance().mapLayersByName("fusa – ground intensity")[0]
    assert intensity.isValid() and intensity.crs() == lines_crs(tmp_path / "roads.gpkg")
    # styles/ground_intensity.qml: grey from 0.1 to 1.2 of the bright ground's intensity
    # (QGIS's own stretch runs to the brightest outlier, 40 times that: a black image)
    stretch = intensity.renderer().contrastEnhancement()
    assert (stretch.minimumValue(), stretch.maximumValue()) == (0.1, 1.2)
    lines = QgsProject.instance().mapLayersByName("fusa – road centre lines")[0]
    assert lines.featureCount() > 20
    assert lines.renderer().symbol().color().name() == "#e31a1c"  # styles/*.qml


def lines_crs(gpkg):
    from qgis.core import QgsVectorLayer
    return QgsVectorLayer(f"{gpkg}|layername=road_centrelines", "lines", "ogr").crs()


def test_the_loaders_network_layers_are_the_cores(qgis_app):
    """processing_provider.loading cannot import gisroads (external mode): its names are
    gisroads.geo's."""
    from gisroads.geo import CENTRELINES, JUNCTIONS, POLYGONS, SERVICE_CENTRELINES
    from processing_provider.loading import NETWORK_LAYERS

    assert NETWORK_LAYERS == (CENTRELINES, POLYGONS, JUNCTIONS, SERVICE_CENTRELINES)
