"""Conflation of extracted road centre lines with an existing road database.

Both sides are sampled every ``step_m`` along their lines. Each sample looks for the nearest
line of the other side within ``search_m`` whose direction differs by at most
``max_angle_deg`` (a crossing road is no match), and the match must be mutual: the sample of
the other side at the matched place must point back to the same road (so that one of two
carriageways 11 m apart does not claim the extracted line of the other). A sample closer than
``tolerance_m`` to a compatible line is matched without that check. Database lines are cut
into stretches of about ``stretch_m``; a stretch is seen when most of its samples match, so a
road seen only in part gives ``missing`` stretches. All of it is vectorised over samples
(shapely 2 STRtree queries, numpy index arithmetic).

Layers (all in the database's CRS; distances and widths in metres):

``confirmed``
    Database roads seen in the data (matched share >= ``min_share``): ``db_id``,
    ``matched_share``, ``mean_offset_m``, ``max_offset_m`` (the largest distance of a matched
    database sample to the extraction, a directed Hausdorff distance), ``db_width_m``,
    ``measured_width_m``, ``width_diff_m``, ``moved``, ``width_changed``, then every column
    of the database unchanged.
``missing``
    Runs of database stretches not seen: ``db_id``, ``length_m``, ``observable_share`` (share
    of the run inside the coverage), ``evidence`` (``not_seen`` where the data could show the
    road, ``not_observable`` where it could not, ``unknown`` without a coverage), then the
    database's columns.
``new``
    Runs of extracted lines matching no database road, at least ``min_new_m`` long:
    ``road_id`` (the extraction's), ``length_m``, ``width_m``, ``score``, ``start_db_id`` and
    ``end_db_id`` (the database road each end touches, within ``tolerance_m + step_m``; null
    where it touches none).
``moved``
    Seen roads whose median offset exceeds ``tolerance_m``, with the proposed geometry (the
    matched extracted line under the road): ``db_id``, the offsets, then the database's
    columns.
``proposed_update``
    The database with moved geometries and measured widths applied, the new roads appended,
    and ``change`` (``unchanged``, ``moved``, ``width``, ``missing`` or ``new``).

Computed columns replace database columns of the same name in the outputs.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import geopandas as gpd
import numpy as np
import pandas as pd
import shapely
from pyproj import CRS, Transformer

from ..errors import GisroadsError
from ..geo import GeoRaster
from ..progress import Progress, report

LAYERS = ("confirmed", "missing", "new", "moved", "proposed_update")
"""Output layer names, in the order they are written (their QML styles are named alike)."""

CHANGES = ("unchanged", "moved", "width", "missing", "new")
"""Values of ``proposed_update.change``."""


@dataclass(frozen=True)
class _Samples:
    """Points every ``step`` along lines, both ends included.

    ``line``: index of the sampled line per sample; ``chainage``: distance from the line's
    start (m); ``xy`` and unit ``direction`` per sample; ``first``, ``count`` and ``spacing``
    per line, so the sample of line ``k`` nearest chainage ``c`` is
    ``first[k] + round(c / spacing[k])``.
    """

    points: np.ndarray
    xy: np.ndarray
    direction: np.ndarray
    line: np.ndarray
    chainage: np.ndarray
    first: np.ndarray
    count: np.ndarray
    spacing: np.ndarray

    def nearest_sample(self, line: np.ndarray, chainage: np.ndarray) -> np.ndarray:
        """Index of the sample of ``line`` nearest ``chainage`` (metres along it)."""
        k = np.rint(chainage / self.spacing[line]).astype(np.int64)
        return self.first[line] + np.clip(k, 0, self.count[line] - 1)


def _tangents(lines: np.ndarray, chainage: np.ndarray, half_m: float = 1.0) -> np.ndarray:
    """Unit direction of ``lines`` at ``chainage`` (m), from points ``half_m`` either side;
    zero where the line has no length."""
    length = shapely.length(lines)
    ahead = shapely.line_interpolate_point(lines, np.minimum(chainage + half_m, length))
    behind = shapely.line_interpolate_point(lines, np.maximum(chainage - half_m, 0.0))
    delta = shapely.get_coordinates(ahead) - shapely.get_coordinates(behind)
    norm = np.hypot(delta[:, 0], delta[:, 1])
    return delta / np.where(norm > 0, norm, 1.0)[:, None]


def _sample(lines: np.ndarray, step_m: float) -> _Samples:
    """Sample 2D LineStrings evenly, at most ``step_m`` apart (see :class:`_Samples`)."""
    length = shapely.length(lines)
    count = np.maximum(np.ceil(length / step_m).astype(np.int64), 1) + 1
    spacing = np.maximum(length / (count - 1), 1e-9)
    line = np.repeat(np.arange(len(lines)), count)
    first = np.cumsum(count) - count
    chainage = (np.arange(count.sum()) - first[line]) * spacing[line]
    points = shapely.line_interpolate_point(lines[line], chainage)
    return _Samples(points, shapely.get_coordinates(points), _tangents(lines[line], chainage),
                    line, chainage, first, count, spacing)


@dataclass(frozen=True)
class _Nearest:
    """Per sample, the nearest compatible line of the other side (``line`` -1: none within
    reach), the chainage of the nearest point on it (m), that point's ``xy`` (NaN where
    none), the distance to it (m), whether it is an end of the line (the sample lies beyond
    the line's end), and the distance (m) to the closest compatible line, chosen or not."""

    line: np.ndarray
    chainage: np.ndarray
    xy: np.ndarray
    distance: np.ndarray
    beyond_end: np.ndarray
    closest: np.ndarray


@dataclass(frozen=True)
class _Pairs:
    """The other side's samples paired both ways (:func:`_mutual`) with a line of this side:
    ``line`` per sample of the other side (-1: none), ``group_of_line`` this side's feature
    per line, and ``own_group`` this side's feature per sample being matched."""

    samples: _Samples
    line: np.ndarray
    group_of_line: np.ndarray
    own_group: np.ndarray


def _nearest_compatible(samples: _Samples, lines: np.ndarray, search_m: float,
                        min_cos: float, pairs: _Pairs | None = None) -> _Nearest:
    """For each sample, the nearest line within ``search_m`` whose direction there is within
    the angle whose cosine is ``min_cos`` of the sample's (either way along).

    A line the sample lies beside ranks before one it lies beyond the end of: past the end of
    a database road, the extracted line's own continuation belongs to the next road, or to
    the same road moved sideways, not to the road that stops there. With ``pairs``, a line
    whose place there is paired both ways with another feature ranks after one that is not:
    a road moved onto its twin carriageway matches its own extracted line 5-10 m away, not
    the twin's; a line that every candidate shares (one line drawn down a divided road)
    still matches.
    """
    n = len(samples.points)
    source, target = shapely.STRtree(lines).query(samples.points, predicate="dwithin",
                                                  distance=search_m)
    chainage = shapely.line_locate_point(lines[target], samples.points[source])
    cos = np.abs(np.einsum("ij,ij->i", samples.direction[source],
                           _tangents(lines[target], chainage)))
    keep = cos >= min_cos
    source, target, chainage = source[keep], target[keep], chainage[keep]
    distance = shapely.distance(samples.points[source], lines[target])
    beyond = (chainage <= 1e-6) | (chainage >= shapely.length(lines[target]) - 1e-6)
    claimed = np.zeros(len(source), dtype=bool)
    if pairs is not None:
        partner = pairs.line[pairs.samples.nearest_sample(target, chainage)]
        claimed = (partner >= 0) & (pairs.group_of_line[np.maximum(partner, 0)]
                                    != pairs.own_group[source])
    order = np.lexsort((distance, beyond, claimed, source))
    best = order[np.r_[True, np.diff(source[order]) != 0]] if len(order) else order
    result = _Nearest(np.full(n, -1), np.zeros(n), np.full((n, 2), np.nan),
                      np.full(n, np.inf), np.zeros(n, dtype=bool), np.full(n, np.inf))
    np.minimum.at(result.closest, source, distance)
    result.line[source[best]] = target[best]
    result.chainage[source[best]] = chainage[best]
    result.distance[source[best]] = distance[best]
    result.beyond_end[source[best]] = beyond[best]
    result.xy[source[best]] = shapely.get_coordinates(shapely.line_interpolate_point(
        lines[target[best]], chainage[best]))
    return result


def _mutual(near: _Nearest, other: _Samples, other_near: _Nearest, own_group: np.ndarray,
            group_of_own_line: np.ndarray) -> np.ndarray:
    """True where a sample's match points back: the other side's sample at the matched place
    has its own nearest line in the sample's group (the same database feature, or the same
    extracted line). A sample beyond the end of its nearest line does not match that way:
    the line stops before it."""
    found = (near.line >= 0) & ~near.beyond_end
    back = np.full(len(near.line), -1)
    idx = other.nearest_sample(near.line[found], near.chainage[found])
    back_line = other_near.line[idx]
    back[found] = np.where(back_line >= 0, group_of_own_line[np.maximum(back_line, 0)], -1)
    return found & (back == own_group)


@dataclass(frozen=True)
class _Runs:
    """Runs of consecutive flagged samples of one line: per sample its run number (-1 where
    not flagged); per run its first sample, its number of samples and the LineString through
    its samples' points."""

    of_sample: np.ndarray
    first: np.ndarray
    size: np.ndarray
    lines: np.ndarray


def _runs(flag: np.ndarray, line: np.ndarray, xy: np.ndarray) -> _Runs:
    """The runs of ``flag`` along sampled lines (``line`` per sample, points ``xy``)."""
    start = flag & ~np.r_[False, flag[:-1] & (line[1:] == line[:-1])]
    run = np.where(flag, np.cumsum(start) - 1, -1)
    first = np.flatnonzero(start)
    size = np.bincount(run[flag], minlength=len(first))
    # a run of one sample repeats its point: a zero-length line keeps runs and lines aligned
    vertices = np.sort(np.concatenate([np.flatnonzero(flag), first[size == 1]]))
    lines = (shapely.linestrings(xy[vertices], indices=run[vertices]) if len(first)
             else np.empty(0, dtype=object))
    return _Runs(run, first, size, lines)


def _working_crs(extracted: gpd.GeoDataFrame, database: gpd.GeoDataFrame) -> CRS:
    """The extraction's CRS when it is projected in metres, else the UTM zone over the
    extraction (over the database when the extraction is empty)."""
    crs = CRS.from_user_input(extracted.crs)
    unit = crs.axis_info[0].unit_name if crs.is_projected else ""
    if unit in ("metre", "meter"):
        return crs
    return CRS.from_user_input((extracted if len(extracted) else database).estimate_utm_crs())


def _line_parts(frame: gpd.GeoDataFrame, crs: CRS) -> tuple[np.ndarray, np.ndarray]:
    """2D LineString parts of a frame's lines in ``crs`` and the row position of each."""
    geoms = np.asarray(frame.to_crs(crs).geometry.values, dtype=object)
    parts, row = shapely.get_parts(shapely.force_2d(geoms), return_index=True)
    lineal = shapely.get_type_id(parts) == shapely.GeometryType.LINESTRING
    usable = lineal & (shapely.length(parts) > 0)
    return parts[usable], row[usable]


def _observable(xy: np.ndarray, crs: CRS, coverage) -> np.ndarray:
    """Per point: 1.0 inside the coverage, 0.0 outside, NaN without a coverage.

    ``coverage`` is a polygon GeoDataFrame (any CRS) or a :class:`GeoRaster` whose cells
    other than 0, NaN and no-data are observable.
    """
    if coverage is None:
        return np.full(len(xy), np.nan)
    if isinstance(coverage, GeoRaster):
        if coverage.crs is not None and CRS.from_user_input(coverage.crs) != crs:
            x, y = Transformer.from_crs(crs, coverage.crs, always_xy=True).transform(
                xy[:, 0], xy[:, 1])
        else:
            x, y = xy[:, 0], xy[:, 1]
        band = coverage.data if coverage.data.ndim == 2 else coverage.data[0]
        row, col = coverage.xy_to_rowcol(x, y)
        inside = (row >= 0) & (row < band.shape[0]) & (col >= 0) & (col < band.shape[1])
        value = np.zeros(len(xy))
        value[inside] = band[row[inside], col[inside]]
        seen = np.isfinite(value) & (value != 0)
        if coverage.nodata is not None:
            seen &= value != coverage.nodata
        return seen.astype(float)
    polygons = coverage.to_crs(crs) if coverage.crs is not None else coverage
    area = shapely.union_all(polygons.geometry.values)
    return shapely.contains_xy(area, xy[:, 0], xy[:, 1]).astype(float)


def _feature_ids(database: gpd.GeoDataFrame, id_field: str | None) -> pd.Series:
    """The database's feature ids: column ``id_field``, else its index (OGR's FIDs when read
    with :func:`gisroads.update.read_database`)."""
    if id_field is None:
        return pd.Series(database.index.to_numpy(), index=database.index, name="db_id")
    if id_field not in database.columns:
        raise GisroadsError(f"the database has no field {id_field!r}; its fields are "
                            f"{[c for c in database.columns if c != database.geometry.name]}")
    return database[id_field].rename("db_id")


def _with_database(stats: pd.DataFrame, database: gpd.GeoDataFrame, rows: np.ndarray,
                   geometry, crs) -> gpd.GeoDataFrame:
    """Computed columns, then the database's columns of ``rows`` unchanged, on ``geometry``."""
    attributes = database.drop(columns=[database.geometry.name]).iloc[rows]
    attributes = attributes.drop(columns=[c for c in stats.columns if c in attributes])
    frame = pd.concat([stats.reset_index(drop=True), attributes.reset_index(drop=True)], axis=1)
    return gpd.GeoDataFrame(frame, geometry=gpd.GeoSeries(geometry, crs=crs), crs=crs)


def _proposed_geometries(db: _Samples, db_near: _Nearest, matched: np.ndarray,
                         of_moved_road: np.ndarray, db_feature: np.ndarray,
                         moved_rows: np.ndarray, n_ext: int) -> np.ndarray:
    """The proposed geometry of each moved road (rows ``moved_rows``): the nearest points on
    the extracted lines its matched samples chose, over every sample of the road whose
    nearest compatible line is one of those (so that it reaches the road's ends)."""
    chosen = np.unique(db.line[matched] * n_ext + db_near.line[matched])
    along = (of_moved_road & (db_near.line >= 0)
             & np.isin(db.line * n_ext + db_near.line, chosen))
    runs = _runs(along, db.line, db_near.xy)
    proposed = shapely.multilinestrings(
        runs.lines, indices=np.searchsorted(moved_rows, db_feature[runs.first]))
    single = shapely.get_num_geometries(proposed) == 1
    proposed[single] = shapely.get_geometry(proposed[single], 0)
    return shapely.simplify(proposed, 0.05)


def _new_layer(extracted: gpd.GeoDataFrame, ext: _Samples, ext_seen: np.ndarray,
               ext_row: np.ndarray, min_new_m: float, db_lines: np.ndarray,
               db_line_ids: np.ndarray, touch_m: float) -> gpd.GeoDataFrame:
    """Runs of unmatched extracted samples at least ``min_new_m`` long, with the id of the
    database line each end touches (within ``touch_m``), in the working CRS."""
    runs = _runs(~ext_seen, ext.line, ext.xy)
    long_enough = shapely.length(runs.lines) >= min_new_m
    lines, row = runs.lines[long_enough], ext_row[ext.line[runs.first[long_enough]]]
    tree = shapely.STRtree(db_lines)

    def touched(points):
        """Database id of the line nearest each point within ``touch_m``, else null."""
        point, line = tree.query_nearest(points, max_distance=touch_m)
        found = pd.Series(db_line_ids[line], index=point).groupby(level=0).first().reindex(
            np.arange(len(points)))
        return found.astype("Int64") if pd.api.types.is_integer_dtype(db_line_ids) else found

    def column(name, default):
        return extracted[name].to_numpy()[row] if name in extracted else default

    return gpd.GeoDataFrame({
        "road_id": column("road_id", row),
        "length_m": shapely.length(lines),
        "width_m": column("width_m", np.full(len(row), np.nan)).astype(float),
        "score": column("score", np.full(len(row), np.nan)).astype(float),
        "start_db_id": touched(shapely.get_point(lines, 0)),
        "end_db_id": touched(shapely.get_point(lines, -1))}, geometry=lines)


def _proposed_update(database: gpd.GeoDataFrame, change: np.ndarray, moved_rows: np.ndarray,
                     proposed: np.ndarray, width_field: str | None, new_width: np.ndarray,
                     index_ids: pd.Series | None, new: gpd.GeoDataFrame) -> gpd.GeoDataFrame:
    """The database with the proposed geometries and widths (``new_width``, NaN: keep),
    ``change``, the index ids as ``db_id`` when the ids are the index, and the new roads
    appended (``change`` 'new', the database's fields null but the width)."""
    update = database.copy()
    geometry = np.asarray(database.geometry.values, dtype=object)
    geometry[moved_rows] = proposed
    update[update.geometry.name] = gpd.GeoSeries(geometry, index=update.index,
                                                 crs=database.crs)
    if width_field is not None:
        update[width_field] = np.where(np.isnan(new_width),
                                       update[width_field].astype(float), new_width)
    if index_ids is not None:
        update["db_id"] = index_ids.to_numpy()
    update["change"] = change
    # integer columns (ids above all) stay integers, null on the appended new roads
    integers = [c for c in update.columns if pd.api.types.is_integer_dtype(update[c])]
    update[integers] = update[integers].astype("Int64")
    additions = gpd.GeoDataFrame({"change": np.full(len(new), "new", dtype=object),
                                  **({width_field: new["width_m"].to_numpy()} if width_field
                                     else {}),
                                  update.geometry.name: new.geometry.values},
                                 geometry=update.geometry.name, crs=database.crs)
    return gpd.GeoDataFrame(
        pd.concat([update.reset_index(drop=True), additions], ignore_index=True),
        geometry=update.geometry.name, crs=database.crs)


@dataclass(frozen=True)
class MatchOptions:
    """The options of :func:`conflate`: how far and how alike an extracted line and a
    database road must be to match, and the least change reported.

    Attributes
    ----------
    tolerance_m : float
        A seen road whose median offset from the extraction exceeds this is ``moved``
        (metres); samples closer than this to a compatible line always match.
    search_m : float
        Largest offset (metres) at which a database road and an extracted line can still be
        the same road: the largest displacement detected as ``moved``.
    max_angle_deg : float
        Largest direction difference (degrees) between matched lines.
    width_tolerance_m : float
        A measured width differing from the database's by more than this (metres) is a
        width change.
    stretch_m : float
        Length (metres) of the database stretches that are seen or missing as a whole.
    step_m : float
        Sampling step along both sides (metres).
    min_share : float
        Share of a database road's length that must be seen for it to be confirmed; below
        it the road is ``missing``.
    min_new_m : float
        Shortest unmatched run of an extracted line reported as ``new`` (metres).
    """

    tolerance_m: float = 3.0
    search_m: float = 15.0
    max_angle_deg: float = 30.0
    width_tolerance_m: float = 2.0
    stretch_m: float = 15.0
    step_m: float = 2.0
    min_share: float = 0.5
    min_new_m: float = 15.0


def conflate(extracted: gpd.GeoDataFrame, database: gpd.GeoDataFrame,
             options: MatchOptions = MatchOptions(), *, id_field: str | None = None,
             width_field: str | None = None, coverage=None, progress: Progress = None,
             **changes) -> dict[str, gpd.GeoDataFrame]:
    """Compare extracted centre lines with a road database: the change layers.

    Parameters
    ----------
    extracted : GeoDataFrame
        Extracted centre lines with a CRS (a gisroads ``road_centrelines`` layer: ``road_id``,
        ``width_m``, ``score`` are used when present).
    database : GeoDataFrame
        Road lines (LineString or MultiLineString) in any CRS; reprojected to the
        extraction's for matching, results written back in the database's CRS.
    id_field : str, optional
        Field holding the database's feature ids; by default the frame's index.
    width_field : str, optional
        Field holding the database's road widths (metres); without it widths are measured
        but not compared.
    coverage : GeoDataFrame or GeoRaster, optional
        Where the data could show a road (polygons, or a raster whose non-zero cells are
        observable: e.g. the data footprint minus occlusion by trees and buildings).
    options : MatchOptions
        Matching distances, angles and least changes (:class:`MatchOptions`).
    progress : callable, optional
    **changes
        Fields of ``options`` to change for this call.

    Returns
    -------
    dict of str to GeoDataFrame
        The layers :data:`LAYERS`, in the database's CRS (see the module docstring).

    Examples
    --------
    A synthetic scene's roads as the extraction, against a database of them where one road
    is gone on the ground, one is not in the database yet and one was digitised 6 m north:

    >>> from gisroads.synthetic import make_scene
    >>> from gisroads.update import conflate
    >>> roads = make_scene(seed=0, size_m=(300, 300)).truth.centrelines
    >>> extracted = roads[roads.road_id != 0]            # road 0 is gone
    >>> database = roads[roads.road_id != 5].copy()      # road 5 is new
    >>> off = database.road_id == 6                      # road 6 is 6 m off
    >>> database.loc[off, "geometry"] = database.geometry[off].translate(yoff=6.0)
    >>> changes = conflate(extracted, database, id_field="road_id", width_field="width_m")
    >>> {name: len(layer) for name, layer in changes.items()}
    {'confirmed': 7, 'missing': 1, 'new': 1, 'moved': 1, 'proposed_update': 9}
    >>> changes["missing"].db_id.tolist(), changes["moved"].db_id.tolist()
    ([0], [6])
    >>> changes["proposed_update"].change.value_counts().sort_index().to_dict()
    {'missing': 1, 'moved': 1, 'new': 1, 'unchanged': 6}
    """
    options = replace(options, **changes)
    if extracted.crs is None or database.crs is None:
        raise GisroadsError("both the extraction and the database need a CRS")
    if not options.tolerance_m < options.search_m:
        raise GisroadsError(f"the tolerance ({options.tolerance_m} m) must be below the search "
                            f"distance ({options.search_m} m)")
    ids = _feature_ids(database, id_field)
    if width_field is not None and width_field not in database.columns:
        raise GisroadsError(f"the database has no width field {width_field!r}")
    report(progress, 0.0, "sampling")
    crs, db_crs = _working_crs(extracted, database), CRS.from_user_input(database.crs)
    db_lines, db_row = _line_parts(database, crs)
    if len(db_lines) == 0:
        raise GisroadsError("the database holds no line geometry")
    ext_lines, ext_row = _line_parts(extracted, crs)
    db, ext = _sample(db_lines, options.step_m), _sample(ext_lines, options.step_m)

    report(progress, 0.2, "matching")
    min_cos = np.cos(np.radians(options.max_angle_deg))
    db_near = _nearest_compatible(db, ext_lines, options.search_m, min_cos)
    ext_near = _nearest_compatible(ext, db_lines, options.search_m, min_cos)
    db_feature = db_row[db.line]
    # the places already paired both ways are claimed: match again around them
    db_pair = np.where(_mutual(db_near, ext, ext_near, db_feature, db_row), db_near.line, -1)
    ext_pair = np.where(_mutual(ext_near, db, db_near, ext_row[ext.line], ext_row),
                        ext_near.line, -1)
    db_near = _nearest_compatible(db, ext_lines, options.search_m, min_cos,
                                  _Pairs(ext, ext_pair, db_row, db_feature))
    ext_near = _nearest_compatible(ext, db_lines, options.search_m, min_cos,
                                   _Pairs(db, db_pair, ext_row, ext_row[ext.line]))
    db_seen = (_mutual(db_near, ext, ext_near, db_feature, db_row)
               | (db_near.closest <= options.tolerance_m))
    ext_seen = (_mutual(ext_near, db, db_near, ext_row[ext.line], ext_row)
                | (ext_near.closest <= options.tolerance_m))

    report(progress, 0.5, "stretches")
    n_stretches = np.maximum(np.rint(shapely.length(db_lines) / options.stretch_m),
                             1).astype(np.int64)
    stretch_length = shapely.length(db_lines) / n_stretches
    stretch = np.minimum((db.chainage // stretch_length[db.line]).astype(np.int64),
                         n_stretches[db.line] - 1)
    stretch_key = np.cumsum(n_stretches)[db.line] - n_stretches[db.line] + stretch
    stretch_seen = (np.bincount(stretch_key, db_seen, n_stretches.sum())
                    >= 0.5 * np.bincount(stretch_key, minlength=n_stretches.sum()))
    seen = stretch_seen[stretch_key]

    n_rows = len(database)
    weight = db.spacing[db.line]
    sampled = np.bincount(db_feature, weight, n_rows)
    share = np.divide(np.bincount(db_feature, weight * seen, n_rows), sampled,
                      out=np.zeros(n_rows), where=sampled > 0)
    matched = seen & db_seen
    offset = np.where(matched, db_near.distance, np.nan)
    frame = pd.DataFrame({"row": db_feature, "offset": offset})
    offsets = frame.groupby("row")["offset"].agg(["mean", "max", "median"]).reindex(
        range(n_rows))
    ext_width = (extracted["width_m"].to_numpy(float) if "width_m" in extracted
                 else np.full(len(extracted), np.nan))
    sample_width = np.full(len(matched), np.nan)
    sample_width[matched] = ext_width[ext_row[db_near.line[matched]]]
    measured = pd.Series(sample_width).groupby(db_feature).mean().reindex(
        range(n_rows)).to_numpy()
    db_width = (pd.to_numeric(database[width_field], errors="coerce").to_numpy(float)
                if width_field else np.full(n_rows, np.nan))
    confirmed = share >= options.min_share
    moved = confirmed & (offsets["median"].to_numpy() > options.tolerance_m)
    width_diff = measured - db_width
    width_changed = confirmed & (np.abs(width_diff) > options.width_tolerance_m)
    change = np.select([~confirmed, moved, width_changed], ["missing", "moved", "width"],
                       "unchanged").astype(object)

    to_db = Transformer.from_crs(crs, db_crs, always_xy=True)

    def back(geoms):
        """Geometries from the working CRS to the database's."""
        return shapely.transform(geoms, lambda xy: np.column_stack(
            to_db.transform(xy[:, 0], xy[:, 1])))

    report(progress, 0.6, "moved roads")
    moved_rows = np.flatnonzero(moved)
    proposed = back(_proposed_geometries(db, db_near, matched, moved[db_feature],
                                         db_feature, moved_rows, len(ext_lines)))

    report(progress, 0.7, "missing stretches")
    runs = _runs(~seen, db.line, db.xy)
    run_line = db.line[runs.first]
    whole = runs.size == db.count[run_line]
    runs.lines[whole] = db_lines[run_line[whole]]
    unseen = ~seen
    observable = (np.bincount(runs.of_sample[unseen],
                              _observable(db.xy, crs, coverage)[unseen], len(runs.first))
                  / np.maximum(runs.size, 1))
    evidence = np.select([np.isnan(observable), observable >= 0.5],
                         ["unknown", "not_seen"], "not_observable").astype(object)
    run_row = db_row[run_line]
    missing = _with_database(pd.DataFrame({
        "db_id": ids.to_numpy()[run_row], "length_m": shapely.length(runs.lines),
        "observable_share": observable, "evidence": evidence}),
        database, run_row, back(runs.lines), db_crs)

    report(progress, 0.8, "new roads")
    new = _new_layer(extracted, ext, ext_seen, ext_row, options.min_new_m, db_lines,
                     ids.to_numpy()[db_row], options.tolerance_m + options.step_m)
    new = new.set_geometry(gpd.GeoSeries(back(new.geometry.values), crs=db_crs), crs=db_crs)

    report(progress, 0.9, "layers")
    stats = pd.DataFrame({"db_id": ids.to_numpy(), "matched_share": share,
                          "mean_offset_m": offsets["mean"].to_numpy(),
                          "max_offset_m": offsets["max"].to_numpy(),
                          "db_width_m": db_width, "measured_width_m": measured,
                          "width_diff_m": width_diff, "moved": moved,
                          "width_changed": width_changed})
    rows = np.flatnonzero(confirmed)
    replace_width = width_changed & np.isfinite(measured)
    layers = {
        "confirmed": _with_database(stats.iloc[rows], database, rows,
                                    database.geometry.values[rows], db_crs),
        "missing": missing,
        "new": new,
        "moved": _with_database(stats.iloc[moved_rows][["db_id", "matched_share",
                                                        "mean_offset_m", "max_offset_m"]],
                                database, moved_rows, proposed, db_crs),
        "proposed_update": _proposed_update(
            database, change, moved_rows, proposed, width_field,
            np.where(replace_width, measured, np.nan), ids if id_field is None else None, new),
    }
    report(progress, 1.0, "done")
    return layers
