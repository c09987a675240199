"""One call for every metric of an extracted road network, and a short text summary."""
from __future__ import annotations

import math

import geopandas as gpd
import shapely

from .apls import apls_score
from .area import area_metrics
from .buffer import align_to_reference, buffer_metrics, metric_lines, typed_parts
from .topology import topology_metrics


def evaluate_network(extracted, reference, *, buffer_m: float = 3.0, cell_m: float = 0.5,
                     junction_radius_m: float = 10.0, valid_area=None,
                     extracted_polygons=None, reference_polygons=None,
                     reference_junctions=None) -> dict:
    """Buffer, topology, APLS and (given both polygon sets) area metrics of a road network.

    The centre lines are aligned to one metric CRS and clipped to ``valid_area`` once, and
    every line metric sees the same clipped lines.

    Parameters
    ----------
    extracted, reference : GeoDataFrame, GeoSeries or sequence of (Multi)LineString
        Centre lines; see :mod:`gisroads.evaluate.buffer` for the CRS and empty-layer rules.
    buffer_m : float
        Buffer half-width of :func:`~gisroads.evaluate.buffer.buffer_metrics`, metres.
    cell_m : float
        Grid cell of :func:`~gisroads.evaluate.area.area_metrics`, metres.
    junction_radius_m : float
        Junction matching radius of :func:`~gisroads.evaluate.topology.topology_metrics`.
    valid_area : GeoDataFrame, GeoSeries or (Multi)Polygon, optional
        Where the reference is complete; everything outside is ignored.
    extracted_polygons, reference_polygons : GeoDataFrame, optional
        Road areas; the ``area`` group is computed only when both are given.
    reference_junctions : GeoDataFrame, optional
        The reference's digitised junctions (points); by default they are derived from its
        lines (see :func:`~gisroads.evaluate.topology.topology_metrics`). Those outside
        ``valid_area`` are left out.

    Returns
    -------
    dict
        ``{"buffer": {...}, "topology": {...}, "apls": {...}[, "area": {...}]}``, each a flat
        dict of Python ints and floats (undefined ratios are NaN, which ``json.dumps``
        writes as ``NaN``); the keys are those of the four metric functions.

    Examples
    --------
    An extraction that missed the avenue, against a synthetic scene's truth:

    >>> from gisroads.evaluate import evaluate_network, format_report
    >>> from gisroads.synthetic import make_scene
    >>> truth = make_scene(seed=0, size_m=(300, 300)).truth
    >>> lines = truth.centrelines
    >>> extracted = lines[lines.road_id != 2]        # road 2: the avenue
    >>> results = evaluate_network(extracted, lines, buffer_m=3.0)
    >>> sorted(results)
    ['apls', 'buffer', 'topology']
    >>> round(results["buffer"]["correctness"], 3), round(results["buffer"]["completeness"], 2)
    (1.0, 0.87)
    >>> print(format_report(results))
    Buffer 3.00 m: completeness 87.4 %, correctness 100.0 %, quality 87.1 %, RMS 0.00 m
      length: extracted 1784.04 m, reference 2084.04 m
    Topology: components 3 extracted, 2 reference; junctions 5 extracted, 11 reference,
      5 matched within 10.00 m (precision 100.0 %, recall 45.5 %)
    APLS: ... %)
    """
    ext, ref, crs = metric_lines(extracted, reference, valid_area=valid_area)
    ext, ref = gpd.GeoSeries(ext, crs=crs), gpd.GeoSeries(ref, crs=crs)
    if reference_junctions is not None and valid_area is not None:
        _, _, (points, area) = align_to_reference(reference, reference_junctions, valid_area)
        area = shapely.union_all(typed_parts(area, (shapely.GeometryType.POLYGON,
                                                    shapely.GeometryType.MULTIPOLYGON),
                                             layer="valid area"))
        reference_junctions = gpd.GeoSeries(points[shapely.intersects(points, area)], crs=crs)
    results = {
        "buffer": buffer_metrics(ext, ref, buffer_m=buffer_m).as_dict(),
        "topology": topology_metrics(ext, ref, junction_radius_m=junction_radius_m,
                                     reference_junctions=reference_junctions),
        "apls": apls_score(ext, ref),
    }
    if extracted_polygons is not None and reference_polygons is not None:
        results["area"] = area_metrics(extracted_polygons, reference_polygons, cell_m=cell_m,
                                       valid_area=valid_area).as_dict()
    return results


def _percent(value: float) -> str:
    return "n/a" if math.isnan(value) else f"{100 * value:.1f} %"


def _direction(value: float) -> str:
    """The spill direction, in [-1, 1], and which way it points."""
    if math.isnan(value):
        return "n/a"
    return f"{value:+.2f} ({'outward' if value > 0 else 'inward' if value < 0 else 'none'})"


def _metres(value: float) -> str:
    return "n/a" if math.isnan(value) else f"{value:.2f} m"


def format_report(results: dict) -> str:
    """A few lines of text summarising :func:`evaluate_network`'s results."""
    b, t, a = results["buffer"], results["topology"], results["apls"]
    lines = [
        f"Buffer {_metres(b['buffer_m'])}: completeness {_percent(b['completeness'])}, "
        f"correctness {_percent(b['correctness'])}, quality {_percent(b['quality'])}, "
        f"RMS {_metres(b['rms_m'])}",
        f"  length: extracted {_metres(b['extracted_length_m'])}, "
        f"reference {_metres(b['reference_length_m'])}",
        f"Topology: components {t['components_extracted']} extracted, "
        f"{t['components_reference']} reference; junctions {t['junctions_extracted']} "
        f"extracted, {t['junctions_reference']} reference, {t['junction_matches']} matched "
        f"within {_metres(t['junction_radius_m'])} (precision "
        f"{_percent(t['junction_precision'])}, recall {_percent(t['junction_recall'])})",
        f"APLS: {_percent(a['apls'])} (reference to extracted "
        f"{_percent(a['apls_reference_to_extracted'])}, extracted to reference "
        f"{_percent(a['apls_extracted_to_reference'])})",
    ]
    if "area" in results:
        r = results["area"]
        lines.append(
            f"Area ({_metres(r['cell_m'])} cells): precision {_percent(r['precision'])}, "
            f"recall {_percent(r['recall'])}, quality {_percent(r['quality'])}, "
            f"spill size {_metres(r['spill_size_m'])}, spill direction "
            f"{_direction(r['spill_direction'])}")
    return "\n".join(lines)
