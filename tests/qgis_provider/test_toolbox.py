"""What a QGIS user sees of the provider before running anything: the toolbox tree (stages
in pipeline order) and the number fields of the algorithm dialogs (decimals, units).

The toolbox model and the parameter widgets are QGIS's own (qgis.gui), built in a child
process: widgets need a GUI QgsApplication, and this session's (pytest-qgis) has none.
"""
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from qgis.core import QgsApplication, QgsProcessingParameterNumber

REPO = Path(__file__).resolve().parents[2]

SCRIPT = r"""
import json, sys
from qgis.core import QgsApplication, QgsProcessingContext
from qgis.gui import QgsDoubleSpinBox, QgsGui, QgsProcessingGui, QgsProcessingToolboxProxyModel
from qgis.PyQt.QtCore import QModelIndex, Qt
from qgis.PyQt.QtWidgets import QLabel

app = QgsApplication([], True)
app.initQgis()
from processing_provider.provider import GisroadsProvider
registry = QgsApplication.processingRegistry()
registry.addProvider(GisroadsProvider())

toolbox = QgsProcessingToolboxProxyModel(None, registry)
toolbox.sort(0)
tree = {}
def walk(index, group):
    for row in range(toolbox.rowCount(index)):
        child = toolbox.index(row, 0, index)
        algorithm = toolbox.toolboxModel().algorithmForIndex(toolbox.mapToSource(child))
        if algorithm is None:
            walk(child, toolbox.data(child, Qt.DisplayRole))
        elif algorithm.provider().id() == "gisroads":
            tree.setdefault(group, []).append([algorithm.displayName(), algorithm.name()])
walk(QModelIndex(), None)

context = QgsProcessingContext()
widgets = {}
for listed in registry.providerById("gisroads").algorithms():
    algorithm = registry.createAlgorithmById(listed.id())  # as the dialog makes it
    for parameter in algorithm.parameterDefinitions():
        if parameter.type() not in ("number", "distance"):
            continue
        wrapper = QgsGui.processingGuiRegistry().createParameterWidgetWrapper(
            parameter, QgsProcessingGui.Standard)
        widget = wrapper.createWrappedWidget(context)
        spins = widget.findChildren(QgsDoubleSpinBox)
        if isinstance(widget, QgsDoubleSpinBox):
            spins.append(widget)
        widgets[f"{algorithm.name()}:{parameter.name()}"] = {
            "type": parameter.type(), "description": parameter.description(),
            "spins": [spin.text() for spin in spins],
            "labels": [label.text() for label in widget.findChildren(QLabel)]}
print(json.dumps({"tree": tree, "widgets": widgets}))
app.exitQgis()
"""


def seen_in_qgis():
    env = {**os.environ, "QT_QPA_PLATFORM": "offscreen", "PYTHONPATH": str(REPO)}
    done = subprocess.run([sys.executable, "-c", SCRIPT], env=env, cwd=REPO,
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


PIPELINES = {  # algorithm ids (never renamed) in pipeline order
    "LiDAR": ["lidargroundintensity", "lidarsegmentation", "lidarlikelihood", "lidarmincover",
              "rectanglestonetwork", "tagroadpoints"],
    "Imagery": ["imagesegmentation", "segmentgrouping", "roadparts", "subgraphlinking",
                "junctionconstruction"],
    "Map-guided snakes": ["registerroadmap", "curbattractormap"],
}


def test_the_toolbox_and_the_dialogs_as_qgis_shows_them():
    seen = seen_in_qgis()
    tree, widgets = seen["tree"], seen["widgets"]
    # the toolbox sorts by name: the numbered stages come first, in pipeline order
    for group, stages in PIPELINES.items():
        listed = tree[group]
        assert [name for _, name in listed[:len(stages)]] == stages, listed
        assert [shown.split(" ")[0] for shown, _ in listed[:len(stages)]] == [
            str(i) for i in range(1, len(stages) + 1)]
        assert not any(shown[0].isdigit() for shown, _ in listed[len(stages):])
    assert ["1 Ground planes and intensity image", "lidargroundintensity"] in tree["LiDAR"]
    assert ["LiDAR road network (Zhu & Mordohai)", "lidarroadnetwork"] in tree["LiDAR"]
    # number fields show the decimals their values need, not QGIS's default six
    assert widgets["lidarroadnetwork:TILE"]["spins"] == ["300.0"]
    assert widgets["lidarroadnetwork:OVERLAP"]["spins"] == ["100.0"]
    assert widgets["lidarroadnetwork:THRESHOLD"]["spins"] == ["0.80"]
    assert widgets["syntheticroadscene:WIDTH"]["spins"] == ["400.0"]
    assert widgets["evaluateroadnetwork:BUFFER"]["spins"] == ["3.00"]
    six = {key for key, w in widgets.items() for text in w["spins"]
           if len(text.split(".")[-1]) == 6}
    assert six == {"imagesegmentation:W_NDVI"}  # its minimum is 0.000001
    # no unit QGIS cannot name: no distance in a layer's units, metres in the label instead
    assert not [key for key, w in widgets.items() if w["type"] == "distance"]
    assert not [key for key, w in widgets.items() if "<unknown>" in w["labels"]]
    assert "(metres" in widgets["evaluateroadnetwork:BUFFER"]["description"]
    assert "(metres)" in widgets["evaluateroadnetwork:JUNCTION_RADIUS"]["description"]


def test_every_decimal_number_parameter_sets_its_decimals(qgis_app):
    from processing_provider.provider import algorithm_classes
    checked = 0
    for algorithm_class in algorithm_classes():
        algorithm = algorithm_class()
        algorithm.initAlgorithm()
        for parameter in algorithm.parameterDefinitions():
            if isinstance(parameter, QgsProcessingParameterNumber) \
                    and parameter.dataType() == QgsProcessingParameterNumber.Double:
                decimals = parameter.metadata()["widget_wrapper"]["decimals"]
                assert 1 <= decimals <= 6, (algorithm.name(), parameter.name())
                default = parameter.defaultValue()
                if default is not None:  # the default shows exactly
                    assert abs(round(default, decimals) - default) < 1e-9, parameter.name()
                checked += 1
        assert algorithm.displayName().startswith(f"{algorithm_class.STAGE} ") \
            == bool(algorithm_class.STAGE)
    assert checked > 50
    assert QgsApplication.instance() is not None


def test_the_point_cloud_input_is_a_layer_where_qgis_opens_las_and_a_file_elsewhere(
        qgis_app, monkeypatch, tmp_path):
    from qgis.core import (QgsProcessingContext, QgsProcessingException,
                           QgsProcessingParameterFile, QgsProcessingParameterPointCloudLayer)

    from processing_provider.algorithms import base
    from processing_provider.algorithms.lidar_ground_intensity import LidarGroundIntensity
    from processing_provider.provider import algorithm_classes

    cloud = str(tmp_path / "area.laz")
    clouds = [a for a in (c() for c in algorithm_classes()) if a.initAlgorithm() is None
              and isinstance(a.parameterDefinition("INPUT"), QgsProcessingParameterFile)
              and "LAS" in a.parameterDefinition("INPUT").fileFilter()]
    assert len(clouds) == 8  # every algorithm reading a point cloud
    # Debian's QGIS has no PDAL provider: a file, read as given
    assert not base.reads_point_clouds()
    context = QgsProcessingContext()
    assert base.cloud_path(clouds[0], {"INPUT": cloud}, context) == cloud

    monkeypatch.setattr(base, "reads_point_clouds", lambda: True)
    algorithm = LidarGroundIntensity()
    algorithm.initAlgorithm()
    assert isinstance(algorithm.parameterDefinition("INPUT"),
                      QgsProcessingParameterPointCloudLayer)
    with pytest.raises(QgsProcessingException, match="no point cloud that this QGIS can open"):
        base.cloud_path(algorithm, {"INPUT": cloud}, context)
