"""Buffer metrics for road centre lines (Wiedemann et al., 1998), and the input rules shared by
every metric of :mod:`gisroads.evaluate`.

Input rules
-----------
Layers are GeoDataFrames, GeoSeries, single shapely geometries or sequences of them; missing
and empty geometries are dropped.

CRS
    When both layers have a CRS and they differ, the extracted layer is reprojected to the
    reference's. When only one has a CRS, the other is assumed to share it. When that CRS is
    geographic (SpaceNet's EPSG:4326) or its linear unit is not the metre, both layers are
    reprojected to ``reference.estimate_utm_crs()``, so every figure is in metres. A valid area
    given as a bare shapely geometry is taken to be in the reference's CRS.
Empty layers
    An empty extracted layer is valid and scores zero; ratios with nothing to divide by
    (such as the correctness of nothing) are NaN. An empty reference raises ``ValueError``.

References
----------
Wiedemann, C., Heipke, C., Mayer, H., Jamet, O. (1998). Empirical evaluation of automatically
extracted road axes. In *Empirical Evaluation Techniques in Computer Vision*, IEEE, 172-187.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import geopandas as gpd
import numpy as np
import shapely

from ..errors import GisroadsError

_KIND = shapely.GeometryType
_LINE_TYPES = (_KIND.LINESTRING, _KIND.LINEARRING)
_POLYGON_TYPES = (_KIND.POLYGON,)
_TYPE_NAMES = {_KIND.POINT: "Point", _KIND.LINESTRING: "LineString",
               _KIND.LINEARRING: "LinearRing", _KIND.POLYGON: "Polygon"}


def _as_series(layer) -> gpd.GeoSeries | None:
    if layer is None or isinstance(layer, gpd.GeoSeries):
        return layer
    if isinstance(layer, gpd.GeoDataFrame):
        return layer.geometry
    if isinstance(layer, shapely.Geometry):
        return gpd.GeoSeries([layer])
    return gpd.GeoSeries(list(layer))


def _is_metric(crs) -> bool:
    return not crs.is_geographic and all(axis.unit_conversion_factor == 1.0
                                         for axis in crs.axis_info[:2])


def _geometries(series: gpd.GeoSeries) -> np.ndarray:
    geoms = np.asarray(series.values, dtype=object)
    return geoms[~(shapely.is_missing(geoms) | shapely.is_empty(geoms))]


def align_to_reference(reference, *others):
    """Geometry arrays of a reference layer and other layers, all in one metric CRS.

    Applies the CRS rules of the module docstring.

    Parameters
    ----------
    reference : GeoDataFrame, GeoSeries, shapely geometry or sequence of geometries
    *others : same kinds, or None
        Layers to bring into the reference's frame (extracted layer, valid area ...).

    Returns
    -------
    crs : pyproj.CRS or None
        The working CRS (None when no layer has one).
    reference : ndarray of shapely geometries
        Missing and empty geometries dropped.
    others : list of (ndarray of shapely geometries or None)

    Raises
    ------
    ValueError
        When the reference holds no geometry.
    """
    ref = _as_series(reference)
    series = [_as_series(layer) for layer in others]
    if len(_geometries(ref)) == 0:
        raise GisroadsError("the reference layer is empty: there is nothing to evaluate "
                            "against")
    shared = ref.crs or next((s.crs for s in series if s is not None and s.crs is not None),
                             None)
    if shared is None:
        return None, _geometries(ref), [s if s is None else _geometries(s) for s in series]
    ref = ref.set_crs(shared) if ref.crs is None else ref
    crs = ref.crs if _is_metric(ref.crs) else ref.estimate_utm_crs()
    # Each layer goes straight from its own CRS to the working one: a layer already there
    # keeps its exact coordinates, which noding and junction snapping depend on.
    aligned = [s if s is None else (s.set_crs(shared) if s.crs is None else s).to_crs(crs)
               for s in [ref, *series]]
    return crs, _geometries(aligned[0]), [s if s is None else _geometries(s)
                                          for s in aligned[1:]]


def typed_parts(geoms, kinds, *, layer: str) -> np.ndarray:
    """Single-part geometries of ``geoms``; ``ValueError`` if any is not of ``kinds``.

    Parameters
    ----------
    geoms : ndarray of shapely geometries
    kinds : tuple of shapely.GeometryType
        The single-part types accepted.
    layer : str
        The layer's name in the error message.
    """
    parts = shapely.get_parts(np.asarray(geoms, dtype=object))
    type_id = shapely.get_type_id(parts)
    wrong = ~np.isin(type_id, [int(k) for k in kinds])
    if wrong.any():
        _, first = np.unique(type_id[wrong], return_index=True)
        found = sorted(geom.geom_type for geom in parts[wrong][first])
        expected = sorted(_TYPE_NAMES[k] for k in kinds)
        raise GisroadsError(f"the {layer} layer holds {', '.join(found)} geometries; "
                            f"expected {' or '.join(expected)}")
    return parts


def clip_lines(lines: np.ndarray, area) -> np.ndarray:
    """Parts of LineStrings inside an area (a geometry array, dissolved first)."""
    if area is None:
        return lines
    pieces = shapely.get_parts(shapely.intersection(lines, shapely.union_all(area)))
    # Lines touching the area's boundary leave points behind; only linework is kept.
    keep = np.isin(shapely.get_type_id(pieces), [int(t) for t in _LINE_TYPES])
    return pieces[keep & ~shapely.is_empty(pieces)]


def metric_lines(extracted, reference, *, valid_area=None):
    """Extracted and reference centre lines as LineString arrays in one metric CRS.

    Applies the input rules of the module docstring, then clips both to ``valid_area``.

    Returns
    -------
    extracted, reference : ndarray of LineString
    crs : pyproj.CRS or None
    """
    crs, ref, (ext, area) = align_to_reference(reference, extracted, valid_area)
    ext = typed_parts(ext, _LINE_TYPES, layer="extracted")
    ref = typed_parts(ref, _LINE_TYPES, layer="reference")
    area = None if area is None else typed_parts(area, _POLYGON_TYPES, layer="valid area")
    ref = clip_lines(ref, area)
    if len(ref) == 0:
        raise GisroadsError("the reference layer has no line inside the valid area")
    return clip_lines(ext, area), ref, crs


def nearest_on_lines(points, lines, *, max_distance: float | None = None):
    """Nearest point on a set of lines for each point, by linear reference.

    Parameters
    ----------
    points : ndarray of Point
    lines : ndarray of LineString
    max_distance : float, optional
        Points farther than this (metres) from every line get no match.

    Returns
    -------
    line : ndarray of int
        Index of the nearest line, -1 where there is none.
    along_m : ndarray of float
        Distance along that line, from its first vertex, to the nearest point; NaN if none.
    distance_m : ndarray of float
        Distance from the point to the line; inf if none.
    """
    coords, owner = shapely.get_coordinates(lines, return_index=True)
    inner = (owner[1:] == owner[:-1]) & np.any(coords[1:] != coords[:-1], axis=1)
    start, end = coords[:-1][inner], coords[1:][inner]
    seg_owner = owner[1:][inner]
    seg_len = np.hypot(*(end - start).T)
    before = np.cumsum(seg_len) - seg_len
    # Segments of one line are contiguous, so subtracting the first one's running total gives
    # the length of the line before each segment.
    offset = before - before[np.searchsorted(seg_owner, seg_owner)]
    # A tree of two-point segments, not of whole lines: long bending lines have envelopes
    # that overlap everything and would defeat the tree.
    tree = shapely.STRtree(shapely.linestrings(np.stack([start, end], axis=1)))
    (which, seg), dist = tree.query_nearest(points, max_distance=max_distance,
                                            return_distance=True, all_matches=False)
    xy = shapely.get_coordinates(points)[which]
    direction = end[seg] - start[seg]
    t = np.clip(np.einsum("ij,ij->i", xy - start[seg], direction) / seg_len[seg] ** 2, 0, 1)
    line = np.full(len(points), -1, dtype=np.int64)
    along = np.full(len(points), np.nan)
    distance = np.full(len(points), np.inf)
    line[which] = seg_owner[seg]
    along[which] = offset[seg] + t * seg_len[seg]
    distance[which] = dist
    return line, along, distance


def pieces_needed(lengths, step: float) -> np.ndarray:
    """Fewest equal pieces no longer than ``step`` to cut each length into (at least one).

    A length a hair over a multiple of ``step`` (a millionth of it, from rounding or
    reprojection) gets no extra piece, so results do not flip with the last digit.
    """
    return np.maximum(np.ceil(np.asarray(lengths) / step - 1e-6), 1).astype(np.int64)


@dataclass(frozen=True)
class BufferMetrics:
    """Wiedemann's buffer metrics; lengths in metres, ratios in [0, 1] (NaN if undefined).

    Attributes
    ----------
    completeness : float
        ``matched_reference_m / reference_length_m``.
    correctness : float
        ``matched_extracted_m / extracted_length_m``; NaN when nothing was extracted.
    quality : float
        ``matched_extracted_m / (extracted_length_m + reference_length_m
        - matched_reference_m)``.
    rms_m : float
        Root mean square distance from the matched extracted lines to the reference
        (sampled, see :func:`buffer_metrics`); NaN when nothing matched.
    extracted_length_m, reference_length_m : float
        Length of each network, overlapping duplicates counted once.
    matched_extracted_m : float
        Length of extracted lines within ``buffer_m`` of the reference.
    matched_reference_m : float
        Length of reference lines within ``buffer_m`` of the extracted lines.
    buffer_m : float
    """

    completeness: float
    correctness: float
    quality: float
    rms_m: float
    extracted_length_m: float
    reference_length_m: float
    matched_extracted_m: float
    matched_reference_m: float
    buffer_m: float

    def as_dict(self) -> dict[str, float]:
        """Plain ``{name: float}``, ready for JSON."""
        return {name: float(value) for name, value in asdict(self).items()}


def _split_by_buffer(lines, around, buffer_m: float):
    """Dissolved ``lines`` cut into the part within ``buffer_m`` of ``around`` and the rest."""
    # Round caps and joins: the zone is every point within buffer_m of the linework, up to
    # GEOS's 8 segments per quarter circle (the outline sags inwards by < 0.5 % of buffer_m).
    # Buffering the parts and dissolving the polygons is faster in GEOS than buffering the
    # whole multi-line at once, and gives the same zone.
    zone = shapely.union_all(shapely.buffer(shapely.get_parts(around), buffer_m))
    return shapely.intersection(lines, zone), shapely.difference(lines, zone)


def _line_pieces(geometry) -> np.ndarray:
    parts = shapely.get_parts(geometry)
    return parts[np.isin(shapely.get_type_id(parts), [int(t) for t in _LINE_TYPES])]


def _sampled_rms(lines: np.ndarray, reference: np.ndarray, step_m: float) -> float:
    """Length-weighted RMS distance from ``lines`` to ``reference``, by the midpoint rule."""
    lengths = shapely.length(lines)
    lines, lengths = lines[lengths > 0], lengths[lengths > 0]
    if len(lines) == 0:
        return float("nan")
    count = pieces_needed(lengths, step_m)
    owner = np.repeat(np.arange(len(lines)), count)
    rank = np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)
    points = shapely.line_interpolate_point(lines[owner], (rank + 0.5) / count[owner],
                                           normalized=True)
    _, _, distance = nearest_on_lines(points, reference)
    weight = (lengths / count)[owner]
    return float(np.sqrt(np.sum(weight * distance ** 2) / np.sum(weight)))


def buffer_metrics(extracted, reference, *, buffer_m: float = 3.0, valid_area=None,
                   rms_step_m: float = 0.5) -> BufferMetrics:
    """Completeness, correctness, quality and RMS of extracted centre lines (Wiedemann 1998).

    Both networks are dissolved (overlapping duplicates count once). With
    ``zone(X) = {points within buffer_m of X}`` (round caps and joins):

    - ``matched_reference = length(reference ∩ zone(extracted))``
    - ``matched_extracted = length(extracted ∩ zone(reference))``
    - ``completeness = matched_reference / length(reference)``
    - ``correctness = matched_extracted / length(extracted)``
    - ``quality = matched_extracted / (length(extracted) + length(reference) -
      matched_reference)``, i.e. TP / (TP + FP + FN) with TP the matched extracted length,
      FP the unmatched extracted length and FN the unmatched reference length.
    - ``rms = sqrt(∫ d(s)² ds / matched_extracted)`` over the matched extracted lines, ``d``
      the distance to the reference. It is sampled: each matched piece is cut into
      ``ceil(length / rms_step_m)`` equal parts, ``d`` is taken at their midpoints and the
      squares are weighted by part length (midpoint rule), so a constant offset is exact.

    Parameters
    ----------
    extracted, reference : GeoDataFrame, GeoSeries or sequence of (Multi)LineString
        Centre lines; see the module docstring for CRS and empty-layer rules.
    buffer_m : float
        Buffer half-width in metres.
    valid_area : GeoDataFrame, GeoSeries or (Multi)Polygon, optional
        Both networks are clipped to it first.
    rms_step_m : float
        Sampling step of the RMS distance in metres.

    Returns
    -------
    BufferMetrics
        ``correctness`` and ``rms_m`` are NaN when nothing was extracted (or matched).

    Examples
    --------
    A synthetic scene's centre lines moved 1 m east, against the truth:

    >>> from gisroads.evaluate import buffer_metrics
    >>> from gisroads.synthetic import make_scene
    >>> truth = make_scene(seed=0, size_m=(300, 300)).truth.centrelines
    >>> moved = truth.translate(xoff=1.0)
    >>> scores = buffer_metrics(moved, truth, buffer_m=3.0)
    >>> round(scores.completeness, 3), round(scores.correctness, 3), round(scores.quality, 3)
    (1.0, 1.0, 1.0)
    >>> 0.5 < scores.rms_m < 1.0   # 1 m east is less than 1 m across a road not north-south
    True
    >>> buffer_metrics(moved, truth, buffer_m=0.5).completeness < 0.5
    True
    """
    ext, ref, _ = metric_lines(extracted, reference, valid_area=valid_area)
    ext_union, ref_union = shapely.union_all(ext), shapely.union_all(ref)
    ext_matched, ext_unmatched = _split_by_buffer(ext_union, ref_union, buffer_m)
    ref_matched, ref_unmatched = _split_by_buffer(ref_union, ext_union, buffer_m)
    matched_ext, unmatched_ext, matched_ref, unmatched_ref = (
        float(length) for length in shapely.length(
            [ext_matched, ext_unmatched, ref_matched, ref_unmatched]))
    # Totals as sums of their parts keep every ratio within [0, 1] despite rounding.
    ext_length, ref_length = matched_ext + unmatched_ext, matched_ref + unmatched_ref
    return BufferMetrics(
        completeness=matched_ref / ref_length,
        correctness=matched_ext / ext_length if ext_length > 0 else float("nan"),
        quality=matched_ext / (ext_length + unmatched_ref),
        rms_m=_sampled_rms(_line_pieces(ext_matched), ref, rms_step_m),
        extracted_length_m=ext_length, reference_length_m=ref_length,
        matched_extracted_m=matched_ext, matched_reference_m=matched_ref,
        buffer_m=float(buffer_m))


def _status_layer(inside, outside, matched: str, unmatched: str, crs) -> gpd.GeoDataFrame:
    pieces = [_line_pieces(inside), _line_pieces(outside)]
    geoms = np.concatenate(pieces)
    status = np.repeat(np.array([matched, unmatched], dtype=object), [len(p) for p in pieces])
    return gpd.GeoDataFrame({"status": status, "length_m": shapely.length(geoms)},
                            geometry=geoms, crs=crs)


def match_layers(extracted, reference, *, buffer_m: float = 3.0,
                 valid_area=None) -> dict[str, gpd.GeoDataFrame]:
    """QA layers of the buffer match, for display in QGIS.

    Parameters
    ----------
    extracted, reference, buffer_m, valid_area
        As in :func:`buffer_metrics`.

    Returns
    -------
    dict
        ``eval_extracted``: dissolved extracted lines cut at the reference's buffer, with
        ``status`` 'TP' (within ``buffer_m`` of the reference) or 'FP', and ``length_m``;
        ``eval_reference``: the same for the reference, ``status`` 'TP' or 'FN'. Both are in
        the working CRS (the reference's, or its UTM zone when that is geographic).
    """
    ext, ref, crs = metric_lines(extracted, reference, valid_area=valid_area)
    ext_union, ref_union = shapely.union_all(ext), shapely.union_all(ref)
    return {
        "eval_extracted": _status_layer(*_split_by_buffer(ext_union, ref_union, buffer_m),
                                        "TP", "FP", crs),
        "eval_reference": _status_layer(*_split_by_buffer(ref_union, ext_union, buffer_m),
                                        "TP", "FN", crs),
    }
