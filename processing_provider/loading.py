"""Output GeoPackages added to the QGIS project when an algorithm ends, styled and named.

Standard library and qgis only: the external-tool mode (:mod:`.external`) loads its outputs
with it where gisroads cannot be imported. The styles are those gisroads stores in every
GeoPackage it writes (its ``layer_styles`` table, from ``styles/<layer>.qml``): Processing
loads layers without their stored default style, so a post-processor loads it.
"""
from __future__ import annotations

import sqlite3
from pathlib import Path

from qgis.core import (QgsProcessingContext, QgsProcessingException,
                       QgsProcessingLayerPostProcessorInterface, QgsVectorLayer)

#: The road network's own layers (gisroads.geo's CENTRELINES, POLYGONS, JUNCTIONS and
#: SERVICE_CENTRELINES): ticked when a run loads them; the others it loads beside them
#: (rectangles, bridged gaps, rejected parts...) are QA layers, loaded unticked.
NETWORK_LAYERS = ("road_centrelines", "road_polygons", "junctions", "service_centrelines")

#: What the layer tree calls a layer (its table name otherwise, underscores as spaces).
LAYER_TITLES = {"road_centrelines": "road centre lines", "road_polygons": "road polygons",
                "service_centrelines": "service ways", "gap_edges": "bridged gaps (QA)",
                "junction_connections": "junction connections (QA)",
                "rejected": "rejected parts (QA)", "rectangles": "selected rectangles (QA)",
                "hypotheses": "rectangle hypotheses (QA)", "segments": "segments (QA)",
                "road_parts": "road parts (QA)", "ribbon_patches": "ribbons (QA)",
                "registered_map": "registered map (QA)"}


class ApplyStyle(QgsProcessingLayerPostProcessorInterface):
    """Styles an output layer when QGIS loads it (with a QML file, or the default style
    stored with the layer) and leaves it unticked, its legend folded, in the layer tree
    unless ``visible``."""

    def __init__(self, qml_path: str | None = None, *, visible: bool = True):
        super().__init__()
        self.qml_path = qml_path
        self.visible = visible

    def postProcessLayer(self, layer, context, feedback):  # noqa: N802
        if isinstance(layer, QgsVectorLayer):
            if self.qml_path is None:
                layer.loadDefaultStyle()
            else:
                layer.loadNamedStyle(self.qml_path)
            layer.triggerRepaint()
        project = context.project()
        node = project.layerTreeRoot().findLayer(layer.id()) if project is not None else None
        if node is not None:
            node.setItemVisibilityChecked(self.visible)
            node.setExpanded(self.visible)  # a QA layer's legend folded away


class PlaceBeneath(QgsProcessingLayerPostProcessorInterface):
    """Moves a raster loaded with a run's layers (its input image, a cloud's ground
    intensity) beneath them: just below the lowest layer of its group whose name starts
    with ``prefix`` (the run's layers are named after its input), above whatever was
    there before. Layers loaded after it go on top of it anyway. Styled with
    ``qml_path`` when given."""

    def __init__(self, prefix: str, qml_path: str | None = None):
        super().__init__()
        self.prefix = prefix
        self.qml_path = qml_path

    def postProcessLayer(self, layer, context, feedback):  # noqa: N802
        if self.qml_path is not None:
            layer.loadNamedStyle(self.qml_path)
            layer.triggerRepaint()
        project = context.project()
        node = project.layerTreeRoot().findLayer(layer.id()) if project is not None else None
        if node is None:
            return
        parent = node.parent()
        run = [i for i, child in enumerate(parent.children())
               if child.name().startswith(self.prefix)
               and getattr(child, "layerId", lambda: None)() != layer.id()]
        if not run:
            return
        parent.insertChildNode(max(run) + 1, node.clone())
        parent.removeChildNode(node)


_POST_PROCESSORS = []  # QGIS does not own them: keep them alive until the run ends


def on_load(context, dest_id: str, processor) -> None:
    """Run ``processor`` on the output ``dest_id`` when QGIS loads it."""
    if context.willLoadLayerOnCompletion(dest_id):
        _POST_PROCESSORS.append(processor)
        context.layerToLoadOnCompletionDetails(dest_id).setPostProcessor(processor)


def geopackage_layers(path: str) -> list[str]:
    """The layers with geometry of a GeoPackage, in its order (not its ``layer_styles``)."""
    from osgeo import ogr

    source = ogr.Open(str(path))
    if source is None:
        return []
    layers = [source.GetLayerByIndex(i) for i in range(source.GetLayerCount())]
    return [layer.GetName() for layer in layers if layer.GetGeomType() != ogr.wkbNone]


def load_geopackage_on_completion(context, path: str, layer_names=None, *, group: str = "",
                                  title: str | None = None) -> None:
    """Add layers of a GeoPackage (by default all of them) to the project when the
    algorithm ends, each with the style stored in the file.

    Named "``title`` – road centre lines" (:data:`LAYER_TITLES`) with a ``title`` (the
    input's name), else "``group`` layer". When the network's own layers
    (:data:`NETWORK_LAYERS`) are among them, the other layers are QA layers: loaded, but
    unticked."""
    names = geopackage_layers(path) if layer_names is None else list(layer_names)
    network = any(name in NETWORK_LAYERS for name in names)
    for name in names:
        uri = f"{path}|layername={name}"
        shown = (f"{title} – {LAYER_TITLES.get(name, name.replace('_', ' '))}" if title
                 else f"{group} {name}".strip())
        context.addLayerToLoadOnCompletion(
            uri, QgsProcessingContext.LayerDetails(shown, context.project(), name))
        on_load(context, uri, ApplyStyle(visible=not network or name in NETWORK_LAYERS))


def load_beneath_on_completion(context, source: str, what: str, *, title: str) -> None:
    """Add the raster ``source`` (``what`` it is: "image", "ground intensity") to the
    project when the algorithm ends, named "``title`` – ``what``", beneath the layers named
    after ``title`` (:class:`PlaceBeneath`); nothing when ``source`` is a layer of the
    project already."""
    project = context.project()
    if project is None or any(layer.source() == source
                              for layer in project.mapLayers().values()):
        return
    context.addLayerToLoadOnCompletion(
        source, QgsProcessingContext.LayerDetails(f"{title} – {what}", project, what))
    on_load(context, source, PlaceBeneath(f"{title} – ", style_path(what.replace(" ", "_"))))


def style_path(name: str) -> str | None:
    """The QML style ``name`` of styles/ (in the plugin: gisroads/_styles), None if none."""
    here = Path(__file__).resolve().parent
    for folder in (here / "gisroads" / "_styles", here.parent / "styles"):
        if (folder / f"{name}.qml").is_file():
            return str(folder / f"{name}.qml")
    return None


def load_scene_on_completion(context, paths: dict, folder: str) -> dict:
    """Add a synthetic scene's truth (road polygons, centre lines, junctions) and its image
    and DSM to the project when the algorithm ends; returns the algorithm's outputs.
    ``paths``: what ``gisroads synth`` wrote (``truth``, optionally ``cloud``, ``image``,
    ``dsm``)."""
    truth = str(paths["truth"])
    load_geopackage_on_completion(context, truth, ("road_polygons", "road_centrelines",
                                                   "junctions"), group="truth")
    outputs = {"TRUTH": truth, "TRUTH_CENTRELINES": f"{truth}|layername=road_centrelines",
               "CLOUD": str(paths.get("cloud", "")), "OUTPUT_FOLDER": folder}
    for key in ("IMAGE", "DSM"):
        if key.lower() in paths:
            outputs[key] = str(paths[key.lower()])
            context.addLayerToLoadOnCompletion(
                outputs[key], QgsProcessingContext.LayerDetails(key.lower(), context.project(),
                                                                key))
    return outputs


def geopackage_layer_names(path) -> list[str]:
    """The vector layers of a GeoPackage, in the order they were written (its
    ``gpkg_contents`` table, read with the standard library's sqlite3)."""
    if not Path(path).is_file():
        raise QgsProcessingException(f"{path}: no such file")
    try:
        connection = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
        try:
            rows = connection.execute("SELECT table_name FROM gpkg_contents WHERE data_type "
                                      "= 'features' ORDER BY rowid").fetchall()
        finally:
            connection.close()
    except sqlite3.DatabaseError:
        raise QgsProcessingException(f"{path}: not a GeoPackage") from None
    return [name for (name,) in rows]


def open_geopackage_layers(path: str) -> list[tuple[str, QgsVectorLayer, bool]]:
    """Each layer of a GeoPackage as the QGIS desktop opens it: with the default style
    stored in the file. Returns ``(name, layer, styled_from_file)`` per layer."""
    opened = []
    for name in geopackage_layer_names(path):
        options = QgsVectorLayer.LayerOptions()
        options.loadDefaultStyle = False  # loaded explicitly below, to know if it worked
        layer = QgsVectorLayer(f"{path}|layername={name}", name, "ogr", options)
        if not layer.isValid():
            raise QgsProcessingException(f"{path}: layer {name} cannot be opened")
        _, styled = layer.loadDefaultStyle()
        opened.append((name, layer, bool(styled)))
    return opened
