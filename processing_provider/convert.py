"""QGIS layers, parameters and feedback <-> gisroads' GeoDataFrames and callbacks, in one place."""
from __future__ import annotations

from contextlib import contextmanager, nullcontext

import geopandas as gpd
import numpy as np
import pandas as pd
import shapely
from pyproj import CRS
from qgis.core import (QgsCoordinateReferenceSystem, QgsFeature, QgsFeatureSink, QgsField,
                       QgsFields, QgsGeometry, QgsProcessingException, QgsWkbTypes)
from qgis.PyQt.QtCore import QVariant

from gisroads.errors import INPUT_ERRORS, reported_warnings
from gisroads.io.vector import STYLES_DIR
from gisroads.progress import Cancelled

from .loading import ApplyStyle, on_load


def to_pyproj(crs: QgsCoordinateReferenceSystem) -> CRS | None:
    if not crs.isValid():
        return None
    return CRS.from_wkt(crs.toWkt(QgsCoordinateReferenceSystem.WKT_PREFERRED))


def to_qgis(crs) -> QgsCoordinateReferenceSystem:
    if crs is None:
        return QgsCoordinateReferenceSystem()
    return QgsCoordinateReferenceSystem.fromWkt(CRS.from_user_input(crs).to_wkt())


#: pandas dtypes of QGIS field types (others: object).
_DTYPES = {QVariant.Int: "int64", QVariant.LongLong: "int64", QVariant.UInt: "int64",
           QVariant.ULongLong: "int64", QVariant.Double: "float64", QVariant.Bool: "bool"}


def source_to_frame(source, feedback=None) -> gpd.GeoDataFrame:
    """A QgsFeatureSource (layer or selection) as a GeoDataFrame in the source's CRS."""
    if source is None:
        raise QgsProcessingException("the input layer could not be loaded")
    names = source.fields().names()
    wkb, rows = [], []
    for i, feature in enumerate(source.getFeatures()):
        if feedback is not None and i % 1000 == 0:
            if feedback.isCanceled():
                raise QgsProcessingException("cancelled")
        geometry = feature.geometry()
        wkb.append(bytes(geometry.asWkb()) if not geometry.isNull() else None)
        # PyQt hands NULL attributes over as QVariant; every other value arrives as Python
        rows.append([None if isinstance(v, QVariant) else v for v in feature.attributes()])
    geometries = shapely.from_wkb(np.array(wkb, dtype=object)) if wkb else []
    if rows:
        frame = pd.DataFrame(rows, columns=names)
    else:  # an empty layer keeps its field types (a writer refuses a text fid, for one)
        frame = pd.DataFrame({field.name(): pd.Series(dtype=_DTYPES.get(field.type(), object))
                              for field in source.fields()})
    return gpd.GeoDataFrame(frame, geometry=gpd.GeoSeries(geometries, index=frame.index),
                            crs=to_pyproj(source.sourceCrs()))


def _field(name: str, dtype) -> QgsField:
    if pd.api.types.is_bool_dtype(dtype):
        return QgsField(name, QVariant.Bool)
    if pd.api.types.is_integer_dtype(dtype):
        return QgsField(name, QVariant.LongLong)
    if pd.api.types.is_float_dtype(dtype):
        return QgsField(name, QVariant.Double)
    return QgsField(name, QVariant.String)


_WKB_TYPES = {"LineString": QgsWkbTypes.LineString, "Polygon": QgsWkbTypes.Polygon,
              "Point": QgsWkbTypes.Point, "MultiLineString": QgsWkbTypes.MultiLineString,
              "MultiPolygon": QgsWkbTypes.MultiPolygon}


def frame_to_sink(algorithm, parameters, name, context, frame: gpd.GeoDataFrame,
                  geometry_type: str, feedback=None) -> str:
    """Write a GeoDataFrame into the feature sink parameter ``name``; returns its dest id."""
    columns = [c for c in frame.columns if c != frame.geometry.name]
    fields = QgsFields()
    for column in columns:
        fields.append(_field(column, frame[column].dtype))
    sink, dest_id = algorithm.parameterAsSink(parameters, name, context, fields,
                                              _WKB_TYPES[geometry_type], to_qgis(frame.crs))
    if sink is None:
        raise QgsProcessingException(algorithm.invalidSinkError(parameters, name))
    wkb = shapely.to_wkb(frame.geometry.values) if len(frame) else []
    values = frame[columns].astype(object).where(frame[columns].notna(), None).to_numpy()
    for i, row in enumerate(values):
        if feedback is not None and feedback.isCanceled():
            raise QgsProcessingException("cancelled")
        feature = QgsFeature(fields)
        geometry = QgsGeometry()
        geometry.fromWkb(wkb[i])
        feature.setGeometry(geometry)
        feature.setAttributes([v.item() if isinstance(v, np.generic) else v for v in row])
        sink.addFeature(feature, QgsFeatureSink.FastInsert)
    return dest_id


def progress_callback(feedback):
    """A gisroads progress callback driving ``feedback``; raises Cancelled on cancel."""
    def progress(fraction: float, message: str = "") -> None:
        if feedback.isCanceled():
            raise Cancelled()
        feedback.setProgress(100.0 * fraction)
        if message:
            feedback.setProgressText(message)
    return progress


@contextmanager
def gisroads_errors(feedback=None):
    """Turn gisroads' input errors (:data:`gisroads.errors.INPUT_ERRORS`) and a cancel into
    QgsProcessingException (exit 1 in qgis_process, a message box in the desktop); stages
    write atomically, so nothing half-written is left. Any other exception is a bug and
    keeps its traceback. With ``feedback``, gisroads' warnings (no road found: empty
    layers written, the algorithm succeeds) are pushed to it as warnings."""
    try:
        with (reported_warnings(feedback.pushWarning) if feedback is not None
              else nullcontext()):
            yield
    except Cancelled:
        raise QgsProcessingException("cancelled; nothing was written") from None
    except INPUT_ERRORS as err:
        raise QgsProcessingException(str(err)) from None


def style_on_load(context, dest_id: str, layer_name: str) -> None:
    """Give the output ``dest_id`` its ``styles/<layer_name>.qml`` when QGIS loads it."""
    qml = STYLES_DIR / f"{layer_name}.qml"
    if qml.exists():
        on_load(context, dest_id, ApplyStyle(str(qml)))
